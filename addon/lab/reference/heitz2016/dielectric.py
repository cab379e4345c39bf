"""The Heitz, Hanika, d'Eon & Dachsbacher 2016 dielectric: the walk of heitz2016.walk on both
sides of a rough interface, reflecting with probability F and refracting otherwise, and its
first order in closed form. The paper's own equation numbers are not cited (see the package
doc).

* Dielectric random walk: the walk continues on either side of the interface. Below it the
  medium sees the flipped microsurface (heights -h, normals -m, directions -w) and the relative
  index 1 / eta; with symmetric (uniform) heights the flipped surface has the same C1, so every
  step below is the step above applied to the negated quantities.
* First order in closed form (`eval_single`, the authors' code calls it evalSingleScattering):
  reflection as the conductor's (heitz2016.conductor: height-correlated Walter, Heitz 2014
  eq. 99); averaging the first event over its height (C1(h1) has density (1 + Lambda_i)
  c^Lambda_i) gives transmission: the Walter BTDF (Walter 2007 eq. 21) times |wo.z| with the
  height-correlated transmission G2: the escape of wo from below is (1 - C1(h1))^Lambda_o and
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
"""
from __future__ import annotations

import numpy as np

from ..fresnel import fresnel_dielectric
from ..microfacet import Microfacet, dot, normalize, reflect_about
from .medium import G1_height, beta_function, phase_dielectric, sample_height, sample_visible
from .walk import MAX_ORDER, SmithWalk, WalkSample, flip, rows


def _refract(wi, m, eta):
    """Walter 2007 eq. 40 with a per-row eta (microfacet.refract_about takes a scalar): wi.m > 0,
    eta = n_t / n_i; returns (wo, ok), ok False under total internal reflection."""
    c = dot(wi, m)
    cos_t2 = 1.0 - (1.0 - c * c) / (eta * eta)
    ok = cos_t2 > 0.0
    ct = np.sqrt(np.maximum(cos_t2, 0.0))
    wo = (c / eta - ct)[..., None] * m - wi / eta[..., None]
    return normalize(wo), ok


class HeitzDielectric(SmithWalk):
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
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
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
        wr = np.where(refl[:, None], reflect_about(wi_ev, m), wt)
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
            r = self.run(wo[refl], rng, max_order, wo=wi[refl], order=order)[1]
            out[refl] = r * (wo[refl, 2] / wi[refl, 2])[:, None]
        t = ~refl
        if t.any():
            other = HeitzDielectric(self.mf, 1.0 / self.eta, self.tint)  # full walk: the pair is masked after
            r = other.run(flip(wo[t]), rng, max_order, wo=flip(wi[t]), order=order)[1]
            out[t] = self.eta ** 2 * r * (np.abs(wo[t, 2]) / wi[t, 2])[:, None]
        return out

    def eval_single(self, wi, wo):
        """Closed-form first order f_1 |wo.n| (RGB (N, 3)), the mean of eval(..., order=1):
        reflection F(wi.h) D G2 / (4 wi.z), G2 = 1 / (1 + Lambda_i + Lambda_o) (height-
        correlated, Heitz 2014 eq. 99); transmission (Walter 2007 eq. 21 times |wo.z|)
        |wi.h| |wo.h| eta^2 (1 - F(wi.h)) D(h) G2_t / (wi.z (wi.h + eta wo.h)^2),
        h = -+normalize(wi + eta wo) with h.z > 0, with the height-correlated transmission
        G2_t = B(1 + Lambda_i, 1 + Lambda_o) (derivation in the module doc)."""
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
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
