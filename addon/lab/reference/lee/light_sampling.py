"""Native + Residual light sampling for Lee 2018 V-grooves, the numpy twin of
osl/lee_vgroove.osl (docs/light-sampling.md, "Lee"): the layout of a sample's uniforms, the
first bounce as a V-cavity BRDF that the lamp controls bound (first_order), the cones aimed at
(aimed_cones), the low bounce orders aimed into them (low_orders: symmetric eval, seed eq. 5-7,
or the asymmetric partner-wall estimate) and the estimator itself (sample_light_sampled).
"""
from __future__ import annotations

import numpy as np

from .. import controls
from ..bsdf import MicrofacetBRDF, reflection_pdf
from ..lamps import GUIDE_FRACTION, sample_cone
from .asymmetric import eval_asymmetric
from .model import LeeBRDF
from .symmetric import eval


# -- Native + Residual (osl/lee_vgroove.osl, docs/light-sampling.md "Lee") -----------------------
# The bounce terms aimed into the lamps' cones (osl LEE_AIMED_ORDERS).
AIMED_ORDERS = 16
# Uniforms of one Native + Residual sample: 0-5 the sampler (3-5: an asymmetric groove's
# partner), 6 the branch, 7-9 the cone, then (asymmetric grooves) one per frame, k and side of
# the aimed terms' Monte Carlo rule (eval_asymmetric's u; osl LEE_PARTNER_DIM).
PARTNER_DIM = 10


def uniforms_needed(groove: str) -> int:
    """The width of sample_light_sampled's u."""
    return PARTNER_DIM + (4 * AIMED_ORDERS if groove == "asymmetric" else 0)


def first_order(bsdf: LeeBRDF):
    """The k = 1 term of the symmetric grooves as a BRDF: exactly the V-cavity Cook-Torrance
    model with the grooves' D and Fresnel (docs/models.md sec. 4); the lamp controls bound it."""
    return MicrofacetBRDF(bsdf.mf, "vcavity", "vndf", bsdf.fresnel_kind, bsdf.ior, bsdf.n,
                          bsdf.k, bsdf.tint)


def aimed_cones(bsdf: LeeBRDF, records, P, wi):
    """[(axis, th, w_K, valid, th_lamp)]: the cones as controls.control_terms gives them
    (symmetric grooves have lamp controls on their first bounce, the V-cavity term; an
    asymmetric groove's first bounce is not that term, so there the cones are the lamps' own,
    with no control, w_K = 0), then controls.add_aim_cones' (the lamps left without one, no
    control); th_lamp is the lamp's own cone inside th (th where the cone is not widened)."""
    P = np.asarray(P, dtype=float)
    zero = np.zeros(np.shape(wi))
    Ng = np.broadcast_to(np.array([0.0, 0.0, 1.0]), np.shape(P))
    if bsdf.groove == "symmetric":
        terms = [(axis, th, w, valid, np.where(valid, controls.lamp_bounding_cone(rec, P)[1], th))
                 for rec, (axis, th, w, valid)
                 in zip(records, controls.control_terms(first_order(bsdf), records, P, wi))]
    else:
        terms = [(axis, np.where(valid, th, controls.MIN_HALF_ANGLE), zero, valid,
                  np.where(valid, th, controls.MIN_HALF_ANGLE))
                 for axis, th, valid in controls.select_cones(records, P, Ng)]
    chosen = [(axis, th, valid) for axis, th, _, valid, _ in terms]
    added = controls.add_aim_cones(records, P, Ng, chosen)[len(chosen):]
    return terms + [(axis, th, zero, valid, th) for axis, th, valid in added]


def mis_density(bsdf: LeeBRDF, wi, wo):
    """osl lee_mis_density: the density the balance heuristic between the aimed cones and the
    sampler uses for the sampler, whose exits' density has no closed form: the first order's
    visible-normal density q_1 times f_{k<=AIMED_ORDERS} / f_1 of symmetric grooves (closed
    form, colour means). Near the mirror direction the terms k >= 2 grow as 1 / d (d the
    distance to it: the grooves' azimuths fold their exits there), so an aimed direction over
    q_1 alone had an unbounded weight; the sampler's own exits follow that spike, and so does
    this q. Asymmetric grooves use it too (their spike is at most about 1.1 times this one).
    Any density used in both weights keeps the estimate exact."""
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-30)
    q1 = reflection_pdf(first_order(bsdf), wi, h)
    f1 = eval(wi, wo, bsdf.mf, bsdf.fresnel_table, 1, bsdf.kmax).mean(-1)
    fk = eval(wi, wo, bsdf.mf, bsdf.fresnel_table, AIMED_ORDERS, bsdf.kmax).mean(-1)
    return np.where(f1 > 0.0, q1 * np.maximum(fk, f1) / np.where(f1 > 0.0, f1, 1.0), q1)


def cones_pdf(terms, wo):
    """osl cones_pdf: the density of sample_light_sampled's aimed direction, each valid cone
    with probability 1 / count; in a widened cone half uniform over it, half over the lamp's
    own cone."""
    valid = np.stack([v for *_, v, _ in terms], -1)
    count = valid.sum(-1)
    pdf = 0.0
    for axis, th, _, v, th_l in terms:
        widened = th_l < th
        full = controls.toon_value(axis, th, wo)
        lamp = controls.toon_value(axis, th_l, wo)
        pdf = pdf + np.where(v, np.where(widened, 0.5 * (full + np.where(full > 0, lamp, 0.0)),
                                         full), 0.0)
    return np.where(count > 0, pdf / np.maximum(count, 1), 0.0)


def low_orders(bsdf: LeeBRDF, wi, wo, u):
    """f_{k<=AIMED_ORDERS}(wi, wo) RGB, tint included: symmetric grooves in closed form (eval),
    asymmetric ones by the one-node Monte Carlo rule over the partner wall (eval_asymmetric
    with u[..., PARTNER_DIM:]), an unbiased estimate."""
    if bsdf.groove == "symmetric":
        f = eval(wi, wo, bsdf.mf, bsdf.fresnel_table, AIMED_ORDERS, bsdf.kmax)
    else:
        uu = np.asarray(u)[..., PARTNER_DIM:PARTNER_DIM + 4 * AIMED_ORDERS]
        f = eval_asymmetric(wi, wo, bsdf.mf, bsdf.fresnel_table, AIMED_ORDERS,
                            fresnel_bounces=bsdf.kmax,
                            u=uu.reshape(uu.shape[:-1] + (2, AIMED_ORDERS, 2)))
    return f * bsdf.tint


def sample_light_sampled(bsdf: LeeBRDF, records, P, wi, u):
    """One sample of the Native + Residual estimator (the twin of lee_vgroove.osl): (wo, weight
    RGB of the delta lobe, tint included, terms: the controls as controls.control_terms gives
    them, which ride on every sample). With A the chosen cones (each lamp's, widened where it
    has a control; aimed_cones) and, where there are any, lam = max(GUIDE_FRACTION,
    controls.residual_guide_fraction) (the first bounce standing for the residual): with
    probability lam a direction in one of them (each with probability 1 / count; uniform in it,
    or where a control widened it, half the time uniform in the lamp's own cone: cones_pdf),
    weighted by (f_{k<=AIMED_ORDERS} cos - sum w t) / (lam p + (1 - lam) q) (low_orders;
    q = mis_density); otherwise a path of the sampler over 1 - lam, its exit where
    k <= AIMED_ORDERS and wo lies in A times the balance heuristic's share
    (1 - lam) q / (lam p + (1 - lam) q) and, beside controls, 1 - sum w t / (f_{k<=AIMED_ORDERS}
    cos) (exact for any q: the two weights sum to 1 at every direction, Veach 1997 sec. 9.2).
    u: (..., uniforms_needed(groove)) uniforms, laid out as PARTNER_DIM says."""
    P, wi, u = (np.asarray(x, dtype=float) for x in (P, wi, u))
    n = wi.shape[0]
    terms = aimed_cones(bsdf, records, P, wi)
    valid = np.stack([v for *_, v, _ in terms], -1) if terms else np.zeros((n, 0), bool)
    count = valid.sum(-1)
    # The OSL keeps the valid cones first, in table order: the j-th valid one is slot j.
    # How often to aim: at least GUIDE_FRACTION, more where the first bounce (the V-cavity
    # term, standing for the aimed terms) says so (controls.residual_guide_fraction).
    guess = controls.residual_guide_fraction(first_order(bsdf), records, P, wi,
                                             [t[:4] for t in terms])
    lam = np.where(count > 0, np.maximum(GUIDE_FRACTION, guess), 0.0)
    wo_s, w_s, k_s = bsdf.sample(wi, u[..., :6])
    wo = wo_s.copy()
    aimed = u[:, 6] < lam
    x = u[:, 7] * count
    slot = np.minimum(np.floor(x), np.maximum(count - 1, 0)).astype(int)
    to_lamp = x - slot < 0.5
    rank = np.cumsum(valid, -1) - 1
    for j, (axis, th, _, _, th_l) in enumerate(terms):
        sel = aimed & valid[:, j] & (rank[:, j] == slot)
        if np.any(sel):
            a = np.broadcast_to(axis, (n, 3))[sel]
            th_j, th_lj = np.broadcast_to(th, (n,))[sel], np.broadcast_to(th_l, (n,))[sel]
            cone = np.where((th_lj < th_j) & to_lamp[sel], th_lj, th_j)
            wo[sel] = sample_cone(a, 2.0 * np.sin(0.5 * cone) ** 2, u[sel, 8], u[sel, 9])
    p_aim = cones_pdf(terms, wo) if terms else np.zeros(n)
    inside = p_aim > 0.0
    terms = [t[:4] for t in terms]
    low = low_orders(bsdf, wi, wo, u)
    carried = controls.controls_value(terms, wo)
    r = low * np.maximum(wo[:, 2], 0.0)[:, None] - carried
    q = (1.0 - lam) * mis_density(bsdf, wi, wo)
    ok = p_aim > 0.0
    w_aim = np.where(ok[:, None], np.maximum(r, 0.0) / np.where(ok, lam * p_aim + q, 1.0)[:, None],
                     0.0)
    # A path's exit inside the cones with k <= AIMED_ORDERS: the balance heuristic's share
    # q / (lam p + q), less the controls' share of the first bounce terms there (symmetric
    # grooves; low is their closed form at the path's own exit, wo_s = wo off the aimed branch).
    both = (k_s <= AIMED_ORDERS) & inside
    share = np.where(both, q / np.where(both, lam * p_aim + q, 1.0), 1.0)[:, None]
    low_cos = low * np.maximum(wo[:, 2], 0.0)[:, None]
    less = np.where(low_cos > 0.0, np.maximum(1.0 - carried / np.where(low_cos > 0.0, low_cos,
                                                                        1.0), 0.0), 0.0)
    share = share * np.where((both & (np.sum(carried, -1) > 0.0))[:, None], less, 1.0)
    w_path = np.where((count > 0)[:, None], w_s * share / (1.0 - lam)[:, None], w_s)
    return wo, np.where(aimed[:, None], w_aim, w_path), terms
