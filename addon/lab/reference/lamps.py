"""The residual's direct light in numpy: lamp sampling and the guided residual, the twin of
osl/lamps.h (docs/light-sampling.md, "The residual's direct light").

The shader draws its residual's direction from the mixture
    p(wo) = (1 - lam) p_model(wo) + lam sum_j pi_j p_j(wo)
and weights it r cos / p(wo) (Veach 1997, one-sample balance heuristic), so the estimate is
exact whatever the lamp records say. Records are addon/lamps.py LampRecords (world space); here
the shading frame is the world frame (n = z, tangent = x), so local and world directions agree.
(So the OSL's frame changes, sample_lamps_local and lamps_density_local, have no twin here, nor
its readers of the generated table, lamp_vector, lamp_kind, lamp_u and lamp_v: `extents` and
the record's fields.)

Shapes: points P and normals (..., 3); directions (..., 3); uniforms (...,).
"""
from __future__ import annotations

import numpy as np

from ...lamps import LampRecord
from .bsdf import reflection_pdf
from .microfacet import dot, normalize, reflect_about
from .split import eval_native

# osl/lamps.h MFL_GUIDE_FRACTION, MFL_LAMP_MARGIN (tests/test_reference_lamps.py checks they
# agree). Sampling and density use each lamp enlarged by MARGIN (a cone's sin^2, an area's
# half-extents), so that float rounding on the lamp's rim never leaves a direction Cycles sees
# inside the lamp outside the density (a rare, heavy sample); only the proposal changes.
GUIDE_FRACTION = 0.5
MARGIN = 2e-3


def in_cone(dirs, axis, sin2):
    """Whether dirs lie in the cone of sin^2(half-angle) sin2 around axis (half-angles below
    pi/2): sin^2 from the cross product, exact for tiny cones where 1 - cos rounds away."""
    c = np.cross(dirs, axis)
    return (dot(dirs, axis) > 0.0) & (np.sum(c * c, axis=-1) <= sin2)


def cone_density(th):
    """The uniform density over a cone of half-angle th: 1 / (2 pi (1 - cos th))."""
    omc = 2.0 * np.sin(0.5 * np.asarray(th, dtype=float)) ** 2
    return 1.0 / (2.0 * np.pi * np.maximum(omc, 1e-30))


def lamp_cone(rec: LampRecord, P):
    """(axis, 1 - cos, sin^2, valid) of the cone toward the sun or a sphere lamp from P."""
    P = np.asarray(P, dtype=float)
    if rec.kind == "sun":
        axis = np.broadcast_to(np.asarray(rec.axis, dtype=float), P.shape)
        sin2 = np.full(P.shape[:-1], rec.size * (2.0 - rec.size))
        valid = np.ones(P.shape[:-1], bool)
    else:
        to = np.asarray(rec.position, dtype=float) - P
        d2 = np.sum(to * to, axis=-1)
        valid = d2 > rec.size ** 2
        d2s = np.where(valid, d2, 1.0)
        axis = to / np.sqrt(d2s)[..., None]
        # A sphere subtends asin(r / d); a disk facing P (Soft Falloff) atan(r / d).
        sin2 = np.where(valid, rec.size ** 2 / (d2s if rec.is_sphere else d2s + rec.size ** 2),
                        1.0)
    sin2 = np.minimum(sin2 * (1.0 + MARGIN), 1.0)
    omc = sin2 / (1.0 + np.sqrt(np.maximum(1.0 - sin2, 0.0)))
    return axis, omc, sin2, valid


def extents(rec: LampRecord):
    """An area lamp's half-extent axes, enlarged by MARGIN."""
    return (np.asarray(rec.u, dtype=float) * (1.0 + MARGIN),
            np.asarray(rec.v, dtype=float) * (1.0 + MARGIN))


def lamp_area(rec: LampRecord) -> float:
    u, v = extents(rec)
    a = np.linalg.norm(u) * np.linalg.norm(v)
    return float(np.pi * a if rec.kind == "ellipse" else 4.0 * a)


def lamp_weight(rec: LampRecord, P, Ng):
    """Guiding weight of a lamp at P (osl lamp_weight): a rough irradiance, 0 where the lamp is
    behind the surface, P inside it or behind an area lamp."""
    P, Ng = np.broadcast_arrays(np.asarray(P, dtype=float), np.asarray(Ng, dtype=float))
    if rec.kind == "sun":
        s = np.sqrt(rec.size * (2.0 - rec.size))
        return np.where(dot(Ng, np.asarray(rec.axis)) > -s, rec.power, 0.0)
    to = np.asarray(rec.position, dtype=float) - P
    d2 = np.sum(to * to, axis=-1)
    if rec.kind == "sphere":
        ok = (d2 > rec.size ** 2) & (dot(Ng, to) >= -rec.size)
        return np.where(ok, rec.power / (4.0 * np.pi * np.where(ok, d2, 1.0)), 0.0)
    front = -dot(np.asarray(rec.axis), to)
    extent = np.linalg.norm(rec.u) + np.linalg.norm(rec.v)
    ok = (front > 0.0) & (dot(Ng, to) >= -extent)
    d2s = np.where(ok, d2, 1.0)
    return np.where(ok, rec.power * front / (np.pi * np.sqrt(d2s) *
                                             np.maximum(d2s, lamp_area(rec))),
                    0.0)


def frame(axis):
    helper = np.where((np.abs(axis[..., 2]) < 0.9)[..., None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    t = normalize(np.cross(helper, axis))
    return t, np.cross(axis, t)


def sample_cone(axis, one_minus_cos, u1, u2):
    """Uniform directions in the cones around `axis` (..., 3) with the given 1 - cos(half-angle)
    (osl sample_cone)."""
    s = u1 * one_minus_cos
    sin_t = np.sqrt(np.maximum(s * (2.0 - s), 0.0))
    phi = 2.0 * np.pi * u2
    t, b = frame(axis)
    return ((sin_t * np.cos(phi))[..., None] * t + (sin_t * np.sin(phi))[..., None] * b
            + (1.0 - s)[..., None] * axis)


def sample_lamp(rec: LampRecord, P, u1, u2):
    """A direction toward the lamp from P, drawn from p_i (uniform over the cone or the area)."""
    P = np.asarray(P, dtype=float)
    u1, u2 = np.broadcast_arrays(np.asarray(u1, dtype=float), np.asarray(u2, dtype=float))
    if rec.kind in ("sun", "sphere"):
        axis, omc, _, _ = lamp_cone(rec, P)
        return sample_cone(axis, omc, u1, u2)
    if rec.kind == "ellipse":
        r = np.sqrt(u1)
        s, t = r * np.cos(2 * np.pi * u2), r * np.sin(2 * np.pi * u2)
    else:
        s, t = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0
    u, v = extents(rec)
    q = np.asarray(rec.position) + s[..., None] * u + t[..., None] * v
    return normalize(q - P)


def lamp_pdf(rec: LampRecord, P, dirs):
    """p_i(dir) over solid angle (osl lamp_pdf)."""
    P, dirs = np.broadcast_arrays(np.asarray(P, dtype=float), np.asarray(dirs, dtype=float))
    if rec.kind in ("sun", "sphere"):
        axis, omc, sin2, valid = lamp_cone(rec, P)
        inside = valid & in_cone(dirs, axis, sin2)
        return np.where(inside, 1.0 / (2.0 * np.pi * np.where(inside, omc, 1.0)), 0.0)
    n = np.asarray(rec.axis, dtype=float)
    (u, v), c = extents(rec), np.asarray(rec.position, dtype=float)
    cos_l = -dot(dirs, n)
    ok = cos_l > 0.0
    dist = np.where(ok, dot(P - c, n) / np.where(ok, cos_l, 1.0), -1.0)
    q = P + dist[..., None] * dirs - c
    s, t = dot(q, u) / np.dot(u, u), dot(q, v) / np.dot(v, v)
    inside = (s * s + t * t <= 1.0) if rec.kind == "ellipse" else \
        (np.abs(s) <= 1.0) & (np.abs(t) <= 1.0)
    ok &= (dist > 0.0) & inside
    return np.where(ok, dist * dist / (lamp_area(rec) * np.where(ok, cos_l, 1.0)), 0.0)


def lamp_bounding_cone(rec, P):
    """(axis, half-angle, valid): a cone holding every direction toward the lamp from P (sun and
    sphere lamps: lamps.lamp_cone; rectangles and ellipses: about the centre, out to the farthest
    corner of the rectangle; osl lamp_bounding_cone)."""
    P = np.asarray(P, dtype=float)
    if rec.kind in ("sun", "sphere"):
        axis, omc, sin2, valid = lamp_cone(rec, P)
        th = np.where(rec.kind == "sun", 2.0 * np.arcsin(np.sqrt(0.5 * omc)),
                      np.arcsin(np.sqrt(np.clip(sin2, 0.0, 1.0))))
        return axis, th, valid
    c = np.asarray(rec.position, dtype=float)
    u, v = extents(rec)
    axis = normalize(c - P)
    th = np.zeros(P.shape[:-1])
    for su in (-1.0, 1.0):
        for sv in (-1.0, 1.0):
            corner = normalize(c + su * u + sv * v - P)
            th = np.maximum(th, np.arccos(np.clip(dot(corner, axis), -1.0, 1.0)))
    return axis, th, np.linalg.norm(c - P, axis=-1) > 0.0


def lamp_share(rec: LampRecord, P, Ng, set_=0):
    """A lamp's weight in a set (osl lamp_share): set 0 the lamps the residual aims at, 1 those
    whose light the shaders' control variate estimates, 2 every lamp. The control variate
    (osl/nee.h) acts on the camera's hits only and has no twin: numpy models the other hits,
    where every lamp is aimed at (sets 0 and 2) and none estimated (set 1)."""
    return np.zeros(np.shape(P)[:-1]) if set_ == 1 else lamp_weight(rec, P, Ng)


def lamps_total_weight(records, P, Ng, set_=0):
    """The sum of a set's guiding weights at P (...,)."""
    P = np.asarray(P, dtype=float)
    total = np.zeros(P.shape[:-1])
    for rec in records:
        total = total + lamp_share(rec, P, Ng, set_)
    return total


def guide_fraction(records, P, Ng):
    """(lam, total): GUIDE_FRACTION where some lamp has weight at P, else 0; the weights' sum."""
    total = lamps_total_weight(records, P, Ng)
    return np.where(total > 0.0, GUIDE_FRACTION, 0.0), total


def lamps_pdf(records, P, Ng, dirs, set_=0):
    """sum_j pi_j p_j(dir) over a set, pi_j = weight_j / total."""
    total = lamps_total_weight(records, P, Ng, set_)
    pdf = 0.0
    for rec in records:
        pdf = pdf + lamp_share(rec, P, Ng, set_) * lamp_pdf(rec, P, dirs)
    return np.where(total > 0.0, pdf / np.where(total > 0.0, total, 1.0), 0.0)


def sample_lamps(records, P, Ng, u0, u1, u2, set_=0):
    """Lamp j of a set with probability pi_j, then a direction from p_j."""
    P = np.asarray(P, dtype=float)
    weights = np.stack([np.broadcast_to(lamp_share(r, P, Ng, set_), P.shape[:-1])
                        for r in records], axis=-1)
    cdf = np.cumsum(weights, axis=-1)
    target = np.asarray(u0) * cdf[..., -1]
    chosen = np.minimum(np.sum(cdf <= target[..., None], axis=-1), len(records) - 1)
    out = np.zeros(P.shape)
    for j, rec in enumerate(records):
        sel = chosen == j
        out[sel] = sample_lamp(rec, P[sel], np.asarray(u1)[sel], np.asarray(u2)[sel])
    return out


def sample_guided_residual(bsdf, records, P, wi, u, less=None, lam=None):
    """One guided residual sample at points P (normal z): (wo, weight, model_share), weight =
    r cos / p(wo) (RGB, r = f_specular - c f_native), model_share = (1 - lam) p_model / p (osl
    sample_guided_residual). u: (..., 7) uniforms: 3 for the model's sampler, the choice
    between lamps and model, the lamp, and 2 for the lamp's direction. less(P, wi, Ng, wo):
    what to take off r cos (controls.guided_residual_beside_controls: the lamp controls'
    part); lam (...,): the share aimed where some lamp has weight (default GUIDE_FRACTION)."""
    P, wi, u = (np.asarray(x, dtype=float) for x in (P, wi, u))
    shape = np.broadcast_shapes(P.shape, wi.shape, u.shape[:-1] + (3,))
    P, wi = np.broadcast_to(P, shape), np.broadcast_to(wi, shape)
    u = np.broadcast_to(u, shape[:-1] + (7,))
    Ng = np.broadcast_to([0.0, 0.0, 1.0], shape)
    default, total = guide_fraction(records, P, Ng)
    lam = default if lam is None else np.where(total > 0.0, lam, 0.0)
    m_model, _ = bsdf.sample_normal(wi, u[..., :3])
    wo = reflect_about(wi, m_model)
    if records:
        aimed = u[..., 3] < lam
        wo = np.where(aimed[..., None],
                      sample_lamps(records, P, Ng, u[..., 4], u[..., 5], u[..., 6]), wo)
    m = normalize(wi + wo)
    p_model = (1.0 - lam) * reflection_pdf(bsdf, wi, m)
    pdf = p_model + lam * (lamps_pdf(records, P, Ng, wo) if records else 0.0)
    r_cos = (bsdf.eval_specular(wi, wo) - eval_native(bsdf, wi, wo)) * \
        np.maximum(wo[..., 2], 0.0)[..., None]
    if less is not None and records:
        r_cos = r_cos - less(P, wi, Ng, wo)
    ok = (pdf > 0.0) & (wo[..., 2] > 0.0) & (wi[..., 2] > 0.0)
    weight = np.where(ok[..., None], np.maximum(r_cos, 0.0) / np.where(ok, pdf, 1.0)[..., None],
                      0.0)
    share = np.where(ok, p_model / np.where(ok, pdf, 1.0), 1.0)
    return wo, weight, share
