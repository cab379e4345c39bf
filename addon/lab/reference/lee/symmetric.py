"""The BRDF of symmetric Lee 2018 V-grooves in closed form: G_k_symmetric, the beam fraction making
exactly k bounces (seed eq. 5-3), and eval, the sum over both walls and k (seed eq. 5-7; the
Native + Residual shader's low orders are this with kmax = AIMED_ORDERS).

BRDF (symmetric; seed eq. 5-7, docs/models.md):
    f(wi, wo) = sum over first walls s and k of
        D(s) |wi.s| G_k prod_j F_j |ds/dwo| / (|wi.n| |wo.n|),
    G_k = (length of the offsets in [max(f_B, 0), f_A] giving k bounces) / f_A,
    |ds/dwo| = sin(theta_s) / (2 k |(wi + wo).t|)
(for odd k, (wi + wo).t = 2 (wi.h) sin(theta_h) and this is the seed's
sin(theta_s) / (4 k |wi.h| sin(theta_h))). Given (wi, wo), the groove azimuth is that of
h = wi + wo (every bounce map wi -> wo is a rotation by pi or a rotation about u composed with
-1, so u _|_ wi + wo) up to its sign, and theta_s follows from theta_o(k) (geometry).
"""
from __future__ import annotations

import numpy as np

from ..microfacet import Microfacet
from ..vgroove import fresnel_fn, groove_frame
from .geometry import PI, fresnel_product, max_bounces


# -- G_k ------------------------------------------------------------------------------------------
def G_k_symmetric(theta_i, theta_s, k):
    """Fraction of wall s's projected width (toward wi, 2D) whose rays make exactly k bounces
    (seed eq. 5-3, both cases over f_A): offsets l in [max(f_B, 0), f_A] with
    k(l) = k <=> asin(l) in (pi - phi0 - k tv, pi - phi0 - (k-1) tv]."""
    tv = PI - 2.0 * theta_s
    fA = np.cos(theta_i - theta_s)
    fb = np.maximum(-np.cos(theta_i + theta_s), 0.0)
    phi0 = theta_i + 0.5 * tv
    lo = np.sin(np.clip(PI - phi0 - k * tv, 0.0, 0.5 * PI))
    hi = np.sin(np.clip(PI - phi0 - (k - 1.0) * tv, 0.0, 0.5 * PI))
    length = np.maximum(np.minimum(fA, hi) - np.maximum(fb, lo), 0.0)
    return np.where(fA > 0.0, length / np.where(fA > 0.0, fA, 1.0), 0.0)


# -- evaluation (symmetric) ------------------------------------------------------------------------
def eval(wi, wo, mf: Microfacet, fresnel=None, kmax: int | None = None,
         fresnel_bounces: int | None = None):
    """Symmetric-groove BRDF f(wi, wo) (RGB, without the cosine), summed over k = 1..kmax and
    both walls (seed eq. 5-7). For each sign of t = +-horizontal(wi + wo) and each k, the one
    candidate groove angle: theta_v = (theta_o - theta_i + pi - 2 pi j)/k (k even) or
    (pi - theta_i - theta_o + 2 pi j)/k (k odd), j chosen so that k theta_v lies in the window
    (-theta_i, 3 pi/2 - theta_i) where G_k can be non-zero (at most one j; j depends on the
    parity of k only, so every k is one row of a (k, direction) block).

    kmax: the number of bounce terms summed, the truncation of the series (default
    max_bounces(alpha): longer paths carry less than 1e-4 of the energy); kmax = 1 is the
    single-bounce term alone. fresnel_bounces: Max Bounces, the first fresnel_bounces bounces
    of a path get their Fresnel factor and later ones F = 1, as in the sampler (default: every
    bounce). LeeBRDF.eval passes the derived bound as kmax and the user's Max Bounces as
    fresnel_bounces, so its cost does not grow with Max Bounces."""
    fresnel = fresnel or fresnel_fn("none")
    wi = np.asarray(wi, dtype=float)
    wo = np.asarray(wo, dtype=float)
    shape = np.broadcast_shapes(wi.shape, wo.shape)
    wi = np.broadcast_to(wi, shape).reshape(-1, 3)
    wo = np.broadcast_to(wo, shape).reshape(-1, 3)
    if kmax is None:
        kmax = max_bounces(max(mf.alpha_x, mf.alpha_y), mf.distribution)
    kmax = max(int(kmax), 1)
    n_f = kmax if fresnel_bounces is None else max(int(fresnel_bounces), 1)
    n = wi.shape[0]
    h = wi + wo
    t0, _ = groove_frame(h)
    out = np.zeros((n, 3))
    valid = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    hh = np.hypot(h[:, 0], h[:, 1])
    ks = np.arange(1.0, kmax + 1.0)[:, None]
    even = np.mod(ks, 2.0) == 0.0
    chunk = max(1, (1 << 18) // kmax)  # directions per (k, direction) block
    for sg in (1.0, -1.0):
        t = sg * t0
        theta_i = np.arctan2(np.sum(wi * t, -1), wi[:, 2])
        theta_o = np.arctan2(np.sum(wo * t, -1), wo[:, 2])
        rho = np.hypot(np.sum(wi * t, -1), wi[:, 2])
        c = 0.75 * PI - theta_i
        X = theta_o - theta_i + PI  # k even
        ktv_even = X - 2.0 * PI * np.round((X - c) / (2.0 * PI))
        X = PI - theta_i - theta_o  # k odd
        ktv_odd = X + 2.0 * PI * np.round((c - X) / (2.0 * PI))
        for start in range(0, n, chunk):
            sl = slice(start, start + chunk)
            tv = np.where(even, ktv_even[sl], ktv_odd[sl]) / ks
            ok = valid[sl] & (tv > 0.0) & (tv < PI)
            theta_s = 0.5 * (PI - tv)
            G = np.where(ok, G_k_symmetric(theta_i[sl], theta_s, ks), 0.0)
            kk, pp = np.nonzero(G > 0.0)
            if kk.size == 0:
                continue
            p = pp + start
            k = ks[kk, 0]
            ts, tvp = theta_s[kk, pp], tv[kk, pp]
            s = np.sin(ts)[:, None] * t[p]
            s[:, 2] += np.cos(ts)
            D = mf.D(s)
            wis = rho[p] * np.cos(theta_i[p] - ts)
            # |(wi + wo).t| -> 0 is an integrable singularity of the Jacobian; the floor keeps
            # eval finite on that measure-zero set (the sampler, and the OSL twin, never eval).
            jac = np.sin(ts) / (2.0 * k * np.maximum(hh[p], 1e-12))
            F = fresnel_product(fresnel, rho[p], theta_i[p] + 0.5 * tvp, tvp, k, n_f)
            val = D * wis * G[kk, pp] * jac / (wi[p, 2] * wo[p, 2])
            for ch in range(3):
                out[:, ch] += np.bincount(p, weights=val * F[:, ch], minlength=n)
    return out.reshape(shape[:-1] + (3,))
