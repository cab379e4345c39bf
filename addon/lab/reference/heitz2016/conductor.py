"""The Heitz, Hanika, d'Eon & Dachsbacher 2016 conductor: the walk of heitz2016.walk with a
mirror reflection off a visible microfacet at every event, weighted by F per RGB channel, and
its first order in closed form. The paper's own equation numbers are not cited (see the
package doc).

* First order in closed form (`eval_single`, the authors' code calls it evalSingleScattering):
  averaging the first event over its height (C1(h1) has density (1 + Lambda_i) c^Lambda_i) gives
  reflection: F D G2 / (4 wi.z), G2 = 1 / (1 + Lambda_i + Lambda_o): single-scattering Walter
  with the HEIGHT-CORRELATED Smith G2 (Heitz 2014 eq. 99), i.e. make_bsdf("walter_reflection",
  {masking: "height_correlated"}).eval_cos exactly (the dielectric's transmission:
  heitz2016.dielectric).
"""
from __future__ import annotations

import numpy as np

from ..fresnel import fresnel_conductor, fresnel_dielectric
from ..microfacet import Microfacet, dot, normalize, reflect_about
from .medium import TINY, G1_height, phase_reflection, sample_visible
from .walk import SmithWalk, rows


class HeitzConductor(SmithWalk):
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
        return reflect_about(wi_ev, m), thr * self.F(c), outside

    def _next_event(self, wi_ev, wo, h, outside):
        """F x phase function x G1(wo, h): the next-event term toward wo (RGB)."""
        hv = normalize(wi_ev + wo)
        p = phase_reflection(self.mf, wi_ev, wo) * G1_height(self.mf, wo, h)
        return self.F(dot(wi_ev, hv)) * p[..., None]

    def _reverse_estimate(self, wi, wo, rng, max_order, order):
        """Reciprocity f(wi, wo) = f(wo, wi): est(wo -> wi) |wo.z| / |wi.z|."""
        rev = self.run(wo, rng, max_order, wo=wi, order=order)[1]
        ratio = np.where(wo[:, 2] > 0.0, wo[:, 2] / np.maximum(wi[:, 2], TINY), 0.0)
        return rev * ratio[:, None]

    def single_kernel(self, wi, wo):
        """(F(wi.h) RGB, D G2 / (4 wi.z) with the height-correlated G2, 0 where wi or wo is
        below the horizon): the first order's two factors, for rows of wi, wo."""
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
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
