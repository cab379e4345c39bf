"""The bounce geometry of Lee et al. 2018's kaleidoscopic V-grooves: the groove cross-section's
2D angles, the bounce count k and exit angle of a ray (the seed's eqs. 5-1 and 5-2, resolved
below), the Fresnel product over a path's bounces (Max Bounces, docs/lee-asymmetric-grooves.md
sec. 4), and the bound on the number of bounces (truncation tails, max_bounces, its closed form
tail_ratio / max_bounces_closed_form and the shader's kmax_for). Everything else in the package
builds on these kernels.

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
"""
from __future__ import annotations

import math

import numpy as np

from ..special import erfc
from .fresnel_table import FresnelTable

PI = math.pi
TRUNCATION = 1e-4  # energy allowed in paths beyond max_bounces
BECKMANN_Y_MAX = 6.5  # Beckmann slopes beyond 6.5 alpha carry exp(-42) of the mass


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
    running are a prefix: the cost is the number of factors, not kmax times the paths. The
    blocks grow from 1 to `block` factors: most paths end after one to three bounces, and a
    block costs every live path all of its factors."""
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
    j0, size = 0, 1
    while j0 < int(ms[0]):
        live = order[:int(np.searchsorted(neg, -j0, side="left"))]
        jj = np.arange(j0, j0 + size, dtype=float)
        c = np.minimum(rho[live, None] * np.abs(np.sin(phi0[live, None]
                                                        + jj * theta_v[live, None])), 1.0)
        if isinstance(fresnel, FresnelTable):
            out[live] *= fresnel.product(c, ms[:live.size] - j0)
        else:
            F = np.asarray(fresnel(c), dtype=float)
            past = jj[None, :] >= ms[:live.size, None]  # factors beyond the path's own count
            if past.any():
                F = np.where(past[..., None], 1.0, F)
            out[live] *= np.prod(F, axis=1)
        j0, size = j0 + size, min(2 * size, block)
    return out.reshape(shape + (3,))
