"""Numpy-only reference implementation of Microfacet Lab's models (no bpy).

Modules: special (erf, erfinv, chi-square tail), fresnel, microfacet (the distribution class),
bsdf (catalog models), quadrature (directional moments for sphere images).
"""
from .bsdf import MicrofacetBRDF, make_bsdf
from .fresnel import fresnel_conductor, fresnel_dielectric
from .microfacet import Microfacet, dot, normalize, reflect
from .special import erf, erfc, erfinv

__all__ = ["Microfacet", "MicrofacetBRDF", "make_bsdf", "fresnel_dielectric",
           "fresnel_conductor", "erf", "erfc", "erfinv", "dot", "normalize", "reflect"]
