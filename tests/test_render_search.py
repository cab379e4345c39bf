"""The OSL conductor Fresnel's least value over an interval (osl/split.h conductor_min, the
golden-section search of fresnel_min: Blender 4.x's native factor, and the lamp controls' bound
on every version) against its numpy twin (addon/lab/reference/split.py), case by case.

A plane seen by an orthographic camera, one pixel per case: the probe shader reads the case's
interval [lo, hi] and complex IOR per channel from a table by the pixel's column and row, and
emits the search's result (emission() gives its weight as the pixel's radiance). The OSL search
loops over sides and channels through one call site (docs/cycles-osl.md, "Constant folding"),
the twin broadcasts them, so this catches a step that keeps the wrong bracket, a point lost, a
side of the critical angle left out, a channel mixed up. The two differ by float32 rounding only
(measured below).
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import compat, shaders  # noqa: E402
from addon.lab import grid, harness  # noqa: E402
from addon.lab.reference import split  # noqa: E402

ROWS, COLS = 12, 16
SLOTS = 8  # lo, hi, n (3), k (3)

PROBE = """#include "split.h"
float case_datum(int i, int j)
{
    float table[%(size)d] = {%(data)s};
    return table[%(slots)d * i + j];
}

shader probe(output closure color Emission = 0)
{
    // The plane spans [-COLS/2, COLS/2] x [-ROWS/2, ROWS/2], one unit a pixel, row 0 at the top.
    int col = clamp(int(floor(P[0] + %(cols)d / 2.0)), 0, %(cols)d - 1);
    int row = clamp(int(floor(%(rows)d / 2.0 - P[1])), 0, %(rows)d - 1);
    int i = row * %(cols)d + col;
    color n = color(case_datum(i, 2), case_datum(i, 3), case_datum(i, 4));
    color k = color(case_datum(i, 5), case_datum(i, 6), case_datum(i, 7));
    Emission = conductor_min(case_datum(i, 0), case_datum(i, 1), n, k) * emission();
}
"""


def _cases(rng):
    """(ROWS * COLS, SLOTS): the intervals and indices the shaders meet, the hard ones often: n
    below 1 with little absorption (a cusp at the critical angle, two sides searched), k = 0,
    intervals from 1e-3 wide to [0, 1]."""
    count = ROWS * COLS
    lo = rng.uniform(0.0, 0.99, count)
    hi = np.minimum(1.0, lo + rng.choice([1e-3, 0.05, 0.5, 1.0], count))
    n = rng.choice([0.2, 0.6, 0.95], (count, 3)) * rng.uniform(0.9, 1.1, (count, 3))
    n = np.where(rng.random((count, 3)) < 0.5, n, rng.uniform(0.05, 3.0, (count, 3)))
    k = rng.choice([0.0, 0.3, 0.9], (count, 3))
    k = np.where(rng.random((count, 3)) < 0.5, k, rng.uniform(0.0, 6.0, (count, 3)))
    # float32 first: the shader reads the table as floats, so numpy gets the same inputs
    return np.column_stack([lo, hi, n, k]).astype(np.float32).astype(float)


def _probe_material(cases):
    data = ", ".join(f"{x:.9g}" for x in cases.ravel())
    source = PROBE % {"size": cases.size, "data": data, "slots": SLOTS, "rows": ROWS,
                      "cols": COLS}
    source = shaders.assemble(source)
    compat.expose_bundled_modules()
    material = harness.osl_material(source, "search probe")
    harness.check_compiled()
    return material


def test_the_osl_search_finds_what_its_twin_finds():
    cases = _cases(np.random.default_rng(11))
    layout = grid.GridLayout(rows=ROWS, cols=COLS, cell_px=1, spacing=1.0)
    scene = harness.new_scene()
    harness.configure_render(scene, layout, 1, 0)
    harness.add_camera(scene, layout)
    half_x, half_y = COLS / 2.0, ROWS / 2.0
    plane = harness.add_quad(scene, "probe plane", [(-half_x, -half_y, 0.0), (half_x, -half_y, 0.0),
                                                    (half_x, half_y, 0.0), (-half_x, half_y, 0.0)],
                             (0.0, 0.0, 0.0))
    plane.data.materials[0] = _probe_material(cases)
    image, _ = harness.render(scene)
    got = image[..., :3].reshape(-1, 3)

    lo, hi = cases[:, 0:1] * np.ones(3), cases[:, 1:2] * np.ones(3)
    want = split.conductor_min(cases[:, 2:5], cases[:, 5:8], lo, hi)
    diff = np.abs(got - want)
    rel = diff / want
    print(f"\n[conductor_min] {want.size} searches: relative difference median "
          f"{np.median(rel):.1e}, max {rel.max():.1e}; absolute max {diff.max():.1e}")
    # float32 rounding: about 1e-7 of F's terms, which are of order 1 and cancel where n is
    # near 1 and k near 0 (F down to 3e-7 here, known to a few percent in float32), hence the
    # absolute part; and where f1 and f2 differ by that much the two searches may keep different
    # brackets, both about the same minimum. A step that keeps the wrong bracket ends up to 2e-3
    # off (the search's own error bound, test_reference_controls), a lost side or channel far
    # more: over the bound wherever F exceeds 1e-4.
    assert np.all(diff <= 1e-6 * want + 1e-7), (diff.max(), np.argmax(diff - 1e-6 * want))
