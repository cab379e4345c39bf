"""Cycles' own closures that our models are held against, as raw OSL (no bpy).

Each entry is the body of a one-closure shader; `native_source(kind, roughness)` gives the whole
text for a Script node (harness.osl_material). Roughness maps to alpha as everywhere
(catalog.alphas); the conductor and glass use the catalog's default gold and IOR 1.5.
"""
from ..catalog import MODELS, alphas

GOLD_N = MODELS["walter_reflection"].param("n").default
GOLD_K = MODELS["walter_reflection"].param("k").default

NATIVE = {
    # Height-correlated Smith, no Fresnel (F = 1).
    "ggx": 'BSDF = microfacet("ggx", N, {alpha:.9g}, 0.0, 0);',
    "beckmann": 'BSDF = microfacet("beckmann", N, {alpha:.9g}, 0.0, 0);',
    # Exact conductor Fresnel with complex IOR n + ik.
    "conductor": ('BSDF = conductor_bsdf(N, vector(0), {alpha:.9g}, {alpha:.9g}, '
                  'color({n[0]}, {n[1]}, {n[2]}), color({k[0]}, {k[1]}, {k[2]}), "ggx");'),
    # Cycles' multiscatter GGX conductor (single-scattering GGX scaled to preserve energy):
    # what Cycles offers for multiple scattering, the comparison for Lee's V-grooves.
    "multi_ggx": ('BSDF = conductor_bsdf(N, vector(0), {alpha:.9g}, {alpha:.9g}, '
                  'color({n[0]}, {n[1]}, {n[2]}), color({k[0]}, {k[1]}, {k[2]}), "multi_ggx");'),
    # Rough dielectric; Cycles flips the IOR on back faces itself.
    "glass": ('BSDF = dielectric_bsdf(N, vector(0), color(1), color(1), {alpha:.9g}, {alpha:.9g}, '
              '1.5, "ggx");'),
}


def native_source(kind: str, roughness: float) -> str:
    body = NATIVE[kind].format(alpha=alphas(roughness)[0], n=GOLD_N, k=GOLD_K)
    return f'#include "stdcycles.h"\nshader native(output closure color BSDF = 0) {{ {body} }}'
