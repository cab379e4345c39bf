"""The closed-form directional albedo of Lee 2018 V-grooves by deterministic quadrature (albedo):
composite Gauss-Legendre rules for the wall angles in smooth variables (_wall_nodes), and the
beam's runs of equal bounce count integrated exactly from the bounce-count definition of
geometry (_albedo_runs; docs/lee-asymmetric-grooves.md sec. 2, its convergence sec. 6). The
reference the sampler, the evaluations and the OSL shader are measured against.
"""
from __future__ import annotations

import math

import numpy as np

from ..microfacet import Microfacet
from ..vgroove import fresnel_fn
from .fresnel_table import FresnelTable
from .geometry import BECKMANN_Y_MAX, PI, max_bounces


# -- the deterministic albedo ---------------------------------------------------------------------
GAUSS_PANEL = 2  # Gauss-Legendre nodes per panel of albedo()'s wall rules


def _wall_nodes(distribution: str, alpha: float, n: int, partner: bool = False, breaks=()):
    """Nodes (theta, weight) of a wall angle, weights summing to 1, for albedo(): composite
    Gauss-Legendre (GAUSS_PANEL nodes per panel, about n in all) in a variable where the
    density is smooth at both ends (the inverse CDF u is not: tan theta ~ sqrt(u) at 0, and
    GGX has tan theta ~ 1/sqrt(1 - u) at 1, a tail the midpoint rule in u resolves only as
    about n^-1.3), with panel ends at `breaks` (wall angles where the integrand has a kink
    for every other groove coordinate, see albedo):
      drawn wall, D(s)(s.n): GGX tan theta = alpha tan x, x in [0, pi/2], weight sin(2x)
        (u = sin^2 x); Beckmann tan theta = alpha y, y in [0, BECKMANN_Y_MAX], weight
        2 y exp(-y^2) (u = 1 - exp(-y^2));
      partner, D sin^2 (sample_partner): GGX tan theta = alpha tan b, b = (pi/2)(1 - (1 - v)^2)
        (v graded toward the steep end, where the density peaks and the bounce-count kinks
        accumulate), weight sin^2(b) db/dv; Beckmann y, weight y^2 exp(-y^2).
    The panels are spread over the intervals between breaks in proportion to their length in
    the variable (at least one each)."""
    ggx = distribution == "ggx"
    top = 1.0 if (ggx and partner) else 0.5 * PI if ggx else BECKMANN_Y_MAX

    def var(theta):  # the integration variable of a wall angle
        t = math.tan(min(max(theta, 0.0), 0.5 * PI)) / alpha
        if not ggx:
            return min(t, BECKMANN_Y_MAX)
        b = math.atan(t)
        return 1.0 - math.sqrt(max(1.0 - 2.0 * b / PI, 0.0)) if partner else b

    ends = sorted({0.0, top, *(var(b) for b in breaks if 0.0 < b < 0.5 * PI)})
    ends = [e for i, e in enumerate(ends) if i == 0 or e - ends[i - 1] > 1e-12 * top]
    panels = max(1, -(-n // GAUSS_PANEL))
    gx, gw = np.polynomial.legendre.leggauss(GAUSS_PANEL)
    vs, ws = [], []
    for a, b in zip(ends[:-1], ends[1:]):
        m = max(1, round(panels * (b - a) / top))
        e = np.linspace(a, b, m + 1)
        h = 0.5 * np.diff(e)[:, None]
        vs.append((0.5 * (e[:-1] + e[1:])[:, None] + h * gx).ravel())
        ws.append((h * gw).ravel())
    v, w = np.concatenate(vs), np.concatenate(ws)
    if ggx:
        if partner:
            x = 0.5 * PI * (1.0 - (1.0 - v) ** 2)
            w = w * np.sin(x) ** 2 * (1.0 - v)
        else:
            x = v
            w = w * np.sin(2.0 * x)
        theta = np.arctan(alpha * np.tan(x))
    else:
        w = w * (v * v if partner else 2.0 * v) * np.exp(-v * v)
        theta = np.arctan(alpha * v)
    return theta, w / w.sum()


def _albedo_runs(ti, tl, tr, lo, hi, Ll, Lr, rho, fresnel, kmax):
    """Sum over k of (length of the left-first offsets in (lo, hi] making k bounces) times
    prod_{j <= min(k, kmax)} F_j, per groove (RGB): the runs of equal count from the
    DEFINITION k(l) = first m with f(V_m) < l (k(l) >= j + 1 <=> l <= min_{m <= j} f(V_m); not
    from the sampler's counting formula), the Fresnel product kept cumulatively, the grooves
    whose runs have all left dropped as the walk goes. After kmax bounces the factors are 1
    (as in the sampler), so what is left of the beam then adds with the product so far."""
    tv = PI - tl - tr
    phi0 = ti + 0.5 * PI - tl
    out = np.zeros(np.shape(ti) + (3,))
    idx = np.arange(np.size(ti))
    prev = np.maximum(hi - lo, 0.0)  # length with k >= 1
    run_min = np.full(np.shape(ti), np.inf)
    F = np.ones(np.shape(ti) + (3,))
    j = 0
    while idx.size:
        j += 1
        if j > kmax:
            out[idx] += prev[:, None] * F
            break
        F = F * fresnel(np.minimum(rho * np.abs(np.sin(phi0 + (j - 1) * tv)), 1.0))
        run_min = np.minimum(run_min, (Ll if j % 2 == 0 else Lr) * np.sin(phi0 + j * tv))
        cur = np.minimum(np.clip(np.minimum(run_min, hi) - lo, 0.0, None), prev)
        out[idx] += (prev - cur)[:, None] * F  # length with k == j
        keep = cur > 0.0
        idx, prev = idx[keep], cur[keep]
        ti, tl, tr, lo, hi, Ll, Lr, rho, tv, phi0, run_min, F = (
            a[keep] for a in (ti, tl, tr, lo, hi, Ll, Lr, rho, tv, phi0, run_min, F))
    return out


def albedo(wi, mf: Microfacet, fresnel=None, groove: str = "symmetric", n: int = 512,
           kmax: int | None = None, n_partner: int = 96):
    """Closed-form directional albedo (RGB) by deterministic quadrature over the grooves:
    E_s[ sum over first walls and k of (beam fraction with k bounces) prod F ], s ~ D(s)(s.n)
    on a tensor grid: the wall angle on about n nodes of _wall_nodes (composite 2-point
    Gauss-Legendre in a variable smooth at both ends: GGX tan theta = alpha tan x, Beckmann
    tan theta = alpha y), the azimuth on n/2 midpoint nodes over [0, pi), doubled by the
    symmetry y -> -y (wi must lie in the xz plane; isotropic D, alpha_x is used; one azimuth
    at normal incidence); asymmetric grooves: the partner angle on about n_partner nodes of
    its own smooth variable. The wall rules have panel ends at the wall angles where the
    integrand has a kink whatever the other coordinates: pi/4 and (pi/2 -+ theta)/2 (the
    single-bounce exit turns from up to down, theta the incidence: the groove-frame incidence
    ranges over [-theta, theta]) and pi/2 - theta (the wall turns away from wi). The beam
    fractions are the closed-form lengths of offset intervals (_albedo_runs); nothing is
    sampled. kmax is Max Bounces (default: the derived bound): the first kmax bounces of a
    path get their Fresnel factor, later ones 1, as in the sampler; every path is counted.
    Fresnel is tabulated (FresnelTable, < 1e-7 per factor); weights are normalised, so with
    F = 1 the result is 1 to rounding.
    Convergence (tests/test_reference_lee.py, test_albedo_quadrature_converges): symmetric, n vs
    2n within 1e-5 from n = 512 (GGX and Beckmann; the former midpoint rule in the inverse
    CDF read up to 1.1e-4 high at n = 512); asymmetric, (n, n_partner) = (128, 64) vs
    (256, 128) within 1e-5 (docs/lee-asymmetric-grooves.md sec. 6)."""
    fresnel = fresnel or fresnel_fn("none")
    if not isinstance(fresnel, FresnelTable):
        fresnel = FresnelTable(fresnel)  # interpolation error < 1e-7 per factor
    wi = np.asarray(wi, dtype=float)
    if kmax is None:
        kmax = max_bounces(max(mf.alpha_x, mf.alpha_y), mf.distribution, groove)
    alpha = mf.alpha_x
    th = math.acos(min(max(float(wi[2]), -1.0), 1.0))
    breaks = (0.25 * PI, 0.5 * (0.5 * PI - th), 0.5 * (0.5 * PI + th), 0.5 * PI - th)
    t1, w1 = _wall_nodes(mf.distribution, alpha, n, breaks=breaks)
    # At normal incidence every groove azimuth sees the same cross-section (isotropic D).
    n_phi = 1 if wi[0] == 0.0 and wi[1] == 0.0 else max(n // 2, 1)
    phi = (np.arange(n_phi) + 0.5) / n_phi * PI
    T1, P = np.meshgrid(t1, phi, indexing="ij")
    W = np.repeat(w1, n_phi) / n_phi
    theta_l = T1.ravel()
    P = P.ravel()
    # wi in the groove frame t = (-cos phi, -sin phi, 0) (the wall s = normalize(-tan cos phi,
    # -tan sin phi, 1) leans toward t): theta_i = atan2(wi.t, wi.z), rho = |(wi.t, wi.z)|.
    px = -(wi[0] * np.cos(P) + wi[1] * np.sin(P))
    theta_i = np.arctan2(px, wi[2])
    rho = np.hypot(px, wi[2])
    if groove == "symmetric":
        partners = [(theta_l, 1.0)]
    else:
        tp, wp = _wall_nodes(mf.distribution, alpha, n_partner, partner=True, breaks=breaks)
        partners = list(zip(tp, wp))
    total = np.zeros(3)
    for theta_r_, wgt in partners:
        theta_r = np.broadcast_to(theta_r_, theta_l.shape)
        if groove == "symmetric":
            Ll = Lr = np.ones_like(theta_l)
        else:
            Ll, Lr = np.sin(theta_r), np.sin(theta_l)
        fA = Ll * np.cos(theta_i - theta_l)
        fB = -Lr * np.cos(theta_i + theta_r)
        width = fA - fB
        acc = np.zeros(theta_l.shape + (3,))
        for sg in (1.0, -1.0):  # left-first part, then the mirrored right-first part
            if sg > 0:
                ti, tl, tr, Ll_, Lr_, hi_, lo_ = theta_i, theta_l, theta_r, Ll, Lr, fA, fB
            else:
                ti, tl, tr, Ll_, Lr_, hi_, lo_ = -theta_i, theta_r, theta_l, Lr, Ll, -fB, -fA
            lo_ = np.maximum(lo_, 0.0)
            hi_ = np.maximum(hi_, lo_)
            acc += _albedo_runs(ti, tl, tr, lo_, hi_, Ll_, Lr_, rho, fresnel, kmax)
        total += wgt * (W @ (acc / width[:, None]))
    return total
