"""Heitz 2016 multiple scattering rendered in Cycles OSL (osl/heitz2016.osl): what only the walk
has (its sphere grids against the twin's Monte Carlo moment tables are
tests/test_render_grids.py's `heitz2016` suite).

1. The zero-noise furnace: with F = 1 every walk that escapes weighs exactly 1 and none is lost
   at Max Bounces 100 (measured share below 1e-5), so every pixel is 1 at any roughness (the
   Stochastic estimator: the native part of Native + Residual is light-sampled, hence noisy).
2. Max Bounces 1 is single scattering: the walk's first order equals Walter 2007 with the
   height-correlated Smith G2 (the paper's result), held against the quadrature reference of
   `walter_reflection` (an independent formula and integrator, not the walk), and the full walk
   is measurably brighter than it at roughness 1 (multiple scattering is there).
3. Light Sampling under a lamp: Native + Residual against Stochastic under a 45-degree sun over
   a black world, pixel by pixel.
What this catches: walks cut short or weighted wrong, a first order that is not Walter's, the
native part counted twice or missed.
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402
from grid_suites import HEITZ  # noqa: E402


# -- the zero-noise furnace ---------------------------------------------------------------------
def test_zero_noise_furnace():
    """F = 1: every escaped walk weighs exactly 1, so 4 samples per pixel give 1 everywhere, for
    both distributions from the mirror to roughness 1."""
    specs = [SphereSpec("heitz2016", {"fresnel_type": "none", "distribution": d, "roughness": r,
                                      "estimator": "stochastic"}, f"{d} {r}")
             for d in ("ggx", "beckmann") for r in (0.0, 0.05, 0.3, 0.6, 0.8, 1.0)]
    layout, image, _ = harness.render_specs(specs, grid.WHITE, 4, seed=3, cols=6, cell_px=24)
    index, _, _ = layout.pixel_geometry()
    assert np.isfinite(image).all()
    err = np.abs(image[index >= 0][:, :3] - 1.0).max()
    assert err < 1e-4, f"max |pixel - 1| = {err}"


# -- Max Bounces 1: single scattering, against Walter 2007 height-correlated -------------------
FIRST_ORDER_ROUGHNESS = (0.3, 0.7, 1.0)


@pytest.fixture(scope="module")
def first_order():
    gold = {"fresnel_type": "conductor"}
    specs, controls = [], []
    for d in ("ggx", "beckmann"):
        for r in FIRST_ORDER_ROUGHNESS:
            specs.append(SphereSpec("heitz2016", {**gold, "distribution": d, "roughness": r,
                                                  "max_order": 1.0}, f"heitz {d} order 1 r={r}"))
            controls.append(SphereSpec("walter_reflection", {
                **gold, "distribution": d, "roughness": r, "masking": "height_correlated"},
                f"walter {d} hc r={r}"))
    full = [SphereSpec("heitz2016", {**gold, "distribution": "ggx", "roughness": 1.0},
                       "heitz ggx full walk r=1")]
    all_specs = specs + full
    layout, image, _ = harness.render_specs(all_specs, grid.GRADIENT, HEITZ.samples, seed=4,
                                            cell_px=HEITZ.cell_px)
    reference = grid.reference_grid_image(layout, controls + [None], grid.GRADIENT)
    return layout, image, reference, all_specs


def test_max_bounces_one_is_height_correlated_walter(first_order):
    layout, image, reference, specs = first_order
    bands = [b for b in grid.band_stats(layout, image, reference) if b.sphere < len(specs) - 1]
    z_crit = grid.sidak_z(3 * len(bands))
    failures = [f"{specs[b.sphere].label} mu in {b.band} side {b.side}: bias {b.bias} "
                f"stderr {b.stderr} ref {b.reference}"
                for b in bands if grid.inconsistent(b, z_crit)]
    assert not failures, f"z_crit {z_crit:.2f}:\n" + "\n".join(failures)


def test_full_walk_is_brighter_than_its_first_order(first_order):
    """The power of the test above: the higher orders at roughness 1 (GGX gold, about 10% of
    the light) are many standard errors away from single scattering."""
    layout, image, reference, specs = first_order
    index, _, mu = layout.pixel_geometry()
    full = image[(index == len(specs) - 1) & (mu > 0.05)][:, :3]
    single = image[(index == FIRST_ORDER_ROUGHNESS.index(1.0)) & (mu > 0.05)][:, :3]
    diff = full.mean(0) - single.mean(0)
    se = np.sqrt(full.var(0, ddof=1) / len(full) + single.var(0, ddof=1) / len(single))
    assert (diff > 10 * se).all(), f"full - first order {diff}, se {se}"


# -- Light Sampling: the native first order under a lamp ----------------------------------------
SUN_DEG = 45.0  # large enough for the stochastic walk to find it often
# Power margin (0.1 mean over the detectable error, the worst sphere), measured: 2.45 at 512 /
# 4096 samples, 1.82 at 256 / 2048, 1.63 at 256 / 1024 (the light-sampled render's noise weighs
# most), 1.16 at 128 / 1024.
SUN_SAMPLES = {"light_sampled": 256, "stochastic": 1024}


def _sun_row(estimator, seed):
    from addon.lab.report.scenes import add_sun

    specs = [SphereSpec("heitz2016", {**values, "roughness": r, "estimator": estimator},
                        f"{values['fresnel_type']} r={r} {estimator}")
             for values in ({"fresnel_type": "conductor"},
                            {"fresnel_type": "dielectric", "ior": 2.5})  # R: 18% at 0 deg
             for r in (0.3, 0.8)]
    scene = harness.new_scene()
    mats = [harness.model_material(s.model_id, s.values, f"{i:03d} {s.label}")
            for i, s in enumerate(specs)]
    layout = grid.GridLayout(rows=1, cols=len(specs), cell_px=48, spacing=2.2)
    harness.build_grid_scene(layout, mats, grid.Environment("black", 0.0),
                             SUN_SAMPLES[estimator], seed=seed)
    add_sun(scene, strength=1.0, angle_deg=SUN_DEG)
    image, _ = harness.render(scene)
    return layout, image, specs


def test_light_sampled_walk_equals_stochastic_walk_under_a_sun():
    """Native + Residual and Stochastic are two estimators of the same walk: under a 45-degree
    sun over a black world (so every bit of light comes through the lamp, which Cycles
    light-samples for the native part and the walk's delta exits hit by chance), their sphere
    means agree within the Sidak-corrected noise of both. Catches the native part counted
    twice or missed (MIS of the native closure with the lamp against the residual's hits), a
    wrong native factor c, or a wrong first-order residual. Power: the native first order is
    most of the light, so a double count would be an error of order the signal: the test must
    resolve 10% of each sphere's mean."""
    layout, split, specs = _sun_row("light_sampled", seed=7)
    _, stochastic, _ = _sun_row("stochastic", seed=8)
    assert np.isfinite(split).all() and np.isfinite(stochastic).all()
    # Per pixel the two renders have the same expectation: the band statistics of their
    # difference are its mean and noise (pixels are independent; the highlight cancels).
    diff = grid.band_stats(layout, split, stochastic)
    z_crit = grid.sidak_z(3 * len(diff))
    failures = []
    for d in diff:
        if (np.abs(d.bias) > z_crit * d.stderr).any():
            failures.append(f"{specs[d.sphere].label} mu in {d.band} side {d.side}: split - "
                            f"stochastic {d.bias} se {d.stderr} (stochastic mean {d.reference})")
    assert not failures, f"z_crit {z_crit:.2f}:\n" + "\n".join(failures)
    # Power: on whole spheres a 10% error of the brightest channel would be seen.
    spheres = grid.band_stats(layout, split, stochastic, bands=((0.05, 1.0001),), sides=False)
    z_s = grid.sidak_z(3 * len(spheres))
    margin = min(0.1 * d.reference.max() / (z_s * d.stderr.max()) for d in spheres)
    print(f"\n[heitz sun] power margin (10% of the mean over the detectable): {margin:.2f}")
    for d in spheres:
        assert 0.1 * d.reference.max() > z_s * d.stderr.max(), \
            f"{specs[d.sphere].label}: no power (se {d.stderr}, mean {d.reference})"
