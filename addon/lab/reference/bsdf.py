"""The models of the catalog as numpy BRDFs: thin wrappers around `Microfacet` and Fresnel.

    bsdf = make_bsdf("walter_reflection", {"roughness": 0.3, "distribution": "beckmann"})
    f = bsdf.eval(wi, wo)              # RGB BSDF value (..., 3), not multiplied by cos
    wo, weight, pdf = bsdf.sample(wi, u)

Shapes: directions (..., 3) unit vectors in the local frame (n = z, tangent = x); u (..., 3)
uniforms in [0, 1); RGB quantities (..., 3); pdf (...). f is 0 where wi.z <= 0 or wo.z <= 0.

Roughness 0 (alpha below 1e-7) makes the specular lobe a perfect mirror: `eval` and
`eval_specular` return 0 for that delta part (a delta has no finite value), `sample` returns the
mirror direction with weight F * tint and pdf 1 (the discrete probability of the delta, as
pbrt-v4), and `delta_reflectance(wi)` gives its reflectance for the quadrature.

The twin of osl/bsdf.h: sample_reflection_factor and reflection_pdf (the shaders' one
reflection sample per sampler and its density); the OSL's sample_reflection is `sample` here,
with the Fresnel factor and the tint.
"""
from __future__ import annotations

import numpy as np

from ...catalog import MODELS, alphas
from .fresnel import fresnel_color
from .microfacet import Microfacet, broadcast_pair, dot, normalize, reflect_about

_TINY = 1e-30


class MicrofacetBRDF:
    """Single-scattering microfacet reflection (Walter 2007 eq. 20, Cook & Torrance 1982):
    f = tint F(wi.h) D(h) G2(wi, wo, h) / (4 wi.n wo.n), h = normalize(wi + wo),
    plus an optional Lambertian term diffuse_albedo / pi."""

    def __init__(self, mf: Microfacet, masking: str, sampler: str, fresnel: str, ior=1.5,
                 n=(1.0, 1.0, 1.0), k=(0.0, 0.0, 0.0), tint=(1.0, 1.0, 1.0),
                 diffuse_albedo=(0.0, 0.0, 0.0)):
        if sampler not in ("dcos", "vndf", "vcavity"):
            raise ValueError(f"unknown sampler {sampler!r}")
        if fresnel not in ("dielectric", "conductor", "none"):
            raise ValueError(f"unknown fresnel {fresnel!r}")
        self.mf = mf
        self.masking = masking
        self.sampler = sampler
        self.fresnel = fresnel
        self.ior = float(ior)
        self.n = np.asarray(n, dtype=float)
        self.k = np.asarray(k, dtype=float)
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.asarray(diffuse_albedo, dtype=float)
        self.is_delta = mf.delta

    def F(self, cos_i):
        """RGB Fresnel factor (..., 3) at cos_i = wi.m."""
        return fresnel_color(self.fresnel, cos_i, self.ior, self.n, self.k)

    def eval_specular(self, wi, wo):
        """Specular lobe f_s (..., 3); 0 for the delta lobe (roughness 0)."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        valid = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        if self.is_delta:
            return np.zeros(wi.shape)
        h = normalize(wi + wo)
        D = self.mf.D(h)
        G = self.mf.G2(wi, wo, h, self.masking)
        denom = 4.0 * np.where(valid, wi[..., 2] * wo[..., 2], 1.0)
        scalar = np.where(valid, D * G / denom, 0.0)
        # wo = -wi has no half vector: mask the whole product, not only the scalar factor.
        return np.where(valid[..., None], self.tint * self.F(dot(wi, h)) * scalar[..., None], 0.0)

    def eval(self, wi, wo):
        """f(wi, wo) (..., 3): specular + Lambertian diffuse_albedo / pi; 0 below the horizon."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        valid = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        diffuse = np.where(valid[..., None], self.diffuse_albedo / np.pi, 0.0)
        return self.eval_specular(wi, wo) + diffuse

    def eval_cos(self, wi, wo):
        """f(wi, wo) * wo.n."""
        wo = np.asarray(wo, dtype=float)
        return self.eval(wi, wo) * np.maximum(wo[..., 2], 0.0)[..., None]

    def delta_reflectance(self, wi):
        """Reflectance F(wi.n) * tint (..., 3) of the mirror lobe (roughness 0); zeros otherwise."""
        wi = np.asarray(wi, dtype=float)
        if not self.is_delta:
            return np.zeros(wi.shape)
        return np.where((wi[..., 2] > 0.0)[..., None], self.tint * self.F(wi[..., 2]), 0.0)

    def sample_normal(self, wi, u):
        """The sampler's microfacet normal m and its density over solid angle of m."""
        u1, u2, u3 = u[..., 0], u[..., 1], u[..., 2]
        mf = self.mf
        if self.sampler == "dcos":
            m = mf.sample_dcos(u1, u2)
            return m, mf.pdf_dcos(m)
        if self.sampler == "vndf":
            m = mf.sample_vndf(wi, u1, u2)
            return m, mf.pdf_vndf(wi, m)
        m = mf.sample_vcavity(wi, u1, u2, u3)
        return m, mf.pdf_vcavity(wi, m)

    def inv_pdf_factor(self, wi, m):
        """The sampler's part of the sample weight, f cos / (F G2 tint pdf), for the normal m
        it drew (the closed forms listed in `sample`; OSL: sample_reflection_factor)."""
        wz = wi[..., 2]
        c = dot(wi, m)
        safe_wz = np.where(wz > 0.0, wz, 1.0)
        safe_mz = np.maximum(m[..., 2], _TINY)
        if self.sampler == "dcos":
            return np.abs(c) / (safe_wz * safe_mz)
        if self.sampler == "vndf":
            g1 = self.mf.G1(wi, m)
            return np.where(g1 > 0.0, 1.0 / np.where(g1 > 0.0, g1, 1.0), 0.0)
        cm = np.maximum(dot(wi, m * np.array([-1.0, -1.0, 1.0])), 0.0)
        return (np.maximum(c, 0.0) + cm) / (2.0 * safe_wz * safe_mz)

    def sample(self, wi, u):
        """Sample the specular lobe: returns (wo, weight, pdf), weight = f_s cos / pdf (RGB),
        pdf over solid angle of wo = pdf_m / (4 |wi.m|) (Walter 2007 eq. 14, Jacobian of the
        reflection). Closed-form weights (D cancels analytically):
        dcos  (Walter 2007 eq. 41):        F G2 |wi.m| / (wi.n m.n)
        vndf  (Heitz & d'Eon 2014 eq. 8):  F G2 / G1(wi)
        vcavity (Heitz 2014 sec. 6):       F G2 (<wi,m>+ + <wi,m'>+) / (2 wi.n m.n)
                                           = F G2 / G1_vcavity(wi, m)
        all times the tint; 0 where wo.n <= 0 (or wi.n <= 0)."""
        wi, u = broadcast_pair(wi, u)
        wz = wi[..., 2]
        if self.is_delta:
            wo = wi * np.array([-1.0, -1.0, 1.0])
            return wo, self.delta_reflectance(wi), np.where(wz > 0.0, 1.0, 0.0)
        m, pdf_m = self.sample_normal(wi, u)
        wo = reflect_about(wi, m)
        c = dot(wi, m)
        pdf = pdf_m / (4.0 * np.maximum(np.abs(c), _TINY))
        w = self.mf.G2(wi, wo, m, self.masking) * self.inv_pdf_factor(wi, m)
        valid = (wz > 0.0) & (wo[..., 2] > 0.0) & (c > 0.0) & (pdf_m > 0.0)
        weight = np.where(valid[..., None], self.tint * self.F(c) * w[..., None], 0.0)
        return wo, weight, np.where(wz > 0.0, pdf, 0.0)


def sample_reflection_factor(bsdf: MicrofacetBRDF, wi, u):
    """(m, factor): the sampler's microfacet normal m for wi and its part of the reflection
    sample weight, f cos / (F G2 tint pdf) (`inv_pdf_factor`), 0 where wi.n <= 0 or wi.m <= 0
    (osl sample_reflection_factor). u (..., 3): the sampler's uniforms."""
    wi = np.asarray(wi, dtype=float)
    m, _ = bsdf.sample_normal(wi, u)
    ok = (wi[..., 2] > 0.0) & (dot(wi, m) > 0.0)
    return m, np.where(ok, bsdf.inv_pdf_factor(wi, m), 0.0)


def reflection_pdf(bsdf: MicrofacetBRDF, wi, m):
    """The model sampler's density of wo = reflect_about(wi, m): pdf_m(m) / (4 wi.m) (osl
    reflection_pdf)."""
    mf, c = bsdf.mf, dot(wi, m)
    if bsdf.sampler == "dcos":
        pdf_m = mf.pdf_dcos(m)
    elif bsdf.sampler == "vndf":
        pdf_m = mf.pdf_vndf(wi, m)
    else:
        pdf_m = mf.pdf_vcavity(wi, m)
    ok = (c > 0.0) & (m[..., 2] > 0.0) & (wi[..., 2] > 0.0)
    return np.where(ok, pdf_m / (4.0 * np.where(ok, c, 1.0)), 0.0)


# The catalog adapter: model id -> builder(resolved params). Each model module registers its
# own (glass, lee, heitz2016), so this module imports none of them; the package's __init__
# imports them all, so make_bsdf knows every model however it was reached.
BUILDERS: dict = {}


def builds(model_id: str):
    """Decorator: register `builder(params) -> BSDF` for a catalog model."""
    def register(builder):
        BUILDERS[model_id] = builder
        return builder
    return register


def make_bsdf(model_id: str, values: dict | None = None):
    """Build a catalog model from user values (resolved and clamped by the catalog)."""
    params = MODELS[model_id].resolve(values)
    if model_id not in BUILDERS:
        raise KeyError(f"no reference implementation for model {model_id!r}")
    return BUILDERS[model_id](params)


@builds("cook_torrance")
def _cook_torrance(params) -> MicrofacetBRDF:
    # Cook & Torrance 1982: f = d R_d + s R_s with Beckmann D, V-cavity G, exact Fresnel;
    # normalised D (integral D cos = 1) with 4 (n.wi)(n.wo), see docs/models.md sec. 1.
    s = params["specular"]
    ax, ay = alphas(params["roughness"])
    return MicrofacetBRDF(
        Microfacet("beckmann", ax, ay), masking="vcavity", sampler=params["sampler"],
        fresnel=params["fresnel_type"], ior=params["ior"], n=params["n"], k=params["k"],
        tint=(s, s, s), diffuse_albedo=tuple((1.0 - s) * c for c in params["base_color"]))


@builds("walter_reflection")
def _walter_reflection(params) -> MicrofacetBRDF:
    # Walter et al. 2007 eq. 20 (reflection part).
    ax, ay = alphas(params["roughness"], params["anisotropy"])
    return MicrofacetBRDF(
        Microfacet(params["distribution"], ax, ay), masking=params["masking"],
        sampler=params["sampler"], fresnel=params["fresnel_type"], ior=params["ior"],
        n=params["n"], k=params["k"], tint=params["base_color"])
