"""Bad input never renders NaN, Inf or negative values, and clamps as documented.

Values reach the shader through linked Value / Combine nodes (a node group's own sockets clamp to
their range in the UI, but a linked input does not), so the OSL clamps themselves are tested:
roughness outside [0, 1] or NaN, IOR at or below 0 or NaN, negative n or k. Roughness 0 is a
perfect mirror with no division by zero: deterministic, so it is compared to the reference
mirror without noise.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness  # noqa: E402
from addon.catalog import MODELS  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

NAN = float("nan")
BAD = [
    {"roughness": -1.0}, {"roughness": 2.0}, {"roughness": NAN}, {"roughness": 0.0},
    {"ior": 0.0, "fresnel_type": "dielectric"}, {"ior": -3.0, "fresnel_type": "dielectric"},
    {"ior": NAN, "fresnel_type": "dielectric"}, {"ior": 1.0, "fresnel_type": "dielectric"},
    {"n": (-1.0, 0.0, NAN)}, {"k": (-2.0, NAN, 0.0)}, {"n": (0.0, 0.0, 0.0), "k": (0.0, 0.0, 0.0)},
    {"roughness": 1e-9},
]


def linked_material(model_id, bad, name):
    return lambda: harness.linked_model_material(model_id, bad, name)


@pytest.fixture(scope="module")
def stress():
    cases = [(m, b) for m in MODELS for b in BAD if all(k in MODELS[m].resolve() for k in b)]
    makers = [linked_material(m, b, f"bad {i}") for i, (m, b) in enumerate(cases)]
    layout, image, _ = harness.render_specs(None, grid.GRADIENT, 16, seed=7, cols=6,
                                            materials=makers)
    return cases, layout, image


def test_stress_grid_is_finite_and_non_negative(stress):
    cases, layout, image = stress
    index, _, _ = layout.pixel_geometry()
    for i, (model, bad) in enumerate(cases):
        px = image[index == i][:, :3]
        assert np.isfinite(px).all(), f"{model} {bad}: NaN/Inf pixels"
        assert (px >= 0).all(), f"{model} {bad}: negative pixels"
        if bad.get("ior") != 1.0:  # index-matched dielectric reflects nothing: black is right
            assert px.max() > 0, f"{model} {bad}: rendered black (shader did not run?)"


MIRRORS = [{"roughness": 0.0}, {"roughness": -1.0}, {"roughness": 1e-9}]


REFLECTION_MODELS = [m for m in MODELS if "transmission" not in MODELS[m].tags]


@pytest.mark.parametrize("model_id", REFLECTION_MODELS)
def test_roughness_zero_and_below_is_the_exact_mirror(model_id):
    """Deterministic, so one sample per pixel (it lands on the pixel centre) is compared with
    the reference mirror pixel by pixel. Cook-Torrance's diffuse part is switched off.
    (Perfect glass picks reflection or refraction at random: tests/test_render_glass.py.)"""
    base = {"specular": 1.0} if model_id == "cook_torrance" else {}
    makers = [linked_material(model_id, {**base, **bad}, f"mirror {i}")
              for i, bad in enumerate(MIRRORS)]
    layout, image, _ = harness.render_specs(None, grid.GRADIENT, 1, seed=3, cols=3,
                                            materials=makers)
    spec = SphereSpec(model_id, {**base, "roughness": 0.0})
    reference = grid.reference_grid_image(layout, [spec] * len(MIRRORS), grid.GRADIENT)
    index, _, mu = layout.pixel_geometry()
    for i, bad in enumerate(MIRRORS):
        sel = (index == i) & (mu > 0.05)
        err = np.abs(image[sel][:, :3] - reference[sel]).max()
        assert err < 2e-5, f"{model_id} {bad}: mirror off by {err}"
