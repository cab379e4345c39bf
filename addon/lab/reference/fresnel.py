"""Exact unpolarised Fresnel reflectance (scalar per direction, or per RGB channel), and
`fresnel_color`, the one dispatcher on a model's Fresnel choice. The twin of osl/fresnel.h.

Shapes: `cos_i` is any array; the result has the broadcast shape of the arguments. For RGB
conductors pass `cos_i[..., None]` with `n`, `k` of shape (3,): the result is (..., 3).
"""
from __future__ import annotations

import numpy as np


def fresnel_dielectric(cos_i, eta):
    """Unpolarised reflectance of a dielectric interface, eta = n_t / n_i.

    Cook & Torrance 1982 eq. 9 (seed eq. 2-6): c = |cos_i|, g^2 = eta^2 - 1 + c^2,
    F = 1/2 ((g-c)/(g+c))^2 (1 + ((c(g+c)-1)/(c(g-c)+1))^2); F = 1 for g^2 < 0 (total internal
    reflection); eta == 1 gives exactly 0 (no interface, also at c = 0 where the formula is 0/0).
    """
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=float)), 1.0)
    eta = np.asarray(eta, dtype=float)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    gpc = g + c
    a = (g - c) / np.where(gpc > 0.0, gpc, 1.0)
    b = (c * gpc - 1.0) / (c * (g - c) + 1.0)  # denominator >= 1 - c^2 + c g > 0 unless c=1,g=0
    F = 0.5 * a * a * (1.0 + b * b)
    F = np.where(g2 < 0.0, 1.0, F)
    return np.where(eta == 1.0, 0.0, F)


def fresnel_conductor(cos_i, n, k):
    """Unpolarised reflectance from vacuum onto a conductor of complex IOR eta = n + i k.

    Exact Fresnel equations with complex arithmetic (Born & Wolf sec. 14.2; pbrt-v4 FrComplex):
    cos_t = sqrt(1 - sin_i^2 / eta^2), r_s = (c - eta cos_t)/(c + eta cos_t),
    r_p = (eta c - cos_t)/(eta c + cos_t), F = (|r_s|^2 + |r_p|^2) / 2.
    At normal incidence F0 = ((n-1)^2 + k^2) / ((n+1)^2 + k^2).
    """
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=float)), 1.0)
    eta = np.asarray(n, dtype=float) + 1j * np.asarray(k, dtype=float)
    sin2 = 1.0 - c * c
    cos_t = np.sqrt(1.0 - sin2 / (eta * eta))
    # At exact grazing incidence on an index-matched medium (n = 1, k = 0) both ratios are 0/0;
    # take the grazing limit of every other medium, |r| = 1 (same guard in the OSL twin).
    ds, dp = c + eta * cos_t, eta * c + cos_t
    r_s = np.where(ds == 0, 1.0, (c - eta * cos_t) / np.where(ds == 0, 1.0, ds))
    r_p = np.where(dp == 0, 1.0, (eta * c - cos_t) / np.where(dp == 0, 1.0, dp))
    return 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)


FRESNEL_KINDS = ("none", "dielectric", "conductor")


def fresnel_color(kind: str, cos_i, ior, n, k):
    """The Fresnel factor (..., 3) of a model's Fresnel choice at cos_i (...) per RGB channel:
    'dielectric' (eta = ior, grey), 'conductor' (complex IOR n + ik per channel, n and k of
    shape (3,)) or 'none' (1, exactly). The one dispatcher (osl fresnel_color)."""
    cos_i = np.asarray(cos_i, dtype=float)
    if kind == "dielectric":
        return fresnel_dielectric(cos_i, ior)[..., None] * np.ones(3)
    if kind == "conductor":
        return fresnel_conductor(cos_i[..., None], np.asarray(n, dtype=float),
                                 np.asarray(k, dtype=float))
    if kind == "none":
        return np.ones(cos_i.shape + (3,))
    raise ValueError(f"fresnel kind must be one of {FRESNEL_KINDS}, not {kind!r}")
