"""Lamp controls in numpy: the part of the residual toward each lamp that Cycles light-samples,
the twin of osl/controls.h (`control_terms`, `cone_value_lo`; docs/light-sampling.md, "Lamp
controls").

For a lamp whose directions from P lie in a cone K (axis a, half-angle th), the shader returns
Cycles' `glossy_toon(normalize(wi + a), th / (pi/2), 0)`: a lobe uniform over K, whose value
times cos is 1 / (2 pi (1 - cos th)) inside K and 0 outside, and which Cycles evaluates toward
its lamps with multiple importance sampling like any of its closures. Weighted by

    w_K = 2 pi (1 - cos th) inf_{wo in K} r(wi, wo) cos(wo)      (per channel)

it stays below the residual r everywhere, so the residual keeps r - w_K t_K >= 0 and the sum is
the model, for any cone: only the noise depends on where K lies. r cos = F D G / (4 wi.n) has
no cos(wo) left; its infimum over K is bounded below factor by factor (`cone_value_lo`): every
half vector of K lies within beta = asin(sin(th/2) / wi.h_a) of h_a = normalize(wi + a)
(|wo - a| <= 2 sin(th/2), |wi + a| = 2 wi.h_a), every wo within th of a.

Shapes: wi, axis (..., 3) local (n = z); th (...,); results RGB (..., 3).
"""
from __future__ import annotations

import math

import numpy as np

from .lamps import (cone_density, extents, lamp_bounding_cone, lamp_cone, lamp_share,  # noqa: F401
                    sample_guided_residual)
from .microfacet import Microfacet, dot, normalize
from .split import conductor_min, eval_residual, native_factor, supports_split

# osl/controls.h MFL_CONTROL_*: at most this many controls per shading point; a control whose mean
# weight is below MIN_WEIGHT is widened or left out (Cycles drops closures below 1e-5, so a
# Mix Shader factor down to 0.1 keeps every control, as for delta lobes); GROW_CAP, GROW_MAX: how far a small
# lamp's cone may be widened (times alpha_min, radians); weights are lowered
# by MARGIN against float rounding in the shader's residual; cones narrower than MIN_HALF_ANGLE
# are left out (Cycles clamps a toon's size to 1e-5 of pi/2, and a sharp toon beside the delta
# residual would meet Cycles' 1e6 stand-in pdf for deltas); the cone must clear the horizons
# of N and Ng by HORIZON_MARGIN (cos).
CONTROL_SLOTS = 4
MIN_WEIGHT = 1e-4
MARGIN = 1e-3
GROW_CAP = 0.5
GROW_MAX = 0.1
MIN_HALF_ANGLE = 2e-3
HORIZON_MARGIN = 0.01
# osl/controls.h MFL_GUIDE_*: residual_guide_fraction's guess of the ambient radiance, and the
# range of the share of samples it aims at the lamps.
GUIDE_AMBIENT = 1.0
GUIDE_MIN = 0.05
GUIDE_MAX = 0.95


def cone_half_vectors(wi, axis, th):
    """(h_a, beta, valid): the half vector toward the cone's axis and the largest angle between
    it and the half vector of any wo in the cone."""
    h = normalize(wi + axis)
    s = np.sin(0.5 * th) / np.maximum(dot(wi, h), 1e-30)
    valid = s < 1.0
    return h, np.arcsin(np.minimum(s, 1.0)), valid


def residual_masking_lo(bsdf, lam_i, lam_o, cos_h_max, cos_o_min, wi_z, u_hi, split):
    """Least masking factor of r cos over the cone: G2 (no native part) or G2 - c G2_hc with
    c = G_lo (separable with a native part: (1 - c) G1(wo) G2_hc), lam_o the largest Lambda(wo).
    A Beckmann split's residual G2 - c' G2_native is at least this (split.BECKMANN_LAMBDA_GAP)."""
    if bsdf.masking == "vcavity":
        return np.minimum(1.0, 2.0 * cos_h_max * np.minimum(wi_z, cos_o_min) / u_hi)
    if bsdf.masking == "separable":
        if split:
            return (lam_i / (1.0 + lam_i)) / ((1.0 + lam_o) * (1.0 + lam_i + lam_o))
        return 1.0 / ((1.0 + lam_i) * (1.0 + lam_o))
    return np.zeros_like(lam_i) if split else 1.0 / (1.0 + lam_i + lam_o)


def fresnel_lo(bsdf, u_lo, u_hi):
    """Least Fresnel factor over wi.h in [u_lo, u_hi] (..., 3): a dielectric's F falls as wi.h
    grows (at the upper end); a conductor's is searched (split.conductor_min)."""
    if bsdf.fresnel == "dielectric":
        return bsdf.F(u_hi)
    if bsdf.fresnel == "conductor":
        return conductor_min(bsdf.n, bsdf.k, u_lo[..., None] * np.ones(3),
                             u_hi[..., None] * np.ones(3))
    return np.ones(np.shape(u_lo) + (3,))


def cone_value_lo(bsdf, wi, axis, th):
    """A lower bound of r(wi, wo) cos(wo) over wo in the cone, without the tint (..., 3); 0 where
    the cone reaches the horizon or no bound holds."""
    wi, axis = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(axis, dtype=float))
    th = np.broadcast_to(np.asarray(th, dtype=float), wi.shape[:-1])
    mf = bsdf.mf
    split = supports_split(bsdf)
    h, beta, valid = cone_half_vectors(wi, axis, th)
    theta_o = np.arccos(np.clip(axis[..., 2], -1.0, 1.0)) + th
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    h_max = theta_h + beta
    gamma = np.arccos(np.clip(dot(wi, h), -1.0, 1.0))
    u_lo, u_hi = np.cos(gamma + beta), np.cos(np.maximum(gamma - beta, 0.0))
    valid &= (theta_o < 0.5 * math.pi) & (h_max < 0.5 * math.pi) & (u_lo > 0.0) & (wi[..., 2] > 0)
    h_max = np.where(valid, h_max, 0.0)
    theta_o = np.where(valid, theta_o, 0.0)
    # D = g(e) / (pi ax ay cos^4): g falls with the stretched slope e <= tan^2 / alpha_min^2,
    # 1 / cos^4 grows with theta_m >= theta_h - beta (Walter 2007 eqs. 25, 33).
    a_min, a_max = min(mf.alpha_x, mf.alpha_y), max(mf.alpha_x, mf.alpha_y)
    e = np.tan(h_max) ** 2 / a_min ** 2
    g = 1.0 / (1.0 + e) ** 2 if mf.ggx else np.exp(-e)
    d_lo = g / (math.pi * mf.alpha_x * mf.alpha_y * np.cos(np.maximum(theta_h - beta, 0.0)) ** 4)
    # Lambda grows with theta and with the projected roughness (at most alpha_max).
    w_o = np.stack([np.sin(theta_o), np.zeros_like(theta_o), np.cos(theta_o)], axis=-1)
    lam_o = Microfacet(mf.distribution, a_max, a_max).lambda_(w_o)
    lam_i = mf.lambda_(wi)
    g_lo = residual_masking_lo(bsdf, lam_i, lam_o, np.cos(h_max), np.cos(theta_o), wi[..., 2],
                               np.where(valid, u_hi, 1.0), split)
    F = fresnel_lo(bsdf, np.where(valid, u_lo, 1.0), np.where(valid, u_hi, 1.0))
    value = F * (d_lo * g_lo / (4.0 * np.where(valid, wi[..., 2], 1.0)))[..., None]
    return np.where(valid[..., None], np.maximum(value, 0.0), 0.0)


def _weight(bsdf, wi, axis, th):
    """tint 2 pi (1 - cos th) cone_value_lo (1 - MARGIN) (..., 3)."""
    omc = 2.0 * np.sin(0.5 * th) ** 2
    return bsdf.tint * cone_value_lo(bsdf, wi, axis, th) * \
        (2.0 * math.pi * omc * (1.0 - MARGIN))[..., None]


def control_cone(bsdf, wi, axis, th):
    """(th_K, w_K): the control's half-angle and weight (..., 3), tint included. The cone is the
    lamp's; where its weight would fall below MIN_WEIGHT (a small lamp: w_K is about the lobe's
    value times the cone's solid angle) it is widened once, to the solid angle that would give
    2 MIN_WEIGHT at the lamp cone's bound, at most GROW_CAP alpha_min (the lobe stays nearly
    constant across it) and GROW_MAX; w_K = 0 where it still falls below MIN_WEIGHT or the lamp's
    cone is narrower than MIN_HALF_ANGLE."""
    wi, axis = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(axis, dtype=float))
    th = np.broadcast_to(np.asarray(th, dtype=float), wi.shape[:-1])
    w = _weight(bsdf, wi, axis, th)
    mean = np.mean(w, axis=-1)
    a_min = min(bsdf.mf.alpha_x, bsdf.mf.alpha_y)
    cap = np.maximum(th, min(GROW_MAX, GROW_CAP * a_min))
    omc = 2.0 * np.sin(0.5 * th) ** 2
    target = np.where(mean > 0.0, omc * 2.0 * MIN_WEIGHT / np.maximum(mean, 1e-300), 0.0)
    grown = np.minimum(2.0 * np.arcsin(np.sqrt(np.minimum(0.5 * target, 1.0))), cap)
    grow = (mean < MIN_WEIGHT) & (grown > th)
    th_k = np.where(grow, grown, th)
    w = np.where(grow[..., None], _weight(bsdf, wi, axis, th_k), w)
    keep = (np.mean(w, axis=-1) >= MIN_WEIGHT) & (th >= MIN_HALF_ANGLE)
    return th_k, np.where(keep[..., None], w, 0.0)


def control_weight(bsdf, wi, axis, th):
    """w_K (..., 3) of control_cone."""
    return control_cone(bsdf, wi, axis, th)[1]


def toon_value(axis, th, wo):
    """Cycles' glossy toon with smooth 0 about normalize(wi + axis), its value times cos at wo:
    1 / (2 pi (1 - cos th)) inside the cone, else 0 (kernel/closure/bsdf_toon.h)."""
    axis, wo = np.broadcast_arrays(np.asarray(axis, dtype=float), np.asarray(wo, dtype=float))
    th = np.asarray(th, dtype=float)
    c = np.cross(wo, axis)
    inside = (dot(wo, axis) > 0.0) & (np.sum(c * c, axis=-1) < np.sin(th) ** 2)
    return np.where(inside, cone_density(th), 0.0)


def select_cones(records, P, Ng):
    """One cone per record [(axis, th, valid)], valid for at most CONTROL_SLOTS of them per
    point, in table order (brightest first): lamps with
    weight at P whose cone, widened as far as control_cone may (GROW_MAX), clears the horizon of
    Ng (here also the shading normal) and every cone chosen before it (two overlapping controls
    could sum above the residual)."""
    P = np.asarray(P, dtype=float)
    chosen = []
    running = np.zeros(P.shape[:-1], dtype=int)
    for rec in records:
        axis, th, valid = lamp_bounding_cone(rec, P)
        valid = valid & (running < CONTROL_SLOTS)
        reach = np.maximum(th, GROW_MAX)
        valid = valid & (lamp_share(rec, P, Ng) > 0.0) & (th < 0.5 * math.pi)
        valid &= dot(axis, Ng) > np.sin(reach) + HORIZON_MARGIN
        for a2, th2, v2 in chosen:
            apart = np.arccos(np.clip(dot(axis, a2), -1.0, 1.0)) > reach + np.maximum(th2, GROW_MAX)
            valid &= apart | ~v2
        chosen.append((axis, th, valid))
        running = running + valid
    return chosen


def control_terms(bsdf, records, P, wi, Ng=(0.0, 0.0, 1.0)):
    """[(axis, th, w_K, valid)] of the chosen cones at P for wi (osl control_terms): w_K tint
    included, 0 where left out; th the control's cone, the lamp's where it has no control;
    valid where select_cones chose the cone."""
    P, wi = np.broadcast_arrays(np.asarray(P, dtype=float), np.asarray(wi, dtype=float))
    Ng = np.broadcast_to(np.asarray(Ng, dtype=float), P.shape)
    terms = []
    for axis, th, valid in select_cones(records, P, Ng):
        th_v = np.where(valid, th, MIN_HALF_ANGLE)
        th_k, w = control_cone(bsdf, wi, np.where(valid[..., None], axis, Ng), th_v)
        w = np.where(valid[..., None], w, 0.0)
        th_k = np.where(np.sum(w, axis=-1) > 0.0, th_k, th_v)
        terms.append((axis, th_k, w, valid))
    return terms


def controls_value(terms, wo):
    """sum_K w_K t_K(wo) (..., 3): what the controls carry toward wo (osl controls_value)."""
    value = 0.0
    for axis, th, w, _ in terms:
        value = value + w * toon_value(axis, th, wo)[..., None]
    return value


def nearest_in_cone(axis, th, R):
    """The direction of the cone (axis, th) nearest to R (..., 3): R where the cone holds it,
    else the axis turned toward R by th (osl nearest_in_cone)."""
    axis, R = np.broadcast_arrays(np.asarray(axis, dtype=float), np.asarray(R, dtype=float))
    th = np.broadcast_to(np.asarray(th, dtype=float), axis.shape[:-1])[..., None]
    perp = R - dot(R, axis)[..., None] * axis
    length = np.linalg.norm(perp, axis=-1, keepdims=True)
    turned = np.cos(th) * axis + np.sin(th) * perp / np.maximum(length, 1e-300)
    angle = np.arccos(np.clip(dot(axis, R), -1.0, 1.0))[..., None]
    return np.where(angle <= th, R, np.where(length ** 2 <= 1e-18, axis, turned))


def residual_guide_fraction(bsdf, records, P, wi, terms, Ng=(0.0, 0.0, 1.0)):
    """lam (...,): the share of the residual's samples aimed at the lamps at P for wi (osl
    residual_guide_fraction), U / (U + A GUIDE_AMBIENT) within [GUIDE_MIN, GUIDE_MAX]:
    U = sum_j E_j min(u_j, A / Omega_j), E_j lamp j's guiding weight, u_j the residual's
    r cos less the controls (terms) toward the direction of the lamp's bounding cone nearest
    the mirror direction, A = tint (1 - c) the residual's albedo bound. A guess: any lam keeps
    the one-sample balance heuristic exact."""
    P, wi = np.broadcast_arrays(np.asarray(P, dtype=float), np.asarray(wi, dtype=float))
    Ng = np.broadcast_to(np.asarray(Ng, dtype=float), P.shape)
    A = np.mean(bsdf.tint * (1.0 - native_factor(bsdf, wi)), axis=-1)
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    U = np.zeros(P.shape[:-1])
    for rec in records:
        E = lamp_share(rec, P, Ng)
        axis, th, valid = lamp_bounding_cone(rec, P)
        d = nearest_in_cone(axis, th, mirror)
        r_cos = eval_residual(bsdf, wi, d) * np.maximum(d[..., 2], 0.0)[..., None]
        u = np.maximum(np.mean(r_cos - controls_value(terms, d), axis=-1), 0.0)
        omega = 4.0 * math.pi * np.sin(0.5 * th) ** 2
        ok = valid & (E > 0.0) & (d[..., 2] > 0.0) & (wi[..., 2] > 0.0)
        U = U + np.where(ok, E * np.minimum(u, A / np.maximum(omega, 1e-12)), 0.0)
    lam = np.clip(U / np.where(U > 0.0, U + A * GUIDE_AMBIENT, 1.0), GUIDE_MIN, GUIDE_MAX)
    return np.where(U > 0.0, lam, GUIDE_MIN)


def guided_residual_beside_controls(bsdf, records, P, wi, u):
    """lamps.sample_guided_residual less what the lamp controls carry, aiming as often as
    residual_guide_fraction says: the residual as the shaders return it beside them (osl
    sample_guided_residual with controls)."""
    Ng = np.broadcast_to([0.0, 0.0, 1.0], np.broadcast_shapes(np.shape(P), np.shape(wi)))
    lam = residual_guide_fraction(bsdf, records, P, wi, control_terms(bsdf, records, P, wi, Ng))

    def less(P, wi, Ng, wo):
        return controls_value(control_terms(bsdf, records, P, wi, Ng), wo)
    return sample_guided_residual(bsdf, records, P, wi, u, less=less, lam=lam)

