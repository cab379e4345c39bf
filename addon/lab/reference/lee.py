"""Lee, Jarabo, Jeon, Gutierrez, Kim 2018 "Practical multiple scattering for rough surfaces":
the kaleidoscopic closed form of multiple mirror reflection in V-grooves (numpy reference).

Derivation (own geometry, no code of the authors) in docs/lee-asymmetric-grooves.md; ground
truth: addon/lab/reference/vgroove.py (brute-force tracing). Conventions: docs/models.md (n = (0,0,1),
wi toward the viewer, wo away from the surface, vectors (..., 3)).

2D angles. A groove is seen in its cross-section (the plane of t and n, t horizontal _|_ the
groove axis u = n x t). A direction w with w.z > 0 has the 2D angle theta = atan2(w.t, w.z)
(positive toward +t) and the 2D length rho = sqrt(1 - (w.u)^2). The groove's left wall has
normal s_l = sin(theta_l) t + cos(theta_l) n (leans toward +t: it faces rays coming from +t),
the right wall -sin(theta_r) t + cos(theta_r) n; opening angle theta_v = pi - theta_l - theta_r
(symmetric: theta_l = theta_r = theta_s, theta_v = pi - 2 theta_s). Formulas below are for
rays whose first bounce is on the LEFT wall; the others are the mirror image (t -> -t:
theta_i -> -theta_i, theta_l <-> theta_r, theta_o -> -theta_o).

Kaleidoscope (apex at the origin, polar angle psi counter-clockwise from n). Unfold the groove
by reflecting it across its walls: wedges of angle theta_v around the apex; the ray becomes a
straight line, each crossing of a wedge boundary is one bounce, and it leaves when it crosses
the outer chord of a wedge. Let e = (-cos theta_i, sin theta_i) (the beam's transverse axis)
and l = e.P the offset of the ray line (any point P of it): over the opening the rays'
offsets are uniform on [f_B, f_A], f_A = L_l cos(theta_i - theta_l) (left rim),
f_B = -L_r cos(theta_i + theta_r) (right rim), L_l, L_r the wall lengths; l > 0 means the left
wall is hit first (the fraction f_A / (f_A - f_B), clamped: the V-cavity visible-normal
rule). The polygon vertices (wall ends) are V_m at psi = pi/2 - theta_l + m theta_v, radius L_l
(m even) or L_r (m odd), with offsets f(V_m) = R_m sin(phi0 + m theta_v),
phi0 = theta_i + pi/2 - theta_l. The line enters through the chord [V_-1, V_0] and leaves
through the first chord [V_(k-1), V_k] with f(V_k) < l (the polygon is convex), so

    k = #{m >= 0 : R_m sin(phi0 + m theta_v) >= l}     (bounce count)

Symmetric (R_m = 1, l in [0, 1]): k = floor((pi - asin(l) - phi0) / theta_v) + 1; its maximum
over the beam (l -> 0, the ray through the apex)
is floor((pi - theta_i) / theta_v + 1/2), and the beam splits into exactly two counts, k-1 and
k. (The seed's eq. 5-1, floor((pi + 2 theta_i)/theta_v) + 1, is not this: 3 for a 90-degree
groove at normal incidence where every ray makes 2 bounces; see the doc.)
Exit angle (the unfolding maps wedge k back onto the groove: a rotation by -k theta_v for even
k, a reflection for odd k):

    k even: theta_o = theta_i + k theta_v - pi
    k odd:  theta_o = 2 theta_l - theta_i - (k - 1) theta_v   (symmetric: pi - theta_i - k theta_v)

i.e. theta_o = (-1)^k (theta_i + k theta_v - pi) for symmetric grooves. The seed's eq. 5-2 is
this one formula, theta_o(n) = (-1)^n (theta_i + pi - n theta_v), in the opposite angle
convention (theta -> -theta), evaluated at the ray's own bounce count n (k-1 in its first case,
k in its second): tested against the tracer ray by ray. Bounce j (1-based) meets its wall at
the 2D
cosine |sin(phi0 + (j-1) theta_v)|, the 3D cosine is rho times it (the Fresnel argument).
wo = rho (sin theta_o t + cos theta_o n) - (wi.u) u.

BRDF (symmetric; seed eq. 5-7, docs/models.md):
    f(wi, wo) = sum over first walls s and k of
        D(s) |wi.s| G_k prod_j F_j |ds/dwo| / (|wi.n| |wo.n|),
    G_k = (length of the offsets in [max(f_B, 0), f_A] giving k bounces) / f_A,
    |ds/dwo| = sin(theta_s) / (2 k |(wi + wo).t|)
(for odd k, (wi + wo).t = 2 (wi.h) sin(theta_h) and this is the seed's
sin(theta_s) / (4 k |wi.h| sin(theta_h))). Given (wi, wo), the groove azimuth is that of
h = wi + wo (every bounce map wi -> wo is a rotation by pi or a rotation about u composed with
-1, so u _|_ wi + wo) up to its sign, and theta_s follows from theta_o(k) above.

BRDF (asymmetric; doc sec. 5, eval_asymmetric): the same two frames and k, and for each the
integral over the partner wall theta_r of the groove density g = D_l D_r sin(theta_r)
sin(theta_l + theta_r) / Z (landed on either wall) times the beam fraction and the Fresnel
product, with |ds_l/dwo| = sin(theta_l) / (c_k |(wi + wo).t|), c_k = k (even) or k + 1 (odd):
theta_l is fixed by theta_r through the exit angle, and a Gauss-Legendre rule over the window
of theta_r, invariant under path reversal, keeps f(wi, wo) = f(wo, wi) to rounding.

Max Bounces (the catalog's max_bounces, LeeBRDF.kmax; 0 = the derived bound max_bounces()):
the first kmax bounces of a path get their Fresnel factor, later bounces F = 1, and every path
is followed to its exact exit. One meaning in sample, eval / eval_asymmetric (fresnel_bounces;
their kmax is the number of terms summed, which LeeBRDF sets to the derived bound), albedo,
moments and the OSL shader (doc sec. 4): energy-conserving (F = 1: exactly 1 at any limit).
"""
from __future__ import annotations

import math

import numpy as np

from ...catalog import alphas
from . import controls
from .bsdf import MicrofacetBRDF, builds
from .lamps import GUIDE_FRACTION, sample_cone
from .microfacet import Microfacet
from .special import erfc
from .vgroove import fresnel_fn, groove_frame

PI = math.pi
TRUNCATION = 1e-4  # energy allowed in paths beyond max_bounces


# -- bounce count bound ------------------------------------------------------------------------
def _tail_dcos(distribution: str, alpha: float, T: float) -> float:
    """P(tan theta_m > T) for m ~ D(m)(m.n)."""
    x = (T / alpha) ** 2
    return 1.0 / (1.0 + x) if distribution == "ggx" else math.exp(-x)


def _tail_sizebiased(distribution: str, alpha: float, T: float) -> float:
    """P(tan theta > T) for the partner wall of asymmetric grooves (density ~ D sin^2 theta):
    GGX: tan theta = alpha tan b, b with density (4/pi) sin^2 b on [0, pi/2];
    Beckmann: tan^2 theta = alpha^2 G, G ~ Gamma(3/2), P(G > g) = erfc(sqrt g) + 2 sqrt(g/pi) e^-g."""
    if distribution == "ggx":
        b = math.atan(T / alpha)
        return (PI / 4.0 - b / 2.0 + math.sin(2.0 * b) / 4.0) / (PI / 4.0)
    g = (T / alpha) ** 2
    return float(erfc(math.sqrt(g))) + 2.0 * math.sqrt(g / PI) * math.exp(-g)


def max_bounces(alpha: float, distribution: str = "ggx", groove: str = "symmetric",
                eps: float = TRUNCATION, limit: int = 100000) -> int:
    """Smallest N such that paths with more than N bounces carry less than eps of the energy,
    for every incidence (F <= 1, so energy <= probability).

    Symmetric: a ray whose first wall is s makes k <= floor((pi - theta_i)/theta_v + 1/2)
    bounces with theta_i > theta_s - pi/2 (s visible), so k < pi / (2 x) + 1, x = pi/2 - theta_s;
    k > N needs theta_s > pi/2 - pi/(2N). Grooves are met in proportion to D(s)(s.n) whatever
    wi, so P(k > N) <= P(tan theta_s > cot(pi / (2N))) = 1 / (1 + T^2/alpha^2) (GGX) or
    exp(-T^2/alpha^2) (Beckmann), T = cot(pi/(2N)).
    Asymmetric: k <= floor(pi / theta_v) + 1 (phi0 > 0), so k > N needs theta_v < pi / N,
    i.e. theta_l + theta_r > pi - pi/N: BOTH walls steeper than pi/2 - pi/N. The drawn wall and
    its size-biased partner are independent, so P(k > N) <= P_D(tan > T) P_partner(tan > T),
    T = cot(pi / N).
    alpha is the largest of alpha_x, alpha_y (conservative)."""
    alpha = max(float(alpha), 1e-7)
    for N in range(1, limit + 1):
        if groove == "asymmetric":
            T = 1.0 / math.tan(PI / N) if N > 2 else 0.0
            p = _tail_dcos(distribution, alpha, T) * _tail_sizebiased(distribution, alpha, T)
        else:
            T = 1.0 / math.tan(PI / (2.0 * N))
            p = _tail_dcos(distribution, alpha, T)
        if p < eps:
            return N
    return limit


# -- 2D kernels --------------------------------------------------------------------------------
def bounce_count_symmetric(theta_i, theta_v, ell):
    """k for a left-first ray of offset ell in [0, 1] (unit walls); float array (may be huge)."""
    phi0 = theta_i + 0.5 * theta_v
    x = (PI - np.arcsin(np.clip(ell, 0.0, 1.0)) - phi0) / theta_v
    return np.maximum(np.floor(x), 0.0) + 1.0


def bounce_count(theta_i, theta_l, theta_r, ell, L_l, L_r):
    """k = #{m >= 0 : R_m sin(phi0 + m theta_v) >= ell} for a left-first ray (ell > 0), closed
    form: even m count the phases in [.., pi - asin(ell/L_l)], odd m the phases in
    [asin(ell/L_r), pi - asin(ell/L_r)] (float array)."""
    tv = PI - theta_l - theta_r
    phi0 = theta_i + 0.5 * PI - theta_l
    hi_l = PI - np.arcsin(np.clip(ell / L_l, 0.0, 1.0))
    n_even = np.maximum(np.floor((hi_l - phi0) / (2.0 * tv)), -1.0) + 1.0
    rr = ell / L_r
    lo_r = np.arcsin(np.clip(rr, 0.0, 1.0))
    j_lo = np.maximum(np.ceil((lo_r - phi0 - tv) / (2.0 * tv)), 0.0)
    j_hi = np.floor((PI - lo_r - phi0 - tv) / (2.0 * tv))
    n_odd = np.where(rr < 1.0, np.maximum(j_hi - j_lo + 1.0, 0.0), 0.0)
    return n_even + n_odd


def exit_angle(theta_i, theta_l, theta_r, k):
    """2D exit angle after k bounces (left-first ray): even k theta_i + k tv - pi, odd k
    2 theta_l - theta_i - (k-1) tv."""
    tv = PI - theta_l - theta_r
    return np.where(np.mod(k, 2.0) == 0.0, theta_i + k * tv - PI,
                    2.0 * theta_l - theta_i - (k - 1.0) * tv)


def fresnel_product(fresnel, rho, phi0, theta_v, k, kmax: int, block: int = 16):
    """prod_{j=1..min(k, kmax)} F(rho |sin(phi0 + (j-1) theta_v)|), RGB: the first min(k, kmax)
    bounces get their Fresnel factor, later ones F = 1 (Max Bounces, doc sec. 4). Vectorised
    over `block` bounces at a time, the paths sorted by their count so that the paths still
    running are a prefix: the cost is the number of factors, not kmax times the paths."""
    rho, phi0, theta_v = (np.asarray(a, dtype=float) for a in (rho, phi0, theta_v))
    k = np.asarray(k, dtype=float)
    m = np.minimum(np.where(k >= 1.0, k, 0.0), float(kmax)).astype(np.int64)  # NaN: none
    shape = np.broadcast_shapes(rho.shape, phi0.shape, theta_v.shape, m.shape)
    rho, phi0, theta_v, m = (np.broadcast_to(a, shape).ravel() for a in (rho, phi0, theta_v, m))
    if isinstance(fresnel, FresnelTable) and fresnel.constant:  # F = 1 (or any constant)
        return (fresnel.F[0] ** m[:, None].astype(float)).reshape(shape + (3,))
    out = np.ones((m.size, 3))
    if m.size == 0 or m.max() <= 0:
        return out.reshape(shape + (3,))
    order = np.argsort(-m, kind="stable")
    ms = m[order]
    neg = -ms  # ascending: the count of paths with more than j0 factors is a searchsorted
    for j0 in range(0, int(ms[0]), block):
        live = order[:int(np.searchsorted(neg, -j0, side="left"))]
        jj = np.arange(j0, j0 + block, dtype=float)
        c = np.minimum(rho[live, None] * np.abs(np.sin(phi0[live, None]
                                                        + jj * theta_v[live, None])), 1.0)
        if isinstance(fresnel, FresnelTable):
            out[live] *= fresnel.product(c, ms[:live.size] - j0)
            continue
        F = np.asarray(fresnel(c), dtype=float)
        past = jj[None, :] >= ms[:live.size, None]  # factors beyond the path's own count
        if past.any():
            F = np.where(past[..., None], 1.0, F)
        out[live] *= np.prod(F, axis=1)
    return out.reshape(shape + (3,))


def _vec(t, n3, u, rho, theta, wu):
    return (rho * np.sin(theta))[..., None] * t + (rho * np.cos(theta))[..., None] * n3 \
        - wu[..., None] * u


def _local(wi, t, u):
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
    theta_i, rho, wu = _local(wi, t, ax)
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


# -- G_k and the deterministic albedo ------------------------------------------------------------
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


# -- the derived bounce bound in closed form (the OSL shader's formula) ----------------------------
def _asymmetric_tail_ratio(distribution: str, eps: float = TRUNCATION) -> float:
    """c with P_D(tan > c alpha) P_partner(tan > c alpha) = eps: both tails depend on T / alpha
    only, so the asymmetric threshold is T* = c alpha with c a constant per distribution
    (bisection in log c, to float64 precision)."""
    lo, hi = math.log(1e-6), math.log(1e8)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        c = math.exp(mid)
        p = _tail_dcos(distribution, 1.0, c) * _tail_sizebiased(distribution, 1.0, c)
        lo, hi = (mid, hi) if p >= eps else (lo, mid)
    return math.exp(hi)


def tail_ratio(distribution: str, groove: str = "symmetric", eps: float = TRUNCATION) -> float:
    """T* / alpha, the tangent (per unit alpha) of the wall angle beyond which grooves carry less
    than eps: symmetric GGX sqrt((1 - eps)/eps), Beckmann sqrt(ln(1/eps)); asymmetric: the root
    of the product of the two tails (a constant per distribution, hard-coded in the shader)."""
    if groove == "asymmetric":
        return _asymmetric_tail_ratio(distribution, eps)
    if distribution == "ggx":
        return math.sqrt((1.0 - eps) / eps)
    return math.sqrt(math.log(1.0 / eps))


def max_bounces_closed_form(alpha: float, distribution: str = "ggx", groove: str = "symmetric",
                            eps: float = TRUNCATION) -> int:
    """max_bounces() without the search, as the OSL shader computes it: with T = alpha T*/alpha,
    symmetric N = floor(pi / (2 atan(1/T))) + 1 (k > N needs cot(pi/(2N)) > T), asymmetric
    N = floor(pi / atan(1/T)) + 1 (k > N needs cot(pi/N) > T). Equal to max_bounces() except
    where the bound ties exactly (tested)."""
    T = max(float(alpha), 1e-7) * tail_ratio(distribution, groove, eps)
    half = 1.0 if groove == "asymmetric" else 0.5
    return int(math.floor(half * PI / math.atan(1.0 / T))) + 1


def kmax_for(alpha: float, distribution: str, groove: str, max_bounces_param: float = 0.0) -> int:
    """The Fresnel-loop bound of the shader: the user's Max Bounces (floored, at least 1) or,
    when it is 0, the bound derived from the roughness (max_bounces_closed_form)."""
    if max_bounces_param > 0.0:
        return max(1, int(math.floor(max_bounces_param)))
    return max_bounces_closed_form(alpha, distribution, groove)


# -- deterministic directional moments -------------------------------------------------------------
BECKMANN_Y_MAX = 6.5  # Beckmann slopes beyond 6.5 alpha carry exp(-42) of the mass


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


class FresnelTable:
    """A Fresnel callable tabulated on [0, 1] in cos (n + 1 uniform nodes, linear
    interpolation by direct indexing; exact at the nodes). For the moments' inner loop, where
    the exact conductor formula dominated the cost; the interpolation error is below 1e-7 at
    n = 8192 (tested)."""

    def __init__(self, fresnel, n: int = 8192):
        self.n = n
        self.c = np.linspace(0.0, 1.0, n + 1)
        self.F = np.asarray(fresnel(self.c), dtype=float)
        self.constant = bool(np.all(self.F == self.F[0]))

    def _index(self, c):
        """Cell index and fraction of cosines c (NaN: index 0, flagged)."""
        x = np.clip(c, 0.0, 1.0) * self.n
        bad = np.isnan(x)
        if bad.any():
            x = np.where(bad, 0.0, x)
        i = np.minimum(x.astype(np.int64), self.n - 1)
        return i, x - i, bad

    def __call__(self, c):
        c = np.asarray(c, dtype=float)
        if self.constant:
            return np.broadcast_to(self.F[0], c.shape + (3,))
        i, f, bad = self._index(c)
        f = f[..., None]
        out = self.F[i] * (1.0 - f) + self.F[i + 1] * f
        return np.where(bad[..., None], np.nan, out) if bad.any() else out

    def product(self, c, count=None):
        """prod over the last axis of self(c), (..., 3): the same interpolation, gathered per
        channel from contiguous tables (3x faster than self(c) then np.prod). With `count`
        (shape c.shape[:-1]) only the first `count` factors of each row are taken (the others
        are 1: a slot past the table's end holds 1 exactly)."""
        c = np.asarray(c, dtype=float)
        if self.constant:
            if count is None:
                return np.broadcast_to(self.F[0] ** c.shape[-1], c.shape[:-1] + (3,))
            m = np.clip(np.asarray(count), 0, c.shape[-1])[..., None]
            return np.broadcast_to(self.F[0] ** m, c.shape[:-1] + (3,))
        if not hasattr(self, "_rows"):
            self._rows = [(np.append(self.F[:-1, ch], 1.0),
                           np.append(self.F[1:, ch] - self.F[:-1, ch], 0.0))
                          for ch in range(3)]
        i, f, bad = self._index(c)
        if count is not None:
            past = np.arange(c.shape[-1]) >= np.asarray(count)[..., None]
            i = np.where(past, self.n, i)
            f = np.where(past, 0.0, f)
            bad = bad & ~past
        out = np.stack([np.prod(a[i] + f * d[i], axis=-1) for a, d in self._rows], axis=-1)
        return np.where(bad.any(-1)[..., None], np.nan, out) if bad.any() else out


def moments(mu, mf: Microfacet, fresnel=None, groove: str = "symmetric", kmax: int | None = None,
            n_theta: int | None = None, n_phi: int | None = None, n_partner: int | None = None):
    """Directional moments (E, Vn, Vt), each (len(mu), 3), for wi = (sqrt(1 - mu^2), 0, mu):
    E = integral f cos_o dwo (the albedo), (Vn, Vt) = z and x components of
    integral f cos_o wo dwo. The same integral as albedo(), organised for speed:
    grooves on a midpoint grid in smooth variables (_groove_nodes), the entry offsets
    integrated exactly (the beam splits into runs of equal bounce count whose lengths are
    closed form, _albedo_runs' rule), each run's exit direction exact (it depends on k only).
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


class LeeBRDF:
    """The catalog's lee_vgroove as a numpy BRDF (make_bsdf): the analytic sampler, the
    evaluation (symmetric grooves: closed form, `eval`; asymmetric grooves: the integral over
    the partner wall by Gauss-Legendre, `eval_asymmetric`, 0.03-0.5 ms of CPU per direction,
    most at GGX roughness 1 with a conductor; doc sec. 5), and deterministic directional
    moments for the sphere-grid reference (quadrature.tabulate_moments uses
    `directional_moments` when a BSDF has one: the generic quadrature integrates single-facet
    lobes around reflect(wi, m), which multi-bounce lobes are not). Both evaluations sum
    k = 1 .. kterms, the derived bound (paths beyond carry < 1e-4 of the energy), and are
    reciprocal to rounding.

    Max Bounces (`kmax`, the catalog's max_bounces; 0 = the derived bound) has one meaning
    everywhere, sampler, eval, moments and the OSL shader: the first kmax bounces of a path get
    their Fresnel factor, later bounces reflect with F = 1, and every path is followed to its
    exact exit. So a low limit brightens and desaturates (never darkens) a conductor, and with
    F = 1 nothing changes: the furnace stays exactly 1 at any limit."""

    masking = "vcavity"  # for code that asks; the model has its own multi-bounce masking

    def __init__(self, mf: Microfacet, groove: str = "symmetric", fresnel: str = "conductor",
                 ior: float = 1.5, n=(1.0, 1.0, 1.0), k=(0.0, 0.0, 0.0), tint=(1.0, 1.0, 1.0),
                 max_bounces_param: float = 0.0, quad: dict | None = None):
        if groove not in ("symmetric", "asymmetric"):
            raise ValueError(f"groove must be symmetric or asymmetric, not {groove!r}")
        self.mf = mf
        self.groove = groove
        self.fresnel_kind = fresnel
        self.ior, self.n, self.k = float(ior), np.asarray(n, dtype=float), np.asarray(k, dtype=float)
        self.fresnel = fresnel_fn(fresnel, ior, n, k)
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.zeros(3)
        self.is_delta = mf.delta
        alpha = max(mf.alpha_x, mf.alpha_y)
        # Max Bounces: the bounces of a path that get their Fresnel factor (later ones F = 1;
        # every path is followed to its exit), in the sampler, eval and the moments alike.
        self.kmax = kmax_for(alpha, mf.distribution, groove, max_bounces_param)
        # The terms eval sums: the derived bound whatever Max Bounces (longer paths carry less
        # than 1e-4 of the energy), so eval's cost does not grow with Max Bounces.
        self.kterms = kmax_for(alpha, mf.distribution, groove, 0.0)
        self.quad = dict(quad or {})
        # Sampler and eval use the Fresnel tabulated (interpolation error < 1e-7 per bounce,
        # float32's level; the exact formula per bounce dominated their cost); self.fresnel
        # stays the exact callable.
        self._fresnel_table = FresnelTable(self.fresnel)

    def delta_reflectance(self, wi):
        """Roughness 0: one mirror bounce, tint F(wi.n) (zeros otherwise)."""
        wi = np.asarray(wi, dtype=float)
        if not self.is_delta:
            return np.zeros(wi.shape)
        c = np.clip(wi[..., 2], 0.0, 1.0)
        return np.where((wi[..., 2] > 0.0)[..., None], self.tint * self.fresnel(c), 0.0)

    def sample(self, wi, u):
        """(wo, weight RGB, k) from lee.sample; u (..., 3) symmetric or (..., 6) asymmetric."""
        wi = np.asarray(wi, dtype=float)
        if self.is_delta:
            shape = np.broadcast_shapes(wi.shape, np.shape(u)[:-1] + (3,))
            wi = np.broadcast_to(wi, shape)
            return (wi * np.array([-1.0, -1.0, 1.0]), self.delta_reflectance(wi),
                    np.ones(shape[:-1], dtype=np.int64))
        wo, w, k = sample(wi, u, self.mf, self._fresnel_table, self.groove, self.kmax)
        return wo, w * self.tint, k

    def eval(self, wi, wo):
        """f(wi, wo) RGB, without the cosine (zeros for roughness 0, a delta)."""
        if self.is_delta:
            return np.zeros(np.broadcast_shapes(np.shape(wi), np.shape(wo)))
        if self.groove == "symmetric":
            return eval(wi, wo, self.mf, self._fresnel_table, self.kterms, self.kmax) * self.tint
        return eval_asymmetric(wi, wo, self.mf, self._fresnel_table, self.kterms,
                               fresnel_bounces=self.kmax) * self.tint

    eval_specular = eval

    def directional_moments(self, mu, order=None):
        """(E, Vn, Vt) for wi = (sqrt(1 - mu^2), 0, mu), each (len(mu), 3) (see moments())."""
        mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=float)), 0.0, 1.0)
        if self.is_delta:
            wi = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
            R = self.delta_reflectance(wi)
            return R, R * mu[:, None], -R * np.sqrt(1.0 - mu * mu)[:, None]
        E, Vn, Vt = moments(mu, self.mf, self.fresnel, self.groove, self.kmax, **self.quad)
        return E * self.tint, Vn * self.tint, Vt * self.tint


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
        f = eval(wi, wo, bsdf.mf, bsdf._fresnel_table, AIMED_ORDERS, bsdf.kmax)
    else:
        uu = np.asarray(u)[..., PARTNER_DIM:PARTNER_DIM + 4 * AIMED_ORDERS]
        f = eval_asymmetric(wi, wo, bsdf.mf, bsdf._fresnel_table, AIMED_ORDERS,
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


@builds("lee_vgroove")
def _lee_vgroove(params) -> LeeBRDF:
    # Lee et al. 2018: kaleidoscopic multi-bounce V-grooves.
    ax, _ = alphas(params["roughness"])
    return LeeBRDF(Microfacet(params["distribution"], ax), groove=params["groove"],
                   fresnel=params["fresnel_type"], ior=params["ior"], n=params["n"],
                   k=params["k"], tint=params["base_color"],
                   max_bounces_param=params["max_bounces"])
