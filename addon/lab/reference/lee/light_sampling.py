"""Native + Residual light sampling for Lee 2018 V-grooves, the numpy twin of
osl/lee_vgroove.osl (docs/light-sampling.md, "Lee"): the layout of a sample's uniforms, the
first bounce as a V-cavity BRDF that the lamp controls bound (first_order), the cones aimed at
(aimed_cones), the low bounce orders aimed into them (low_orders: symmetric eval, seed eq. 5-7,
or the asymmetric partner-wall estimate) and the estimator itself (sample_light_sampled).
"""
from __future__ import annotations

import numpy as np

from .. import controls
from ..bsdf import MicrofacetBRDF
from ..lamps import GUIDE_FRACTION, sample_cone
from .asymmetric import eval_asymmetric
from .model import LeeBRDF
from .symmetric import eval


# -- Native + Residual (osl/lee_vgroove.osl, docs/light-sampling.md "Lee") -----------------------
# The bounce terms aimed into the lamps' cones (osl LEE_AIMED_ORDERS).
AIMED_ORDERS = 6
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
    """[(axis, th, w_K, valid)] as controls.control_terms gives them: symmetric grooves have
    lamp controls on their first bounce (the V-cavity term); an asymmetric groove's first
    bounce is not that term, so there the cones are the lamps' own, with no control (w_K = 0)."""
    if bsdf.groove == "symmetric":
        return controls.control_terms(first_order(bsdf), records, P, wi)
    zero = np.zeros(np.shape(wi))
    Ng = np.broadcast_to(np.array([0.0, 0.0, 1.0]), np.shape(P))
    return [(axis, np.where(valid, th, controls.MIN_HALF_ANGLE), zero, valid)
            for axis, th, valid in controls.select_cones(records, P, Ng)]


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
    has a control; aimed_cones) and lam = GUIDE_FRACTION where there are any: with probability
    lam a direction uniform in one of them (each with probability 1 / count), weighted by
    (f_{k<=AIMED_ORDERS} cos - sum w t) / (lam p) (low_orders); otherwise a path of the sampler,
    its exit dropped where k <= AIMED_ORDERS and wo lies in A, else over 1 - lam. u: (...,
    uniforms_needed(groove)) uniforms, laid out as PARTNER_DIM says."""
    P, wi, u = (np.asarray(x, dtype=float) for x in (P, wi, u))
    n = wi.shape[0]
    terms = aimed_cones(bsdf, records, P, wi)
    valid = np.stack([v for *_, v in terms], -1) if terms else np.zeros((n, 0), bool)
    count = valid.sum(-1)
    # The OSL keeps the valid cones first, in table order: the j-th valid one is slot j.
    lam = np.where(count > 0, GUIDE_FRACTION, 0.0)
    wo_s, w_s, k_s = bsdf.sample(wi, u[..., :6])
    wo = wo_s.copy()
    aimed = u[:, 6] < lam
    slot = np.minimum(np.floor(u[:, 7] * count), np.maximum(count - 1, 0)).astype(int)
    rank = np.cumsum(valid, -1) - 1
    for j, (axis, th, _, _) in enumerate(terms):
        sel = aimed & valid[:, j] & (rank[:, j] == slot)
        if np.any(sel):
            a = np.broadcast_to(axis, (n, 3))[sel]
            omc = 2.0 * np.sin(0.5 * np.broadcast_to(th, (n,))[sel]) ** 2
            wo[sel] = sample_cone(a, omc, u[sel, 8], u[sel, 9])
    p_aim = np.zeros(n)
    inside = np.zeros(n, bool)
    for j, (axis, th, _, _) in enumerate(terms):
        t_j = np.where(valid[:, j], controls.toon_value(axis, th, wo), 0.0)
        p_aim += t_j
        inside |= t_j > 0.0
    p_aim = np.where(count > 0, p_aim / np.maximum(count, 1), 0.0)
    low = low_orders(bsdf, wi, wo, u)
    r = low * np.maximum(wo[:, 2], 0.0)[:, None] - controls.controls_value(terms, wo)
    ok = p_aim > 0.0
    w_aim = np.where(ok[:, None], np.maximum(r, 0.0) / np.where(ok, lam * p_aim, 1.0)[:, None],
                     0.0)
    drop = (k_s <= AIMED_ORDERS) & inside
    w_path = np.where((count > 0)[:, None],
                      np.where(drop[:, None], 0.0, w_s / (1.0 - lam)[:, None]), w_s)
    return wo, np.where(aimed[:, None], w_aim, w_path), terms
