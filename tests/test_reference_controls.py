"""Lamp controls in numpy (addon/lab/reference/controls.py, twin of osl/controls.h: control_terms
and cone_value_lo; docs/light-sampling.md "Lamp controls").

What this catches: a cone bound above the residual somewhere in its cone (Cycles would then
light-sample more than the model has there, and the shader's residual, clamped at 0, could
not give it back: too bright toward lamps), a residual that does not subtract what the
controls carry (too bright) or subtracts it where Cycles' toon is 0 (too dark), controls that
do not lower the second moment under a small sun (the point of them), and constants that drift
from the OSL's.
Tolerances: the bound must hold at every sampled direction (dense, with the cone's rim, where
a unimodal lobe has its least value); the estimator identities by 5 standard errors."""
import math

import numpy as np
import pytest

from addon import lamps as records_mod
from addon.lab.reference import controls, lamps, make_bsdf, split
from addon.lab.reference.fresnel import fresnel_conductor
from addon.lab.reference.lamps import frame
import osl_text  # tests/osl_text.py

# Models with a residual toward lamps (a height-correlated GGX reflection has none).
CASES = [
    # Beckmann splits like GGX (a height-correlated one keeps only the residual of Cycles'
    # approximate Lambda, bounded by 0, so its cases are separable).
    ("walter_reflection", {"distribution": "beckmann", "masking": "separable",
                           "fresnel_type": "conductor"}),
    ("walter_reflection", {"distribution": "beckmann", "masking": "separable",
                           "fresnel_type": "dielectric"}),
    ("walter_reflection", {"distribution": "beckmann", "masking": "separable",
                           "fresnel_type": "none", "anisotropy": 0.8}),
    ("walter_reflection", {"masking": "separable", "fresnel_type": "conductor"}),
    ("walter_reflection", {"masking": "separable", "fresnel_type": "none", "anisotropy": -0.6}),
    ("cook_torrance", {"fresnel_type": "conductor", "specular": 1.0}),
    ("cook_torrance", {"fresnel_type": "dielectric", "specular": 1.0}),
]
HALF_ANGLES = (0.003, 0.035, 0.2, 0.6)


def _cone_directions(axis, th, n, rng):
    """n directions uniform in the cone plus 64 on its rim."""
    s = np.concatenate([rng.random(n), np.ones(64)]) * (1.0 - math.cos(th))
    phi = 2.0 * math.pi * rng.random(s.shape)
    sin_t = np.sqrt(np.maximum(s * (2.0 - s), 0.0))
    t, b = frame(np.asarray(axis, dtype=float)[None, :])
    return ((sin_t * np.cos(phi))[:, None] * t + (sin_t * np.sin(phi))[:, None] * b
            + (1.0 - s)[:, None] * axis)


def _random_case(rng, model_id, values):
    v = dict(values, roughness=float(rng.uniform(0.12, 1.0)))
    if v["fresnel_type"] == "conductor":
        v["n"], v["k"] = tuple(rng.uniform(0.1, 3.0, 3)), tuple(rng.uniform(0.0, 5.0, 3))
    elif v["fresnel_type"] == "dielectric":
        v["ior"] = float(rng.uniform(1.05, 3.0))
    bsdf = make_bsdf(model_id, v)
    ti = math.acos(rng.uniform(0.05, 1.0))
    wi = np.array([math.sin(ti), 0.0, math.cos(ti)])
    ta, pa = rng.uniform(0.0, 1.45), rng.uniform(0.0, 2.0 * math.pi)
    axis = np.array([math.sin(ta) * math.cos(pa), math.sin(ta) * math.sin(pa), math.cos(ta)])
    return bsdf, wi, axis


def _residual_cos(bsdf, wi, wo):
    wi = np.broadcast_to(wi, wo.shape)
    r = bsdf.eval_specular(wi, wo) - split.eval_native(bsdf, wi, wo)
    return r * np.maximum(wo[..., 2], 0.0)[..., None]


@pytest.mark.parametrize("case", range(len(CASES)))
def test_the_cone_bound_holds_everywhere_in_the_cone(case):
    rng = np.random.default_rng(100 + case)
    bound_cases = 0
    for _ in range(60):
        bsdf, wi, axis = _random_case(rng, *CASES[case])
        th = float(rng.choice(HALF_ANGLES))
        lo = controls.cone_value_lo(bsdf, wi, axis, th)
        if not np.any(lo > 0.0):
            continue
        bound_cases += 1
        rc = _residual_cos(bsdf, wi, _cone_directions(axis, th, 3000, rng)) / bsdf.tint
        assert np.all(rc >= lo * (1.0 - 1e-9)), (CASES[case], th, lo, rc.min(axis=0))
    assert bound_cases >= 20  # most random cones are above the horizon and get a bound


def test_the_cone_bound_is_tight_where_the_lobe_is_smooth():
    """Power: at roughness 0.5, a 4-degree sun near the lobe's peak, the bound carries nearly
    all of the residual's least value (a loose bound would leave the light to the residual).
    Cook-Torrance: the models with no native part (a split Beckmann's residual is the small
    masking difference, whose bound is looser and whose light Cycles' closure mostly carries)."""
    for model_id, values in (CASES[5], CASES[6]):
        bsdf = make_bsdf(model_id, dict(values, roughness=0.5))
        wi = np.array([math.sin(0.5), 0.0, math.cos(0.5)])
        axis = np.array([-math.sin(0.55), 0.05, math.cos(0.55)])
        axis /= np.linalg.norm(axis)
        th = math.radians(2.0)
        lo = controls.cone_value_lo(bsdf, wi, axis, th)
        rc = _residual_cos(bsdf, wi, _cone_directions(axis, th, 4000,
                                                       np.random.default_rng(1))) / bsdf.tint
        assert np.all(lo >= 0.85 * rc.min(axis=0)), (model_id, lo, rc.min(axis=0))


def test_conductor_minimum_on_a_sub_interval():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n, k = rng.uniform(0.05, 3.0), rng.choice([0.0, 0.3, rng.uniform(0.0, 6.0)])
        lo = rng.uniform(0.0, 0.99)
        hi = min(1.0, lo + rng.choice([1e-3, 0.05, 0.5]))
        got = split.conductor_min(np.array(n), np.array(k), np.array(lo), np.array(hi))
        x = np.linspace(lo, hi, 20001)
        dense = fresnel_conductor(x, n, k).min()
        assert got <= dense * (1.0 + 1e-12) and got >= dense * (1.0 - 2e-3), (n, k, lo, hi)


SUN = records_mod.sun_record((0.3, -0.2, 0.9), math.radians(4.0), 1.0)
BALL = records_mod.sphere_record((-1.2, 0.6, 2.0), 0.3, 40.0, is_sphere=True)
P0 = np.array([0.0, 0.0, 0.0])
WI = np.array([-0.35, 0.2, 0.915])
WI = WI / np.linalg.norm(WI)


def _guided(bsdf, records, n, seed, with_controls):
    u = np.random.default_rng(seed).random((n, 7))
    sample = (controls.guided_residual_beside_controls if with_controls
              else lamps.sample_guided_residual)
    return sample(bsdf, records, np.broadcast_to(P0, (n, 3)), np.broadcast_to(WI, (n, 3)), u)


def _mean_and_error(x):
    return x.mean(axis=0), x.std(axis=0) / math.sqrt(len(x))


@pytest.mark.parametrize("case", [4, 5, 6])
def test_residual_and_controls_sum_to_the_residual(case):
    """E[residual with controls toward the lamp] + w_K (the toon's integral over its own cone is
    1) is the residual's integral over the lamp, for the sun and a sphere lamp; and the
    controls never push the residual below 0 (the clamp would hide a bias)."""
    bsdf = make_bsdf(*CASES[case])
    records = [SUN, BALL]
    n = 60_000
    terms = controls.control_terms(bsdf, records, P0, WI)
    assert any(np.any(w > 0) for _, _, w, _ in terms)
    wo_c, w_c, _ = _guided(bsdf, records, n, 11, True)
    wo_p, w_p, _ = _guided(bsdf, records, n, 11, False)
    # Before the clamp: the controls stay below the residual at every sampled direction.
    assert np.all(controls.controls_value(terms, wo_p) <= _residual_cos(bsdf, WI, wo_p) + 1e-12)
    for rec, (_, th_k, w_k, _) in zip(records, terms):
        # Each sampler's own directions: the two aim at different rates (the controls' sampler
        # as residual_guide_fraction says), so their samples differ.
        m_c, e_c = _mean_and_error(w_c * (lamps.lamp_pdf(rec, P0, wo_c) > 0)[..., None])
        m_p, e_p = _mean_and_error(w_p * (lamps.lamp_pdf(rec, P0, wo_p) > 0)[..., None])
        # The toon's integral over the lamp's cone: 1, or the solid-angle ratio where the
        # control's cone was widened around it.
        th = controls.lamp_bounding_cone(rec, P0)[1]
        carried = w_k * (1.0 - math.cos(th)) / (1.0 - math.cos(th_k))
        assert np.all(np.abs(m_c + carried - m_p) <= 5 * np.hypot(e_c, e_p) + 1e-12), \
            (m_c, carried, m_p)


def test_controls_lower_the_second_moment_under_a_small_sun():
    """The residual's sun-lit second moment falls once the controls carry the lamp (Cook-Torrance
    gold r0.4 and Cook-Torrance dielectric r0.5 under the 4-degree sun; measured 700 and 240
    times)."""
    for case, roughness in ((5, 0.4), (6, 0.5)):
        bsdf = make_bsdf(CASES[case][0], dict(CASES[case][1], roughness=roughness))
        n = 60_000
        moments = []
        for with_controls in (False, True):
            wo, w, _ = _guided(bsdf, [SUN], n, 13, with_controls)
            lit = (w * (lamps.lamp_pdf(SUN, P0, wo) > 0)[..., None]).sum(-1)
            moments.append(np.mean(lit ** 2))
        assert moments[0] / moments[1] > 5, moments


def test_cones_that_reach_the_horizon_or_overlap_are_left_out():
    low = records_mod.sun_record((1.0, 0.0, 0.02), math.radians(4.0), 1.0)
    twin = records_mod.sun_record((0.4, -0.2, 0.9), math.radians(4.0), 1.0)
    chosen = controls.select_cones([low, SUN, twin], P0[None], np.array([[0.0, 0.0, 1.0]]))
    assert [bool(v[0]) for _, _, v in chosen] == [False, True, False]


def test_osl_constants_are_the_numpy_ones():
    src = osl_text.source("controls.h")
    for name, value in (("SLOTS", controls.CONTROL_SLOTS), ("MIN_WEIGHT", controls.MIN_WEIGHT),
                        ("MARGIN", controls.MARGIN), ("MIN_HALF_ANGLE", controls.MIN_HALF_ANGLE),
                        ("HORIZON_MARGIN", controls.HORIZON_MARGIN),
                        ("GROW_CAP", controls.GROW_CAP), ("GROW_MAX", controls.GROW_MAX)):
        assert osl_text.define_float(src, f"MFL_CONTROL_{name}") == value, name
    for name, value in (("AMBIENT", controls.GUIDE_AMBIENT), ("MIN", controls.GUIDE_MIN),
                        ("MAX", controls.GUIDE_MAX)):
        assert osl_text.define_float(src, f"MFL_GUIDE_{name}") == value, name


def test_nearest_in_cone_is_the_cone_point_nearest_the_direction():
    axis = np.array([0.0, 0.0, 1.0])
    inside = np.array([math.sin(0.1), 0.0, math.cos(0.1)])
    assert np.allclose(controls.nearest_in_cone(axis, 0.2, inside), inside)
    far = np.array([0.0, math.sin(1.0), math.cos(1.0)])
    got = controls.nearest_in_cone(axis, 0.2, far)
    assert np.allclose(got, [0.0, math.sin(0.2), math.cos(0.2)])
    dense = [controls.nearest_in_cone(axis, 0.2, d) for d in (far, -far)]
    assert all(abs(np.linalg.norm(d) - 1.0) < 1e-12 for d in dense)


def test_guide_fraction_aims_where_the_lobe_meets_an_uncarried_lamp():
    """residual_guide_fraction: GUIDE_MAX toward a bright lamp at the mirror direction with no
    controls, GUIDE_MIN where the lobe misses every lamp, and less where the controls carry the
    lamp than where they do not. What it would catch: a guess that aims where the lobe cannot
    use it (a starved rest of the lobe) or never aims at a lamp the delta must find."""
    bsdf = make_bsdf(*CASES[5])  # Cook-Torrance gold, roughness default
    mirror = WI * np.array([-1.0, -1.0, 1.0])
    at_mirror = records_mod.sun_record(tuple(mirror), math.radians(1.0), 100.0)
    behind = records_mod.sun_record((-0.9, 0.4, 0.15), math.radians(1.0), 100.0)
    P, wi = P0[None], WI[None]
    lam = controls.residual_guide_fraction(bsdf, [at_mirror], P, wi, [])
    assert lam[0] == pytest.approx(controls.GUIDE_MAX)
    lam = controls.residual_guide_fraction(bsdf, [behind], P, wi, [])
    assert lam[0] == pytest.approx(controls.GUIDE_MIN)
    dim = records_mod.sun_record(tuple(mirror), math.radians(4.0), 0.5)
    free = controls.residual_guide_fraction(bsdf, [dim], P, wi, [])
    carried = controls.residual_guide_fraction(
        bsdf, [dim], P, wi, controls.control_terms(bsdf, [dim], P, wi))
    assert controls.GUIDE_MIN <= carried[0] < free[0] < controls.GUIDE_MAX


# --- Lee's V-grooves (symmetric): controls on the first bounce, the first bounces aimed ---------

def test_the_first_bounce_of_symmetric_grooves_is_the_v_cavity_model():
    """What the controls bound for Lee (lee.first_order): its k = 1 term, exactly."""
    from addon.lab.reference import lee

    rng = np.random.default_rng(21)
    for values in ({"roughness": 0.4}, {"roughness": 0.8, "distribution": "beckmann",
                                        "fresnel_type": "dielectric"}):
        bsdf = make_bsdf("lee_vgroove", values)
        wi, wo = (normalize_rows(rng.normal(size=(4000, 3))) for _ in range(2))
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
        f1 = lee.eval(wi, wo, bsdf.mf, bsdf.fresnel_table, kmax=1) * bsdf.tint
        vc = lee.first_order(bsdf).eval(wi, wo)
        np.testing.assert_allclose(f1, vc, rtol=1e-6, atol=1e-12)


def normalize_rows(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _lee_sample_holds_the_albedo(bsdf, records, n, seed):
    """n samples of lee.sample_light_sampled at P0 for WI: (P, wi, wo, w, terms, u), checking
    that every weight is non-negative and that their mean plus the controls is the plain
    sampler's albedo, within 5 sigma."""
    from addon.lab.reference import lee

    u = np.random.default_rng(seed).random((n, lee.uniforms_needed(bsdf.groove)))
    P, wi = np.broadcast_to(P0, (n, 3)), np.broadcast_to(WI, (n, 3))
    wo, w, terms = lee.sample_light_sampled(bsdf, records, P, wi, u)
    assert np.all(w >= 0.0)
    _, w_plain, _ = bsdf.sample(wi, np.random.default_rng(seed + 1).random((n, 6)))
    m, e = _mean_and_error(w)
    m_p, e_p = _mean_and_error(w_plain)
    carried_all = sum(w_k[0] for _, _, w_k, _ in terms)
    assert np.all(np.abs(m + carried_all - m_p) <= 5 * np.hypot(e, e_p)), (m, carried_all, m_p)
    return P, wi, wo, w, terms, u


@pytest.mark.parametrize("groove", ("symmetric", "asymmetric"))
def test_lee_native_and_residual_is_the_model(groove):
    """lee.sample_light_sampled (twin of lee_vgroove.osl): its mean plus the controls is the
    albedo (against the plain sampler) and, inside each lamp, the model's integral over the
    lamp (sampling the lamp, full eval); and it lowers the sun-lit second moment (measured 30
    times at roughness 0.6 for symmetric grooves, with controls, and 28 times for asymmetric
    ones, aimed with the Monte Carlo estimate of their first bounce terms, no controls)."""
    from addon.lab.reference import lee

    bsdf = make_bsdf("lee_vgroove", {"roughness": 0.6, "groove": groove})
    records = [SUN, BALL]
    # Asymmetric grooves: every lamp check evaluates the partner-wall quadrature (43 s at 60,000
    # samples); 20,000 keep the 5-sigma checks and the second moment's margin (28 against 10).
    n = 60_000 if groove == "symmetric" else 20_000
    P, wi, wo, w, terms, u = _lee_sample_holds_the_albedo(bsdf, records, n, 23)
    for i, (rec, (_, th_k, w_k, _)) in enumerate(zip(records, terms)):
        inside = (lamps.lamp_pdf(rec, P0, wo) > 0)[..., None]
        m_c, e_c = _mean_and_error(w * inside)
        th = controls.lamp_bounding_cone(rec, P0)[1]
        carried = w_k[0] * (1.0 - math.cos(th)) / (1.0 - math.cos(th_k[0]))
        rng = np.random.default_rng(30 + i)
        wl = lamps.sample_lamp(rec, P, rng.random(n), rng.random(n))
        f = bsdf.eval(wi, wl) * wl[:, 2:3] / lamps.lamp_pdf(rec, P0, wl)[:, None]
        m_l, e_l = _mean_and_error(f)
        assert np.all(np.abs(m_c + carried - m_l) <= 5 * np.hypot(e_c, e_l)), (m_c, carried, m_l)
    wo_s, w_s, _ = bsdf.sample(wi, u[:, :6])
    lit = lambda d, x: (x * (lamps.lamp_pdf(SUN, P0, d) > 0)[..., None]).sum(-1)  # noqa: E731
    assert np.mean(lit(wo_s, w_s) ** 2) > 10 * np.mean(lit(wo, w) ** 2)


def _rect_around(direction, distance, half, offset):
    """An area record of half-extent `half`, facing P0, centred `distance` along `direction`
    turned by `offset` (a vector added before normalising)."""
    axis = normalize_rows(np.asarray(direction, float) + offset)
    u = normalize_rows(np.cross(axis, [0.0, 0.0, 1.0]))
    v = np.cross(axis, u)
    return records_mod.area_record("SQUARE", tuple(distance * axis), tuple(-axis),
                                   tuple(half * u), tuple(half * v), 400.0)


def test_lee_aims_at_the_lamps_and_about_the_mirror_direction():
    """lee.sample_light_sampled's aimed directions (sample_aimed): a rectangle over its area, a
    lamp on the horizon that has no control, and, where the mirror direction meets a lamp,
    about it (the 1 / theta spike of the terms k >= 2: mis_density, sample_spike). Still the
    model: the mean plus the controls is the plain sampler's albedo, and inside each lamp the
    model's integral over it, within 5 sigma. What this catches: a spike or area density that
    is not the one sampled (a bias); aiming into the rectangle's bounding cone (32% of these
    samples met the rectangle, 66% now); the unbounded weight of a direction near the mirror
    (the grooves' terms grow as 1 / d there). Measured here, the rectangle-lit variance and
    largest weight: 0.143 and 103 with the first order's density as the stand-in and aiming
    into cones, 0.044 and 2.9 with mis_density, 0.0087 and 0.64 now."""
    from addon.lab.reference import lee

    bsdf = make_bsdf("lee_vgroove", {"roughness": 0.7, "groove": "symmetric"})
    mirror = WI * np.array([-1.0, -1.0, 1.0])
    rect = _rect_around(mirror, 2.3, 0.75, np.array([0.05, 0.1, 0.0]))
    low = records_mod.sun_record((1.0, 0.0, 0.02), math.radians(4.0), 1.0)
    records = [rect, low]
    n = 200_000
    assert lee.light_sampling.spike_angle(records, P0[None], np.array([[0.0, 0.0, 1.0]]),
                                          mirror[None])[0] > 0.0
    P, wi, wo, w, terms, _ = _lee_sample_holds_the_albedo(bsdf, records, n, 41)
    rng = np.random.default_rng(43)
    for rec, (axis, th_k, w_k, _) in zip(records, terms):
        inside = lamps.lamp_pdf(rec, P0, wo) > 0
        assert inside.mean() > (0.5 if rec is rect else 0.005)  # the lamp on the horizon too
        if rec is rect:
            assert float(w.mean(-1)[inside].max()) < 1.0
        m_c, e_c = _mean_and_error(w * inside[..., None])
        # the control's part inside the lamp: its cone's share that the lamp covers
        d = lamps.sample_cone(np.broadcast_to(axis[0], (n, 3)),
                              np.full(n, 2.0 * math.sin(0.5 * th_k[0]) ** 2), rng.random(n),
                              rng.random(n))
        carried = w_k[0] * np.mean(lamps.lamp_pdf(rec, P0, d) > 0)
        wl = lamps.sample_lamp(rec, P, rng.random(n), rng.random(n))
        f = bsdf.eval(wi, wl) * wl[:, 2:3] / lamps.lamp_pdf(rec, P0, wl)[:, None]
        m_l, e_l = _mean_and_error(f)
        assert np.all(np.abs(m_c + carried - m_l) <= 5 * np.hypot(e_c, e_l)), (m_c, carried, m_l)
