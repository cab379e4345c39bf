"""Heitz, Hanika, d'Eon & Dachsbacher 2016, "Multiple-scattering microfacet BSDFs with the Smith
model" (SIGGRAPH 2016): the numpy twin of osl/heitz2016.osl (catalog model `heitz2016`).

    bsdf = HeitzConductor(Microfacet("ggx", 0.25), fresnel="conductor", n=..., k=...)
    bsdf = HeitzDielectric(Microfacet("ggx", 0.25), ior=1.5)
    s = bsdf.sample(wi, rng)                  # WalkSample(wo, weight, order, lost), one per row
    est = bsdf.eval(wi, wo, rng)              # one unbiased estimate of f(wi, wo) |wo.n| per row
    mean, se = bsdf.eval_mean(wi, wo, 4096, rng)
    bsdf.eval_single(wi, wo)                  # closed-form first order, f_1 |wo.n|
    bsdf.albedo(wi, 10**5, rng)               # Albedo(E, E_se, R, T, R_se, T_se, lost,
                                              #        mean_order)
    directional_moments_mc(bsdf, mu, 10**5, rng)   # (E, Vn, Vt) and their standard errors

Conventions (docs/models.md): local frame n = (0,0,1); wi.z > 0 points from the surface to the
viewer; wo points away from the surface, wo.z < 0 is transmission; eta = n_t / n_i seen from wi's
side (the upper medium has index 1, the lower one eta); Cycles' transport convention for the
dielectric: a refraction carries weight 1 (no 1/eta^2 radiance factor), as in glass.py. Directions
are arrays (N, 3) (any (..., 3) is flattened), one random walk per row; RGB results (N, 3).
`rng` is a numpy Generator or any object with a `random(shape)` method returning uniforms in
[0, 1) (a stream of prepared numbers): every scattering step draws `rng.random((n_alive, 4))`
(column 0 the next height, 1-2 the visible normal, 3 the Fresnel choice of the dielectric), and
the downward visible-normal samplers draw extra numbers for their rejection loops.

The model (Heitz et al. 2016). The paper's equation, section and algorithm numbers are NOT
cited here: I could not check them against the paper's text, so each quantity is described
instead; where it helps, the name of the corresponding function of the authors' published
supplemental code is given (sampleHeight, G_1(w, h0), evalPhaseFunction, samplePhaseFunction,
evalSingleScattering), whose structure was checked against a public port of that code (libbsdf's
MultipleScatteringSmith); no code was copied, this is an independent vectorised derivation.

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
* Dielectric random walk: the walk continues on either side of the interface. Below it the
  medium sees the flipped microsurface (heights -h, normals -m, directions -w) and the relative
  index 1 / eta; with symmetric (uniform) heights the flipped surface has the same C1, so every
  step below is the step above applied to the negated quantities.
* Sampling (`sample`): the walk starts above the surface going down along -wi, scatters until it
  escapes: upwards (reflection), or, for the dielectric, downwards from below (transmission).
  The weight is the product of the Fresnel factors (conductor) or 1 (dielectric), so with F = 1
  or without absorption the density of wo is f |wo.n| exactly. Walks that reach `max_order`
  scattering events without escaping are stopped with weight 0 and flagged `lost` (a bias of at
  most their fraction, reported).
* Stochastic evaluation (`eval`), as in the paper: the walk from wi, with at every scattering
  event a next-event term toward wo: throughput x phase function (wi_event -> wo) x the escape
  probability of wo from the event's height (G1(wo, h) above, G1(-wo, -h) below). Its expectation
  is f(wi, wo) |wo.n| (the BSDF times the cosine of wo, NOT f); each call is one unbiased estimate
  per row (up to the max_order truncation). `eval(..., bidirectional=True)` averages it with the
  reverse walk from wo turned into an estimate of the same quantity through reciprocity (f
  symmetric for reflection; f_t(wi, wo; eta) = eta^2 f_t(flip(wo), flip(wi); 1/eta) for
  transmission in Cycles' convention, flip(x, y, z) = (x, y, -z)): still unbiased. This averaging
  is my addition; I did not verify whether the paper combines the two directions (with MIS
  weights or otherwise), so the default is the unidirectional estimator.
* First order in closed form (`eval_single`, the authors' code calls it evalSingleScattering):
  averaging the first event over its height (C1(h1) has density (1 + Lambda_i) c^Lambda_i) gives
  reflection: F D G2 / (4 wi.z), G2 = 1 / (1 + Lambda_i + Lambda_o): single-scattering Walter
  with the HEIGHT-CORRELATED Smith G2 (Heitz 2014 eq. 99), i.e. make_bsdf("walter_reflection",
  {masking: "height_correlated"}).eval_cos exactly;
  transmission: the Walter BTDF (Walter 2007 eq. 21) times |wo.z| with the height-correlated
  transmission G2: the escape of wo from below is (1 - C1(h1))^Lambda_o and
  E[(1 - C1(h1))^Lambda_o] = (1 + Lambda_i) B(1 + Lambda_i, 1 + Lambda_o), which with the
  1 / (1 + Lambda_i) of D_wi leaves G2_t = B(1 + Lambda_i, 1 + Lambda_o), the Beta-function form
  that glass.py cites as Heitz 2014 eq. 100. NOTE: walter_glass (and Cycles) use
  1 / (1 + Lambda_i + Lambda_o) for transmission too, so the walk's first order equals
  walter_glass's f_t only after replacing that G2 by the Beta form. B(a, b) <= 1 / (a + b - 1),
  equal when Lambda_i = 0 (normal incidence) or Lambda_o = 0: the walk's first-order
  transmission is darker, much so at grazing incidence on rough glass (measured, GGX alpha 1,
  eta 1.5, mu = 0.3: first-order albedo R_1 + T_1 = 0.406, against 0.704 for walter_glass;
  Beckmann 0.818 against 0.881). So Cycles' single-scattering glass is an exact control of the
  walk's first order for reflection only.

Variance (measured; tests/test_reference_heitz2016.py and the report). The sampler's weights
are bounded (products of Fresnel factors), so albedos and moments from it have honest standard
errors. The stochastic evaluation is unbiased but can be heavy-tailed: the next-event term of a
rare walk can be many orders above the typical one (a hit from below, probability ~ Lambda,
has a phase function ~ 1 / (|w.z| Lambda); and with Beckmann's light tails reaching a given wo
at order >= 2 can be a rare event). Per-walk relative standard deviation, wi at 45 deg: GGX
alpha 0.5 / 1 and Beckmann 0.5 / 1: 0.2 .. 1.4; GGX alpha 0.1 toward grazing wo: ~50-60 (and
Beckmann alpha 0.6 order 3: the 5 largest of 4M walks carry 93 % of the term). The sample
standard error then understates the error when the rare walks were not drawn, so compare
evaluations in z-tests only where the tails are mild (the tests say where), or use the
sampler (patch transport, chi-square). bidirectional=True lowers the per-walk relative standard
deviation by about 1.3-2x in most configurations measured (not all: toward the normal at GGX
alpha 0.1 it rises from 0.7 to 1.1).

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
from typing import NamedTuple

import numpy as np

from ...catalog import alphas
from . import lamps as lamp_twin
from .bsdf import builds
from .fresnel import fresnel_conductor, fresnel_dielectric
from .microfacet import Microfacet, dot, normalize, reflect, vec
from .quadrature import MU_MIN, MomentTable, merge
from .special import erfinv

MAX_ORDER = 100  # scattering events before a walk is stopped (counted as lost)
_TINY = 1e-300
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
    c = np.maximum(C1(h), _TINY)
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
    log_c0 = np.log(np.maximum(C1(h0), _TINY))
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
        ok = np.log(np.maximum(extra[:, 0], _TINY)) < log_acc
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


def _refract(wi, m, eta):
    """Walter 2007 eq. 40 with a per-row eta (glass.refract takes a scalar): wi.m > 0,
    eta = n_t / n_i; returns (wo, ok), ok False under total internal reflection."""
    c = dot(wi, m)
    cos_t2 = 1.0 - (1.0 - c * c) / (eta * eta)
    ok = cos_t2 > 0.0
    ct = np.sqrt(np.maximum(cos_t2, 0.0))
    wo = (c / eta - ct)[..., None] * m - wi / eta[..., None]
    return normalize(wo), ok


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


# -- results -----------------------------------------------------------------------------------
class WalkSample(NamedTuple):
    wo: np.ndarray       # (N, 3) exit direction (wo.z < 0: transmission); (0,0,0) where lost
    weight: np.ndarray   # (N, 3) product of the Fresnel factors (conductor), 1 (dielectric), x tint
    order: np.ndarray    # (N,) number of scattering events (max_order where lost)
    lost: np.ndarray     # (N,) True: stopped at max_order without escaping (weight 0)


class Albedo(NamedTuple):
    E: np.ndarray        # (3,) integral of f |cos_o| over the sphere, mean of the weights
    E_se: np.ndarray     # (3,) its Monte Carlo standard error
    R: np.ndarray        # (3,) the part with wo.z > 0
    T: np.ndarray        # (3,) the part with wo.z < 0 (dielectric)
    R_se: np.ndarray
    T_se: np.ndarray
    lost: int            # walks stopped at max_order
    mean_order: float    # mean number of scattering events per walk


class MCMoments(NamedTuple):
    E: np.ndarray        # (len(mu), 3), as quadrature.directional_moments
    Vn: np.ndarray
    Vt: np.ndarray
    E_se: np.ndarray
    Vn_se: np.ndarray
    Vt_se: np.ndarray
    lost: np.ndarray     # (len(mu),) walks stopped at max_order


def _rows(x):
    x = np.asarray(x, dtype=float)
    return x.reshape(-1, 3)


def _mean_se(x):
    """Mean over the rows and its standard error."""
    n = len(x)
    se = x.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.zeros(x.shape[1:])
    return x.mean(axis=0), se


def flip(w):
    """(x, y, z) -> (x, y, -z): the same direction seen with the interface flipped."""
    return np.asarray(w, dtype=float) * np.array([1.0, 1.0, -1.0])


# -- the random walk --------------------------------------------------------------------------
class _SmithWalk:
    """Shared random walk; subclasses set `dielectric` and the scattering rule."""

    dielectric = False
    has_transmission = False

    def __init__(self, mf: Microfacet, tint=(1.0, 1.0, 1.0)):
        self.mf = mf
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.zeros(3)

    # Hooks -----------------------------------------------------------------------------
    def _next_height(self, wr, h, outside, u):
        return sample_height(self.mf, wr, h, u)

    def _escape_is_exit(self, wr, outside):
        return np.ones(len(wr), dtype=bool)

    # Walk --------------------------------------------------------------------------------
    def _walk(self, wi, rng, max_order, wo=None, order=None, from_order=1):
        """The random walk from wi (rows); if wo is given also the next-event estimate toward
        wo (rows), restricted to scattering order `order` when not None. Returns
        (WalkSample, estimate or None)."""
        wi = _rows(wi)
        n = len(wi)
        out_wo = np.zeros((n, 3))
        out_w = np.zeros((n, 3))
        out_order = np.full(n, max_order, dtype=int)
        lost = np.zeros(n, dtype=bool)
        est = None if wo is None else np.zeros((n, 3))
        if wo is not None:
            wo = np.broadcast_to(_rows(wo), (n, 3))
        idx = np.arange(n)
        wr = -wi  # travel direction
        h = np.ones(n)  # the top of the height support: C1 = 1
        outside = np.ones(n, dtype=bool)
        thr = np.ones((n, 3))
        valid = wi[:, 2] > 0.0
        idx, wr, h, outside, thr = idx[valid], wr[valid], h[valid], outside[valid], thr[valid]
        out_order[~valid] = 0
        for k in range(max_order + 1):
            if len(idx) == 0:
                break
            u = rng.random((len(idx), 4))
            h, esc = self._next_height(wr, h, outside, u[:, 0])
            if esc.any():
                e = idx[esc]
                out_wo[e] = wr[esc]
                out_w[e] = thr[esc]
                out_order[e] = k
            keep = ~esc
            idx, wr, h, outside, thr, u = (idx[keep], wr[keep], h[keep], outside[keep],
                                           thr[keep], u[keep])
            if k == max_order:
                lost[idx] = True
                break
            # scattering event number k + 1 at height h
            wi_ev = -wr
            if est is not None and (order is None or order == k + 1) and k + 1 >= from_order:
                est[idx] += thr * self._next_event(wi_ev, wo[idx], h, outside)
            if est is not None and order is not None and k + 1 >= order:
                break  # later events cannot contribute to a single order
            wr, thr, outside = self._scatter(wi_ev, thr, outside, u, rng)
        out_w = out_w * self.tint
        sample = WalkSample(out_wo, out_w, out_order, lost)
        if est is not None:
            est = est * self.tint
        return sample, est

    # Public API -------------------------------------------------------------------------
    def sample(self, wi, rng, max_order: int = MAX_ORDER) -> WalkSample:
        """One random walk per row of wi: WalkSample(wo, weight RGB, order, lost). wo has
        density f |wo.n| / (its integral) up to the weights; E[weight * g(wo)] =
        integral f(wi, wo) |wo.n| g(wo) dwo (minus the lost walks' share)."""
        return self._walk(wi, rng, max_order)[0]

    def eval(self, wi, wo, rng, max_order: int = MAX_ORDER, order: int | None = None,
             bidirectional: bool = False):
        """One stochastic, unbiased estimate per row of f(wi, wo) |wo.n| (RGB; the BSDF times
        the cosine of wo, not f): the walk from wi with next-event estimation toward wo at
        every scattering event (the paper's stochastic evaluation). order=k keeps only the
        k-th scattering event's term (order=1: the first-order term, whose mean is
        `eval_single`). bidirectional=True averages with the reverse walk from wo (see the
        module doc), which needs twice the walks."""
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        fwd = self._walk(wi, rng, max_order, wo=wo, order=order)[1]
        if not bidirectional:
            return fwd
        return 0.5 * (fwd + self._reverse_estimate(wi, wo, rng, max_order, order))

    def eval_mean(self, wi, wo, n_walks: int, rng, max_order: int = MAX_ORDER,
                  order: int | None = None, bidirectional: bool = False, chunk: int = 1 << 18):
        """Mean and standard error (each (P, 3)) of `eval` over n_walks walks per pair
        (rows of wi, wo)."""
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        P = len(wi)
        per = max(1, chunk // max(P, 1))
        done = 0
        scale = None
        mean = np.zeros((P, 3))
        M2 = np.zeros((P, 3))
        while done < n_walks:
            m = min(per, n_walks - done)
            e = self.eval(np.repeat(wi, m, axis=0), np.repeat(wo, m, axis=0), rng, max_order,
                          order, bidirectional).reshape(P, m, 3)
            if scale is None:  # values may be ~1e-170: squares would underflow
                scale = np.abs(e).max(axis=1)
                scale = np.where(scale > 0.0, scale, 1.0)
            e = e / scale[:, None, :]
            mb = e.mean(axis=1)
            M2b = ((e - mb[:, None, :]) ** 2).sum(axis=1)
            delta = mb - mean
            n_new = done + m
            mean = mean + delta * (m / n_new)
            M2 = M2 + M2b + delta * delta * (done * m / n_new)  # Chan et al.'s update
            done = n_new
        var = M2 / max(n_walks - 1, 1)
        return mean * scale, np.sqrt(var / n_walks) * scale

    def albedo(self, wi, n_walks: int, rng, max_order: int = MAX_ORDER,
               order: int | None = None) -> Albedo:
        """Directional albedo E(wi) = integral f |cos_o| dwo from n_walks sampled walks, with
        its standard error, the reflected / transmitted parts, the lost walks and the mean
        walk length. order=k keeps only walks of exactly k scattering events (order=1: the
        single-scattering albedo)."""
        wi = np.broadcast_to(_rows(wi)[0], (n_walks, 3))
        s = self.sample(wi, rng, max_order)
        w = s.weight if order is None else s.weight * (s.order == order)[:, None]
        up = (s.wo[:, 2] > 0.0)[:, None]
        E, E_se = _mean_se(w)
        R, R_se = _mean_se(w * up)
        T, T_se = _mean_se(w * ~up)
        return Albedo(E, E_se, R, T, R_se, T_se, int(s.lost.sum()), float(s.order.mean()))


class HeitzConductor(_SmithWalk):
    """Heitz et al. 2016 conductor (reflection only): every scattering event is a mirror
    reflection off a visible microfacet with weight F(wi.m) per RGB channel.
    fresnel: "conductor" (complex IOR n + i k per channel), "dielectric" (ior; reflection
    weighted by F, the transmitted part discarded, as walter_reflection's dielectric option) or
    "none" (F = 1: a white furnace)."""

    def __init__(self, mf: Microfacet, fresnel: str = "conductor", ior: float = 1.5,
                 n=(1.0, 1.0, 1.0), k=(0.0, 0.0, 0.0), tint=(1.0, 1.0, 1.0)):
        super().__init__(mf, tint)
        if fresnel not in ("conductor", "dielectric", "none"):
            raise ValueError(f"unknown fresnel {fresnel!r}")
        self.fresnel = fresnel
        self.ior = float(ior)
        self.n = np.asarray(n, dtype=float)
        self.k = np.asarray(k, dtype=float)

    def __repr__(self):
        return f"HeitzConductor({self.mf!r}, fresnel={self.fresnel!r})"

    def F(self, cos_i):
        cos_i = np.asarray(cos_i, dtype=float)
        if self.fresnel == "conductor":
            return fresnel_conductor(cos_i[..., None], self.n, self.k)
        if self.fresnel == "dielectric":
            return fresnel_dielectric(cos_i, self.ior)[..., None] * np.ones(3)
        return np.ones(cos_i.shape + (3,))

    def _scatter(self, wi_ev, thr, outside, u, rng):
        m = sample_visible(self.mf, wi_ev, u[:, 1], u[:, 2], rng)
        c = dot(wi_ev, m)
        return reflect(wi_ev, m), thr * self.F(c), outside

    def _next_event(self, wi_ev, wo, h, outside):
        """F x phase function x G1(wo, h): the next-event term toward wo (RGB)."""
        hv = normalize(wi_ev + wo)
        p = phase_reflection(self.mf, wi_ev, wo) * G1_height(self.mf, wo, h)
        return self.F(dot(wi_ev, hv)) * p[..., None]

    def _reverse_estimate(self, wi, wo, rng, max_order, order):
        """Reciprocity f(wi, wo) = f(wo, wi): est(wo -> wi) |wo.z| / |wi.z|."""
        rev = self._walk(wo, rng, max_order, wo=wi, order=order)[1]
        ratio = np.where(wo[:, 2] > 0.0, wo[:, 2] / np.maximum(wi[:, 2], _TINY), 0.0)
        return rev * ratio[:, None]

    def single_kernel(self, wi, wo):
        """(F(wi.h) RGB, D G2 / (4 wi.z) with the height-correlated G2, 0 where wi or wo is
        below the horizon): the first order's two factors, for rows of wi, wo."""
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        mf = self.mf
        valid = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        hv = normalize(wi + wo)
        G2 = 1.0 / (1.0 + mf.lambda_(wi) + mf.lambda_(wo))
        val = mf.D(hv) * G2 / (4.0 * np.where(valid, wi[:, 2], 1.0))
        return self.F(dot(wi, hv)), np.where(valid, val, 0.0)

    def eval_single(self, wi, wo):
        """Closed-form first order, f_1(wi, wo) |wo.n| = F D G2 / (4 wi.z) with the
        height-correlated G2 = 1 / (1 + Lambda_i + Lambda_o) (Heitz 2014 eq. 99): the mean of
        eval(..., order=1) (derivation in the module doc). RGB (N, 3)."""
        F, val = self.single_kernel(wi, wo)
        return F * val[:, None] * self.tint


class HeitzDielectric(_SmithWalk):
    """Heitz et al. 2016 dielectric: at every event reflection with probability F, else
    refraction; the walk continues above or below the interface until it escapes upward
    (reflection) or downward (transmission). eta = ior = n_below / n_above, wi above. No
    absorption: every walk weighs `tint` (R + T = 1 up to lost walks)."""

    dielectric = True
    has_transmission = True

    def __init__(self, mf: Microfacet, ior: float = 1.5, tint=(1.0, 1.0, 1.0),
                 forward_transmission: bool = True):
        super().__init__(mf, tint)
        self.eta = float(ior)
        self.ior = self.eta
        self.forward_transmission = forward_transmission

    @staticmethod
    def is_forward(wi, wo):
        """Transmitted directions with wi.wo >= 0 ("forward" through the interface), which a
        multiple-scattering walk reaches but no refraction can: for any eta > 0 a refraction
        has wi.wo = (cos_i^2 - 1) / eta - cos_i |cos_t| < 0 (Walter 2007 eq. 40). Cycles'
        refraction closure cannot return them, so osl/heitz2016.osl drops them (weight 0);
        forward_transmission=False does the same here (docs/multiple-scattering.md measures
        the share)."""
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        return (wo[:, 2] < 0.0) & (dot(wi, wo) >= 0.0)

    def sample(self, wi, rng, max_order: int = MAX_ORDER) -> WalkSample:
        s = super().sample(wi, rng, max_order)
        if self.forward_transmission:
            return s
        keep = ~self.is_forward(wi, s.wo)
        return s._replace(weight=s.weight * keep[:, None])

    def eval(self, wi, wo, rng, max_order: int = MAX_ORDER, order: int | None = None,
             bidirectional: bool = False):
        est = super().eval(wi, wo, rng, max_order, order, bidirectional)
        if self.forward_transmission:
            return est
        return est * ~self.is_forward(wi, wo)[:, None]

    def __repr__(self):
        return f"HeitzDielectric({self.mf!r}, eta={self.eta:g})"

    def _next_height(self, wr, h, outside, u):
        """Above: sample_height; below: the same on the flipped microsurface (heights -h,
        directions -w), escape there being the transmission."""
        s = np.where(outside, 1.0, -1.0)
        hn, esc = sample_height(self.mf, s[:, None] * wr, s * h, u)
        return s * hn, esc

    def _scatter(self, wi_ev, thr, outside, u, rng):
        s = np.where(outside, 1.0, -1.0)[:, None]
        m = s * sample_visible(self.mf, s * wi_ev, u[:, 1], u[:, 2], rng)
        eta_l = np.where(outside, self.eta, 1.0 / self.eta)
        c = dot(wi_ev, m)
        F = fresnel_dielectric(c, eta_l)
        refl = u[:, 3] < F
        wt, ok = _refract(wi_ev, m, eta_l)
        refl = refl | ~ok
        wr = np.where(refl[:, None], reflect(wi_ev, m), wt)
        return wr, thr, np.where(refl, outside, ~outside)

    def _next_event(self, wi_ev, wo, h, outside):
        wo_up = wo[:, 2] > 0.0
        p = phase_dielectric(self.mf, wi_ev, wo, self.eta, outside, wo_up)
        shadow = np.where(wo_up, G1_height(self.mf, wo, h), G1_height(self.mf, -wo, -h))
        return (p * shadow)[:, None] * np.ones(3)

    def _reverse_estimate(self, wi, wo, rng, max_order, order):
        """Reflection: f symmetric, est(wo -> wi) |wo.z| / |wi.z|. Transmission (Cycles'
        convention): f_t(wi, wo; eta) = eta^2 f_t(flip(wo), flip(wi); 1/eta), so the reverse
        walk runs on the flipped interface with 1/eta from flip(wo) toward flip(wi):
        eta^2 est'(flip(wo) -> flip(wi)) |wo.z| / |wi.z|."""
        refl = wo[:, 2] > 0.0
        out = np.zeros((len(wi), 3))
        if refl.any():
            r = self._walk(wo[refl], rng, max_order, wo=wi[refl], order=order)[1]
            out[refl] = r * (wo[refl, 2] / wi[refl, 2])[:, None]
        t = ~refl
        if t.any():
            other = HeitzDielectric(self.mf, 1.0 / self.eta, self.tint)  # full walk: the pair is masked after
            r = other._walk(flip(wo[t]), rng, max_order, wo=flip(wi[t]), order=order)[1]
            out[t] = self.eta ** 2 * r * (np.abs(wo[t, 2]) / wi[t, 2])[:, None]
        return out

    def eval_single(self, wi, wo):
        """Closed-form first order f_1 |wo.n| (RGB (N, 3)), the mean of eval(..., order=1):
        reflection F(wi.h) D G2 / (4 wi.z), G2 = 1 / (1 + Lambda_i + Lambda_o) (height-
        correlated, Heitz 2014 eq. 99); transmission (Walter 2007 eq. 21 times |wo.z|)
        |wi.h| |wo.h| eta^2 (1 - F(wi.h)) D(h) G2_t / (wi.z (wi.h + eta wo.h)^2),
        h = -+normalize(wi + eta wo) with h.z > 0, with the height-correlated transmission
        G2_t = B(1 + Lambda_i, 1 + Lambda_o) (derivation in the module doc)."""
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        mf, eta = self.mf, self.eta
        li, lo = mf.lambda_(wi), mf.lambda_(wo)
        up = wi[:, 2] > 0.0
        # reflection
        hr = normalize(wi + wo)
        cr = dot(wi, hr)
        fr = fresnel_dielectric(cr, eta) * mf.D(hr) / (1.0 + li + lo) \
            / (4.0 * np.where(up, wi[:, 2], 1.0))
        fr = np.where(up & (wo[:, 2] > 0.0) & (cr > 0.0), fr, 0.0)
        # transmission
        ht = wi + eta * wo
        ht = normalize(np.where((ht[:, 2] < 0.0)[:, None], -ht, ht))
        ci, co = dot(wi, ht), dot(wo, ht)
        ok = up & (wo[:, 2] < 0.0) & (ci > 0.0) & (co < 0.0)
        den = np.where(ok, wi[:, 2] * (ci + eta * co) ** 2, 1.0)
        ft = np.abs(ci * co) * eta * eta * (1.0 - fresnel_dielectric(ci, eta)) * mf.D(ht) \
            * beta_function(1.0 + li, 1.0 + lo) / den
        ft = np.where(ok, ft, 0.0)
        return np.where(wo[:, 2] > 0.0, fr, ft)[:, None] * self.tint


def directional_moments_mc(bsdf: _SmithWalk, mu, n_walks: int, rng,
                           max_order: int = MAX_ORDER, order: int | None = None) -> MCMoments:
    """Monte Carlo twin of quadrature.directional_moments: for wi = (sqrt(1 - mu^2), 0, mu),
    E = integral f |cos_o| dwo, (Vn, Vt) = the n and t (= x, toward wi) components of
    integral f |cos_o| wo dwo (over the whole sphere for the dielectric: transmission makes Vn
    negative), as means of weight, weight wo.z, weight wo.x over n_walks sampled walks, with
    their standard errors. Each (len(mu), 3). order=k keeps only the walks of exactly k
    scattering events (order=1: the single-scattering moments, to compare with
    quadrature.directional_moments of the height-correlated Walter model)."""
    mu = np.atleast_1d(np.asarray(mu, dtype=float))
    out = [np.zeros((len(mu), 3)) for _ in range(6)]
    lost = np.zeros(len(mu), dtype=int)
    for i, m in enumerate(mu):
        s = math.sqrt(max(1.0 - m * m, 0.0))
        wi = np.broadcast_to(np.array([s, 0.0, m]), (n_walks, 3))
        smp = bsdf.sample(wi, rng, max_order)
        w = smp.weight if order is None else smp.weight * (smp.order == order)[:, None]
        for j, x in enumerate((w, w * smp.wo[:, 2:3], w * smp.wo[:, 0:1])):
            out[j][i], out[j + 3][i] = _mean_se(x)
        lost[i] = int(smp.lost.sum())
    return MCMoments(*out, lost)


# -- the catalog model ------------------------------------------------------------------------
class _PreparedStream:
    """An rng for `_SmithWalk`: the first draw (the first event's four numbers, rows of the
    walks that start) comes from prepared uniforms, every later one from a seeded Generator."""

    def __init__(self, first, seed: int):
        self.first = first
        self.rest = np.random.default_rng(seed)

    def random(self, shape):
        if self.first is not None and tuple(shape) == self.first.shape:
            out, self.first = self.first, None
            return out
        return self.rest.random(shape)


class HeitzBSDF:
    """The catalog model `heitz2016` (make_bsdf) in the interface the lab's tools use: a
    conductor or dielectric walk (`walk`) with `max_order` events, and
      eval(wi, wo), eval_cos(wi, wo): Monte Carlo estimates (mean of `eval_walks` walks from a
        fixed seed) of f and f |cos_o|: the walk has no closed form;
      sample(wi, u): one walk per row, u (N, >= 4) the first event's uniforms (height, visible
        normal, Fresnel choice), later events from a seed derived from u; returns (wo, weight,
        pdf) with pdf a one-walk estimate of the density of wo (that of the F = 1 walk for a
        conductor, the walk's own for a dielectric, whose weights are 1);
      directional_moments(mu): (E, Vn, Vt) from `moment_walks` sampled walks per mu (Monte
        Carlo; `moment_tables` gives them with their standard errors)."""

    diffuse_albedo = np.zeros(3)
    stochastic_eval = True  # eval is a Monte Carlo estimate, not a closed form

    def __init__(self, walk: _SmithWalk, max_order: int = MAX_ORDER, eval_walks: int = 16,
                 moment_walks: int = 200_000, seed: int = 0):
        self.walk = walk
        self.mf = walk.mf
        self.max_order = int(max_order)
        self.eval_walks = eval_walks
        self.moment_walks = moment_walks
        self.seed = seed
        self.has_transmission = walk.has_transmission
        self.is_delta = walk.mf.delta
        if walk.dielectric:
            self._density = walk
        else:
            self._density = HeitzConductor(walk.mf, "none")

    def __repr__(self):
        return f"HeitzBSDF({self.walk!r}, max_order={self.max_order})"

    def eval_cos(self, wi, wo):
        lead = np.broadcast_shapes(np.shape(wi), np.shape(wo))[:-1]
        wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
        mean, _ = self.walk.eval_mean(wi, wo, self.eval_walks, np.random.default_rng(self.seed),
                                      self.max_order)
        return mean.reshape(lead + (3,))

    def eval(self, wi, wo):
        cos_o = np.abs(np.asarray(wo, dtype=float)[..., 2:3])
        fc = self.eval_cos(wi, wo)
        return np.where(cos_o > 0.0, fc / np.where(cos_o > 0.0, cos_o, 1.0), 0.0)

    def sample(self, wi, u):
        lead = np.shape(wi)[:-1]  # any (..., 3), as the other models
        wi = _rows(wi)
        u = np.asarray(u, dtype=float).reshape(len(wi), -1)
        if u.shape[1] < 4:
            raise IndexError("the walk's first event takes 4 uniforms")
        first = np.clip(u[wi[:, 2] > 0.0, :4], 0.0, 1.0 - 2.0 ** -53)
        seed = int(np.frombuffer(np.ascontiguousarray(u).tobytes(), dtype=np.uint64).sum()
                   % (2 ** 63)) if u.size else 0
        s = self.walk.sample(wi, _PreparedStream(first, seed), self.max_order)
        live = s.weight.max(axis=1) > 0.0
        pdf = np.zeros(len(wi))
        if live.any():
            est = self._density.eval(wi[live], s.wo[live], np.random.default_rng(seed + 1),
                                     self.max_order)
            pdf[live] = est[:, 0] / np.maximum(np.abs(s.wo[live, 2]), _TINY)
        return s.wo.reshape(lead + (3,)), s.weight.reshape(lead + (3,)), pdf.reshape(lead)

    def directional_moments(self, mu):
        m = directional_moments_mc(self.walk, mu, self.moment_walks,
                                   np.random.default_rng(self.seed), self.max_order)
        return m.E, m.Vn, m.Vt


def moment_tables(bsdf: HeitzBSDF, mu, n_walks: int, rng):
    """Moment tables of the walk for the sphere-grid reference, with their Monte Carlo error:
    (table, se_table), two quadrature.MomentTable on the nodes `mu` (in (0, 1]; see
    `table_nodes`), the second holding the standard errors of E, Vn and Vt (moments_at on it
    interpolates the errors, which is what a reference pixel's error is up to the
    interpolation weights)."""
    mu = np.unique(np.asarray(mu, dtype=float))
    x = np.log(mu)
    m = directional_moments_mc(bsdf.walk, np.minimum(mu, 1.0 - 1e-8), n_walks, rng,
                               bsdf.max_order)
    empty = MomentTable(np.zeros(0), *(np.zeros((0, 3)),) * 3)
    return merge(empty, x, (m.E, m.Vn, m.Vt)), merge(empty, x, (m.E_se, m.Vn_se, m.Vt_se))


def table_nodes(n_mu: int = 24, uniform_from: float | None = None, spacing: float = 0.025):
    """Incidences for `moment_tables`: n_mu nodes uniform in log(mu) on [MU_MIN, 1] (as the
    quadrature tables), or, with `uniform_from`, those below it and nodes every `spacing` in mu
    from it to 1: glass seen from the denser side bends on the scale of the roughness around
    the critical angle (where quadrature.tabulate_moments refines by itself), and cubic
    interpolation through Monte Carlo nodes wants them evenly spaced (clustered nodes amplify
    their noise)."""
    mu = np.exp(np.linspace(np.log(MU_MIN), 0.0, max(int(n_mu), 4)))
    if uniform_from is None:
        return mu
    even = np.arange(1.0, uniform_from - 1e-9, -spacing)[::-1]
    return np.concatenate([mu[mu < even[0] - 0.5 * spacing], even])


# -- Light Sampling: the aimed residual (osl/heitz2016.osl) -----------------------------------
def eval_residual(walk: HeitzConductor, wi, wo, c, rng, max_order: int = MAX_ORDER):
    """One unbiased estimate per row of the residual r(wi, wo) |wo.n| = f |wo.n| - c F f_ggx
    |wo.n| (RGB) of the conductor walk, as the shader's eval_residual: the first order in closed
    form with F (1 - c) for F (F (1 - c) D G2 / (4 wi.n), G2 height-correlated: eval_single's
    form), plus one walk's next-event terms from the second event on. c: (3,) or (N, 3), the
    share of the first order the native part carries (split.native_factor: 1, the native part
    being Cycles' conductor_bsdf, F included)."""
    wi, wo = np.broadcast_arrays(_rows(wi), _rows(wo))
    F, val = walk.single_kernel(wi, wo)
    first = F * np.maximum(1.0 - np.asarray(c, dtype=float), 0.0) * val[:, None] * walk.tint
    higher = walk._walk(wi, rng, max_order, wo=wo, from_order=2)[1]
    return first + higher


def sample_aimed_residual(walk: HeitzConductor, records, P, wi, c, rng,
                          max_order: int = MAX_ORDER):
    """The shader's residual sample with the lamps (osl/heitz2016.osl, lamps.py twin): rows of
    wi at points P (normal z). The directions toward the lamps, L = {lamps_pdf > 0}, and the
    rest are two integrals: with probability lam a direction from lamps_pdf weighted
    eval_residual / (lam lamps_pdf) covers L, otherwise the walk (its first-order exit
    weighing F (1 - c), later orders their throughput) counted only outside L, over 1 - lam,
    covers the rest. Returns (wo, weight RGB); E[weight g(wo)] = integral r |cos| g for any
    records (a stale table moves noise only)."""
    wi = _rows(wi)
    n = len(wi)
    P = np.broadcast_to(np.asarray(P, dtype=float), (n, 3))
    Ng = np.broadcast_to([0.0, 0.0, 1.0], (n, 3))
    lam, _ = lamp_twin.guide_fraction(records, P, Ng) if records else (np.zeros(n), None)
    u = rng.random((n, 4))
    aimed = u[:, 0] < lam
    wo = np.zeros((n, 3))
    weight = np.zeros((n, 3))
    if aimed.any():
        a = np.nonzero(aimed)[0]
        d = lamp_twin.sample_lamps(records, P[a], Ng[a], u[a, 1], u[a, 2], u[a, 3])
        p = lamp_twin.lamps_pdf(records, P[a], Ng[a], d)
        ok = (d[:, 2] > 0.0) & (p > 0.0)
        r = eval_residual(walk, wi[a], d, c, rng, max_order)
        wo[a] = d
        weight[a] = np.where(ok[:, None], r / np.where(ok, lam[a] * p, 1.0)[:, None], 0.0)
    rest = np.nonzero(~aimed)[0]
    if len(rest):
        s = walk.sample(wi[rest], rng, max_order)
        w = np.where((s.order == 1)[:, None], s.weight * np.maximum(1.0 - np.asarray(c), 0.0),
                     s.weight)
        if records:
            inside = lamp_twin.lamps_pdf(records, P[rest], Ng[rest], s.wo) > 0.0
            w = np.where(inside[:, None], 0.0, w / (1.0 - lam[rest])[:, None])
        wo[rest] = s.wo
        weight[rest] = w
    return wo, weight


@builds("heitz2016")
def _heitz2016(params) -> HeitzBSDF:
    ax, _ = alphas(params["roughness"])
    mf = Microfacet(params["distribution"], ax, ax)
    if params["fresnel_type"] == "dielectric":
        # As the shader renders it: Cycles' refraction closure cannot return forward transmission.
        walk = HeitzDielectric(mf, params["ior"], tint=params["base_color"],
                               forward_transmission=False)
    else:
        walk = HeitzConductor(mf, params["fresnel_type"], n=params["n"], k=params["k"],
                              tint=params["base_color"])
    return HeitzBSDF(walk, max_order=int(math.floor(params["max_order"] + 0.5)))
