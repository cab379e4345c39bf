"""The numpy references the renders are measured against: moment tables computed once, the
sun-disk term by quadrature over the sun's cone, and the relative RMSE of a render."""
from __future__ import annotations

import numpy as np

from .. import grid
from .config import CONE_LIGHTS, SUN_DIRECTION, SUN_WORLD


def _table_key(spec):
    return (spec.model_id, tuple(sorted((k, str(v)) for k, v in spec.values.items()
                                        if k not in ("sampler", "estimator"))))


class ReferenceTables:
    """Moment tables by (model, values without the sampler and estimator: the same BSDF),
    computed once."""

    def __init__(self, order: int):
        self.order = order
        self.cache = {}

    def get(self, spec):
        from ..reference import make_bsdf
        from ..reference.quadrature import tabulate_moments

        key = _table_key(spec)
        if key not in self.cache:
            self.cache[key] = tabulate_moments(make_bsdf(spec.model_id, spec.values),
                                               order=self.order)
        return self.cache[key]


def sun_unit() -> np.ndarray:
    d = np.asarray(SUN_DIRECTION, dtype=float)
    return d / np.linalg.norm(d)


def sun_cone_nodes(half_angle: float, n_r: int, n_phi: int):
    """Directions and solid-angle weights of a product rule on the cone of half-angle
    `half_angle` around the sun: Gauss-Legendre in the polar angle (weight sin), midpoint
    (periodic trapezoid) in azimuth."""
    d = sun_unit()
    e1 = np.cross(d, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    x, w = np.polynomial.legendre.leggauss(n_r)
    theta = 0.5 * half_angle * (x + 1.0)
    wt = 0.5 * half_angle * w * np.sin(theta)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    dirs = (np.cos(T)[..., None] * d + np.sin(T)[..., None]
            * (np.cos(P)[..., None] * e1 + np.sin(P)[..., None] * e2))
    weights = (wt[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :])
    return dirs.reshape(-1, 3), weights.reshape(-1)


def _sun_pixels(bsdf, n, t, b, m, dirs, weights) -> np.ndarray:
    """The integral of f(wi, wo) |wo.n| over the cone's nodes for pixels with normal n, tangent
    t, binormal b and mu m, in chunks of 256 pixels: (p, 3)."""
    wi = np.stack([np.sqrt(np.clip(1.0 - m * m, 0.0, 1.0)), np.zeros_like(m), m], -1)
    vals = np.empty((len(m), 3))
    for start in range(0, len(m), 256):
        s = slice(start, start + 256)
        wo = np.stack([t[s] @ dirs.T, b[s] @ dirs.T, n[s] @ dirs.T], -1)  # (p, K, 3)
        with np.errstate(all="ignore"):
            f = bsdf.eval(wi[s, None, :], wo)
        f = np.nan_to_num(f)
        vals[s] = np.einsum("pkc,pk,k->pc", f, np.abs(wo[..., 2]), weights)
    return vals


def sun_term(layout, specs, radiance: float, half_angle: float, nodes: tuple) -> np.ndarray:
    """L_sun times the integral of f(wi, wo) |wo.n| over the sun's cone, per pixel (H, W, 3).
    Spheres are invisible to secondary rays, so a reflected or transmitted ray meets the sun
    directly (single-interface convention for glass)."""
    from ..reference import make_bsdf

    index, normal, mu = layout.pixel_geometry()
    tangent = grid.tangent_toward_view(normal)
    flat = np.linalg.norm(tangent, axis=-1) < 0.5  # mu = 1: any tangent
    tangent[flat] = [1.0, 0.0, 0.0]
    binormal = np.cross(normal, tangent)
    dirs, weights = sun_cone_nodes(half_angle, *nodes)
    out = np.zeros(index.shape + (3,))
    bsdfs = {}
    for i, spec in enumerate(specs):
        sel = np.nonzero(index == i)
        if spec is None or len(sel[0]) == 0:
            continue
        key = _table_key(spec)
        if key not in bsdfs:
            bsdfs[key] = make_bsdf(spec.model_id, spec.values)
        vals = _sun_pixels(bsdfs[key], normal[sel], tangent[sel], binormal[sel], mu[sel],
                           dirs, weights)
        out[sel] = radiance * vals
    return out


def reference_image(layout, specs, env_key, tables: ReferenceTables, sun=None, nodes=(24, 48)):
    """The reference of a grid under 'white', 'gradient' or a cone light of CONE_LIGHTS (then
    `sun` = (radiance, half_angle)); returns (image, sun-quadrature error estimate or 0)."""
    from ..reference.quadrature import moments_at

    tabs = [None if s is None else tables.get(s) for s in specs]
    if env_key not in CONE_LIGHTS:
        return grid.reference_image(layout, tabs, grid.ENVIRONMENTS[env_key], moments_at), 0.0
    world = grid.Environment("sun world", SUN_WORLD)
    base = grid.reference_image(layout, tabs, world, moments_at)
    radiance, half = sun
    fine = sun_term(layout, specs, radiance, half, nodes)
    coarse = sun_term(layout, specs, radiance, half, (nodes[0] // 2, nodes[1] // 2))
    index, _, _ = layout.pixel_geometry()
    err = float(np.abs(fine - coarse)[index >= 0].max()) if (index >= 0).any() else 0.0
    return base + fine, err


def relative_rmse(image, reference, sel) -> float:
    d = image[..., :3][sel] - reference[sel]
    return float(np.sqrt(np.mean(d * d)) / np.mean(reference[sel]))
