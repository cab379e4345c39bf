"""The numpy references the renders are measured against: moment tables computed once, the
sun-disk term by quadrature over the sun's cone, and the relative RMSE of a render."""
from __future__ import annotations

import numpy as np

from .. import grid
from .config import AREA_LAMP, CONE_LIGHTS, LAMP_ENVS, POINT_LAMP, SUN_WORLD
from .lights import area_lamp_axes, hdri_spot, point_radiance, sun_unit
from ...world_spots import equirect_direction
from ..reference import make_bsdf
from ..reference.quadrature import moments_at, tabulate_moments


def _table_key(spec):
    return (spec.model_id, tuple(sorted((k, str(v)) for k, v in spec.values.items()
                                        if k not in ("sampler", "estimator"))))


class ReferenceTables:
    """Moment tables by (model, values without the sampler and estimator: the same BSDF),
    computed once: by quadrature of `order`, or for a walk (Heitz 2016, whose evaluation is
    Monte Carlo) from `walks` sampled walks per incidence (None: the model's default)."""

    def __init__(self, order: int, walks: int | None = None):
        self.order = order
        self.walks = walks
        self.cache = {}

    def get(self, spec):
        key = _table_key(spec)
        if key not in self.cache:
            bsdf = make_bsdf(spec.model_id, spec.values)
            if self.walks and getattr(bsdf, "stochastic_eval", False):
                bsdf.moment_walks = self.walks
            self.cache[key] = tabulate_moments(bsdf, order=self.order)
        return self.cache[key]


def cone_nodes(axis, half_angle, n_r: int, n_phi: int):
    """Directions and solid-angle weights of a product rule on cones of half-angle `half_angle`
    around `axis` (one cone, or one per point: axis (..., 3), half_angle (...)): Gauss-Legendre
    in the polar angle (weight sin), midpoint (periodic trapezoid) in azimuth. Returns
    (..., K, 3) directions and (..., K) weights, K = n_r n_phi."""
    d = np.asarray(axis, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    half = np.asarray(half_angle, dtype=float)[..., None, None]
    helper = np.where((np.abs(d[..., 2]) < 0.9)[..., None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(d, e1)
    x, w = np.polynomial.legendre.leggauss(n_r)
    theta = 0.5 * half * (x[:, None] + 1.0)  # (..., n_r, 1)
    wt = 0.5 * half * w[:, None] * np.sin(theta)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    ct, st = np.cos(theta)[..., None], np.sin(theta)[..., None]
    cp, sp = np.cos(phi)[:, None], np.sin(phi)[:, None]
    dirs = (ct * d[..., None, None, :] + st * (cp * e1[..., None, None, :]
                                               + sp * e2[..., None, None, :]))
    weights = np.broadcast_to(wt * (2.0 * np.pi / n_phi), dirs.shape[:-1])
    shape = d.shape[:-1] + (n_r * n_phi,)
    return dirs.reshape(shape + (3,)), weights.reshape(shape)


def sun_cone_nodes(half_angle: float, n_r: int, n_phi: int):
    """cone_nodes around the sun's direction: (K, 3) directions, (K,) weights."""
    return cone_nodes(sun_unit(), half_angle, n_r, n_phi)


def _sun_pixels(bsdf, n, t, b, m, dirs, weights) -> np.ndarray:
    """The integral of f(wi, wo) |wo.n| over the nodes (shared: (K, 3) and (K,); or per pixel:
    (p, K, 3) and (p, K)) for pixels with normal n, tangent t, binormal b and mu m, in chunks
    of 256 pixels: (p, 3)."""
    wi = np.stack([np.sqrt(np.clip(1.0 - m * m, 0.0, 1.0)), np.zeros_like(m), m], -1)
    vals = np.empty((len(m), 3))
    for start in range(0, len(m), 256):
        s = slice(start, start + 256)
        d = np.broadcast_to(dirs if dirs.ndim == 2 else dirs[s], (len(m[s]),) + dirs.shape[-2:])
        w = np.broadcast_to(weights if weights.ndim == 1 else weights[s], d.shape[:-1])
        wo = np.stack([np.einsum("pkj,pj->pk", d, frame[s]) for frame in (t, b, n)], -1)
        with np.errstate(all="ignore"):
            f = bsdf.eval(wi[s, None, :], wo)
        f = np.nan_to_num(f)
        vals[s] = np.einsum("pkc,pk,pk->pc", f, np.abs(wo[..., 2]), w)
    return vals


def _light_term(layout, specs, nodes_of):
    """Per pixel (H, W, 3): the integral of f |wo.n| L over a light; `nodes_of(sel, points,
    normals)` gives that light's directions and solid-angle weights times radiance for the
    pixels sel (surface points and normals of those pixels; sphere centres at z = 0)."""

    index, normal, mu = layout.pixel_geometry()
    tangent = grid.tangent_toward_view(normal)
    flat = np.linalg.norm(tangent, axis=-1) < 0.5  # mu = 1: any tangent
    tangent[flat] = [1.0, 0.0, 0.0]
    binormal = np.cross(normal, tangent)
    centres = layout.centers()
    out = np.zeros(index.shape + (3,))
    bsdfs = {}
    for i, spec in enumerate(specs):
        sel = np.nonzero(index == i)
        if spec is None or len(sel[0]) == 0:
            continue
        key = _table_key(spec)
        if key not in bsdfs:
            bsdfs[key] = make_bsdf(spec.model_id, spec.values)
        points = np.append(centres[i], 0.0) + layout.radius * normal[sel]
        dirs, weights = nodes_of(sel, points, normal[sel])
        out[sel] = _sun_pixels(bsdfs[key], normal[sel], tangent[sel], binormal[sel], mu[sel],
                               dirs, weights)
    return out


def sun_term(layout, specs, radiance: float, half_angle: float, nodes: tuple) -> np.ndarray:
    """L_sun times the integral of f(wi, wo) |wo.n| over the sun's cone, per pixel (H, W, 3).
    Spheres are invisible to secondary rays, so a reflected or transmitted ray meets the sun
    directly (single-interface convention for glass)."""
    dirs, weights = sun_cone_nodes(half_angle, *nodes)
    return _light_term(layout, specs, lambda sel, points, normals: (dirs, radiance * weights))


def point_lamp_term(layout, specs, position, lamp_radius: float, radiance: float,
                    nodes: tuple, is_sphere: bool = False) -> np.ndarray:
    """The same for a point lamp of uniform radiance: the cone it subtends from each surface
    point, half-angle atan(r / d) for the disk facing the point that Cycles makes of it with
    Soft Falloff (Blender's default), asin(r / d) for a sphere."""
    def nodes_of(sel, points, normals):
        to = np.asarray(position, dtype=float) - points
        d = np.linalg.norm(to, axis=-1)
        half = (np.arcsin(np.clip(lamp_radius / d, 0.0, 1.0)) if is_sphere
                else np.arctan(lamp_radius / d))
        dirs, weights = cone_nodes(to, half, *nodes)
        return dirs, radiance * weights

    return _light_term(layout, specs, nodes_of)


def area_lamp_term(layout, specs, centre, u, v, radiance: float, nodes: tuple) -> np.ndarray:
    """The same for a rectangular area lamp of uniform radiance (Cycles' area lamp: P / (pi A))
    with centre c and half-extent axes u, v along the lamp's X and Y: Gauss-Legendre nodes over
    the rectangle, d omega = cos_l dA / d^2, emitting on its front side only (the lamp's -Z,
    -(u x v) normalized)."""
    c, u, v = (np.asarray(x, dtype=float) for x in (centre, u, v))
    normal = -np.cross(u, v) / np.linalg.norm(np.cross(u, v))
    x, w = np.polynomial.legendre.leggauss(nodes[0])
    s_, t_ = np.meshgrid(x, x, indexing="ij")
    q = c + s_.reshape(-1, 1) * u + t_.reshape(-1, 1) * v  # (K, 3)
    dA = (np.outer(w, w) * np.linalg.norm(np.cross(u, v))).reshape(-1)

    def nodes_of(sel, points, normals):
        to = q[None, :, :] - points[:, None, :]
        d2 = np.sum(to * to, axis=-1)
        dirs = to / np.sqrt(d2)[..., None]
        cos_l = np.maximum(-dirs @ normal, 0.0)
        return dirs, radiance * dA[None, :] * cos_l / d2

    return _light_term(layout, specs, nodes_of)


def equirect_cell_nodes(radiance, n: int):
    """Directions and solid-angle weights times radiance over the lit pixels of an
    equirectangular world image (H, W) seen with Closest interpolation (each pixel a cell of
    constant radiance, addon/world_spots.py conventions): Gauss-Legendre in cos(theta) and in
    the azimuth, n x n per cell, exact measure dphi dcos(theta). Returns (K, 3), (K,)."""

    radiance = np.asarray(radiance, dtype=float)
    height, width = radiance.shape
    rows, cols = np.nonzero(radiance > 0.0)
    x, w = np.polynomial.legendre.leggauss(n)
    a, b = np.meshgrid((x + 1.0) / 2.0, (x + 1.0) / 2.0, indexing="ij")
    wab = np.outer(w, w).reshape(-1) / 4.0
    u = (cols[:, None] + a.reshape(-1)) / width  # (cells, n n)
    z_lo = np.cos(np.pi * (1.0 - rows / height))
    z_hi = np.cos(np.pi * (1.0 - (rows + 1) / height))
    z = z_lo[:, None] + (z_hi - z_lo)[:, None] * b.reshape(-1)
    v = 1.0 - np.arccos(np.clip(z, -1.0, 1.0)) / np.pi
    dirs = equirect_direction(u, v).reshape(-1, 3)
    dz_dphi = ((z_hi - z_lo) * (2.0 * np.pi / width))[:, None] * wab
    weights = (radiance[rows, cols][:, None] * dz_dphi).reshape(-1)
    return dirs, weights


def image_world_term(layout, specs, radiance, n: int) -> np.ndarray:
    """The integral of f |wo.n| L over an equirectangular world image of `radiance` (H, W),
    black elsewhere, per pixel (H, W, 3): what a grid renders under that world alone."""
    dirs, weights = equirect_cell_nodes(radiance, n)
    return _light_term(layout, specs, lambda sel, points, normals: (dirs, weights))


def reference_image(layout, specs, env_key, tables: ReferenceTables, sun=None, nodes=(24, 48)):
    """The reference of a grid under 'white', 'gradient', a cone light of CONE_LIGHTS (then
    `sun` = (radiance, half_angle)) or the point lamp; returns (image, the lamp quadrature's
    error estimate or 0)."""

    tabs = [None if s is None else tables.get(s) for s in specs]
    if env_key not in LAMP_ENVS:
        return grid.reference_image(layout, tabs, grid.ENVIRONMENTS[env_key], moments_at), 0.0
    world = grid.Environment("sun world", SUN_WORLD)
    base = grid.reference_image(layout, tabs, world, moments_at)
    if env_key == "point":
        def term(n):
            return point_lamp_term(layout, specs, (0.0, 0.0, POINT_LAMP["height"]),
                                   POINT_LAMP["radius"], point_radiance(), n)
    elif CONE_LIGHTS.get(env_key, ("",))[0] == "image":
        spot = hdri_spot(env_key, None)

        def term(n):  # per pixel cell: a quarter of the cone rule's radial nodes, squared
            return image_world_term(layout, specs, spot, max(2, n[0] // 4))
    elif env_key == "area":
        sx, sy = AREA_LAMP["size"]
        radiance = AREA_LAMP["power"] / (np.pi * sx * sy)

        def term(n):
            return area_lamp_term(layout, specs, *area_lamp_axes(), radiance, (n[0], n[0]))
    else:
        radiance, half = sun

        def term(n):
            return sun_term(layout, specs, radiance, half, n)
    fine = term(nodes)
    coarse = term((nodes[0] // 2, nodes[1] // 2))
    index, _, _ = layout.pixel_geometry()
    err = float(np.abs(fine - coarse)[index >= 0].max()) if (index >= 0).any() else 0.0
    return base + fine, err


def relative_rmse(image, reference, sel) -> float:
    d = image[..., :3][sel] - reference[sel]
    return float(np.sqrt(np.mean(d * d)) / np.mean(reference[sel]))
