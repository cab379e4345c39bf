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

    The Fresnel equations (Born & Wolf sec. 14.2) in the closed form of |r_s|^2, |r_p|^2
    without complex arithmetic, as the OSL twin: with s^2 = 1 - c^2, t0 = n^2 - k^2 - s^2,
    a^2 + b^2 = sqrt(t0^2 + 4 n^2 k^2), a = sqrt((a^2 + b^2 + t0) / 2),
    R_s = (a^2 + b^2 + c^2 - 2 a c) / (a^2 + b^2 + c^2 + 2 a c),
    R_p = R_s (c^2 (a^2 + b^2) + s^4 - 2 a c s^2) / (c^2 (a^2 + b^2) + s^4 + 2 a c s^2),
    F = (R_s + R_p) / 2. At normal incidence F0 = ((n-1)^2 + k^2) / ((n+1)^2 + k^2).
    (tests/test_reference_special_fresnel.py holds it against the complex-valued equations;
    it is four times faster than them, and the split's Fresnel search calls it often.)
    """
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=float)), 1.0)
    n = np.asarray(n, dtype=float)
    k = np.asarray(k, dtype=float)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = n * n - k * k - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * n * n * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    # At exact grazing incidence on an index-matched medium (n = 1, k = 0) R_s is 0/0; take the
    # grazing limit of every other medium, F = 1 (same guard in the OSL twin).
    grazing = t1 + t2 <= 0.0
    # R_s is a squared modulus: where a = c (an index-matched medium) t1 - t2 cancels to a
    # few ulps either side of 0, and a negative one would make F negative.
    rs = np.maximum((t1 - t2) / np.where(grazing, 1.0, t1 + t2), 0.0)
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    rp = rs * (t3 - t4) / np.where(t3 + t4 > 0.0, t3 + t4, 1.0)
    return np.where(grazing, 1.0, 0.5 * (rp + rs))


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
