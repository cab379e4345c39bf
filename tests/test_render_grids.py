"""Rendered sphere grids against the numpy reference (headless Cycles with OSL), one body of
tests for every suite of tests/grid_suites.py:

- `models` and `models-stochastic` (the Stochastic estimator's rows, at more samples):
  Cook-Torrance and Walter reflection, every sampler, masking and estimator, roughness 0.05 .. 1,
  against the reference computed by quadrature of the model's evaluation formula
  (addon/lab/reference/quadrature.py), which shares no code with the samplers the shaders use;
- `lee`: Lee 2018 V-grooves (symmetric and asymmetric, GGX and Beckmann, gold) against LeeBRDF's
  deterministic directional moments (addon/lab/reference/lee/directional_moments.py, checked
  against lee.sample Monte Carlo in tests/test_reference_lee_moments.py);
- `heitz2016`: the Heitz 2016 walk (gold, glass from either side, GGX and Beckmann) against the
  twin's Monte Carlo moment tables (24 incidences, 200,000 walks each), whose standard errors
  join the noise (the band mean of grid.reference_error_image: table errors added in magnitude,
  fully correlated across the band, so conservative). The glass rows use the twin with forward
  transmission dropped, as the shader must (tests/test_reference_heitz2016_shader.py measures it).

Each under a white furnace and a smooth gradient. Statistics: each pixel has its own random
stream, so the noise of a mean over pixels is the scatter of the per-pixel residuals over
sqrt(n); a second seed checks that this estimate is calibrated. A band's bias is flagged when
it exceeds a Sidak-corrected z (family-wise error 1e-3 over the test's comparisons) times its
noise, plus the reference's accuracy (grid.REFERENCE_ACCURACY, coarser for asymmetric Lee
grooves). The power check asserts that the noise could reveal a 1% bias of each sphere; the 1%
criterion is then tested directly on each sphere, both seeds pooled.
What this catches: a wrong weight, pdf or Jacobian in any sampler, a wrong G2 form, a wrong
Fresnel, the hash stream being correlated with the sample, the roughness mapping, a harness
error in geometry or environment; for the walk, a wrong height sampling or masking exponent, a
wrong visible-normal sampler from below, eta not inverted below the interface, a wrong Fresnel
per event, walks cut short, a wrong exit closure, the forward-transmission drop not matching
the twin.
"""
import functools

import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness  # noqa: E402
from addon.lab.reference.quadrature import moments_at  # noqa: E402
from grid_suites import SUITES  # noqa: E402

ENVS = ("white", "gradient")
CASES = [(suite, env) for suite in SUITES for env in ENVS]


@functools.lru_cache(maxsize=1)
def _renders(suite_name):
    """A suite's grid under every environment, two seeds each, in one scene (its OSL compiled
    once: harness.render_seeds_envs)."""
    suite = SUITES[suite_name]
    return harness.render_seeds_envs(suite.specs, [grid.ENVIRONMENTS[e] for e in ENVS],
                                     suite.samples, (1, 2), cell_px=suite.cell_px)


@pytest.fixture(scope="module", params=CASES, ids=[f"{s}-{e}" for s, e in CASES])
def converged(request):
    """(suite, env, layout, two seeds' images, reference, reference error image or None)."""
    suite, env = SUITES[request.param[0]], grid.ENVIRONMENTS[request.param[1]]
    tables, error_tables = suite.tables()
    layout, by_env = _renders(suite.name)
    image, image2 = by_env[env.name]
    reference = grid.reference_image(layout, tables, env, moments_at)
    error = (None if error_tables is None else
             grid.reference_error_image(layout, error_tables, env, moments_at))
    return suite, env, layout, image, image2, reference, error


def test_no_nan_and_background_is_environment(converged):
    suite, env, layout, image, image2, _, _ = converged
    assert np.isfinite(image).all() and np.isfinite(image2).all()
    background = image[grid.background_mask(layout)][:, :3]
    # Background pixels see L(-z) directly (catches a wrong world set-up).
    assert np.allclose(background, env.radiance(-grid.VIEW), atol=1e-5)


def test_every_sphere_converges_to_reference(converged):
    suite, env, layout, image, _, reference, error = converged
    z_crit, failures = grid.band_failures(layout, image, reference, suite.labels,
                                          suite.floors(), error)
    assert not failures, f"z_crit {z_crit:.2f} ({suite.name}, {env.name}):\n" + \
        "\n".join(failures)


def test_every_sphere_within_one_percent_with_power(converged):
    """Both seeds pooled (2 x samples per pixel) so that a 1% bias stands out of the noise."""
    suite, env, layout, image, image2, reference, error = converged
    failures = grid.relative_bias_failures(layout, 0.5 * (image + image2), reference,
                                           suite.labels, error=error)
    assert not failures, "\n".join(failures)


def test_noise_estimate_is_calibrated(converged):
    """Two seeds: the difference of sphere means, divided by the per-pixel noise estimate,
    must be standard normal (catches correlated pixels, which would make every z too large
    or too small)."""
    suite, env, layout, image, image2, reference, _ = converged
    failure = grid.noise_calibration_failure(layout, image, image2, reference)
    assert not failure, failure
