"""The BRDF of asymmetric Lee 2018 V-grooves (docs/lee-asymmetric-grooves.md sec. 5): the
normalisation of the partner-wall density (partner_norm), the window of partner angles that send
wi to wo after k bounces (_partner_window, from the exit angle of geometry) and eval_asymmetric,
the integral over the partner wall by Gauss-Legendre, or its one-node Monte Carlo form (the
Native + Residual shader's aimed terms).

BRDF (asymmetric; doc sec. 5, eval_asymmetric): the same two frames and k, and for each the
integral over the partner wall theta_r of the groove density g = D_l D_r sin(theta_r)
sin(theta_l + theta_r) / Z (landed on either wall) times the beam fraction and the Fresnel
product, with |ds_l/dwo| = sin(theta_l) / (c_k |(wi + wo).t|), c_k = k (even) or k + 1 (odd):
theta_l is fixed by theta_r through the exit angle, and a Gauss-Legendre rule over the window
of theta_r, invariant under path reversal, keeps f(wi, wo) = f(wo, wi) to rounding.
"""
from __future__ import annotations

import math

import numpy as np

from ..microfacet import Microfacet
from ..vgroove import fresnel_fn, groove_frame
from .fresnel_table import FresnelTable
from .geometry import BECKMANN_Y_MAX, PI, max_bounces


# -- evaluation (asymmetric) -----------------------------------------------------------------------
def partner_norm(distribution: str, alpha: float) -> float:
    """Z = integral_0^{pi/2} D(theta) sin^2(theta) d theta (isotropic D; the normalisation of the
    partner density D sin^2 / Z): with x = tan(theta) / alpha it is alpha/pi times
    integral x^2 / (1 + x^2)^2 dx = pi/4 (GGX) or integral x^2 exp(-x^2) dx = sqrt(pi)/4
    (Beckmann), so Z = alpha / 4 (GGX), alpha / (4 sqrt(pi)) (Beckmann)."""
    return alpha / 4.0 if distribution == "ggx" else alpha / (4.0 * math.sqrt(PI))


def _partner_window(theta_i, theta_o, k: int):
    """The line of grooves that send wi to wo after k bounces, left wall first (frame fixed):
    theta_l = A + B theta_r from the exit angle (sec. 2):
      k even: theta_v = (theta_o - theta_i + pi)/k (fixed), theta_l = pi - theta_v - theta_r;
      k odd:  (k + 1) theta_l = theta_o + theta_i + (k - 1)(pi - theta_r).
    and the interval (a, b) of theta_r where the necessary conditions hold: both walls in
    (0, pi/2); the left wall lit, phi0 > 0 <=> theta_l < theta_i + pi/2; the k-th wall end
    above the line, phi0 + (k-1) theta_v < pi <=> theta_l < theta_o + pi/2 (k odd) or
    theta_l > theta_o + pi/2 - theta_v (k even). The last condition is the first one for the
    reversed path (wo -> wi), so the window is the same set of grooves both ways (reciprocity
    of the quadrature, not only of the integral). Returns (A, B, a, b)."""
    if k % 2 == 0:
        tv = (theta_o - theta_i + PI) / k
        A, B = PI - tv, -1.0
        lo_l = np.maximum(0.0, theta_o + 0.5 * PI - tv)
        hi_l = np.minimum(0.5 * PI, theta_i + 0.5 * PI)
    else:
        A, B = (theta_o + theta_i + (k - 1) * PI) / (k + 1), -(k - 1.0) / (k + 1.0)
        lo_l = np.zeros_like(theta_i)
        hi_l = np.minimum(np.minimum(0.5 * PI, theta_i + 0.5 * PI), theta_o + 0.5 * PI)
    if k == 1:  # theta_l = A does not depend on theta_r
        ok = (A > lo_l) & (A < hi_l)
        a = np.zeros_like(A)
        b = np.where(ok, 0.5 * PI, 0.0)
    else:
        a = np.maximum((A - hi_l) / -B, 0.0)
        b = np.minimum((A - lo_l) / -B, 0.5 * PI)
    return A, B, a, b


def eval_asymmetric(wi, wo, mf: Microfacet, fresnel=None, kmax: int | None = None,
                    n_partner: int = 12, fresnel_bounces: int | None = None, u=None):
    """Asymmetric-groove BRDF f(wi, wo) (RGB, without the cosine), k = 1..kmax, isotropic D
    (docs/lee-asymmetric-grooves.md sec. 5):

        f = sum over frames t = +-horizontal(wi + wo), k of
            integral d theta_r  g(theta_l, theta_r) len_k / (f_A - f_B) prod_j F_j
                                sin(theta_l) / (c_k |(wi + wo).t|) / (wo.n),
        g = D(theta_l) D(theta_r) sin(theta_r) sin(theta_l + theta_r) / Z     (both landings),
        c_k = k (k even) or k + 1 (k odd)   (|d theta_o / d theta_l| at fixed theta_r),

    theta_l the first-hit (left) wall of frame t, fixed by theta_r through the exit angle
    (_partner_window). len_k, the offsets making exactly k bounces left wall first, is the
    width of the strip of lines above the wall ends V_0 .. V_(k-1) and below V_-1, V_k and the
    apex: len_k = (min_{0<=m<k} f(V_m) - max(f(V_-1), f(V_k), 0))+, f(V_m) = R_m sin(phi0 +
    m theta_v) (sec. 2); the window keeps the phases of V_0 .. V_(k-1) in (0, pi), where sin is
    concave, so the minimum is over V_0, V_1, V_(k-2), V_(k-1) (each parity's ends).
    Quadrature: the theta_r window is split where theta_l = theta_r; on each side the variable
    is the gentler wall's (GGX: b with tan(theta) = alpha tan(b); Beckmann: y = tan(theta) /
    alpha up to BECKMANN_Y_MAX), where g peaks at whichever wall is nearly flat; n_partner
    Gauss-Legendre nodes per side, frame and k. The rule is invariant under path reversal
    (odd k: same frame, theta_i <-> theta_o; even k: the other frame, theta_l <-> theta_r), so
    f(wi, wo) = f(wo, wi) to rounding. The integrand has kinks where len_k reaches 0, so the
    rule converges algebraically (measured in the doc). fresnel is tabulated (FresnelTable:
    exact at 8193 nodes, interpolation error < 1e-7). kmax and fresnel_bounces as in eval():
    the terms summed, and Max Bounces (the bounces that get their Fresnel factor).

    u: (..., 2, kmax, 2) uniforms (frame, k, side) turn the rule into its one-node Monte Carlo
    form: one node per side, frame and k, uniform in the variable (weight: the interval), an
    unbiased estimate of the same sum (lee_low_orders_asymmetric in osl/lee_vgroove.osl, which
    the Native + Residual shader evaluates on its aimed samples)."""
    if abs(mf.alpha_x - mf.alpha_y) > 1e-12 * mf.alpha_x:
        raise ValueError("asymmetric grooves are implemented for isotropic D only")
    fresnel = fresnel or fresnel_fn("none")
    if not isinstance(fresnel, FresnelTable):
        fresnel = FresnelTable(fresnel)
    wi = np.asarray(wi, dtype=float)
    wo = np.asarray(wo, dtype=float)
    shape = np.broadcast_shapes(wi.shape, wo.shape)
    wi = np.broadcast_to(wi, shape).reshape(-1, 3)
    wo = np.broadcast_to(wo, shape).reshape(-1, 3)
    alpha = mf.alpha_x
    if kmax is None:
        kmax = max_bounces(alpha, mf.distribution, "asymmetric")
    n_f = kmax if fresnel_bounces is None else max(int(fresnel_bounces), 1)
    Z = partner_norm(mf.distribution, alpha)
    x_gl, w_gl = np.polynomial.legendre.leggauss(n_partner)
    x_gl, w_gl = 0.5 * (x_gl + 1.0), 0.5 * w_gl  # on [0, 1]
    if u is not None:
        u = np.broadcast_to(np.asarray(u, dtype=float), shape[:-1] + (2, kmax, 2))
        u = u.reshape(-1, 2, kmax, 2)
    h = wi + wo
    t0, _ = groove_frame(h)
    hh = np.maximum(np.hypot(h[:, 0], h[:, 1]), 1e-12)  # |(wi + wo).t|; see eval()
    acc = np.zeros((wi.shape[0], 3))
    valid = (wi[:, 2] > 0) & (wo[:, 2] > 0)

    if mf.distribution == "ggx":
        def var(theta):  # the smooth variable of a wall angle
            return np.arctan(np.tan(np.clip(theta, 0.0, 0.5 * PI)) / alpha)

        def tan_of(b):  # tan(theta) = alpha tan(b), d theta / d b
            tb = np.tan(b)
            T = alpha * tb
            return T, alpha * (1.0 + tb * tb) / (1.0 + T * T)
    else:
        def var(theta):  # y = tan(theta) / alpha, capped at BECKMANN_Y_MAX
            return np.minimum(np.tan(np.clip(theta, 0.0, 0.5 * PI)) / alpha, BECKMANN_Y_MAX)

        def tan_of(y):
            T = alpha * y
            return T, alpha / (1.0 + T * T)

    def nodes(v0, v1, x, w):
        """Nodes x (on [0, 1]) with weights w in the variable on [v0, v1]: the wall angles,
        their sin and cos, and the weights in d theta."""
        T, d = tan_of(v0[:, None] + (v1 - v0)[:, None] * x)
        c = 1.0 / np.sqrt(1.0 + T * T)
        return np.arctan(T), T * c, c, (v1 - v0)[:, None] * w * d

    def D(s, c):
        return mf.D(np.stack([s, np.zeros_like(s), c], axis=-1))

    for frame, sg in enumerate((1.0, -1.0)):
        t = sg * t0
        p_i, p_o = np.sum(wi * t, -1), np.sum(wo * t, -1)
        theta_i = np.arctan2(p_i, wi[:, 2])
        theta_o = np.arctan2(p_o, wo[:, 2])
        rho = np.hypot(p_i, wi[:, 2])
        for k in range(1, kmax + 1):
            A, B, a, b = _partner_window(theta_i, theta_o, k)
            idx = np.nonzero(valid & (b > a))[0]
            if idx.size == 0:
                continue
            A, a, b = A[idx], a[idx], b[idx]
            sA, cA = np.sin(A)[:, None], np.cos(A)[:, None]
            split = np.clip(A / (1.0 - B), a, b)  # theta_l = theta_r there
            if u is None:
                (x1, q1), (x2, q2) = (x_gl, w_gl), (x_gl, w_gl)
            else:
                one = np.ones(1)
                (x1, q1), (x2, q2) = ((u[idx, frame, k - 1, side][:, None], one)
                                      for side in (0, 1))
            n1 = np.size(x1, -1)
            # Side 1, theta_r in [a, split]: theta_r is the gentler wall, nodes in its variable.
            tr1, s_r1, c_r1, w1 = nodes(var(a), var(split), x1, q1)
            # Side 2, theta_r in [split, b]: nodes in theta_l's variable, d theta_r = d theta_l
            # / |B| (k = 1: theta_l = A is fixed, theta_r's variable again).
            if k == 1:
                tr2, s_r2, c_r2, w2 = nodes(var(split), var(b), x2, q2)
                tl = np.broadcast_to(A[:, None], tr1.shape[:1] + (tr1.shape[1] + tr2.shape[1],))
                s_l, c_l = (np.broadcast_to(v, tl.shape) for v in (sA, cA))
                tr = np.concatenate([tr1, tr2], axis=1)
                s_r, c_r = np.concatenate([s_r1, s_r2], 1), np.concatenate([c_r1, c_r2], 1)
                wq = np.concatenate([w1, w2], axis=1)
            else:
                tl2, s_l2, c_l2, w2 = nodes(var(A + B * b), var(A + B * split), x2, q2)
                tr = np.concatenate([tr1, (A[:, None] - tl2) / -B], axis=1)
                tl = np.concatenate([A[:, None] + B * tr1, tl2], axis=1)
                wq = np.concatenate([w1, w2 / -B], axis=1)
                if k % 2 == 0:  # theta_l + theta_r = A: the other wall by angle addition
                    s_l1, c_l1 = sA * c_r1 - cA * s_r1, cA * c_r1 + sA * s_r1
                    s_r2, c_r2 = sA * c_l2 - cA * s_l2, cA * c_l2 + sA * s_l2
                else:
                    s_l1, c_l1 = np.sin(tl[:, :n1]), np.cos(tl[:, :n1])
                    s_r2, c_r2 = np.sin(tr[:, n1:]), np.cos(tr[:, n1:])
                s_l, c_l = np.concatenate([s_l1, s_l2], 1), np.concatenate([c_l1, c_l2], 1)
                s_r, c_r = np.concatenate([s_r1, s_r2], 1), np.concatenate([c_r1, c_r2], 1)
            ti = theta_i[idx, None]
            s_i, c_i = np.sin(ti), np.cos(ti)
            s_o, c_o = np.sin(theta_o[idx, None]), np.cos(theta_o[idx, None])
            s_v = s_l * c_r + c_l * s_r              # sin(theta_v) = sin(theta_l + theta_r)
            c_v = s_l * s_r - c_l * c_r              # cos(theta_v)
            P = c_i * c_l + s_i * s_l                # sin(phi0) = cos(theta_i - theta_l)
            Q = c_i * s_l - s_i * c_l                # cos(phi0)
            fA = s_r * P                             # f(V_0), L_l = sin(theta_r)
            fB = -s_l * (c_i * c_r - s_i * s_r)      # f(V_-1), L_r = sin(theta_l)
            upper = np.minimum(fA, s_l * (P * c_v + Q * s_v)) if k >= 2 else fA  # V_1
            # Phase of V_(k-1), phi0 + (k-1) theta_v, by the exit angle: pi/2 + theta_l -
            # theta_o (k odd) or pi/2 + theta_o + theta_r (k even).
            if k % 2:
                sp, cp = c_l * c_o + s_l * s_o, c_l * s_o - s_l * c_o
                R_last, R_next = s_r, s_l           # R_m: L_l (m even), L_r (m odd)
            else:
                sp, cp = c_o * c_r - s_o * s_r, -(s_o * c_r + c_o * s_r)
                R_last, R_next = s_l, s_r
            if k >= 3:
                upper = np.minimum(upper, np.minimum(R_last * sp, R_next * (sp * c_v - cp * s_v)))
            lower = np.maximum(np.maximum(fB, 0.0), R_next * (sp * c_v + cp * s_v))  # V_k
            length = upper - lower
            on = length > 0.0
            if not np.any(on):
                continue
            row = np.nonzero(on)[0]
            s_l, c_l, s_r, c_r, s_v = s_l[on], c_l[on], s_r[on], c_r[on], s_v[on]
            g = D(s_l, c_l) * D(s_r, c_r) * s_r * s_v / Z
            ck = float(k if k % 2 == 0 else k + 1)
            val = g * length[on] / (fA - fB)[on] * s_l / ck * wq[on]
            val = np.where(np.isfinite(val), val, 0.0)  # guard for degenerate inputs
            if fresnel.constant:
                contrib = val[:, None] * fresnel.F[0]
            else:
                tl_, tr_ = tl[on], tr[on]
                phi0 = theta_i[idx][row] + 0.5 * PI - tl_
                tv = PI - tl_ - tr_
                cosb = np.minimum(rho[idx][row][:, None] * np.abs(  # the first min(k, n_f)
                    np.sin(phi0[:, None] + np.arange(min(k, n_f)) * tv[:, None])), 1.0)
                contrib = val[:, None] * fresnel.product(cosb)
            for ch in range(3):
                acc[idx, ch] += np.bincount(row, weights=contrib[:, ch], minlength=idx.size)
    out = np.where(valid[:, None], acc / (hh * np.where(valid, wo[:, 2], 1.0))[:, None], 0.0)
    return out.reshape(shape[:-1] + (3,))
