"""The sphere-grid scene in numpy: layout, environments, per-pixel geometry, reference image.

No bpy here: the render harness (addon/lab/harness.py) builds the same scene in Blender from these
objects, and the tests compare the two.

Geometry: an orthographic camera on +z looks down -z, so every pixel sees the view direction
wi = (0, 0, 1) and, on a sphere, exactly one normal n (Cycles renders point-cloud points as exact
spheres). With a pixel filter of 0.01 px the render samples the pixel centre. Spheres are
invisible to secondary rays, so a pixel's value is exactly
    integral f(wi, wo) |wo.n| L(wo) dwo           (docs/cycles-osl.md, "Reference images").
Environments are linear in the direction, L(w) = a + b (w.d), which Blender's world nodes express
exactly (Texture Coordinate > Generated is the world direction), so the integral reduces to the
moments of the BSDF: a E(mu) + b (Vn(mu) (d.n) + Vt(mu) (d.t)), t the unit tangent toward wi.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..catalog import MODELS
from .reference import make_bsdf
from .reference.quadrature import moments_at, tabulate_moments

VIEW = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Environment:
    """L(w) = constant + gradient * (w . direction), in world space."""

    name: str
    constant: float
    gradient: float = 0.0
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def unit_direction(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=float)
        return d / np.linalg.norm(d)

    def radiance(self, w: np.ndarray) -> np.ndarray:
        return self.constant + self.gradient * (w @ self.unit_direction())


WHITE = Environment("white furnace", 1.0)
# Smooth, non-uniform and positive everywhere: from 0.05 to 0.95, brightest up and to the right.
GRADIENT = Environment("gradient", 0.5, 0.45, (0.6, 0.48, 0.64))
ENVIRONMENTS = {"white": WHITE, "gradient": GRADIENT}
# The horizontal direction of the gradient, which splits bands into sides (band_stats).
SIDE_DIRECTION = np.array(GRADIENT.direction[:2]) / np.hypot(*GRADIENT.direction[:2])


@dataclass(frozen=True)
class GridLayout:
    rows: int
    cols: int
    cell_px: int = 32  # pixels per sphere cell (the sphere's diameter is cell_px / spacing * 2)
    spacing: float = 2.2  # centre-to-centre distance in world units (radius 1)
    radius: float = 1.0

    @property
    def width(self) -> int:
        return self.cols * self.cell_px

    @property
    def height(self) -> int:
        return self.rows * self.cell_px

    @property
    def ortho_scale(self) -> float:
        # Blender's orthographic scale spans the larger image dimension (sensor fit AUTO).
        return max(self.cols, self.rows) * self.spacing

    @property
    def count(self) -> int:
        return self.rows * self.cols

    def centers(self) -> np.ndarray:
        """World (x, y) of sphere i = row * cols + col; row 0 is the top row of the image."""
        i = np.arange(self.count)
        row, col = np.divmod(i, self.cols)
        x = (col - (self.cols - 1) / 2) * self.spacing
        y = ((self.rows - 1) / 2 - row) * self.spacing
        return np.stack([x, y], axis=-1)

    def pixel_world_xy(self) -> np.ndarray:
        """World (x, y) of every pixel centre, shape (H, W, 2); image row 0 at the top."""
        scale = self.ortho_scale / max(self.width, self.height)
        cols = (np.arange(self.width) + 0.5 - self.width / 2) * scale
        rows = (self.height / 2 - np.arange(self.height) - 0.5) * scale
        x, y = np.meshgrid(cols, rows)
        return np.stack([x, y], axis=-1)

    def pixel_geometry(self):
        """Per pixel: sphere index (-1 outside), world normal (H, W, 3), mu = n.wi."""
        xy = self.pixel_world_xy()
        centers = self.centers()
        scale = self.ortho_scale / max(self.width, self.height)
        cell = np.floor((xy + self.spacing * np.array([self.cols, self.rows]) / 2)
                        / self.spacing).astype(int)
        col, row_from_bottom = cell[..., 0], cell[..., 1]
        row = self.rows - 1 - row_from_bottom
        inside_grid = (col >= 0) & (col < self.cols) & (row >= 0) & (row < self.rows)
        index = np.where(inside_grid, row * self.cols + col, -1)
        local = (xy - centers[np.clip(index, 0, None)]) / self.radius
        r2 = (local ** 2).sum(-1)
        # A pixel counts as sphere only if the filter footprint (0.01 px) is fully inside.
        inside = inside_grid & (np.sqrt(r2) < 1.0 - 0.02 * scale / self.radius)
        index = np.where(inside, index, -1)
        nz = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
        normal = np.concatenate([local, nz[..., None]], axis=-1)
        normal[~inside] = 0.0
        return index, normal, np.where(inside, nz, 0.0)


def background_mask(layout: GridLayout, margin_px: float = 1.0) -> np.ndarray:
    """Pixels whose centre is more than `margin_px` pixels away from every sphere."""
    xy = layout.pixel_world_xy()
    scale = layout.ortho_scale / max(layout.width, layout.height)
    d = np.linalg.norm(xy[:, :, None, :] - layout.centers()[None, None], axis=-1).min(-1)
    return d > layout.radius + margin_px * scale


def tangent_toward_view(normal: np.ndarray) -> np.ndarray:
    """Unit tangent t with wi = mu n + sqrt(1 - mu^2) t (zero at mu = 1, where Vt = 0)."""
    mu = normal[..., 2:3]
    t = VIEW - mu * normal
    norm = np.linalg.norm(t, axis=-1, keepdims=True)
    return np.divide(t, norm, out=np.zeros_like(t), where=norm > 1e-12)


def reference_image(layout: GridLayout, tables: list, env: Environment, moments_at) -> np.ndarray:
    """Reference RGB image of the grid: tables[i] is sphere i's tabulated moments (E, Vn, Vt)
    as returned by `addon.lab.reference.quadrature.tabulate_moments`; `moments_at(table, mu)`
    interpolates them. Background pixels get the environment seen straight down (L(-z))."""
    index, _, _ = layout.pixel_geometry()
    image = np.empty(index.shape + (3,))
    image[:] = env.radiance(-VIEW)
    for sel, (E, Vn, Vt), dn, dt in _sphere_moments(layout, tables, env, moments_at):
        image[sel] = env.constant * E + env.gradient * (Vn * dn + Vt * dt)
    return image


def _sphere_moments(layout: GridLayout, tables: list, env: Environment, moments_at):
    """Per sphere with a table: its pixels (mask), the tables' (E, Vn, Vt) at their mu, and
    n.d, t.d (columns) for the environment's gradient direction d."""
    index, normal, mu = layout.pixel_geometry()
    d = env.unit_direction()
    tangent = tangent_toward_view(normal)
    for i, table in enumerate(tables):
        sel = index == i
        if table is None or not sel.any():
            continue
        yield (sel, moments_at(table, mu[sel]), (normal[sel] @ d)[:, None],
               (tangent[sel] @ d)[:, None])


def reference_error_image(layout: GridLayout, error_tables: list, env: Environment,
                          moments_at) -> np.ndarray:
    """Bound on each reference pixel's error when the moment tables are Monte Carlo estimates
    (the Heitz 2016 walk): error_tables[i] holds the standard errors of sphere i's (E, Vn, Vt)
    (heitz2016.moment_tables), and a pixel's error is at most
    constant SE_E + |gradient| (SE_Vn |n.d| + SE_Vt |t.d|) (its moments' errors added in
    magnitude; interpolation weights near 1). Neighbouring pixels share table nodes, so a band
    mean's reference error is the mean of this image over the band, not less. 0 elsewhere."""
    index, _, _ = layout.pixel_geometry()
    image = np.zeros(index.shape + (3,))
    for sel, (E, Vn, Vt), dn, dt in _sphere_moments(layout, error_tables, env, moments_at):
        image[sel] = env.constant * np.abs(E) + abs(env.gradient) * (np.abs(Vn * dn)
                                                                     + np.abs(Vt * dt))
    return image


@dataclass
class BandStats:
    """Per sphere and band of mu: mean residual, its standard error and the mean reference."""

    sphere: int
    band: tuple[float, float]
    n: int
    bias: np.ndarray  # (3,) mean of render - reference
    stderr: np.ndarray  # (3,) std of the per-pixel residual / sqrt(n)
    reference: np.ndarray  # (3,) mean reference value
    side: int = 0  # +1 / -1: the half of the band leaning toward / away from SIDE_DIRECTION


MU_BANDS = ((0.05, 0.35), (0.35, 0.75), (0.75, 1.0001))
# Absolute accuracy of a reference pixel: quadrature order N vs 2N and the interpolation of the
# moment tables each agree to 1e-4 (tests/test_reference_quadrature.py). A rendered mean can
# only be held to the reference within this, however small its noise.
REFERENCE_ACCURACY = 1e-4


def band_stats(layout: GridLayout, render: np.ndarray, reference: np.ndarray,
               bands=MU_BANDS, sides: bool = True) -> list[BandStats]:
    """Bias of `render` against `reference` per sphere and band of mu, with its noise.

    With `sides` each band is split into the half whose normals lean toward the gradient's
    horizontal direction and the other half (`BandStats.side` +1 / -1; 0 unsplit): an error in
    the tangential moment Vt, or any error odd across the sphere, has opposite signs on the two
    sides (a dipole) and cancels in a whole band. Pixels are independent samples (each pixel has
    its own random streams), so the standard error of a mean residual is the scatter of its
    per-pixel residuals over sqrt(n).
    """
    index, normal, mu = layout.pixel_geometry()
    toward = normal[..., :2] @ SIDE_DIRECTION >= 0.0
    residual = render[..., :3] - reference[..., :3]
    out = []
    for i in range(layout.count):
        for lo, hi in bands:
            band = (index == i) & (mu >= lo) & (mu < hi)
            for side, sel in ([(1, band & toward), (-1, band & ~toward)] if sides
                              else [(0, band)]):
                n = int(sel.sum())
                if n < 8:
                    continue
                r = residual[sel]
                out.append(BandStats(i, (lo, hi), n, r.mean(0),
                                     r.std(0, ddof=1) / np.sqrt(n),
                                     reference[sel][:, :3].mean(0), side))
    return out


@dataclass(frozen=True)
class SphereSpec:
    """One sphere of a grid: a catalog model with parameter values, and a short label."""

    model_id: str
    values: dict
    label: str = ""


_TABLES: dict = {}  # (model, values) -> moment table, for the process


def reference_tables(specs: list) -> list:
    """Tabulated BSDF moments for each sphere (None for a gap), by converged quadrature of the
    model's evaluation formula (addon/lab/reference/quadrature.py), computed once per process for
    each model and set of values (glass tables take seconds) and kept on disk between runs
    (table_cache)."""
    from . import table_cache

    tables = []
    for spec in specs:
        if spec is None:
            tables.append(None)
            continue
        # Keyed by the resolved values (defaults filled in, clamped); the sampler and the
        # estimator do not change the BSDF.
        values = MODELS[spec.model_id].resolve(spec.values)
        key = (spec.model_id, tuple(sorted((k, repr(v)) for k, v in values.items()
                                           if k not in ("sampler", "estimator"))))
        if key not in _TABLES:
            _TABLES[key] = table_cache.tables(
                "quadrature", key, lambda: [tabulate_moments(make_bsdf(spec.model_id,
                                                                       spec.values))])[0]
        tables.append(_TABLES[key])
    return tables


def reference_grid_image(layout: GridLayout, specs: list, env: Environment) -> np.ndarray:
    return reference_image(layout, reference_tables(specs), env, moments_at)


def band_error(layout: GridLayout, error: np.ndarray, stats: list) -> list:
    """Mean of a reference error image (reference_error_image) over each BandStats' pixels
    (the same selection): what the reference's own standard error is in that band."""
    index, normal, mu = layout.pixel_geometry()
    toward = normal[..., :2] @ SIDE_DIRECTION >= 0.0
    out = []
    for b in stats:
        sel = (index == b.sphere) & (mu >= b.band[0]) & (mu < b.band[1])
        if b.side:
            sel &= toward if b.side > 0 else ~toward
        out.append(error[sel].mean(0))
    return out


def band_failures(layout: GridLayout, render: np.ndarray, reference: np.ndarray, labels: list,
                  floors=None, error: np.ndarray | None = None) -> tuple[float, list[str]]:
    """Every band (per sphere, band of mu and side) whose bias exceeds the Sidak z over all
    bands and channels times its noise, plus the reference's accuracy: (z_crit, a message per
    failing band). The noise is the render's, combined with the reference's standard error
    where it has one (`error`: a reference_error_image of Monte Carlo tables); the accuracy is
    `floors[sphere]` (default REFERENCE_ACCURACY for every sphere)."""
    bands = band_stats(layout, render, reference)
    z_crit = sidak_z(3 * len(bands))
    errors = band_error(layout, error, bands) if error is not None else [0.0] * len(bands)
    failures = []
    for b, e in zip(bands, errors):
        floor = REFERENCE_ACCURACY if floors is None else floors[b.sphere]
        noise = np.sqrt(b.stderr ** 2 + e ** 2) if error is not None else b.stderr
        if (np.abs(b.bias) > z_crit * noise + floor).any():
            z = np.abs(b.bias) / np.maximum(noise, 1e-9)
            failures.append(f"{labels[b.sphere]} mu in {b.band} side {b.side}: bias {b.bias} "
                            f"render se {b.stderr} reference se {e} ref {b.reference} "
                            f"z {z.max():.1f}")
    return z_crit, failures


def inconsistent(stats: BandStats, z_crit: float) -> bool:
    """True when a band's bias is not explained by its noise and the reference's accuracy."""
    return bool((np.abs(stats.bias) > z_crit * stats.stderr + REFERENCE_ACCURACY).any())


def relative_bias_failures(layout: GridLayout, render: np.ndarray, reference: np.ndarray,
                           labels: list, limit: float = 0.01,
                           error: np.ndarray | None = None) -> list[str]:
    """Whole spheres (mu > 0.05) held to a relative bias below `limit`: a message per sphere
    whose noise (the render's, with the reference's standard error where `error` gives one)
    could not reveal such a bias (Sidak z over all spheres, the test would have no power) or
    whose bias exceeds it; empty when every sphere passes."""
    spheres = band_stats(layout, render, reference, bands=((0.05, 1.0001),), sides=False)
    z_crit = sidak_z(3 * len(spheres))
    errors = band_error(layout, error, spheres) if error is not None else None
    failures = []
    for i, s in enumerate(spheres):
        noise = np.sqrt(s.stderr ** 2 + errors[i] ** 2) if errors is not None else s.stderr
        relative_noise = noise / s.reference
        relative_bias = np.abs(s.bias) / s.reference
        if (relative_noise * z_crit > limit).any():
            failures.append(f"{labels[s.sphere]}: no power, relative noise {relative_noise}")
        if (relative_bias > limit).any():
            failures.append(f"{labels[s.sphere]}: relative bias {relative_bias}")
    return failures


def noise_calibration_failure(layout: GridLayout, image: np.ndarray, image2: np.ndarray,
                              reference: np.ndarray) -> str:
    """Two seeds: the differences of their band means over the per-pixel noise estimate must be
    standard normal, else pixels are correlated and every z of a test is off; '' when they are.
    One channel: the three share their random numbers, so they are not independent."""
    s1 = band_stats(layout, image, reference)
    s2 = band_stats(layout, image2, reference)
    z = np.array([(a.bias[1] - b.bias[1]) / np.sqrt(a.stderr[1] ** 2 + b.stderr[1] ** 2)
                  for a, b in zip(s1, s2) if a.stderr[1] > 0])
    # Variance of a standard normal estimated from len(z) values: 1 +- a few sqrt(2 / len).
    if abs(z.var() - 1.0) < 5 * np.sqrt(2.0 / len(z)):
        return ""
    return f"var(z) = {z.var():.3f}, n = {len(z)}"


def sidak_z(tests: int, family_alpha: float = 1e-3) -> float:
    """Two-sided z threshold for `tests` comparisons at family-wise error `family_alpha`."""
    from statistics import NormalDist

    alpha = 1.0 - (1.0 - family_alpha) ** (1.0 / max(tests, 1))
    return NormalDist().inv_cdf(1.0 - alpha / 2.0)
