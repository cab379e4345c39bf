"""Native + Residual light sampling for Lee 2018 V-grooves, the numpy twin of
osl/lee_vgroove.osl (docs/light-sampling.md, "Lee"): the layout of a sample's uniforms, the
first bounce as a V-cavity BRDF that the lamp controls bound (first_order, control_cones),
the low bounce orders aimed at the lamps (low_orders: symmetric eval, seed eq. 5-7, or the
asymmetric partner-wall estimate), the sampler's stand-in density (mis_density) and the
estimator itself (sample_light_sampled).
"""
from __future__ import annotations

import numpy as np

from .. import controls, lamps
from ..bsdf import MicrofacetBRDF, reflection_pdf
from ..lamps import GUIDE_FRACTION
from .asymmetric import eval_asymmetric
from .model import LeeBRDF
from .symmetric import eval


# -- Native + Residual (osl/lee_vgroove.osl, docs/light-sampling.md "Lee") -----------------------
# The bounce terms aimed at the lamps (osl LEE_AIMED_ORDERS).
AIMED_ORDERS = 16
# Uniforms of one Native + Residual sample: 0-5 the sampler (3-5: an asymmetric groove's
# partner), 6 the branch, 7-9 the lamp (or the spike) and the direction, then (asymmetric
# grooves) one per frame, k and side of the aimed terms' Monte Carlo rule (eval_asymmetric's u;
# osl LEE_PARTNER_DIM).
PARTNER_DIM = 10


def uniforms_needed(groove: str) -> int:
    """The width of sample_light_sampled's u."""
    return PARTNER_DIM + (4 * AIMED_ORDERS if groove == "asymmetric" else 0)


def first_order(bsdf: LeeBRDF):
    """The k = 1 term of the symmetric grooves as a BRDF: exactly the V-cavity Cook-Torrance
    model with the grooves' D and Fresnel (docs/models.md sec. 4); the lamp controls bound it."""
    return MicrofacetBRDF(bsdf.mf, "vcavity", "vndf", bsdf.fresnel_kind, bsdf.ior, bsdf.n,
                          bsdf.k, bsdf.tint)


def control_cones(bsdf: LeeBRDF, records, P, wi):
    """[(axis, th, w_K, valid)]: the lamp controls of symmetric grooves, on their first bounce,
    the V-cavity term (controls.control_terms); none for asymmetric grooves, whose first bounce
    is not that term."""
    if bsdf.groove != "symmetric":
        return []
    return controls.control_terms(first_order(bsdf), records, P, wi)


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


def spike_angle(records, P, Ng, mirror):
    """osl spike_angle: where the mirror direction meets a lamp with weight (the first in table
    order), the half-angle about it that covers that lamp (its bounding cone), else 0: no spike
    strategy."""
    spike = np.zeros(np.shape(P)[:-1])
    for rec in records:
        axis, th, valid = controls.lamp_bounding_cone(rec, P)
        ang = np.arccos(np.clip(np.sum(axis * mirror, -1), -1.0, 1.0))
        hit = ((spike == 0.0) & valid & (lamps.lamp_share(rec, P, Ng) > 0.0)
               & (lamps.lamp_pdf(rec, P, mirror) > 0.0))
        spike = np.where(hit, ang + th, spike)
    return spike


def spike_density(mirror, spike, wo):
    """osl spike_density: the density of sample_spike, 1 / (2 pi spike sin theta) within the
    angle spike of the mirror direction (theta its angle to wo), else 0."""
    c = np.cross(wo, mirror)
    sin_t = np.sqrt(np.sum(c * c, -1))
    theta = np.arctan2(sin_t, np.sum(wo * mirror, -1))
    ok = (spike > 0.0) & (theta < spike) & (sin_t > 0.0)
    return np.where(ok, 1.0 / (2.0 * np.pi * np.where(ok, spike * sin_t, 1.0)), 0.0)


def sample_spike(mirror, spike, u1, u2):
    """osl sample_spike: theta uniform in [0, spike) about the mirror direction, the 1 / theta
    spike of the terms k >= 2 (mis_density), so an aimed direction there weighs about the
    same."""
    theta = u1 * spike
    phi = 2.0 * np.pi * u2
    t, b = lamps.frame(mirror)
    return ((np.sin(theta) * np.cos(phi))[..., None] * t
            + (np.sin(theta) * np.sin(phi))[..., None] * b + np.cos(theta)[..., None] * mirror)


def sample_aimed(records, P, Ng, mirror, u):
    """osl sample_aimed: (wo, p) an aimed direction and the aimed density p at it: where the
    mirror direction meets a lamp (spike_angle), half the time sample_spike, else
    lamps.sample_lamps (a lamp by its weight, then uniform over its cone or area)."""
    spike = spike_angle(records, P, Ng, mirror)
    has = spike > 0.0
    u0 = np.where(has, 2.0 * u[:, 7] - 1.0, u[:, 7])
    toward = lamps.sample_lamps(records, P, Ng, np.maximum(u0, 0.0), u[:, 8], u[:, 9])
    wo = np.where((u0 < 0.0)[:, None], sample_spike(mirror, spike, u[:, 8], u[:, 9]), toward)
    return wo, spike


def aimed_pdf(records, P, Ng, mirror, spike, wo):
    """osl aimed_pdf: the density of sample_aimed at wo."""
    p = lamps.lamps_pdf(records, P, Ng, wo)
    return np.where(spike > 0.0, 0.5 * (p + spike_density(mirror, spike, wo)), p)


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
    RGB of the delta lobe, tint included, terms: the controls (control_cones), which ride on
    every sample). Where some lamp has weight, lam = max(GUIDE_FRACTION,
    controls.residual_guide_fraction) (the first bounce standing for the aimed terms): with
    probability lam an aimed direction (sample_aimed: toward the lamps, and about the mirror
    direction where it meets one; density p = aimed_pdf), weighted by
    (f_{k<=AIMED_ORDERS} cos - sum w t) / (lam p + (1 - lam) q) (low_orders; q = mis_density);
    otherwise a path of the sampler over 1 - lam, its exit where k <= AIMED_ORDERS times the
    balance heuristic's share (1 - lam) q / (lam p + (1 - lam) q) (1 off the lamps) and, beside
    controls, 1 - sum w t / (f_{k<=AIMED_ORDERS} cos) (exact for any q: the two weights sum to 1
    at every direction, Veach 1997 sec. 9.2).
    u: (..., uniforms_needed(groove)) uniforms, laid out as PARTNER_DIM says."""
    P, wi, u = (np.asarray(x, dtype=float) for x in (P, wi, u))
    n = wi.shape[0]
    Ng = np.broadcast_to(np.array([0.0, 0.0, 1.0]), P.shape)
    terms = control_cones(bsdf, records, P, wi)
    total = lamps.lamps_total_weight(records, P, Ng)
    # How often to aim: at least GUIDE_FRACTION, more where the first bounce (the V-cavity
    # term, standing for the aimed terms) says so (controls.residual_guide_fraction).
    guess = controls.residual_guide_fraction(first_order(bsdf), records, P, wi, terms)
    lam = np.where(total > 0.0, np.maximum(GUIDE_FRACTION, guess), 0.0)
    wo_s, w_s, k_s = bsdf.sample(wi, u[..., :6])
    aimed = u[:, 6] < lam
    wo = wo_s
    p_aim = np.zeros(n)
    if records:
        mirror = wi * np.array([-1.0, -1.0, 1.0])
        toward, spike = sample_aimed(records, P, Ng, mirror, u)
        wo = np.where(aimed[:, None], toward, wo_s)
        p_aim = aimed_pdf(records, P, Ng, mirror, spike, wo)
    low = low_orders(bsdf, wi, wo, u)
    carried = controls.controls_value(terms, wo)
    r = low * np.maximum(wo[:, 2], 0.0)[:, None] - carried
    q = (1.0 - lam) * mis_density(bsdf, wi, wo)
    mix = lam * p_aim + q
    ok = (p_aim > 0.0) & (wo[:, 2] > 0.0)
    w_aim = np.where(ok[:, None], np.maximum(r, 0.0) / np.where(ok, mix, 1.0)[:, None], 0.0)
    # A path's exit with k <= AIMED_ORDERS: the balance heuristic's share q / (lam p + q), less
    # the controls' share of the first bounce terms there (symmetric grooves; low is their
    # closed form at the path's own exit, wo = wo_s off the aimed branch).
    low_k = k_s <= AIMED_ORDERS
    share = np.where(low_k & (mix > 0.0), q / np.where(mix > 0.0, mix, 1.0), 1.0)[:, None]
    low_cos = low * np.maximum(wo[:, 2], 0.0)[:, None]
    less = np.where(low_cos > 0.0, np.maximum(1.0 - carried / np.where(low_cos > 0.0, low_cos,
                                                                        1.0), 0.0), 0.0)
    share = share * np.where((low_k & (np.sum(carried, -1) > 0.0))[:, None], less, 1.0)
    w_path = np.where((total > 0.0)[:, None], w_s * share / np.where(
        total > 0.0, 1.0 - lam, 1.0)[:, None], w_s)
    return wo, np.where(aimed[:, None], w_aim, w_path), terms
