"""The analytic sampler of Lee 2018 V-grooves (the twin of osl/lee_vgroove.osl's sampler): the
groove wall drawn from D(s)(s.n), the size-biased partner wall of asymmetric grooves
(sample_partner, docs/lee-asymmetric-grooves.md), a uniform entry offset, then the bounce count
and exit angle in closed form (geometry, seed eqs. 5-1, 5-2 as resolved there) and the Fresnel
product; sample_albedo averages its weights.
"""
from __future__ import annotations

import numpy as np

from ..microfacet import Microfacet
from ..vgroove import fresnel_fn, groove_frame
from .geometry import (PI, bounce_count, bounce_count_symmetric, exit_angle, fresnel_product,
                       max_bounces)


def _vec(t, n3, u, rho, theta, wu):
    return (rho * np.sin(theta))[..., None] * t + (rho * np.cos(theta))[..., None] * n3 \
        - wu[..., None] * u


def local_angles(wi, t, u):
    """wi in the groove frame (t, u): its 2D angle theta = atan2(wi.t, wi.z), 2D length
    rho = |(wi.t, wi.z)| and wi.u (geometry's conventions)."""
    wi = np.broadcast_to(np.asarray(wi, dtype=float), np.shape(t))
    px = np.sum(wi * t, axis=-1)
    wu = np.sum(wi * u, axis=-1)
    pz = wi[..., 2]
    return np.arctan2(px, pz), np.hypot(px, pz), wu


# -- size-biased partner wall (asymmetric grooves) -----------------------------------------------
def sample_partner(distribution: str, alpha, u1, u2, u3):
    """Partner-wall angle theta_r of an asymmetric groove, density ~ D(theta) sin^2(theta)
    (the slope radius size-biased; docs/lee-asymmetric-grooves.md), closed form from three
    uniforms: with E = -ln u1, c = cos(2 pi u3), s = sin(2 pi u3), L = -ln u2 (a Gamma(1), and
    L c^2, L s^2 two Gamma(1/2) by Box-Muller):
      Beckmann: tan^2 theta = alpha^2 (E + L c^2)              (Gamma(3/2))
      GGX:      tan^2 theta = alpha^2 (E + L c^2) / (L s^2)    (beta-prime(3/2, 1/2))."""
    E = -np.log(np.maximum(u1, 1e-300))
    L = -np.log(np.maximum(u2, 1e-300))
    c = np.cos(2.0 * PI * u3)
    num = alpha * np.sqrt(E + L * c * c)
    if distribution == "ggx":
        s = np.sin(2.0 * PI * u3)
        return np.arctan2(num, np.sqrt(L) * np.abs(s))
    return np.arctan(num)


# -- the sampler -----------------------------------------------------------------------------------
def sample(wi, u, mf: Microfacet, fresnel=None, groove: str = "symmetric", kmax: int | None = None):
    """Analytic sampler: (wo, weight RGB, k). u: uniforms (..., 3) symmetric, (..., 6) asymmetric.

    u0, u1: the drawn wall s ~ D(s)(s.n) (the groove; its frame has s on the left); [u3, u4, u5:
    the partner wall's angle, asymmetric]; u2: the offset l = f_B + u2 (f_A - f_B) (uniform
    entry point on the opening; l < 0 means the right wall first: mirror). Then k, theta_o in
    closed form; weight = prod of the k Fresnel terms (exactly 1 with F = 1). The exit
    direction is exact for every k; the Fresnel loop stops at kmax (Max Bounces; default
    max_bounces(alpha)): paths with k > kmax (with the default, energy < 1e-4) carry the
    product of their first kmax Fresnel terms, so the furnace stays exactly 1."""
    fresnel = fresnel or fresnel_fn("none")
    wi = np.asarray(wi, dtype=float)
    u = np.asarray(u, dtype=float)
    if kmax is None:
        kmax = max_bounces(max(mf.alpha_x, mf.alpha_y), mf.distribution, groove)
    s = mf.sample_dcos(u[..., 0], u[..., 1])
    t, ax = groove_frame(s)
    sh = np.hypot(s[..., 0], s[..., 1])
    theta_l = np.arctan2(sh, s[..., 2])
    if groove == "symmetric":
        theta_r = theta_l
        tv = 2.0 * np.arctan2(s[..., 2], sh)  # pi - 2 theta_s without cancellation
    else:
        theta_r = sample_partner(mf.distribution, mf.alpha_x, u[..., 3], u[..., 4], u[..., 5])
        tv = PI - theta_l - theta_r
    theta_i, rho, wu = local_angles(wi, t, ax)
    L_l, L_r = np.sin(theta_r), np.sin(theta_l)  # wall lengths (apex depth sin_l sin_r)
    if groove == "symmetric":
        L_l = L_r = np.ones_like(theta_l)
    fA = L_l * np.cos(theta_i - theta_l)
    fB = -L_r * np.cos(theta_i + theta_r)
    ell = fB + u[..., 2] * (fA - fB)
    right = ell < 0.0
    sg = np.where(right, -1.0, 1.0)
    ti = sg * theta_i
    tl = np.where(right, theta_r, theta_l)
    tr = np.where(right, theta_l, theta_r)
    Ll = np.where(right, L_r, L_l)
    Lr = np.where(right, L_l, L_r)
    ell = np.abs(ell)
    if groove == "symmetric":
        k = bounce_count_symmetric(ti, tv, ell)
    else:
        k = bounce_count(ti, tl, tr, ell, Ll, Lr)
    k = np.minimum(k, 2.0 ** 52)  # exact integers; huge only when theta_v underflows
    theta_o = sg * exit_angle(ti, tl, tr, k)
    theta_o = np.clip(theta_o, -0.5 * PI, 0.5 * PI)
    n3 = np.zeros_like(t)
    n3[..., 2] = 1.0
    wo = _vec(t, n3, ax, rho, theta_o, wu)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    phi0 = ti + 0.5 * PI - tl
    w = fresnel_product(fresnel, rho, phi0, tv, np.minimum(k, kmax), kmax)
    return wo, w, k.astype(np.int64)


def sample_albedo(wi, mf, n, rng, fresnel=None, groove="symmetric", chunk=1 << 20, kmax=None):
    """Albedo by the analytic sampler: (mean RGB, stderr RGB)."""
    s1, s2, done = np.zeros(3), np.zeros(3), 0
    nu = 3 if groove == "symmetric" else 6
    while done < n:
        m = min(chunk, n - done)
        _, w, _ = sample(wi, rng.random((m, nu)), mf, fresnel, groove, kmax)
        s1 += w.sum(axis=0)
        s2 += (w * w).sum(axis=0)
        done += m
    mean = s1 / n
    return mean, np.sqrt(np.maximum(s2 / n - mean * mean, 0.0) / n)
