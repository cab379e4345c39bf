"""Rendered sphere grids against the numpy reference (headless Cycles with OSL).

Every model x sampler x roughness is rendered on the sphere grid under a white furnace and a
smooth gradient environment, and held against the reference image computed by quadrature of the
model's evaluation formula (addon/lab/reference/quadrature.py), which shares no code with the
samplers the shaders use.

Statistics: each pixel has its own random stream, so the noise of a mean over pixels is the
scatter of the per-pixel residuals over sqrt(n); a second seed checks that this noise estimate is
calibrated. A bias is flagged when it exceeds a Sidak-corrected z threshold (family-wise error
1e-3 over all comparisons of a test) times its noise, plus the reference's own accuracy (1e-4,
grid.REFERENCE_ACCURACY), which is what limits the near-mirror spheres. The power check asserts that the noise is small enough to
see a 1% bias; the 1% criterion is then tested directly on each sphere.
What this catches: a wrong weight, pdf or Jacobian in any sampler, a wrong G2 form, a wrong
Fresnel, the hash stream being correlated with the sample, the roughness mapping, or a harness
error in geometry or environment.
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import GRADIENT, WHITE, SphereSpec  # noqa: E402

ROUGHNESS = (0.05, 0.3, 0.7, 1.0)
SAMPLES = 256
GOLD = {"fresnel_type": "conductor"}  # catalog default n, k: gold
GLASS = {"fresnel_type": "dielectric", "ior": 1.5}

ROWS = [
    ("cook_torrance", {"sampler": "dcos", "specular": 1.0, **GOLD}),
    ("cook_torrance", {"sampler": "vndf", "specular": 0.6, "base_color": (0.1, 0.4, 0.8), **GLASS}),
    ("cook_torrance", {"sampler": "vcavity", "specular": 0.8, "base_color": (0.9, 0.2, 0.1), **GOLD}),
]
for distribution, fresnel in (("ggx", GOLD), ("beckmann", {"fresnel_type": "dielectric", "ior": 2.5})):
    for masking in ("height_correlated", "separable"):
        for sampler in ("dcos", "vndf"):
            ROWS.append(("walter_reflection", {"distribution": distribution, "masking": masking,
                                               "sampler": sampler, **fresnel}))

# GGX rows above render with the default Light Sampling (Native + Residual), which for
# height-correlated masking is Cycles' conductor_bsdf whatever the sampler; the pure stochastic
# estimator keeps two rows of its own (our own GGX maths; D cos at roughness 1 with
# height-correlated masking is too noisy at these samples for the 1% power check).
for masking, sampler in (("height_correlated", "vndf"), ("separable", "dcos")):
    ROWS.append(("walter_reflection", {"distribution": "ggx", "masking": masking,
                                       "sampler": sampler, "estimator": "stochastic", **GOLD}))

SPECS = [SphereSpec(model, {**values, "roughness": r},
                    f"{model} {values.get('distribution', '')} {values.get('masking', '')} "
                    f"{values['sampler']} {values.get('estimator', '')} r={r}")
         for model, values in ROWS for r in ROUGHNESS]


CELL_PX = 40  # about 1000 pixels per sphere


@pytest.fixture(scope="module", params=["white", "gradient"])
def converged(request):
    env = grid.ENVIRONMENTS[request.param]
    layout, image, seconds = harness.render_specs(SPECS, env, SAMPLES, seed=1, cell_px=CELL_PX)
    _, image2, _ = harness.render_specs(SPECS, env, SAMPLES, seed=2, cell_px=CELL_PX)
    reference = grid.reference_grid_image(layout, SPECS, env)
    return env, layout, image, image2, reference, seconds


def test_no_nan_and_background_is_environment(converged):
    env, layout, image, _, reference, _ = converged
    assert np.isfinite(image).all()
    background = image[grid.background_mask(layout)][:, :3]
    # Background pixels see L(-z) directly (catches a wrong world set-up).
    assert np.allclose(background, env.radiance(-grid.VIEW), atol=1e-5)


def test_every_model_and_sampler_converges_to_reference(converged):
    env, layout, image, _, reference, _ = converged
    bands = grid.band_stats(layout, image, reference)
    z_crit = grid.sidak_z(3 * len(bands))
    failures = []
    for b in bands:
        z = np.abs(b.bias) / np.maximum(b.stderr, 1e-9)
        if grid.inconsistent(b, z_crit):
            failures.append(f"{SPECS[b.sphere].label} mu in {b.band} side {b.side}: bias {b.bias} "
                            f"stderr {b.stderr} ref {b.reference} z {z.max():.1f}")
    assert not failures, f"z_crit {z_crit:.2f} ({env.name}):\n" + "\n".join(failures)


def test_every_sphere_within_one_percent(converged):
    """Both seeds pooled (2 x SAMPLES per pixel) so that a 1% bias stands out of the noise."""
    env, layout, image, image2, reference, _ = converged
    pooled = 0.5 * (image + image2)
    failures = grid.relative_bias_failures(layout, pooled, reference, [s.label for s in SPECS])
    assert not failures, "\n".join(failures)


def test_noise_estimate_is_calibrated(converged):
    """Two seeds: the difference of sphere means, divided by the per-pixel noise estimate,
    must be standard normal (catches correlated pixels, which would make every z too large
    or too small)."""
    env, layout, image, image2, reference, _ = converged
    failure = grid.noise_calibration_failure(layout, image, image2, reference)
    assert not failure, failure
