"""Numpy-only reference implementation of Microfacet Lab's models (no bpy).

Layers, each importing only those above it: special (erf, erfinv, chi-square tail) and
fresnel; microfacet (the distribution class); bsdf (single scattering, and make_bsdf, the
catalog adapter) and glass; quadrature (directional moments for sphere images); split (the
native part and the residual); lamps (lamp records' geometry, sampling, the guided residual);
controls (lamp controls); the models built on them: vgroove and lee (Lee 2018), heitz2016.
Each model module registers its builder with bsdf.builds; importing this package imports them
all, so make_bsdf knows every catalog model.
"""
from . import glass, heitz2016, lee  # noqa: F401  (they register their builders)
from .bsdf import MicrofacetBRDF, make_bsdf
from .fresnel import fresnel_conductor, fresnel_dielectric
from .microfacet import Microfacet, dot, normalize, reflect_about
from .special import erf, erfc, erfinv

__all__ = ["Microfacet", "MicrofacetBRDF", "make_bsdf", "fresnel_dielectric",
           "fresnel_conductor", "erf", "erfc", "erfinv", "dot", "normalize", "reflect_about"]
