"""Ground truth for Lee et al. 2018: brute-force ray tracing inside V-grooves (numpy).

The microsurface (docs/models.md sec. 4; Heitz 2014 V-cavities) is a set of grooves whose rims all
lie in the macro plane z = 0. A groove has a horizontal axis u = n x t and two planar mirror
walls whose normals lie in the cross-section plane spanned by the horizontal t and n:
  left wall  normal s_l = ( sin(theta_l) t + cos(theta_l) n )   (tilted toward +t)
  right wall normal s_r = (-sin(theta_r) t + cos(theta_r) n )   (tilted toward -t)
Symmetric grooves (the V-cavity of Heitz 2014): theta_l = theta_r = theta_s, s_r = s' is the
mirror (-s.x, -s.y, s.z) of s = s_l. Asymmetric grooves: see docs/lee-asymmetric-grooves.md.

Which groove a ray meets (justification of the sampling). A ray from direction wi hits the
macro plane at a point uniformly distributed over the macro surface (per unit projected area
toward wi every point of the plane is equally likely: the plane's projected area is
cos(theta_i) times its area, the same factor everywhere). Every groove's opening is a piece of
that plane, so a groove is entered with probability proportional to its opening area, for any
wi, and the entry point is uniform on the opening. The opening area of the groove {s, s'} is
the projected (onto the macro plane) area of its two walls, and D(m)(m.n) dm is by definition
the fraction of macro area covered by walls with normal in dm; so for symmetric grooves we draw
s ~ D(s)(s.n) (the groove {s, s'}; D(s) = D(s') so it does not matter which wall was drawn)
and an entry point uniform on the opening. This is the V-cavity visible-normal rule of
Heitz 2014 (docs/models.md sec. 3) in disguise: the fraction of the opening from which a ray first
meets wall s is <wi,s>+ / (<wi,s>+ + <wi,s'>+) (tested in tests/test_reference_lee.py), and
given that wall the first hit is uniform on its lit part.

Trace. The axis component of the travel direction is unchanged by mirrors whose normals are
_|_ u, so the trace is 2D: in the cross-section the travel direction is the projection of -wi,
of length rho = sqrt(1 - (wi.u)^2); a bounce reflects it about the wall normal; the 3D cosine
of incidence (for Fresnel) is rho |d2.m2| with d2 the unit 2D direction. The ray leaves when it
reaches the opening. wo = rho (d2.x t + d2.y n) - (wi.u) u (pointing away from the surface).
Normalisation: apex at the origin, opening width 1 (depth 1 / (cot theta_l + cot theta_r)).
Each bounce multiplies the RGB throughput by the exact Fresnel reflectance at that bounce.

This file deliberately does not use the unfolding (kaleidoscope) of addon/lab/reference/lee/: it
is the independent ground truth the closed form is tested against.
"""
from __future__ import annotations

import math

import numpy as np

from .fresnel import FRESNEL_KINDS, fresnel_color
from .microfacet import Microfacet

GROOVES = ("symmetric", "asymmetric")
_TINY = 1e-300


# -- Fresnel per bounce ---------------------------------------------------------------------
def fresnel_fn(kind: str = "none", ior=1.5, n=(0.166, 0.429, 1.38), k=(3.15, 2.45, 1.83)):
    """A callable cos_i (...) -> RGB reflectance (..., 3) at one bounce.

    kind: 'none' (F = 1, exactly), 'dielectric' (exact, eta = ior; grey), 'conductor' (exact
    complex IOR n + ik per RGB channel): fresnel.fresnel_color, the one dispatcher."""
    if kind not in FRESNEL_KINDS:
        raise ValueError(f"fresnel kind must be none, dielectric or conductor, not {kind!r}")
    nn, kk = np.asarray(n, dtype=float), np.asarray(k, dtype=float)
    return lambda c: fresnel_color(kind, c, ior, nn, kk)


# -- groove frames --------------------------------------------------------------------------
def groove_frame(s):
    """(t, u) for a wall normal s: t = horizontal unit vector along the azimuth of s, u = n x t
    the groove axis. s = n (measure zero) gets t = x."""
    s = np.asarray(s, dtype=float)
    h = np.hypot(s[..., 0], s[..., 1])
    ok = h > 1e-300
    tx = np.where(ok, s[..., 0] / np.where(ok, h, 1.0), 1.0)
    ty = np.where(ok, s[..., 1] / np.where(ok, h, 1.0), 0.0)
    zero = np.zeros_like(tx)
    t = np.stack([tx, ty, zero], axis=-1)
    u = np.stack([-ty, tx, zero], axis=-1)
    return t, u


def wall_angle(s):
    """Polar angle of a wall normal, atan2(|s_horizontal|, s.z) in [0, pi/2)."""
    s = np.asarray(s, dtype=float)
    return np.arctan2(np.hypot(s[..., 0], s[..., 1]), s[..., 2])


# -- asymmetric grooves: the partner wall -----------------------------------------------------
class SizeBiasedTable:
    """Numerical inverse CDF of the partner-wall angle of asymmetric grooves (isotropic D):
    density proportional to D(theta) sin^2(theta) on [0, pi/2), i.e. the slope radius r = tan
    theta size-biased (density r q(r) / E[r]) with respect to the radial slope density q of
    D(m)(m.n) along a line of slope space (docs/lee-asymmetric-grooves.md). Built by the
    trapezoid rule on a fine grid in theta, independent of lee/sampler.py's closed-form sampler."""

    def __init__(self, mf: Microfacet, n: int = 200001):
        if abs(mf.alpha_x - mf.alpha_y) > 1e-12 * mf.alpha_x:
            raise ValueError("asymmetric grooves are implemented for isotropic D only")
        th = np.linspace(0.0, 0.5 * math.pi, n)
        m = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1)
        dens = mf.D(m) * np.sin(th) ** 2
        dens[-1] = 0.0
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(th))])
        self.theta = th
        self.cdf = cdf / cdf[-1]

    def sample(self, u):
        return np.interp(u, self.cdf, self.theta)


def sample_grooves(mf: Microfacet, n: int, rng, groove: str = "symmetric", table=None):
    """Grooves met by n rays (any wi: see the module docstring), as (t, u, theta_l, theta_r)
    in the frame where the drawn wall s ~ D(s)(s.n) is the left wall.

    symmetric: theta_r = theta_l. asymmetric: the partner (right) wall's angle is drawn from the
    size-biased distribution (SizeBiasedTable), independently of theta_l; the groove type is
    then distributed with density pi(a, b) ~ (a + b) q(a) q(b) in slopes a = tan theta_l,
    b = tan theta_r, which is the area-weighted groove distribution whose facets have the
    projected-area distribution D (proof in docs/lee-asymmetric-grooves.md, test in
    tests/test_reference_lee.py)."""
    s = mf.sample_dcos(rng.random(n), rng.random(n))
    t, u = groove_frame(s)
    theta_l = wall_angle(s)
    if groove == "symmetric":
        theta_r = theta_l
    elif groove == "asymmetric":
        table = table or SizeBiasedTable(mf)
        theta_r = table.sample(rng.random(n))
    else:
        raise ValueError(f"groove must be one of {GROOVES}, not {groove!r}")
    return t, u, theta_l, theta_r


def facet_sample(mf: Microfacet, n: int, rng, groove: str = "symmetric", table=None):
    """Facet normals of the whole microsurface drawn by projected (macro) area: a groove by
    opening area (as the tracer draws them), then one of its walls with probability equal to
    its share of the opening (left: cot theta_l / (cot theta_l + cot theta_r)). Their density
    must be D(m)(m.n) (tested)."""
    t, _, tl, tr = sample_grooves(mf, n, rng, groove, table)
    cl, cr = 1.0 / np.tan(np.maximum(tl, 1e-300)), 1.0 / np.tan(np.maximum(tr, 1e-300))
    left = rng.random(n) * (cl + cr) < cl
    th = np.where(left, tl, tr)
    sgn = np.where(left, 1.0, -1.0)[..., None]
    n3 = np.zeros_like(t)
    n3[..., 2] = 1.0
    return sgn * np.sin(th)[..., None] * t + np.cos(th)[..., None] * n3


# -- the tracer --------------------------------------------------------------------------------
def trace_grooves(wi, t, u, theta_l, theta_r, x_entry, fresnel, max_bounces: int = 100000):
    """Trace rays arriving from wi (3D, pointing to the viewer) into given grooves.

    x_entry in [0, 1]: entry point on the opening, 0 at the left rim, 1 at the right rim.
    Returns (wo (N,3), throughput (N,3), bounces (N,) int). Rays still inside after
    max_bounces (never seen in practice) are returned with throughput 0 and bounces =
    max_bounces + 1."""
    wi = np.broadcast_to(np.asarray(wi, dtype=float), np.shape(t))
    n = t.shape[0]
    wu = np.sum(wi * u, axis=-1)
    px = np.sum(wi * t, axis=-1)
    pz = wi[..., 2]
    rho = np.hypot(px, pz)
    # 2D travel direction (unit), entry point on the opening y = depth.
    dx, dy = -px / rho, -pz / rho
    sl, cl = np.sin(theta_l), np.cos(theta_l)
    sr, cr = np.sin(theta_r), np.cos(theta_r)
    depth = 1.0 / (cl / np.maximum(sl, _TINY) + cr / np.maximum(sr, _TINY))
    ax = -depth * cl / np.maximum(sl, _TINY)  # left rim x (right rim at ax + 1)
    x = ax + x_entry
    y = depth.copy()
    nlx, nly = sl, cl          # left wall normal (through the apex at the origin)
    nrx, nry = -sr, cr         # right wall normal
    last = np.zeros(n, dtype=np.int8)  # 0 none, 1 left, 2 right
    thr = np.ones((n, 3))
    bounces = np.zeros(n, dtype=np.int64)
    active = np.arange(n)
    for _ in range(max_bounces + 1):
        if active.size == 0:
            break
        a = active
        X, Y, DX, DY = x[a], y[a], dx[a], dy[a]
        inf = np.full(a.size, np.inf)
        dl = nlx[a] * DX + nly[a] * DY
        dr = nrx[a] * DX + nry[a] * DY
        okl = (dl < 0.0) & (last[a] != 1)
        okr = (dr < 0.0) & (last[a] != 2)
        tl_ = np.where(okl, np.maximum(-(nlx[a] * X + nly[a] * Y) / np.where(okl, dl, -1.0), 0.0),
                       inf)
        tr_ = np.where(okr, np.maximum(-(nrx[a] * X + nry[a] * Y) / np.where(okr, dr, -1.0), 0.0),
                       inf)
        to = np.where(DY > 0.0, (depth[a] - Y) / np.where(DY > 0.0, DY, 1.0), inf)
        hit_l = okl & (tl_ <= tr_) & (tl_ < to)
        hit_r = okr & ~hit_l & (tr_ < to)
        hit = hit_l | hit_r
        done = ~hit
        # Reflect the rays that hit a wall.
        th_ = np.where(hit_l, tl_, tr_)
        mx = np.where(hit_l, nlx[a], nrx[a])
        my = np.where(hit_l, nly[a], nry[a])
        dn = DX * mx + DY * my
        Xn, Yn = X + th_ * DX, Y + th_ * DY
        hi = a[hit]
        x[hi], y[hi] = Xn[hit], Yn[hit]
        dx[hi] = DX[hit] - 2.0 * dn[hit] * mx[hit]
        dy[hi] = DY[hit] - 2.0 * dn[hit] * my[hit]
        thr[hi] *= fresnel(rho[hi] * np.abs(dn[hit]))
        bounces[hi] += 1
        last[hi] = np.where(hit_l[hit], 1, 2)
        active = a[~done]
    if active.size:
        thr[active] = 0.0
        bounces[active] = max_bounces + 1
    dyc = np.maximum(dy, 0.0)
    n3 = np.zeros_like(t)
    n3[..., 2] = 1.0
    wo = rho[..., None] * (dx[..., None] * t + dyc[..., None] * n3) - wu[..., None] * u
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    return wo, thr, bounces


def trace(wi, mf: Microfacet, n: int, rng, fresnel=None, groove: str = "symmetric",
          max_bounces: int = 100000, table=None):
    """Brute-force BRDF samples for incidence wi (3D unit, wi.z > 0): n rays, each into a groove
    drawn by opening area with a uniform entry point. Returns (wo, throughput RGB, bounces).
    E[throughput] is the directional albedo; the histogram of wo weighted by throughput is
    f(wi, wo) cos_o."""
    fresnel = fresnel or fresnel_fn("none")
    t, u, tl, tr = sample_grooves(mf, n, rng, groove, table)
    return trace_grooves(np.asarray(wi, dtype=float), t, u, tl, tr, rng.random(n), fresnel,
                         max_bounces)


def albedo(wi, mf: Microfacet, n: int, rng, fresnel=None, groove: str = "symmetric",
           bounces=None, chunk: int = 1 << 20, table=None):
    """Directional albedo by the tracer, with its standard error: (mean RGB, stderr RGB).
    bounces: None for all paths, or an int to tally only paths with exactly that many
    bounces (bounces=1 is the single-scattering V-cavity Cook-Torrance albedo)."""
    if groove == "asymmetric" and table is None:
        table = SizeBiasedTable(mf)
    s1 = np.zeros(3)
    s2 = np.zeros(3)
    done = 0
    while done < n:
        m = min(chunk, n - done)
        _, thr, k = trace(wi, mf, m, rng, fresnel, groove, table=table)
        if bounces is not None:
            thr = np.where((k == bounces)[..., None], thr, 0.0)
        s1 += thr.sum(axis=0)
        s2 += (thr * thr).sum(axis=0)
        done += m
    mean = s1 / n
    var = np.maximum(s2 / n - mean * mean, 0.0)
    return mean, np.sqrt(var / n)
