"""Walter et al. 2007 rough dielectric BSDF (reflection plus transmission): the numpy twin of
osl/walter_glass.osl (catalog model `walter_glass`).

    bsdf = make_bsdf("walter_glass", {"roughness": 0.3, "ior": 1.5})
    f = bsdf.eval(wi, wo)              # RGB, over the whole sphere of wo (not times cos)
    wo, weight, pdf = bsdf.sample(wi, u)

Conventions (docs/models.md). Local frame n = (0,0,1); wi.z > 0 (the side wi is on is
+z; f is 0 for wi.z <= 0); wo.z > 0 is reflection, wo.z < 0 transmission. `ior` IS the relative
index eta = n_o / n_i seen from wi's side (n_i = 1 for wi, n_o = eta below the interface); eta < 1
means wi is in the denser medium (the OSL shader passes 1/ior on back faces). Shapes as
addon/lab/reference/bsdf.py: directions (..., 3), u (..., 3), RGB (..., 3), pdf (...).

Model (Walter 2007 eqs. 20, 21; docs/models.md sec. 2):
    f_r = tint F(wi.h_r) G2(wi, wo, h_r) D(h_r) / (4 |wi.n| |wo.n|),   h_r = normalize(wi + wo)
    f_t = tint |wi.h_t| |wo.h_t| / (|wi.n| |wo.n|) eta^2 (1 - F(wi.h_t)) G2 D(h_t)
          / (wi.h_t + eta wo.h_t)^2,                                   h_t = +-normalize(wi + eta wo)
with h_t oriented to h_t.z > 0 and f_t = 0 unless wi.h_t > 0 > wo.h_t (a real refraction;
Walter's eq. 21 with n_i = 1, n_o = eta). F is the exact dielectric Fresnel with F = 1 under
total internal reflection (TIR), so f_t vanishes there.

Transport convention: Cycles' (and the OSL shader's). f_t is Walter's eq. 21 as written: no
1/eta^2 radiance factor (pbrt-v4's radiance-mode f_t is this divided by eta^2). The sample weight
is then tint G2 times the sampler's factor for BOTH lobes (Walter 2007 eq. 41; Heitz & d'Eon 2014
eq. 8), the lobe chosen with probability F(wi.m). Consequence for reciprocity (Walter 2007,
discussion of eq. 21): f_t is NOT symmetric; what holds is
    f_t(wi -> wo) / n_o^2 = f_t(wo -> wi) / n_i^2,
i.e. with relative indices  f_t(wi, wo; eta) = eta^2 f_t(flip(wo), flip(wi); 1/eta), where
flip(x, y, z) = (x, y, -z) puts wo on the +z side of the same interface seen from below
(tests/test_reference_glass.py). f_r is symmetric.

G2 for both lobes (Smith; Lambda uses |w.z|, the same on both sides of the interface):
separable G1(wi, m) G1(wo, m) (Walter 2007 eq. 23), or height-correlated
1 / (1 + Lambda(wi) + Lambda(wo)) with the visibility chi+(wi.m / wi.n) chi+(wo.m / wo.n): Heitz
2014 eq. 99 used for transmission too, as Cycles and pbrt-v4 do. The exact height-correlated
form for transmission (Heitz 2014 eq. 100, a Beta function B(1 + Lambda(wi), 1 + Lambda(wo)))
is not used, so that native comparisons are like for like.

Sampling (as the OSL, dimension by dimension): m from u[..., 0:2] by `dcos` (m ~ D(m)(m.n),
Walter 2007 sec. 5.3) or `vndf` (visible normals, Heitz & d'Eon 2014); reflection if
u[..., 2] < F(wi.m, eta) else refraction (TIR gives F = 1: always reflection);
weight = tint G2 * factor, factor = |wi.m| / (wi.n m.n) (dcos) or 1 / G1(wi, m) (vndf); weight 0
(and pdf 0) when wi.m <= 0 or wo lands on the wrong side (reflection below, refraction above
the surface). pdf is over solid angle of wo and includes the lobe choice:
    reflection  pdf_m(m) F / (4 |wi.m|)                                   (Walter 2007 eq. 14)
    refraction  pdf_m(m) (1 - F) eta^2 |wo.m| / (wi.m + eta wo.m)^2        (Walter 2007 eq. 17)

Deltas. Roughness 0 (alpha < 1e-7) is perfect glass: `eval` is 0 (a delta has no finite value);
`sample` returns the mirror direction with probability F or the refracted one with probability
1 - F, weight tint, pdf = the discrete probability of the chosen lobe (F or 1 - F);
`delta_reflectance` / `delta_transmission` give the two lobes for the quadrature.
Index matched, |eta - 1| < 1e-5 (checked first, at any roughness): the interface vanishes,
a pass-through: wo = -wi with weight tint, pdf 1, and eval 0 (`is_passthrough`).
"""
from __future__ import annotations

import numpy as np

from ...catalog import alphas
from .bsdf import builds
from .fresnel import fresnel_dielectric
from .microfacet import Microfacet, broadcast_pair, dot, normalize, reflect_about, refract_about

_TINY = 1e-30
PASS_THROUGH_EPS = 1e-5  # |eta - 1| below this is index matched (as the OSL shader)


def transmission_jacobian(wi, wo, m, eta):
    """|dwo / dm| of the refraction wo = refract_about(wi, m) (Walter 2007 eq. 17 inverted):
    (wi.m + eta wo.m)^2 / (eta^2 |wo.m|)."""
    im, om = dot(wi, m), dot(wo, m)
    return (im + eta * om) ** 2 / (eta * eta * np.maximum(np.abs(om), _TINY))


class MicrofacetGlass:
    """Walter 2007 rough dielectric BSDF: f = f_r (wo.z > 0) + f_t (wo.z < 0)."""

    has_transmission = True

    def __init__(self, mf: Microfacet, masking: str = "height_correlated",
                 sampler: str = "vndf", ior: float = 1.5, tint=(1.0, 1.0, 1.0)):
        if sampler not in ("dcos", "vndf"):
            raise ValueError(f"glass sampler must be dcos or vndf, not {sampler!r}")
        if masking not in ("height_correlated", "separable"):
            raise ValueError(f"glass masking must be height_correlated or separable, "
                             f"not {masking!r}")
        self.mf = mf
        self.masking = masking
        self.sampler = sampler
        self.eta = float(ior)
        self.ior = self.eta
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.zeros(3)  # for the quadrature's Lambertian term
        self.is_passthrough = abs(self.eta - 1.0) < PASS_THROUGH_EPS
        # No finite BSDF part: perfect glass, or the pass-through.
        self.is_delta = mf.delta or self.is_passthrough

    def __repr__(self):
        return (f"MicrofacetGlass({self.mf!r}, masking={self.masking!r}, "
                f"sampler={self.sampler!r}, eta={self.eta:g})")

    def F(self, cos_i):
        """Scalar dielectric Fresnel F(cos_i, eta) (TIR gives 1)."""
        return fresnel_dielectric(cos_i, self.eta)

    # -- evaluation ---------------------------------------------------------------------------
    def half_vector_transmission(self, wi, wo):
        """Generalised half vector h_t = +-normalize(wi + eta wo), oriented to h_t.z >= 0
        (Walter 2007 eq. 16)."""
        h = np.asarray(wi, dtype=float) + self.eta * np.asarray(wo, dtype=float)
        h = np.where((h[..., 2] < 0.0)[..., None], -h, h)
        return normalize(h)

    def eval_reflection(self, wi, wo):
        """f_r (..., 3); 0 unless wi.z > 0 and wo.z > 0, and 0 for the deltas."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        if self.is_delta:
            return np.zeros(wi.shape)
        valid = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        h = normalize(wi + wo)
        D = self.mf.D(h)
        G = self.mf.G2(wi, wo, h, self.masking)
        denom = 4.0 * np.where(valid, wi[..., 2] * wo[..., 2], 1.0)
        scalar = np.where(valid, self.F(dot(wi, h)) * D * G / denom, 0.0)
        return self.tint * scalar[..., None]

    # The quadrature's reflection path integrates `eval_specular` (as for MicrofacetBRDF).
    eval_specular = eval_reflection

    def eval_transmission(self, wi, wo):
        """f_t (..., 3); 0 unless wi.z > 0 > wo.z and wi.h_t > 0 > wo.h_t; 0 for the deltas."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        if self.is_delta:
            return np.zeros(wi.shape)
        eta = self.eta
        h = self.half_vector_transmission(wi, wo)
        im, om = dot(wi, h), dot(wo, h)
        valid = (wi[..., 2] > 0.0) & (wo[..., 2] < 0.0) & (im > 0.0) & (om < 0.0)
        D = self.mf.D(h)
        G = self.mf.G2(wi, wo, h, self.masking)
        denom = np.where(valid, wi[..., 2] * np.abs(wo[..., 2]) * (im + eta * om) ** 2, 1.0)
        scalar = np.abs(im * om) * eta * eta * (1.0 - self.F(im)) * G * D / denom
        return self.tint * np.where(valid, scalar, 0.0)[..., None]

    def eval(self, wi, wo):
        """f(wi, wo) (..., 3) over the whole sphere of wo: f_r above, f_t below the surface."""
        return self.eval_reflection(wi, wo) + self.eval_transmission(wi, wo)

    def eval_cos(self, wi, wo):
        """f(wi, wo) |wo.n|."""
        wo = np.asarray(wo, dtype=float)
        return self.eval(wi, wo) * np.abs(wo[..., 2])[..., None]

    # -- deltas -------------------------------------------------------------------------------
    def delta_reflectance(self, wi):
        """Reflectance F(wi.n) tint (..., 3) of perfect glass's mirror lobe; zeros otherwise
        (rough glass and the pass-through)."""
        wi = np.asarray(wi, dtype=float)
        if not self.mf.delta or self.is_passthrough:
            return np.zeros(wi.shape)
        R = np.where(wi[..., 2] > 0.0, self.F(wi[..., 2]), 0.0)
        return self.tint * R[..., None]

    def delta_transmission(self, wi):
        """(wo, T): direction and transmittance (..., 3) of the delta transmission: perfect
        glass, wo = refract_about(wi, n), T = (1 - F(wi.n)) tint (0 under TIR); the pass-through,
        wo = -wi, T = tint; zeros for rough glass."""
        wi = np.asarray(wi, dtype=float)
        up = wi[..., 2] > 0.0
        if self.is_passthrough:
            return -wi, np.where(up[..., None], self.tint, 0.0)
        if not self.mf.delta:
            return -wi, np.zeros(wi.shape)
        n = np.array([0.0, 0.0, 1.0])
        wo, ok = refract_about(wi, n, self.eta)
        T = np.where(up & ok, 1.0 - self.F(wi[..., 2]), 0.0)
        return wo, self.tint * T[..., None]

    # -- sampling -----------------------------------------------------------------------------
    def pdf_normal(self, wi, m):
        """Density of the sampler's microfacet normal over solid angle of m."""
        if self.sampler == "dcos":
            return self.mf.pdf_dcos(m)
        return self.mf.pdf_vndf(wi, m)

    def pdf(self, wi, wo):
        """Density over solid angle of the wo that `sample` returns with a non-zero weight,
        lobe choice included (see the module doc); 0 for the deltas. Over the whole sphere it
        integrates to 1 minus the probability of a zero-weight sample."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        if self.is_delta:
            return np.zeros(wi.shape[:-1])
        eta = self.eta
        up = wi[..., 2] > 0.0
        # Reflection.
        hr = normalize(wi + wo)
        cr = dot(wi, hr)
        pr = self.pdf_normal(wi, hr) * self.F(cr) / (4.0 * np.maximum(cr, _TINY))
        pr = np.where(up & (wo[..., 2] > 0.0) & (cr > 0.0), pr, 0.0)
        # Refraction.
        ht = self.half_vector_transmission(wi, wo)
        im, om = dot(wi, ht), dot(wo, ht)
        valid = up & (wo[..., 2] < 0.0) & (im > 0.0) & (om < 0.0)
        jac = eta * eta * np.abs(om) / np.where(valid, (im + eta * om) ** 2, 1.0)
        pt = np.where(valid, self.pdf_normal(wi, ht) * (1.0 - self.F(im)) * jac, 0.0)
        return np.where(wo[..., 2] > 0.0, pr, pt)

    def sample(self, wi, u):
        """One sample as osl/walter_glass.osl: returns (wo, weight, pdf); weight =
        eval_cos / pdf = tint G2 factor (RGB). Zero-weight samples have pdf 0."""
        wi, u = broadcast_pair(wi, u)
        shape = wi.shape
        wz = wi[..., 2]
        up = wz > 0.0
        eta = self.eta
        if self.is_passthrough:
            return -wi, np.where(up[..., None], self.tint, 0.0), np.where(up, 1.0, 0.0)
        mf = self.mf
        delta = mf.delta
        if delta:
            m = np.zeros(shape)
            m[..., 2] = 1.0
            factor = np.ones(shape[:-1])
            pdf_m = np.ones(shape[:-1])
        elif self.sampler == "dcos":
            m = mf.sample_dcos(u[..., 0], u[..., 1])
            factor = np.abs(dot(wi, m)) / (np.where(up, wz, 1.0) * np.maximum(m[..., 2], _TINY))
            pdf_m = mf.pdf_dcos(m)
        else:
            m = mf.sample_vndf(wi, u[..., 0], u[..., 1])
            g1 = mf.G1(wi, m)
            factor = np.where(g1 > 0.0, 1.0 / np.where(g1 > 0.0, g1, 1.0), 0.0)
            pdf_m = mf.pdf_vndf(wi, m)
        c = dot(wi, m)
        F = self.F(c)
        is_refl = u[..., 2] < F
        wo_r = reflect_about(wi, m)
        wo_t, ok_t = refract_about(wi, m, eta)
        wo = np.where(is_refl[..., None], wo_r, wo_t)
        valid = up & (c > 0.0) & (factor > 0.0) & np.where(
            is_refl, wo_r[..., 2] > 0.0, ok_t & (wo_t[..., 2] < 0.0))
        if delta:
            G2 = np.ones(shape[:-1])
            pdf = np.where(is_refl, F, 1.0 - F)
        else:
            G2 = mf.G2(wi, wo, m, self.masking)
            cabs = np.maximum(np.abs(c), _TINY)
            pdf_r = pdf_m * F / (4.0 * cabs)
            pdf_t = pdf_m * (1.0 - F) / np.maximum(transmission_jacobian(wi, wo, m, eta), _TINY)
            pdf = np.where(is_refl, pdf_r, pdf_t)
        w = np.where(valid, G2 * factor, 0.0)
        return wo, self.tint * w[..., None], np.where(valid, pdf, 0.0)


@builds("walter_glass")
def _walter_glass(params) -> MicrofacetGlass:
    # Walter et al. 2007 eqs. 20-21, reflection plus transmission.
    ax, ay = alphas(params["roughness"])
    return MicrofacetGlass(
        Microfacet(params["distribution"], ax, ay), masking=params["masking"],
        sampler=params["sampler"], ior=params["ior"], tint=params["base_color"])
