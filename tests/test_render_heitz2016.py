"""Heitz 2016 multiple scattering rendered in Cycles OSL (osl/heitz2016.osl) against the numpy twin
(addon/lab/reference/heitz2016.py).

1. Sphere grids (gold conductor and glass, GGX and Beckmann, roughness 0.3 .. 1) under the white
   furnace and the gradient against reference images built from the twin's Monte Carlo moment
   tables (`heitz2016.moment_tables`: 24 incidences, WALKS sampled walks each). Their standard
   errors are carried into the tolerance: a band's bias is flagged when it exceeds the
   Sidak-corrected z times sqrt(render noise^2 + reference error^2) plus the interpolation floor
   grid.REFERENCE_ACCURACY; the reference error of a band is the band mean
   of `grid.reference_error_image` (table errors added in magnitude, fully correlated across the
   band: conservative). A power check asserts that a 1% bias of each sphere would be seen.
   The glass rows use the twin with forward transmission dropped, as the shader must (no
   refraction closure reaches wi.wo >= 0); tests/test_reference_heitz2016.py measures that share.
2. The zero-noise furnace: with F = 1 every walk that escapes weighs exactly 1 and none is lost
   at Max Bounces 100 (measured share below 1e-5), so every pixel is 1 at any roughness (the
   Stochastic estimator: the native part of Native + Residual is light-sampled, hence noisy).
4. Light Sampling under a lamp: Native + Residual against Stochastic under a 45-degree sun over
   a black world, pixel by pixel.
3. Max Bounces 1 is single scattering: the walk's first order equals Walter 2007 with the
   height-correlated Smith G2 (the paper's result), held against the quadrature reference of
   `walter_reflection` (an independent formula and integrator, not the walk), and the full walk
   is measurably brighter than it at roughness 1 (multiple scattering is there).
What this catches: a wrong height sampling or masking exponent, a wrong visible-normal sampler
from below, eta not inverted below the interface or on back faces, a wrong Fresnel per event,
walks cut short, a wrong exit closure (direction or weight), and the forward-transmission drop
not matching the twin.
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.catalog import MODELS  # noqa: E402
from addon.lab import grid, harness, table_cache  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402
from addon.lab.reference import make_bsdf  # noqa: E402
from addon.lab.reference.heitz2016 import moment_tables, table_nodes  # noqa: E402
from addon.lab.reference.quadrature import moments_at  # noqa: E402

SAMPLES = 256
CELL_PX = 40
N_MU = 24
WALKS = 200_000

ROWS = [({"fresnel_type": "conductor", "distribution": d}, (0.3, 0.7, 1.0))
        for d in ("ggx", "beckmann")]
ROWS += [({"fresnel_type": "dielectric", "distribution": "ggx", "ior": e}, (0.3, 0.7, 1.0))
         for e in (1.5, 1 / 1.5)]
ROWS += [({"fresnel_type": "dielectric", "distribution": "beckmann", "ior": 1.5}, (0.3, 1.0))]
# The GGX rows above render with the default Light Sampling (Native + Residual: the first order
# natively); the pure stochastic walk keeps rows of its own (Beckmann is stochastic anyway).
ROWS += [({"fresnel_type": f, "distribution": "ggx", "ior": 1.5, "estimator": "stochastic"},
          (0.3, 1.0)) for f in ("conductor", "dielectric")]
SPECS = [SphereSpec("heitz2016", {**values, "roughness": r},
                    f"heitz {values['fresnel_type']} {values['distribution']} "
                    f"eta={values.get('ior', 0):.3g} {values.get('estimator', '')} r={r}")
         for values, rs in ROWS for r in rs]


def _nodes(values):
    """Glass seen from the denser side: even nodes every 0.025 in mu from 0.3 up (its moments
    bend around the critical angle, mu 0.75 at eta 1/1.5; the 24 log-spaced nodes missed that
    bend at roughness 0.3 by up to 0.026); else the 24 log-spaced nodes."""
    if values["fresnel_type"] == "dielectric" and values.get("ior", 1.5) < 1.0:
        return table_nodes(N_MU, uniform_from=0.3)
    return table_nodes(N_MU)


def _key(spec):
    """The estimator does not change the BSDF: one table per walk."""
    values = MODELS[spec.model_id].resolve(spec.values)
    return repr(sorted((k, v) for k, v in values.items() if k != "estimator"))


def _compute_tables():
    """(table, its standard errors) per spec, flat: over a minute of walks, kept on disk
    between runs (addon/lab/table_cache.py)."""
    rng = np.random.default_rng(2016)
    cache = {}
    for s in SPECS:
        if _key(s) not in cache:
            cache[_key(s)] = moment_tables(make_bsdf(s.model_id, s.values), _nodes(s.values),
                                           WALKS, rng)
    return [t for s in SPECS for t in cache[_key(s)]]


@pytest.fixture(scope="module")
def tables():
    inputs = ([(_key(s), _nodes(s.values).tolist()) for s in SPECS], WALKS, 2016)
    flat = table_cache.tables("heitz2016_grid", inputs, _compute_tables)
    return flat[0::2], flat[1::2]


@pytest.fixture(scope="module", params=["white", "gradient"])
def converged(request, tables):
    env = grid.ENVIRONMENTS[request.param]
    layout, image, _ = harness.render_specs(SPECS, env, SAMPLES, seed=1, cell_px=CELL_PX)
    _, image2, _ = harness.render_specs(SPECS, env, SAMPLES, seed=2, cell_px=CELL_PX)
    reference = grid.reference_image(layout, tables[0], env, moments_at)
    error = grid.reference_error_image(layout, tables[1], env, moments_at)
    return env, layout, image, image2, reference, error


def _reference_error(layout, error, stats):
    """Band mean of the reference error image, for each BandStats (same selection)."""
    index, normal, mu = layout.pixel_geometry()
    toward = normal[..., :2] @ grid.SIDE_DIRECTION >= 0.0
    out = []
    for b in stats:
        sel = (index == b.sphere) & (mu >= b.band[0]) & (mu < b.band[1])
        if b.side:
            sel &= toward if b.side > 0 else ~toward
        out.append(error[sel].mean(0))
    return out


def test_no_nan_and_background_is_environment(converged):
    env, layout, image, image2, _, _ = converged
    assert np.isfinite(image).all() and np.isfinite(image2).all()
    background = image[grid.background_mask(layout)][:, :3]
    assert np.allclose(background, env.radiance(-grid.VIEW), atol=1e-5)


def test_walk_converges_to_reference(converged):
    env, layout, image, _, reference, error = converged
    bands = grid.band_stats(layout, image, reference)
    ref_err = _reference_error(layout, error, bands)
    z_crit = grid.sidak_z(3 * len(bands))
    failures = []
    for b, e in zip(bands, ref_err):
        noise = np.sqrt(b.stderr ** 2 + e ** 2)
        if (np.abs(b.bias) > z_crit * noise + grid.REFERENCE_ACCURACY).any():
            failures.append(f"{SPECS[b.sphere].label} mu in {b.band} side {b.side}: bias {b.bias} "
                            f"render se {b.stderr} reference se {e} ref {b.reference}")
    assert not failures, f"z_crit {z_crit:.2f} ({env.name}):\n" + "\n".join(failures)


def test_every_sphere_within_one_percent_with_power(converged):
    """Both seeds pooled; each sphere's bias below 1%, and the render noise and the reference
    error together small enough that a 1% bias would stand out (the power check)."""
    env, layout, image, image2, reference, error = converged
    pooled = 0.5 * (image + image2)
    spheres = grid.band_stats(layout, pooled, reference, bands=((0.05, 1.0001),), sides=False)
    ref_err = _reference_error(layout, error, spheres)
    z_crit = grid.sidak_z(3 * len(spheres))
    failures = []
    for s, e in zip(spheres, ref_err):
        noise = np.sqrt(s.stderr ** 2 + e ** 2) / s.reference
        if (z_crit * noise > 0.01).any():
            failures.append(f"{SPECS[s.sphere].label}: no power, relative noise {noise}")
        if (np.abs(s.bias) / s.reference > 0.01).any():
            failures.append(f"{SPECS[s.sphere].label}: relative bias {s.bias / s.reference}")
    assert not failures, "\n".join(failures)


def test_noise_estimate_is_calibrated(converged):
    env, layout, image, image2, reference, _ = converged
    failure = grid.noise_calibration_failure(layout, image, image2, reference)
    assert not failure, failure


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
    layout, image, _ = harness.render_specs(all_specs, grid.GRADIENT, SAMPLES, seed=4,
                                            cell_px=CELL_PX)
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
SUN_SAMPLES = {"light_sampled": 512, "stochastic": 4096}


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
    for d in spheres:
        assert 0.1 * d.reference.max() > z_s * d.stderr.max(), \
            f"{specs[d.sphere].label}: no power (se {d.stderr}, mean {d.reference})"
