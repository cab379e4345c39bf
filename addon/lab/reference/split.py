"""The light-sampled estimator in numpy: a model split into Cycles' native GGX or Beckmann
closure and a non-negative stochastic residual (the twin of osl/split.h and of the split in the
Walter shaders; design and measurements: docs/light-sampling.md).

    f(wi, wo) = c(wi) F(wi.h) f_native(wi, wo) + r(wi, wo),    r(wi, wo) >= 0 for every wo.

f_native is height-correlated Smith GGX or Beckmann (the model's distribution) with F = 1 and
the model's own alphas, Cycles' `microfacet("ggx", N, U, ax, ay, 0, 0)`; with the model's own
Fresnel factor F it is Cycles' `conductor_bsdf(N, U, ax, ay, n, k, "ggx")` for a conductor and
`dielectric_bsdf(N, U, 1, 0, ax, ay, eta, "ggx")` (no transmission) for a dielectric or glass's
reflection ("beckmann" alike): the same closed forms (tests/test_reference_split.py holds
float32 transcriptions of Cycles' formulas to ours).
Cycles light-samples this native part (lamps, world, emissive meshes, with multiple importance
sampling). The residual r is the stochastic delta lobe of the model's own sampler, weighted by
(f - native) cos / pdf. It must never be negative, because Cycles drops negative closure
weights; so c(wi) is a lower bound of f / (F f_native) over every wo, per RGB channel:

    f / (F f_native) = tint G2(wi, wo) / G2_native(wi, wo)
    c(wi)            = tint G_lo(wi)

G_lo: height-correlated 1; separable inf_wo (1 + Li + Lo) / ((1 + Li)(1 + Lo)) = 1 / (1 + Li)
(Heitz 2014 eqs. 98, 99; approached as wo grazes). So a height-correlated GGX reflection has no
residual at all: it is Cycles' closure. Cycles' Beckmann closure evaluates Walter 2007's rational
approximation of Lambda (`lambda_native`), within BECKMANN_LAMBDA_GAP of the exact one in the
sense below, so for Beckmann G_lo is lowered by 1 - 2 BECKMANN_LAMBDA_GAP and even a
height-correlated Beckmann reflection keeps a residual (under 1% of its value); and as Cycles'
Beckmann sampling divides by that approximate G1(wi), the native part is used only where
Lambda(wi) is below BECKMANN_SAMPLING_TOLERANCE (away from grazing incidence). Glass and Heitz
2016 split GGX only.

The shader returns one of the two reflection parts per sample, never both: when Cycles samples
a singular closure it adds the other closures' values in that direction with the balance
heuristic and a singular pdf of 1e6, which biases a sharp native lobe beside a delta residual.
Walter reflection picks the residual with probability 1 - c (`residual_probability`): for
separable masking F (G2 - c G2_hc) = (1 - c) F G1(wo) G2_hc exactly, so the residual's weight
over 1 - c stays bounded, and the native part's is c / c = 1. Heitz 2016's walk picks with
q = a / (a + r) (`split_closures` in osl/cycles.h, `selection_probability` here).

Glass splits its reflection lobe the same way. Its stochastic part takes the residual
reflection alone with probability F (1 - c) / 2, else the transmission (weight (1 - F) G2 over
the probability) together with the native reflection (weight c over the probability): a
reflection and a refraction lie in opposite hemispheres, so neither has a value where the other
points. With height-correlated masking (c = 1) the reflection is all native.
"""
from __future__ import annotations

import math

import numpy as np

from .bsdf import MicrofacetBRDF, sample_reflection_factor
from .fresnel import fresnel_conductor, fresnel_dielectric
from .glass import MicrofacetGlass
from .microfacet import Microfacet, broadcast_pair, dot, normalize, reflect_about

ESTIMATORS = ("light_sampled", "stochastic")
# Below this alpha (roughness 0.032) the lobe is nearly a mirror: Cycles' near-specular GGX and
# our delta lobe would meet in a region nobody can light-sample; stay stochastic.
ALPHA_SPLIT_MIN = 1e-3


def native_fresnel(bsdf, cos_i):
    """F_n (..., 3): the Fresnel factor the native closure carries at wi.h = cos_i, the model's
    own: a conductor's (Cycles' conductor_bsdf), a dielectric's (dielectric_bsdf with no
    transmission; glass: its reflection lobe's, eta from the side of wi), 1 for none
    (microfacet("ggx"))."""
    cos_i = np.asarray(cos_i, dtype=float)
    if isinstance(bsdf, MicrofacetGlass):
        return fresnel_dielectric(cos_i, bsdf.eta)[..., None] * np.ones(3)
    return bsdf.F(cos_i)


# -- Blender 4.x only: a conductor's native part where conductor_bsdf is not exact ------------
# There Cycles approximates the conductor Fresnel (exact from 5.0: addon/compat.py), so the
# shader's native part for a conductor is microfacet("ggx") (no Fresnel) times c = F_lo G_lo,
# F_lo the least conductor Fresnel over the reachable wi.h (osl/split.h
# conductor_lower_bound), and the residual F G2 - c G2_hc.
# Golden-section steps for the Fresnel minimum: the bracket shrinks to 0.618^16 = 4.6e-4 of
# the searched interval, so the value found exceeds the true minimum by ~F'' 3e-8 (F'' the
# curvature over that interval). Each step is one Fresnel evaluation per channel and side, the
# split's main cost per shading point (24 steps made the split twice as costly as native GGX).
MIN_SEARCH_STEPS = 16
# Below this extinction a conductor with n < 1 has a cusp at its critical angle (see
# conductor_min); above it F is smooth there (tests/test_reference_split.py checks both).
CUSP_K = 1.0
# Relative margin under the minimum found: covers the search and float32 rounding in OSL.
FRESNEL_MARGIN = 1e-4
_GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


def reachable_cos_lo(wi):
    """Least wi.h over reflected directions wo (wo.z >= 0): wo on the horizon opposite wi,
    at angle pi/2 + theta_i from wi, so wi.h = cos(pi/4 + theta_i / 2)."""
    theta = np.arccos(np.clip(np.asarray(wi, dtype=float)[..., 2], -1.0, 1.0))
    return np.maximum(np.cos(0.25 * math.pi + 0.5 * theta), 0.0)


def search_x(t, origin, sign, lo, hi):
    """x = origin + sign t^2 clamped to [lo, hi]: the cosine wi.h at fresnel_min's search
    variable t."""
    return np.clip(origin + sign * t * t, lo, hi)


def fresnel_min(F, lo, hi=1.0, origin=None, steps: int = MIN_SEARCH_STEPS):
    """min of a unimodal F(x) over x in [lo, hi], by golden section in t = sqrt(|x - origin|)
    (the OSL twin runs the same steps, with F the conductor's): the smallest value visited, times
    (1 - FRESNEL_MARGIN). `origin` is the critical angle's cosine at one end of the interval
    (default lo), where F has a square-root cusp that t makes smooth. lo, hi, origin (..., 3)."""
    lo = np.asarray(lo, dtype=float)
    hi = np.broadcast_to(hi, lo.shape) * 1.0
    origin = lo if origin is None else np.broadcast_to(origin, lo.shape) * 1.0
    # x = origin + sign t^2, t from a to b: sign +1 when origin is the lower end, else -1.
    sign = np.where(np.abs(hi - origin) >= np.abs(lo - origin), 1.0, -1.0)

    def G(t):
        return F(search_x(t, origin, sign, lo, hi))

    a = np.sqrt(np.abs(np.where(sign > 0, lo, hi) - origin))
    b = np.sqrt(np.abs(np.where(sign > 0, hi, lo) - origin))
    x1, x2 = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
    f1, f2 = G(x1), G(x2)
    best = np.minimum(G(a), G(b))
    for _ in range(steps):
        best = np.minimum(best, np.minimum(f1, f2))
        left = f1 < f2  # the minimum lies in [a, x2], else in [x1, b]
        a, b = np.where(left, a, x1), np.where(left, x2, b)
        xn = np.where(left, b - _GOLDEN * (b - a), a + _GOLDEN * (b - a))
        fn = G(xn)
        x1, f1, x2, f2 = (np.where(left, xn, x2), np.where(left, fn, f2),
                          np.where(left, x1, xn), np.where(left, f1, fn))
    best = np.minimum(best, np.minimum(f1, f2))
    return best * (1.0 - FRESNEL_MARGIN)


def critical_cos(eta):
    """cos of the critical angle of total internal reflection (0 for eta >= 1): left of it F is
    a plateau at 1, which only rounding would tilt, so the search starts there."""
    eta = np.asarray(eta, dtype=float)
    return np.sqrt(np.maximum(1.0 - eta * eta, 0.0))


def conductor_min(n, k, lo, hi=1.0):
    """Least conductor Fresnel over [lo, hi] (..., 3). With n < 1 and little absorption
    (k < CUSP_K) F has a near-plateau left of the critical angle and a cusp and dip right of
    it, as narrow as 1e-6 in wi.h: the two sides are searched separately (k = 0: the plateau is
    1). Otherwise F is smooth and one search covers [lo, hi]."""
    n = np.asarray(n, dtype=float)
    k = np.asarray(k, dtype=float)
    xc = np.broadcast_to(np.where(k < CUSP_K, critical_cos(n), 0.0), np.shape(lo))
    split_at = np.minimum(np.maximum(lo, xc), hi)

    def F(x):
        return fresnel_conductor(x, n, k)

    right = fresnel_min(F, split_at, hi, xc)
    left = np.where((k > 0.0) & (xc > lo), fresnel_min(F, lo, split_at, xc), 1.0)
    return np.minimum(left, right)


def conductor_lower_bound(bsdf, wi):
    """F_lo(wi) (..., 3): the least conductor Fresnel over the wi.h a reflection from wi can
    reach (the Blender 4.x native factor's Fresnel part)."""
    wi = np.asarray(wi, dtype=float)
    return conductor_min(bsdf.n, bsdf.k, reachable_cos_lo(wi)[..., None] * np.ones(3))


# The largest (Lambda - lambda_native) / (1 + Lambda) over every direction for Beckmann, where
# lambda_native is Cycles' rational approximation: 0.003117 at a = 1.34 (a dense scan of a in
# tests/test_reference_split.py), rounded up. Then 1 + L_i' + L_o' >= (1 - 2 gap)(1 + L_i + L_o),
# so G2_native <= G2_hc / (1 - 2 gap), and c = (1 - 2 gap) G_lo keeps c G2_native <= G_lo G2_hc:
# the residual stays >= 0 and keeps the GGX form's bounds (controls.residual_masking_lo).
BECKMANN_LAMBDA_GAP = 0.0032
# Cycles samples Beckmann's visible normals exactly but divides by its own G1(wi), so its
# BSDF-sampled estimates carry (1 + lambda_native(wi)) / (1 + Lambda(wi)): -0.31% to +0.30%,
# the sign changing with a. A Beckmann native part is used only where Lambda(wi) <= this: then
# lambda_native(wi) = 0 (a > 1.6) and that factor is within 2.5e-4 of 1, the tolerance of the
# float32 Fresnel transcriptions (a >= 2: theta_i <= 63 degrees at alpha 0.25). Elsewhere the
# residual carries the whole lobe, as without a split.
BECKMANN_SAMPLING_TOLERANCE = 2.5e-4


def lambda_native(mf: Microfacet, w):
    """Lambda(w) (...,) of Cycles' native closure: GGX exact (Microfacet.lambda_); Beckmann the
    rational approximation of Walter 2007 eq. 27, G1 = (3.535 a + 2.181 a^2) / (1 + 2.276 a +
    2.577 a^2) for a < 1.6, else 1 (what Cycles' Beckmann closure evaluates)."""
    w = np.asarray(w, dtype=float)
    if mf.ggx or mf.delta:
        return Microfacet.lambda_(mf, w)
    z = np.maximum(np.abs(w[..., 2]), 1e-300)
    p2 = ((mf.alpha_x * w[..., 0]) ** 2 + (mf.alpha_y * w[..., 1]) ** 2) / (z * z)
    a = 1.0 / np.sqrt(np.maximum(p2, 0.39))
    return np.where(p2 < 0.39, 0.0, ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a))


def G2_native(mf: Microfacet, wi, wo, m):
    """G2 (...,) of Cycles' native closure: height-correlated with lambda_native (Heitz 2014
    eq. 99)."""
    vis = (dot(wi, m) * wi[..., 2] > 0.0) & (dot(wo, m) * wo[..., 2] > 0.0)
    return np.where(vis, 1.0 / (1.0 + lambda_native(mf, wi) + lambda_native(mf, wo)), 0.0)


def masking_lower_bound(bsdf, wi):
    """G_lo(wi) (...,): inf over wo of G2 / G2_native (1 for height-correlated GGX; Beckmann
    times 1 - 2 BECKMANN_LAMBDA_GAP, and 0 where Lambda(wi) > BECKMANN_SAMPLING_TOLERANCE)."""
    wi = np.asarray(wi, dtype=float)
    lam_i = bsdf.mf.lambda_(wi)
    g = 1.0 / (1.0 + lam_i) if bsdf.masking == "separable" else np.ones(wi.shape[:-1])
    if bsdf.mf.ggx:
        return g
    return np.where(lam_i <= BECKMANN_SAMPLING_TOLERANCE, g * (1.0 - 2.0 * BECKMANN_LAMBDA_GAP),
                    0.0)


def supports_split(bsdf) -> bool:
    """Whether the light-sampled estimator splits this BSDF (else it renders stochastically):
    rough enough, GGX or (a reflection) Beckmann, and not the index-matched glass nor glass seen
    from its denser side (eta < 1: osl/walter_glass.osl says why)."""
    if not isinstance(bsdf, (MicrofacetBRDF, MicrofacetGlass)):
        return False
    if isinstance(bsdf, MicrofacetBRDF) and bsdf.masking == "vcavity":
        return False
    if isinstance(bsdf, MicrofacetGlass) and (bsdf.is_passthrough or bsdf.eta <= 1.0
                                              or not bsdf.mf.ggx):
        return False
    mf = bsdf.mf
    return not mf.delta and min(mf.alpha_x, mf.alpha_y) >= ALPHA_SPLIT_MIN


def native_factor(bsdf, wi):
    """c(wi) / tint (..., 3) = G_lo: the native closure's weight without the tint; 0 below the
    horizon and for BSDFs the split does not support."""
    wi = np.asarray(wi, dtype=float)
    if not supports_split(bsdf):
        return np.zeros(wi.shape[:-1] + (3,))
    c = masking_lower_bound(bsdf, wi)[..., None] * np.ones(3)
    return np.where((wi[..., 2] > 0.0)[..., None], c, 0.0)


def native_weight(bsdf, wi):
    """c(wi) (..., 3): the weight of the native closure, tint included."""
    return bsdf.tint * native_factor(bsdf, wi)


class NativeMicrofacet(Microfacet):
    """The model's distribution and alphas with Cycles' Lambda (lambda_native)."""

    def lambda_(self, w):
        return lambda_native(self, w)


def native_closure(bsdf) -> MicrofacetBRDF:
    """Cycles' native part: height-correlated GGX or Beckmann with Cycles' Lambda
    (NativeMicrofacet), F = 1, the model's alphas, unit tint. Its sample weight G2 / G1 uses
    Cycles' Lambda too, over the exact visible-normal density: for Beckmann within 0.7% of the
    closure's own albedo (albedo_share, a report figure only)."""
    mf = NativeMicrofacet(bsdf.mf.distribution, bsdf.mf.alpha_x, bsdf.mf.alpha_y)
    return MicrofacetBRDF(mf, "height_correlated", "vndf", "none")


def eval_native(bsdf, wi, wo):
    """c(wi) F_n(wi.h) f_native(wi, wo) (..., 3): what the native closure carries."""
    wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
    F_n = native_fresnel(bsdf, dot(wi, normalize(wi + wo)))
    return native_weight(bsdf, wi) * F_n * native_closure(bsdf).eval(wi, wo)


def eval_residual(bsdf, wi, wo):
    """r = f - c F_n f_native (..., 3): what the stochastic lobe carries (>= 0 by construction)."""
    return bsdf.eval(wi, wo) - eval_native(bsdf, wi, wo)


def residual_weight_reflection(bsdf, wi, wo, m, inv_pdf_factor):
    """The residual's reflection sample weight (..., 3), as the OSL computes it:
    tint inv_pdf_factor F (G2 - c' G2_native), c' = G_lo (no tint; F_n = F), clamped at 0
    against rounding. inv_pdf_factor is the sampler's f cos / (F G2 pdf) (bsdf.py `sample`)."""
    mf = bsdf.mf
    g2 = mf.G2(wi, wo, m, bsdf.masking)[..., None]
    g2_n = G2_native(mf, wi, wo, m)[..., None]
    F = bsdf.F(dot(wi, m))
    w = np.asarray(inv_pdf_factor)[..., None] * np.maximum(g2 - native_factor(bsdf, wi) * g2_n,
                                                           0.0)
    return bsdf.tint * F * w


def sample_residual(bsdf, wi, u):
    """One sample of the residual lobe of a reflection BSDF: (wo, weight), weight =
    r cos / pdf with the model's own sampler (its visible-normal or D cos density)."""
    wi, u = broadcast_pair(wi, u)
    m, inv = sample_reflection_factor(bsdf, wi, u)
    wo = reflect_about(wi, m)
    c = dot(wi, m)
    valid = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0) & (c > 0.0)
    w = residual_weight_reflection(bsdf, wi, wo, m, np.where(valid, inv, 0.0))
    return wo, np.where(valid[..., None], w, 0.0)


def albedo_share(bsdf, wi, n: int = 1 << 16, seed: int = 0):
    """Share of the directional albedo the native closure carries at each wi (..., 3) and
    its standard error: c(wi) E_n(wi) / E(wi), both albedos by Monte Carlo with n samples
    (E_n with the native visible normals, weight F_n G2_native / G1; E with the model's sampler)."""
    wi = normalize(np.asarray(wi, dtype=float).reshape(-1, 3))
    rng = np.random.default_rng(seed)
    u = rng.random((n, 1, 3))
    _, w_model, _ = bsdf.sample(wi[None], u)
    wo_n, w_n, _ = native_closure(bsdf).sample(wi[None], u)
    with np.errstate(invalid="ignore"):  # a failed sample's wo may be 0; its weight is 0
        F_n = native_fresnel(bsdf, dot(wi[None], normalize(wi[None] + wo_n)))
    w_n = np.where(w_n > 0.0, w_n * np.nan_to_num(F_n), 0.0)
    c = native_weight(bsdf, wi)
    E, E_n = w_model.mean(axis=0), w_n.mean(axis=0)
    share = np.where(E > 0, c * E_n / np.where(E > 0, E, 1.0), 0.0)
    # Delta method on the ratio of two means of the same samples.
    cov = ((w_n - E_n) * (w_model - E)).mean(axis=0)
    var_r = (w_n.var(axis=0) / np.maximum(E_n, 1e-30) ** 2 + w_model.var(axis=0)
             / np.maximum(E, 1e-30) ** 2 - 2 * cov / np.maximum(E * E_n, 1e-30))
    err = np.abs(share) * np.sqrt(np.maximum(var_r, 0.0) / n)
    return share, err


def residual_probability(bsdf, wi):
    """The probability (...,) that Walter reflection's shader returns the residual rather than
    the native part: 1 - c (c = G_lo, so 0 for height-correlated masking)."""
    return 1.0 - native_factor(bsdf, wi)[..., 0]


def selection_probability(w_native, w_residual):
    """q, the probability of returning the native part rather than the residual (the OSL's
    split_closures): a / (a + r), a and r the channel sums of their weights; 1 or 0 when one
    of them is zero. Both choices then carry the total weight a + r."""
    a = np.maximum(np.sum(w_native, axis=-1), 0.0)
    r = np.maximum(np.sum(w_residual, axis=-1), 0.0)
    q = a / np.where(a + r > 0, a + r, 1.0)
    return np.where(r <= 0.0, 1.0, np.where(a <= 0.0, 0.0, q))
