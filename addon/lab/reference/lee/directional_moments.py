"""Deterministic directional moments (E, Vn, Vt) of Lee 2018 V-grooves for the sphere-grid
reference (moments, LeeBRDF.directional_moments): the grooves on smooth-variable grids (a tensor
grid for symmetric grooves, an R3 low-discrepancy set for asymmetric ones: _radial_nodes,
_groove_nodes), the entry offsets integrated exactly by runs of equal bounce count, each run's
exit direction exact (geometry's exit angle); MOMENT_NODES, the default rules and their
measured accuracy.
"""
from __future__ import annotations

import math

import numpy as np

from ..microfacet import Microfacet
from ..vgroove import fresnel_fn
from .fresnel_table import FresnelTable
from .geometry import BECKMANN_Y_MAX, PI, exit_angle, max_bounces


# -- deterministic directional moments -------------------------------------------------------------


def _radial_nodes(distribution: str, alpha: float, n: int, partner: bool = False):
    """Midpoint nodes (tan theta, weight) of a wall angle in a variable where the density is
    smooth at both ends (the inverse CDF u is not: tan theta ~ sqrt(u) at 0, and GGX has
    tan theta ~ 1/sqrt(1 - u) at 1, which halves the midpoint rule's order).
    Drawn wall, density D(theta) cos(theta) over the solid angle:
      GGX: tan theta = alpha tan x, x in [0, pi/2], weight sin(2x) (u = sin^2 x);
      Beckmann: tan theta = alpha y, weight 2 y exp(-y^2) (u = 1 - exp(-y^2)).
    Partner wall of asymmetric grooves, density D(theta) sin^2(theta) (sample_partner):
      GGX: tan theta = alpha tan b, weight sin^2 b, with b = (pi/2)(1 - (1 - v)^2) graded
      toward the steep end, where the density peaks and the bounce-count transitions
      accumulate (v midpoint; 10x more accurate than b midpoint at 16 nodes);
      Beckmann: tan theta = alpha y, weight y^2 exp(-y^2) (Gamma(3/2) in y^2).
    Weights normalised to sum 1."""
    v = (np.arange(n) + 0.5) / n
    if distribution == "ggx":
        if partner:
            x = 0.5 * PI * (1.0 - (1.0 - v) ** 2)
            w = np.sin(x) ** 2 * (1.0 - v)
        else:
            x = 0.5 * PI * v
            w = np.sin(2.0 * x)
        tan_t = alpha * np.tan(x)
    else:
        y = v * BECKMANN_Y_MAX
        w = y * y * np.exp(-y * y) if partner else 2.0 * y * np.exp(-y * y)
        tan_t = alpha * y
    return tan_t, w / w.sum()


def _groove_nodes(mf: Microfacet, groove: str, n_theta: int, n_phi: int, n_partner: int):
    """Quadrature nodes of the grooves met by a ray (any wi: by opening area). Returns
    (s, theta_l, theta_r, weight), weights summing to 1; the azimuth covers [0, pi), the other
    half by the symmetry y -> -y (wi lies in the xz plane).
    Symmetric: the drawn wall s ~ D(s)(s.n) on the tensor midpoint grid (_radial_nodes x
    n_phi azimuths). Asymmetric (a 3D integral, where a tensor grid converges slowly): the
    first n_partner * n_theta * n_phi points of the R3 low-discrepancy sequence (Roberts 2018,
    the generalised golden ratio), mapped to (drawn wall, azimuth, partner) by the smooth
    variables of _radial_nodes, weighted by the densities there (self-normalised)."""
    a = mf.alpha_x
    if groove == "symmetric":
        tan_t, w1 = _radial_nodes(mf.distribution, a, n_theta)
        phi = (np.arange(n_phi) + 0.5) / n_phi * PI
        T, P = np.meshgrid(np.arctan(tan_t), phi, indexing="ij")
        th, P = T.ravel(), P.ravel()
        W = np.repeat(w1, n_phi) / n_phi
        tr = th
    else:
        g = 1.2207440846057596  # the real root of x^4 = x + 1
        N = n_theta * n_phi * n_partner
        v = np.mod(0.5 + np.arange(N)[:, None] * np.array([1 / g, 1 / g ** 2, 1 / g ** 3]), 1.0)
        v1, v2, v3 = v.T
        if mf.distribution == "ggx":
            x = 0.5 * PI * v1
            w1, th = np.sin(2.0 * x), np.arctan(a * np.tan(x))
            b = 0.5 * PI * (1.0 - (1.0 - v3) ** 2)
            w3, tr = np.sin(b) ** 2 * (1.0 - v3), np.arctan(a * np.tan(b))
        else:
            y1, y3 = BECKMANN_Y_MAX * v1, BECKMANN_Y_MAX * v3
            w1, th = 2.0 * y1 * np.exp(-y1 * y1), np.arctan(a * y1)
            w3, tr = y3 * y3 * np.exp(-y3 * y3), np.arctan(a * y3)
        P = PI * v2
        W = w1 * w3 / np.sum(w1 * w3)
    s = np.stack([-np.sin(th) * np.cos(P), -np.sin(th) * np.sin(P), np.cos(th)], axis=-1)
    return s, th, tr, W


# Default (n_theta, n_phi, n_partner) of moments() (asymmetric: R3 points = their product).
# Measured accuracy (max abs error of E, Vn, Vt for mu 1 .. 0.01, gold, alpha 0.09 and 1,
# against 8x finer rules; addon/lab/bench_lee.py:moments_accuracy): 1.8e-4 symmetric, 2.5e-4
# asymmetric GGX, 9.1e-4 asymmetric Beckmann; the render test's floors are 2e-4 and 1.5e-3.
MOMENT_NODES = {
    ("symmetric", "ggx"): (128, 128, 1),
    ("symmetric", "beckmann"): (128, 128, 1),
    ("asymmetric", "ggx"): (128, 128, 2),
    ("asymmetric", "beckmann"): (128, 128, 2),
}


def moments(mu, mf: Microfacet, fresnel=None, groove: str = "symmetric", kmax: int | None = None,
            n_theta: int | None = None, n_phi: int | None = None, n_partner: int | None = None):
    """Directional moments (E, Vn, Vt), each (len(mu), 3), for wi = (sqrt(1 - mu^2), 0, mu):
    E = integral f cos_o dwo (the albedo), (Vn, Vt) = z and x components of
    integral f cos_o wo dwo. The same integral as albedo(), organised for speed:
    grooves on a midpoint grid in smooth variables (_groove_nodes), the entry offsets
    integrated exactly (the beam splits into runs of equal bounce count whose lengths are
    closed form, the rule of directional_albedo._albedo_runs), each run's exit direction
    exact (it depends on k only).
    Runs are walked in blocks of bounces (1, 1, 2, 4, 8, ...) with the Fresnel product kept
    cumulatively (frozen after kmax, as the sampler) until every run has left, so the cost is
    about the number of grooves times the mean bounce count, whatever kmax. Convergence in the node counts and agreement with lee.sample Monte Carlo:
    tests/test_reference_lee_moments.py."""
    fresnel = fresnel or fresnel_fn("none")
    d = MOMENT_NODES[groove, mf.distribution]
    n_theta, n_phi, n_partner = n_theta or d[0], n_phi or d[1], n_partner or d[2]
    if not isinstance(fresnel, FresnelTable):
        fresnel = FresnelTable(fresnel)
    mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=float)), 1e-9, 1.0)
    if kmax is None:
        kmax = max_bounces(max(mf.alpha_x, mf.alpha_y), mf.distribution, groove)
    s, theta_l, theta_r, wgt = _groove_nodes(mf, groove, n_theta, n_phi, n_partner)
    sh = np.hypot(s[:, 0], s[:, 1])
    ok = sh > 1e-300
    tx = np.where(ok, s[:, 0] / np.where(ok, sh, 1.0), 1.0)
    ty = np.where(ok, s[:, 1] / np.where(ok, sh, 1.0), 0.0)
    if groove == "symmetric":
        tv_one = 2.0 * np.arctan2(s[:, 2], sh)  # pi - 2 theta_s without cancellation
        L_l = L_r = np.ones_like(theta_l)
    else:
        tv_one = PI - theta_l - theta_r
        L_l, L_r = np.sin(theta_r), np.sin(theta_l)
    # Both first walls as one batch: left-first, then the mirror image (t -> -t).
    sg_all = np.concatenate([np.ones_like(theta_l), -np.ones_like(theta_l)])
    tl_all = np.concatenate([theta_l, theta_r])
    tr_all = np.concatenate([theta_r, theta_l])
    Ll_all = np.concatenate([L_l, L_r])
    Lr_all = np.concatenate([L_r, L_l])
    tv_all = np.concatenate([tv_one, tv_one])
    tx_all = np.concatenate([tx, tx])
    ty_all = np.concatenate([ty, ty])
    out = np.zeros((3, len(mu), 3))
    for i, m in enumerate(mu):
        sin_i = math.sqrt(max(1.0 - m * m, 0.0))
        px, wu = sin_i * tx, -sin_i * ty  # wi.t, wi.u
        theta_i = np.arctan2(px, m)
        rho = np.hypot(px, m)
        fA = L_l * np.cos(theta_i - theta_l)
        fB = -L_r * np.cos(theta_i + theta_r)
        scale = wgt / (fA - fB)
        lo = np.maximum(np.concatenate([fB, -fA]), 0.0)
        hi = np.concatenate([fA, -fB])
        idx = np.nonzero(hi > lo)[0]
        ti = (sg_all * np.concatenate([theta_i, theta_i]))[idx]
        tl, tr, Ll, Lr, tv, sg, tx2, ty2 = (a[idx] for a in (tl_all, tr_all, Ll_all, Lr_all,
                                                              tv_all, sg_all, tx_all, ty_all))
        lo, hi = lo[idx], hi[idx]
        scale = np.concatenate([scale, scale])[idx]
        rho2 = np.concatenate([rho, rho])[idx]
        wu2 = np.concatenate([wu, wu])[idx]
        phi0 = ti + 0.5 * PI - tl
        prev = hi - lo
        run_min = np.full(len(idx), np.inf)
        F = np.ones((len(idx), 3))
        acc = np.zeros((3, 3))
        j_done, C = 0, 1
        while len(prev):
            # Bounces j_done + 1 .. j_done + C of every live run as one (C, runs) block
            # (bounce-major: the cumulative products and minima run along contiguous rows).
            jj = np.arange(j_done + 1, j_done + C + 1, dtype=float)[:, None]
            c = np.minimum(rho2 * np.abs(np.sin(phi0 + (jj - 1.0) * tv)), 1.0)
            Fb = fresnel(c)
            if j_done + C > kmax:
                Fb = np.where((jj <= kmax)[..., None], Fb, 1.0)
            Fcum = F * np.cumprod(Fb, axis=0)
            R = np.where(np.mod(jj, 2.0) == 0.0, Ll, Lr)
            rm = np.minimum.accumulate(np.concatenate(
                [run_min[None, :], R * np.sin(phi0 + jj * tv)], axis=0), axis=0)[1:]
            cur = np.minimum(np.clip(np.minimum(rm, hi) - lo, 0.0, None), prev)
            before = np.concatenate([prev[None, :], cur[:-1]], axis=0)
            w = (before - cur) * scale  # beam fraction with exactly j bounces
            theta_o = np.clip(sg * exit_angle(ti, tl, tr, jj), -0.5 * PI, 0.5 * PI)
            wF = (w[..., None] * Fcum).reshape(-1, 3)
            acc[0] += wF.sum(0)
            acc[1] += (rho2 * np.cos(theta_o)).reshape(-1) @ wF
            acc[2] += (rho2 * np.sin(theta_o) * tx2 + wu2 * ty2).reshape(-1) @ wF  # wo.x
            prev, run_min, F = cur[-1], rm[-1], Fcum[-1]
            keep = prev > 0.0
            (ti, tl, tr, Ll, Lr, lo, hi, tv, scale, rho2, wu2, tx2, ty2, sg, phi0, run_min, F,
             prev) = (a[keep] for a in (ti, tl, tr, Ll, Lr, lo, hi, tv, scale, rho2, wu2, tx2,
                                        ty2, sg, phi0, run_min, F, prev))
            j_done += C
            C = min(2 * C if j_done >= 2 else 1, 512)
        out[:, i] = acc
    return out[0], out[1], out[2]
