"""The Smith microsurface seen as a random medium (Heitz, Hanika, d'Eon & Dachsbacher 2016):
the height distribution, masking at a height, the free path in height, visible normals from
either side, and the phase functions of a scattering event. The paper's own equation numbers
are not cited (see the package doc); the authors' supplemental code's function names are.

* The Smith microsurface seen as a random medium: a ray meets the microsurface at a height
  distributed by the height distribution and the masking function, independently of the slopes.
  Any height distribution gives the same BSDF (the paper's argument for choosing one w.l.o.g.);
  like the authors' code we take heights uniform on [-1, 1]: C1(h) = clamp((h + 1)/2, 0, 1).
* Masking at a height (Smith, height-aware): a ray leaving height h upwards in direction w escapes
  with probability G1(w, h) = C1(h)^Lambda(w) (`G1_height`); averaged over the visible heights it
  is the usual 1 / (1 + Lambda).
* Free path in height ("next height" sampling): along w from height h0 the probability of reaching
  a height with C1 = c unhit is (C1(h0) / c)^Lambda_s(w), with the signed Smith Lambda_s =
  Lambda(w) for w.z > 0 and -1 - Lambda(|w|) for w.z < 0 (`lambda_signed`; a downward ray hits
  for sure). Inverting it with v = 1 - u: c = C1(h0) v^(-1 / Lambda_s), and an upward ray escapes
  when v <= C1(h0)^Lambda(w) (`sample_height`).
* The phase function of a scattering event is the visible-normal distribution of the incoming
  direction wi = -w_travel, D_wi(m) = <wi, m>+ D(m) / A(wi) with the projected area
  A(wi) = wi.z (1 + Lambda_s(wi)) (= wi.z (1 + Lambda) seen from above, |wi.z| Lambda from
  below; `projected_area`, `D_wi`), followed by a mirror reflection (conductor: weight F per
  RGB channel, exact complex Fresnel) or, for a dielectric, reflection with probability F and
  refraction otherwise (exact dielectric Fresnel, F = 1 under total internal reflection). The
  reflection phase function over wo is D_wi(h) / (4 |wi.h|) (Walter 2007 eq. 14 Jacobian); the
  refraction one eta^2 |wo.h| D_wi(h) / (wi.h + eta wo.h)^2 (Walter 2007 eq. 17 Jacobian).

Visible normals: for wi.z >= 0 `Microfacet.sample_vndf` (GGX spherical caps, Beckmann
Heitz & d'Eon 2014 / Jakob 2014). A ray travelling upwards that hits the surface sees it from
below (wi.z < 0), which the existing sampler does not cover (it flips wi); `sample_vndf_below`
samples D_wi there: GGX by the same spherical-cap construction without the flip (the cap
z in [-wi_std.z, 1] is valid for any wi: a uniformly reflected direction c on the unit sphere
gives m = normalize(wi_std + c), and m.z > 0 iff c.z > -wi_std.z); Beckmann exactly by
rejection in the stretched frame rotated to the azimuth of wi, where the visible slope x has
density prop. to (cot(theta) - x) exp(-x^2) on x < cot(theta) < 0 and y ~ N(0, 1/2) (see
`_beckmann_slope_below`).
"""
from __future__ import annotations

import math

import numpy as np

from ..fresnel import fresnel_dielectric
from ..microfacet import Microfacet, dot, normalize, vec
from ..special import erfinv

TINY = 1e-300  # floor of a C1 before its log and of a divisor (shared by the walk's modules)
_REJECTION_ROUNDS = 400  # acceptance >= 0.17 per round: failure probability < 1e-30


# -- heights: uniform on [-1, 1] ----------------------------------------------------------
def C1(h):
    """Height CDF of the uniform height distribution on [-1, 1] (the authors' choice; the BSDF
    does not depend on it): C1(h) = clamp((h + 1) / 2, 0, 1)."""
    return np.clip(0.5 * (np.asarray(h, dtype=float) + 1.0), 0.0, 1.0)


def invC1(c):
    """Inverse of C1: h = 2 c - 1 on [0, 1]."""
    return np.clip(2.0 * np.asarray(c, dtype=float) - 1.0, -1.0, 1.0)


def lambda_signed(mf: Microfacet, w):
    """Smith Lambda with the sign of the direction: Lambda(w) for w.z >= 0, -1 - Lambda(|w|)
    for w.z < 0 (the extension of Lambda to downward directions that makes the free-path law
    and the projected area one formula for both; the authors' code computes the same with
    sign(cot theta) in the GGX Lambda)."""
    w = np.asarray(w, dtype=float)
    lam = mf.lambda_(w)
    return np.where(w[..., 2] >= 0.0, lam, -1.0 - lam)


def projected_area(mf: Microfacet, w):
    """A(w) = integral over m.z > 0 of <w, m>+ D(m) dm = w.z (1 + Lambda_s(w)):
    w.z (1 + Lambda) from above (Heitz 2014 eq. 43 normalisation), |w.z| Lambda(|w|) from below
    (the upward-facing area a ray travelling up can hit)."""
    w = np.asarray(w, dtype=float)
    z = w[..., 2]
    lam = mf.lambda_(w)
    # Written per side: 1 + (-1 - Lambda) would cancel to 0 when Lambda < 1e-16 (steep
    # directions from below, where D_wi is then very peaked but not 0).
    return np.where(z >= 0.0, z * (1.0 + lam), -z * lam)


def D_wi(mf: Microfacet, wi, m):
    """Visible normals of the direction wi, from either side: <wi, m>+ D(m) / A(wi)
    (Heitz & d'Eon 2014 eq. 2 with the two-sided projected area)."""
    wi = np.asarray(wi, dtype=float)
    A = projected_area(mf, wi)
    val = np.maximum(dot(wi, m), 0.0) * mf.D(m)
    return np.where(A > 0.0, val / np.where(A > 0.0, A, 1.0), 0.0)


def G1_height(mf: Microfacet, w, h):
    """Height-aware Smith masking: probability that a ray leaving height h in direction w
    (w.z > 0) escapes the microsurface, C1(h)^Lambda(w); 0 for w.z <= 0. Its average over the
    visible heights is 1 / (1 + Lambda(w)) (Smith's G1)."""
    w = np.asarray(w, dtype=float)
    c = np.maximum(C1(h), TINY)
    g = np.exp(mf.lambda_(w) * np.log(c))
    return np.where(w[..., 2] > 0.0, g, 0.0)


def sample_height(mf: Microfacet, w, h0, u):
    """Next height along the travel direction w from height h0 (the paper's height sampling;
    the authors' code calls it sampleHeight). With v = 1 - u in (0, 1] and the free-path law
    P(no hit before C1 = c) = (C1(h0) / c)^Lambda_s(w):
        upward (w.z >= 0): escape iff v <= C1(h0)^Lambda(w) (probability G1(w, h0)),
                           else C1(h) = C1(h0) v^(-1/Lambda);
        downward:          always hits, C1(h) = C1(h0) v^(1/(1 + Lambda(|w|))).
    Returns (h, escaped); h is meaningless where escaped. Works in log C1 (no overflow when
    Lambda is tiny)."""
    w = np.asarray(w, dtype=float)
    lam = mf.lambda_(w)
    up = w[..., 2] >= 0.0
    log_c0 = np.log(np.maximum(C1(h0), TINY))
    log_v = np.log1p(-np.minimum(np.asarray(u, dtype=float), 1.0 - 2.0 ** -53))
    escaped = up & (log_v <= lam * log_c0)
    lam_s = np.where(up, lam, -1.0 - lam)
    # lam_s = 0 only for a vertical upward ray (Lambda = 0), which always escapes.
    safe = np.where(lam_s == 0.0, 1.0, lam_s)
    with np.errstate(over="ignore", divide="ignore"):  # Lambda ~ 1e-300: c = 1 (escaped anyway)
        log_c = np.minimum(log_c0 - log_v / safe, 0.0)
    return invC1(np.exp(log_c)), escaped


# -- visible normals from either side -------------------------------------------------------
def sample_vndf_below(mf: Microfacet, wi, u1, u2, rng):
    """m ~ D_wi(m) = <wi, m>+ D(m) / A(wi) for wi.z < 0 (the microsurface seen from below: a
    ray travelling upwards meets an upward-facing facet). See the module doc for the method."""
    wi = np.asarray(wi, dtype=float)
    ax, ay = mf.alpha_x, mf.alpha_y
    ws = normalize(vec(ax * wi[..., 0], ay * wi[..., 1], wi[..., 2]))  # not flipped
    if mf.delta:  # a mirror cannot be hit from below
        return np.broadcast_to(np.array([0.0, 0.0, 1.0]), wi.shape).copy()
    if mf.ggx:
        # Spherical caps (the construction of Dupuy & Benyoub 2023) without the flip: the
        # cap z in [-ws.z, 1] is the part of the unit sphere that gives m.z >= 0.
        phi = 2.0 * math.pi * np.asarray(u1, dtype=float)
        z = (1.0 - np.asarray(u2, dtype=float)) * (1.0 + ws[..., 2]) - ws[..., 2]
        sin_t = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
        h = vec(sin_t * np.cos(phi), sin_t * np.sin(phi), z) + ws
        m = vec(ax * h[..., 0], ay * h[..., 1], np.maximum(h[..., 2], 0.0))
        return normalize(m)
    sin_t = np.sqrt(ws[..., 0] ** 2 + ws[..., 1] ** 2)
    has_phi = sin_t > 0.0
    cos_phi = np.where(has_phi, ws[..., 0] / np.where(has_phi, sin_t, 1.0), 1.0)
    sin_phi = np.where(has_phi, ws[..., 1] / np.where(has_phi, sin_t, 1.0), 0.0)
    cot_t = ws[..., 2] / np.maximum(sin_t, 1e-300)  # < 0
    x = _beckmann_slope_below(np.maximum(-cot_t, 0.0), np.asarray(u1, dtype=float), rng)
    y = erfinv(2.0 * np.asarray(u2, dtype=float) - 1.0)
    sx = (cos_phi * x - sin_phi * y) * ax
    sy = (sin_phi * x + cos_phi * y) * ay
    return normalize(vec(-sx, -sy, 1.0))


def _beckmann_slope_below(a, u, rng):
    """Visible slope x of the alpha = 1 Beckmann surface seen from below at stretched polar
    angle theta > 90 deg, a = -cot(theta) > 0. Visibility is x < cot(theta) = -a, and the
    density of x is prop. to (cos t - x sin t) exp(-x^2) prop. to (-a - x) exp(-x^2)
    (the Heitz & d'Eon 2014 sec. 4 visible-slope density, continued past 90 degrees). With
    t = -a - x >= 0 the density is prop. to t exp(-(t + a)^2) prop. to t exp(-t^2) exp(-2 a t).
    Exact rejection sampling (the first uniform is u, the rest come from rng):
      a < 1:  propose the Rayleigh law t exp(-t^2), t = sqrt(-log(1 - u)); accept with
              probability exp(-2 a t) (acceptance >= exp(-sqrt(pi)) = 0.17);
      a >= 1: propose Gamma(2, rate 2 a), t = -(log U + log U') / (2 a); accept with
              probability exp(-t^2) (acceptance >= 0.48, its value at a = 1).
    Returns x = -a - t."""
    a = np.asarray(a, dtype=float)
    shape = a.shape
    a = a.ravel()
    t = np.zeros_like(a)
    pending = np.ones(a.shape, dtype=bool)
    u_first = np.broadcast_to(np.asarray(u, dtype=float), shape).ravel()
    for r in range(_REJECTION_ROUNDS):
        idx = np.nonzero(pending)[0]
        if len(idx) == 0:
            break
        ai = a[idx]
        extra = rng.random((len(idx), 3))
        u0 = u_first[idx] if r == 0 else extra[:, 2]
        small = ai < 1.0
        t_r = np.sqrt(-np.log1p(-np.minimum(u0, 1.0 - 2.0 ** -53)))
        top = 1.0 - 2.0 ** -53
        t_g = -(np.log1p(-np.minimum(u0, top)) + np.log1p(-np.minimum(extra[:, 1], top))) \
            / (2.0 * np.maximum(ai, 1e-300))
        ti = np.where(small, t_r, t_g)
        log_acc = np.where(small, -2.0 * ai * ti, -ti * ti)
        ok = np.log(np.maximum(extra[:, 0], TINY)) < log_acc
        t[idx[ok]] = ti[ok]
        pending[idx[ok]] = False
    # (after _REJECTION_ROUNDS a still pending row keeps t = 0, the visibility edge; the chance
    # is below 0.83^400 per row)
    return (-a - t).reshape(shape)


def sample_visible(mf: Microfacet, wi, u1, u2, rng):
    """m ~ D_wi(m) from either side: Microfacet.sample_vndf for wi.z >= 0, sample_vndf_below
    otherwise."""
    wi = np.asarray(wi, dtype=float)
    below = wi[..., 2] < 0.0
    m = np.empty(wi.shape)
    up = ~below
    if up.any():
        m[up] = mf.sample_vndf(wi[up], u1[up], u2[up])
    if below.any():
        m[below] = sample_vndf_below(mf, wi[below], u1[below], u2[below], rng)
    return m


# -- phase functions --------------------------------------------------------------------------
def phase_reflection(mf: Microfacet, wi, wo):
    """Density over wo of the reflection of wi (either side, wi = -travel direction) off a
    visible facet: D_wi(h) / (4 |wi.h|), h = normalize(wi + wo) (upward-facing facets only;
    Walter 2007 eq. 14 Jacobian). Without the Fresnel factor (the authors' evalPhaseFunction of
    the conductor)."""
    h = normalize(np.asarray(wi, dtype=float) + np.asarray(wo, dtype=float))
    c = dot(wi, h)
    val = D_wi(mf, wi, h) / (4.0 * np.where(c > 0.0, c, 1.0))
    return np.where((c > 0.0) & (h[..., 2] > 0.0), val, 0.0)


def phase_dielectric(mf: Microfacet, wi, wo, eta, wi_outside, wo_outside):
    """Phase function of the dielectric interface over wo (the authors' evalPhaseFunction with
    the two side flags), wi = -travel direction, eta = n_below / n_above. On the lower side
    (wi_outside False) the microsurface is flipped (normals -m) and the relative index is 1/eta.
      reflection (same side):   F(wi.h) D_wi(s wi, s h) / (4 wi.h),  h = normalize(wi + wo);
      refraction (other side):  (1 - F(wi.h)) eta_l^2 D_wi(s wi, s h) <-wo.h>+
                                / (wi.h + eta_l wo.h)^2,  h = -normalize(wi + eta_l wo) turned
                                to the side s of the current medium (Walter 2007 eqs. 16-17);
    with s = +1 above, -1 below and eta_l = eta above, 1/eta below. Scalar (..,)."""
    wi = np.asarray(wi, dtype=float)
    wo = np.asarray(wo, dtype=float)
    wi_outside = np.asarray(wi_outside, dtype=bool)
    wo_outside = np.asarray(wo_outside, dtype=bool)
    s = np.where(wi_outside, 1.0, -1.0)
    eta_l = np.where(wi_outside, eta, 1.0 / eta)
    # reflection
    hr = normalize(wi + wo)
    cr = dot(wi, hr)
    pr = D_wi(mf, s[..., None] * wi, s[..., None] * hr) \
        * fresnel_dielectric(cr, eta_l) / (4.0 * np.where(cr > 0.0, cr, 1.0))
    pr = np.where(cr > 0.0, pr, 0.0)
    # refraction
    ht = -normalize(wi + eta_l[..., None] * wo)
    ht = ht * (s * np.where(ht[..., 2] < 0.0, -1.0, 1.0))[..., None]
    ci, co = dot(wi, ht), dot(wo, ht)
    den = (ci + eta_l * co) ** 2
    ok = (ci > 0.0) & (co < 0.0) & (den > 0.0)
    pt = eta_l * eta_l * (1.0 - fresnel_dielectric(ci, eta_l)) \
        * D_wi(mf, s[..., None] * wi, s[..., None] * ht) * np.maximum(-co, 0.0) \
        / np.where(ok, den, 1.0)
    pt = np.where(ok, pt, 0.0)
    return np.where(wi_outside == wo_outside, pr, pt)


def beta_function(a, b):
    """B(a, b) = Gamma(a) Gamma(b) / Gamma(a + b) through math.lgamma (a, b >= 1 here)."""
    lg = np.vectorize(math.lgamma, otypes=[float])
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return np.exp(lg(a) + lg(b) - lg(a + b))
