"""The OSL models against Cycles' own closures: an anchor nobody here wrote.

Walter reflection with height-correlated Smith G2 is the model behind Cycles' `microfacet`
(GGX, Beckmann; no Fresnel) and `conductor_bsdf` (exact conductor Fresnel) closures. Both are
rendered on the same sphere grid and compared pixel by pixel: the per-pixel differences of two
independent renders give the noise of each band's mean difference.

Then the separable variant is rendered against the same native closure: theory (the reference
quadrature) says separable G2 is darker, most at grazing angles. The test requires that the
measured difference is significant there and agrees with the predicted difference, proving the
comparison can see a G2 error of that size.
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness, native  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

ROUGHNESS = (0.05, 0.3, 0.7, 1.0)
SAMPLES = 256
# Cycles' closures, from the one list the report uses too, that one of our models is exactly
# (glass: tests/test_render_glass.py; multiscatter GGX, the report's comparison for Lee, is none).
NATIVE = {k: v for k, v in native.NATIVE.items() if k not in ("glass", "multi_ggx")}
OURS = {
    "ggx": {"distribution": "ggx", "fresnel_type": "none"},
    "beckmann": {"distribution": "beckmann", "fresnel_type": "none"},
    "conductor": {"distribution": "ggx", "fresnel_type": "conductor"},
}


def native_material(kind, roughness):
    source = native.native_source(kind, roughness)
    return lambda: harness.osl_material(source, f"native {kind} {roughness}")


def paired_band_stats(layout, a, b):
    """Band statistics of a - b, pixel by pixel (a zero reference)."""
    return grid.band_stats(layout, a, b)


@pytest.fixture(scope="module", params=["white", "gradient"])
def renders(request):
    env = grid.ENVIRONMENTS[request.param]
    kinds = list(NATIVE)
    specs = [SphereSpec("walter_reflection", {**OURS[k], "roughness": r, "sampler": "vndf",
                                              "estimator": "stochastic"},
                        f"{k} r={r}") for k in kinds for r in ROUGHNESS]
    separable = [SphereSpec(s.model_id, {**s.values, "masking": "separable"}, s.label + " sep")
                 for s in specs]
    natives = [native_material(k, r) for k in kinds for r in ROUGHNESS]
    layout, ours, t_ours = harness.render_specs(specs, env, SAMPLES, seed=3)
    _, native, t_native = harness.render_specs(None, env, SAMPLES, seed=4, materials=natives)
    _, sep, _ = harness.render_specs(separable, env, SAMPLES, seed=5)
    ref_hc = grid.reference_grid_image(layout, specs, env)
    ref_sep = grid.reference_grid_image(layout, separable, env)
    return env, layout, specs, ours, native, sep, ref_hc, ref_sep


def test_height_correlated_matches_native_closures(renders):
    env, layout, specs, ours, native, _, _, _ = renders
    stats = paired_band_stats(layout, ours, native)
    z_crit = grid.sidak_z(3 * len(stats))
    # Both sides are renders: no reference floor is needed, only the noise of the difference.
    bad = [f"{specs[s.sphere].label} mu {s.band} side {s.side}: ours - native {s.bias}, stderr {s.stderr}"
           for s in stats if (np.abs(s.bias) > z_crit * np.maximum(s.stderr, 1e-7)).any()]
    assert not bad, f"z_crit {z_crit:.2f}, {env.name}:\n" + "\n".join(bad)


def test_separable_differs_from_native_where_theory_says(renders):
    env, layout, specs, _, native, sep, ref_hc, ref_sep = renders
    measured = paired_band_stats(layout, sep, native)
    predicted = paired_band_stats(layout, ref_sep, ref_hc)
    z_crit = grid.sidak_z(3 * len(measured))
    seen = set()
    for m, p in zip(measured, predicted):
        assert (m.sphere, m.band) == (p.sphere, p.band)
        # The measured difference agrees with theory within noise and reference accuracy...
        tolerance = z_crit * m.stderr + 2 * grid.REFERENCE_ACCURACY
        assert (np.abs(m.bias - p.bias) <= tolerance).all(), \
            f"{specs[m.sphere].label} {m.band} side {m.side}: measured {m.bias} predicted {p.bias} se {m.stderr}"
        # ...and where theory predicts a clear difference (always darker: G1 G1 <= 1/(1+L+L)),
        # the test sees it, with the right sign.
        if (p.bias < -2 * z_crit * m.stderr).all():
            assert (m.bias < -z_crit * m.stderr).all(), f"{specs[m.sphere].label} {m.band}"
            seen.add(specs[m.sphere].label.split()[0])
    # The GGX kinds always show a difference the test can see. Beckmann's separable vs
    # height-correlated gap is smaller (measured -0.032 +- 0.002 at r = 1, grazing, white
    # furnace) and the darker gradient environment does not always resolve it at 256 samples.
    assert {"ggx", "conductor"} <= seen, seen
    if env is grid.WHITE:
        assert "beckmann" in seen, seen

