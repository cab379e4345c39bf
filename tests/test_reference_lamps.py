"""The residual's direct light in numpy (addon/lab/reference/lamps.py, twin of osl/lamps.h) and
the lamp records the add-on hands over (addon/lamps.py).

What this catches: a lamp sampler whose density is not the one the shader divides by (a biased
residual: too bright or too dark under that lamp), a density that misses part of the lamp (the
same), a guided estimator that is not the residual (its furnace and lamp integrals must be the
unguided ones), an aiming that does not lower the second moment under a small lamp (the point
of it), bad lamp values that reach the shader (NaN, negative, zero size), and OSL constants
that drift from numpy's.
Tolerances: Monte Carlo, from the samples' own standard errors (5 sigma), and analytic
solid angles."""
import dataclasses
import math

import numpy as np
import pytest

from addon import lamps as records_mod
from addon import shaders
from addon.lab.reference import bsdf as bsdf_mod, lamps, make_bsdf, split
from addon.lab.reference.microfacet import normalize
import osl_text  # tests/osl_text.py

P0 = np.array([0.3, -0.2, 0.0])
SUN = records_mod.sun_record((0.4, 0.3, 0.8), math.radians(4.0), 1.0)
SPHERE = records_mod.sphere_record((1.0, 0.5, 2.0), 0.3, 50.0)  # Soft Falloff: a facing disk
BALL = records_mod.sphere_record((-1.0, -0.5, 1.0), 0.4, 30.0, is_sphere=True)


def _area(shape, centre, u, v):
    """An area lamp spanned by u, v, emitting toward P0 (normal = -(u x v) or u x v)."""
    n = np.cross(u, v)
    n = n if np.dot(n, P0 - np.array(centre)) > 0 else -n
    return records_mod.area_record(shape, centre, tuple(n), u, v, 20.0)


RECT = _area("RECTANGLE", (-0.5, 0.4, 1.5), (0.4, 0.0, 0.08), (0.0, 0.25, 0.0))
DISK = _area("DISK", (0.8, -1.0, 1.2), (0.3, 0.25, 0.0), (-0.1, 0.12, 0.15))
LAMPS = [SUN, SPHERE, BALL, RECT, DISK]


def _mean_and_error(x):
    x = np.asarray(x, dtype=float)
    return x.mean(axis=0), x.std(axis=0) / math.sqrt(len(x))


def _solid_angle_by_uniform_directions(rec, n=2_000_000, seed=0):
    """The lamp's solid angle seen from P0, by uniform directions on the sphere: the fraction
    whose density is positive, and the integral of the density (must be 1)."""
    d = normalize(np.random.default_rng(seed).normal(size=(n, 3)))
    pdf = lamps.lamp_pdf(rec, P0, d)
    hit = pdf > 0
    return 4 * np.pi * hit.mean(), 4 * np.pi * pdf.mean(), 4 * np.pi * pdf.std() / math.sqrt(n)


def _analytic_solid_angle(rec):
    """Cones: the sun's 2 pi (1 - cos h); a sphere's 2 pi (1 - sqrt(1 - r^2/d^2)); a disk of
    radius r facing P0 2 pi (1 - d / sqrt(d^2 + r^2)), each with sin^2 h enlarged by
    lamps.MARGIN (the proposal's cone). Areas: None."""
    if rec.kind == "sun":
        sin2 = rec.size * (2 - rec.size)
    elif rec.kind == "sphere":
        d, r = np.linalg.norm(np.array(rec.position) - P0), rec.size
        sin2 = r * r / (d * d) if rec.is_sphere else r * r / (d * d + r * r)
    else:
        return None
    return 2 * np.pi * (1 - math.sqrt(1 - sin2 * (1 + lamps.MARGIN)))


@pytest.mark.parametrize("rec", LAMPS, ids=lambda r: r.kind + ("_ball" if r.is_sphere else ""))
def test_each_lamp_density_integrates_to_one(rec):
    _, integral, err = _solid_angle_by_uniform_directions(rec)
    assert abs(integral - 1.0) < 5 * err + 1e-3


@pytest.mark.parametrize("rec", LAMPS, ids=lambda r: r.kind + ("_ball" if r.is_sphere else ""))
def test_lamp_samples_land_where_the_density_is_and_weigh_the_solid_angle(rec):
    """E[1 / p(dir)] over the lamp's own samples is its solid angle (analytic for cones, by
    uniform directions for areas); every sample has p > 0."""
    rng = np.random.default_rng(1)
    n = 400_000
    d = lamps.sample_lamp(rec, np.broadcast_to(P0, (n, 3)), rng.random(n), rng.random(n))
    pdf = lamps.lamp_pdf(rec, P0, d)
    assert np.mean(pdf > 0) > 1 - 1e-4  # a few on the rim may round outside
    inv = np.where(pdf > 0, 1.0 / np.where(pdf > 0, pdf, 1.0), 0.0)
    mean, err = _mean_and_error(inv)
    analytic = _analytic_solid_angle(rec)
    if analytic is None:
        omega, _, _ = _solid_angle_by_uniform_directions(rec)
        assert abs(mean - omega) < 5 * err + 0.01 * omega
    else:
        assert abs(mean - analytic) < 5 * err + 1e-9 * analytic


def test_behind_inside_and_below_get_no_weight():
    up = np.array([0.0, 0.0, 1.0])
    inside = np.array(SPHERE.position) + 0.1
    assert lamps.lamp_weight(SPHERE, inside, up) == 0.0
    behind = np.array(RECT.position) - 0.5 * np.array(RECT.axis)  # behind the emitting side
    assert lamps.lamp_weight(RECT, behind, up) == 0.0
    assert lamps.lamp_weight(SUN, P0, -up) == 0.0  # the sun below this surface's horizon
    assert lamps.lamp_weight(SUN, P0, up) == SUN.power


BSDFS = {
    "gold separable r0.5": ("walter_reflection", {"roughness": 0.5, "masking": "separable"}),
    # (height-correlated GGX has no residual: Cycles' own closure carries all of it)
    "dielectric separable r0.3": ("walter_reflection", {"roughness": 0.3, "masking": "separable",
                                                         "fresnel_type": "dielectric"}),
    "beckmann gold r0.4": ("walter_reflection", {"roughness": 0.4, "distribution": "beckmann"}),
    "cook-torrance r0.3": ("cook_torrance", {"roughness": 0.3, "specular": 1.0}),
    "dcos dielectric separable r0.6": ("walter_reflection", {"roughness": 0.6, "sampler": "dcos",
                                                             "masking": "separable",
                                                             "fresnel_type": "dielectric"}),
}
WI = normalize(np.array([0.35, -0.3, 0.7]))


def _guided(bsdf, records, n, seed):
    u = np.random.default_rng(seed).random((n, 7))
    return lamps.sample_guided_residual(bsdf, records, np.broadcast_to(P0, (n, 3)),
                                        np.broadcast_to(WI, (n, 3)), u)


def _cone_indicator(rec, wo):
    return (lamps.lamp_pdf(rec, P0, wo) > 0)[..., None]


def _residual_cos(bsdf, wo):
    wi = np.broadcast_to(WI, wo.shape)
    r = bsdf.eval_specular(wi, wo) - split.eval_native(bsdf, wi, wo)
    return np.maximum(r, 0.0) * np.maximum(wo[..., 2], 0.0)[..., None]


def _lamp_only_estimate(bsdf, rec, n, seed):
    """The residual's integral over one lamp by sampling that lamp alone (its sampler is held
    to its density above): mean of r cos / p_lamp and its standard error."""
    rng = np.random.default_rng(seed)
    wo = lamps.sample_lamp(rec, np.broadcast_to(P0, (n, 3)), rng.random(n), rng.random(n))
    pdf = lamps.lamp_pdf(rec, P0, wo)[..., None]
    return _mean_and_error(np.where(pdf > 0, _residual_cos(bsdf, wo) / np.where(pdf > 0, pdf, 1),
                                    0.0))


@pytest.mark.parametrize("name", BSDFS)
def test_guided_residual_is_the_residual(name):
    """The guided estimator's mean is the residual's: its whole albedo against the unguided
    residual sampler (split.sample_residual), and its part inside each lamp against sampling
    that lamp alone (where the lobe is faint the unguided sampler may not reach the lamp)."""
    bsdf = make_bsdf(*BSDFS[name])
    n = 200_000
    wo_g, w_g, share = _guided(bsdf, LAMPS, n, 2)
    assert np.all((share >= 0) & (share <= 1 + 1e-12))
    u = np.random.default_rng(3).random((n, 3))
    _, w_s = split.sample_residual(bsdf, np.broadcast_to(WI, (n, 3)), u)
    pairs = [(_mean_and_error(w_g), _mean_and_error(w_s))]
    pairs += [(_mean_and_error(w_g * _cone_indicator(r, wo_g)),
               _lamp_only_estimate(bsdf, r, n, 10 + i)) for i, r in enumerate(LAMPS)]
    for (mg, eg), (ms, es) in pairs:
        assert np.all(np.abs(mg - ms) <= 5 * np.hypot(eg, es) + 1e-12), (mg, ms, eg, es)


@pytest.mark.parametrize("name", BSDFS)
def test_aiming_lowers_the_second_moment_under_a_small_sun(name):
    """Under the 4-degree sun alone the guided estimator's second moment of the sun-lit part is
    far below the unguided one's (the rare, heavy hits of a delta lobe are what it removes)."""
    bsdf = make_bsdf(*BSDFS[name])
    n = 200_000
    wo_g, w_g, _ = _guided(bsdf, [SUN], n, 4)
    lit_g = (w_g * _cone_indicator(SUN, wo_g)).sum(-1)
    # The unguided second moment in closed form: E[(w 1_sun)^2] = integral over the sun of
    # (r cos)^2 / p_model, here by sampling the sun (p_model of the model's sampler alone).
    rng = np.random.default_rng(5)
    wo = lamps.sample_lamp(SUN, np.broadcast_to(P0, (n, 3)), rng.random(n), rng.random(n))
    p_sun = lamps.lamp_pdf(SUN, P0, wo)
    p_model = bsdf_mod.reflection_pdf(bsdf, np.broadcast_to(WI, (n, 3)), normalize(WI + wo))
    rc = _residual_cos(bsdf, wo).sum(-1)
    ok = (p_sun > 0) & (p_model > 0)
    unguided = np.mean(np.where(ok, rc ** 2 / np.where(ok, p_model * p_sun, 1.0), 0.0))
    assert lit_g.mean() > 0
    ratio = unguided / np.mean(lit_g ** 2)
    assert ratio > 20, ratio


def test_without_lamps_the_guided_sampler_is_the_model_sampler():
    bsdf = make_bsdf(*BSDFS["gold separable r0.5"])
    n = 50_000
    u = np.random.default_rng(6).random((n, 7))
    wo_g, w_g, share = lamps.sample_guided_residual(bsdf, [], np.broadcast_to(P0, (n, 3)),
                                                    np.broadcast_to(WI, (n, 3)), u)
    wo_s, w_s = split.sample_residual(bsdf, np.broadcast_to(WI, (n, 3)), u[:, :3])
    assert np.all(share == 1.0)
    np.testing.assert_allclose(wo_g, wo_s, atol=1e-12)
    np.testing.assert_allclose(w_g, w_s, rtol=1e-9, atol=1e-12)


# --- the records the add-on hands over -------------------------------------------------------

@pytest.mark.parametrize("strength", [0.0, -3.0, float("nan"), float("inf"), "x"])
def test_lamps_worth_nothing_are_not_aimed_at(strength):
    assert records_mod.guiding_power(strength, (1.0, 1.0, 1.0)) == 0.0


def test_huge_lamps_are_clamped_and_zero_size_lamps_dropped():
    assert records_mod.guiding_power(1e300, (1.0, 1.0, 1.0)) == records_mod.MAX_POWER
    assert records_mod.sun_record((0, 0, 1), 0.0, 1.0) is None
    assert records_mod.sun_record((0, 0, 1), float("nan"), 1.0) is None
    assert records_mod.sun_record((0, 0, 0), 0.1, 1.0) is None
    assert records_mod.sphere_record((0, 0, 0), 0.0, 1.0) is None
    assert records_mod.sphere_record((0, float("nan"), 0), 0.1, 1.0) is None
    assert records_mod.area_record("SQUARE", (0, 0, 0), (0, 0, -1), (0, 0, 0), (0, 1, 0),
                                   1.0) is None
    # A tiny sun keeps 1 - cos(half-angle) without cancellation.
    tiny = records_mod.sun_record((0, 0, 1), 1e-4, 1.0)
    assert tiny.size == pytest.approx(1 - math.cos(5e-5), rel=1e-6)


def test_the_osl_table_holds_every_record_and_nothing_without_lamps():
    assert "#define MFL_LAMP_COUNT 0" in shaders.lamp_table_block([])
    assert "lamp_datum" not in shaders.lamp_table_block([])
    many = [records_mod.sphere_record((i, 0.0, 3.0), 0.1, 1.0) for i in range(100)]
    block = shaders.lamp_table_block(many)
    assert "#define MFL_LAMP_COUNT 100" in block
    assert f"float table[{100 * records_mod.RECORD_SIZE}]" in block
    assert len(shaders.lamp_table_block(many * 2).split("{")[-1].split(",")) == \
        records_mod.MAX_LAMPS * records_mod.RECORD_SIZE
    assert all(len(r.floats()) == records_mod.RECORD_SIZE for r in LAMPS)


def test_world_spot_texels_follow_the_table_only_where_predicted():
    """A world spot's texels go into their own table, the record's slot 15 pointing at them
    (1 + offset), and only with a predicted radiance (a withheld prediction keeps no texels)."""
    texels = records_mod.SpotTexels(8, 4, (1, 2, 2, 1), True, tuple(np.eye(3).reshape(-1)),
                                    (1.0, 2.0, 3.0, 4.0, 5.0, 6.0))
    spot = dataclasses.replace(records_mod.sun_record((0, 0, 1), 0.1, 5.0), texels=texels,
                               radiance=(2.5, 3.5, 4.5))
    lamp = records_mod.sun_record((1, 0, 0), 0.1, 1.0)
    block = shaders.lamp_table_block([lamp, spot, spot])
    assert "#define MFL_SPOT_TEXELS 1" in block
    assert f"float table[{2 * len(texels.floats())}]" in block
    lamp_table = [float(x) for x in block.split("{")[2].split("}")[0].split(",")]
    assert [lamp_table[15 + k * records_mod.RECORD_SIZE] for k in range(3)] == \
        [0.0, 1.0, 1.0 + len(texels.floats())]
    withheld = dataclasses.replace(spot, radiance=(0.0, 0.0, 0.0))
    assert "#define MFL_SPOT_TEXELS 0" in shaders.lamp_table_block([lamp, withheld])


def test_osl_constants_are_the_numpy_ones():
    src = osl_text.source("lamps.h")
    assert osl_text.define_float(src, "MFL_GUIDE_FRACTION") == lamps.GUIDE_FRACTION
    assert osl_text.define_float(src, "MFL_LAMP_MARGIN") == lamps.MARGIN
    for i, kind in enumerate(records_mod.KINDS):
        assert osl_text.define(src, f"MFL_LAMP_{kind.upper()}") == str(i), kind


def test_guided_weights_stay_finite_and_non_negative_on_extreme_inputs():
    """The stiff corners: near-mirror and full roughness, grazing incidence (wi.z down to
    1e-6), extreme IOR, N and K, every sampler, Beckmann and Cook-Torrance, lamps tiny (a
    0.001-degree sun), huge and very close; the aimed weight and the choice's model share stay
    finite, the weight >= 0, the share in [0, 1]."""
    from tests.test_reference_split import random_values

    rng = np.random.default_rng(12)
    tiny_sun = records_mod.sun_record((0.2, -0.1, 1.0), math.radians(1e-3), 1.0)
    close = records_mod.sphere_record((0.3, -0.2, 0.05), 0.04, 1e20, is_sphere=True)
    lamps_sets = [LAMPS, [tiny_sun], [close, DISK], [tiny_sun, close, RECT]]
    for i in range(120):
        model_id = ("walter_reflection", "cook_torrance")[i % 2]
        values = random_values(rng, "walter_reflection") if model_id == "walter_reflection" \
            else {"roughness": float(rng.uniform(0.0, 1.0)), "specular": 1.0}
        values["roughness"] = float(rng.choice([values["roughness"], 1e-3, 0.0316, 1.0]))
        values["sampler"] = str(rng.choice(["dcos", "vndf"] if model_id != "cook_torrance"
                                           else ["dcos", "vndf", "vcavity"]))
        if model_id == "walter_reflection":
            values["distribution"] = str(rng.choice(["ggx", "beckmann"]))
        bsdf = make_bsdf(model_id, values)
        n = 400
        wi = normalize(rng.normal(size=(n, 3)))
        wi[:, 2] = np.abs(wi[:, 2])
        wi[: n // 4, 2] = 10.0 ** rng.uniform(-6, -2, n // 4)
        wi = normalize(wi)
        with np.errstate(all="ignore"):
            _, w, share = lamps.sample_guided_residual(
                bsdf, lamps_sets[i % len(lamps_sets)], np.broadcast_to(P0, (n, 3)), wi,
                rng.random((n, 7)))
        assert np.all(np.isfinite(w)) and np.all(w >= 0.0), values
        assert np.all(np.isfinite(share)) and np.all((share >= 0) & (share <= 1 + 1e-12)), values
