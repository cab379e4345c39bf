"""Bright spots of the world as cone records (numpy only, no bpy): an HDRI's sun found in its
pixels, or the Sky Texture's sun disc.

A Microfacet Lab residual aims at a world spot as at a sun lamp (addon/lamps.py: a record only
guides where rays go, so a spot found too big, too small or in the wrong place changes the
noise, never the converged image). addon/handover.py reads the world's nodes and hands the
spots over with the lamps.

Conventions are Cycles' (kernel/camera/projection.h): an equirectangular image maps the
direction d to u = 1/2 - atan2(d_y, d_x) / (2 pi), v = 1 - acos(d_z) / pi, with image row 0 at
v = 0 (the bottom, Blender's pixel order).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .lamps import LUMINANCE, SpotTexels, sun_record

# At most this many spots per world texture (each costs the shader a record per sample).
MAX_SPOTS = 2
# A pixel belongs to a spot when its radiance is over this many times the world's mean.
SPOT_CONTRAST = 20.0
# A spot is handed over when it carries at least this share of the world's power.
MIN_SPOT_SHARE = 0.05
# Bright pixels this far from a spot's brightest pixel are not part of it (a spot is small).
MAX_SPOT_HALF_ANGLE = math.radians(10.0)
# A spot's own pixels go to the shaders (their prediction of its light, osl/nee.h, and the
# directions drawn toward it, osl/spots.h) when the box a lookup inside its cone may read has
# at most this many a side (40 x 40 RGB and sampling shares: 6,400 floats in the shader's
# text); a larger spot is aimed at and controlled as before.
MAX_TEXELS = 40


def equirect_direction(u, v) -> np.ndarray:
    """Unit directions (..., 3) that Cycles' equirectangular map sends to (u, v)."""
    u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
    phi = math.pi - 2.0 * math.pi * u
    theta = math.pi * (1.0 - v)
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], -1)


def row_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle of one pixel in each image row (row 0 at the bottom): (height,)."""
    z = np.cos(math.pi * (1.0 - np.arange(height + 1) / height))  # cos(theta) at row edges
    return (2.0 * math.pi / width) * np.diff(z)


def luminance(pixels: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of (H, W, >=3) linear pixels; NaN, infinite and negative values as 0."""
    rgb = np.asarray(pixels)[..., :3]
    if rgb.dtype != np.float32:  # float32 stays so (an HDRI's band); anything else in float64
        rgb = rgb.astype(np.float64)
    lum = np.tensordot(rgb, np.asarray(LUMINANCE, dtype=rgb.dtype), axes=1)
    lum = np.nan_to_num(lum, nan=0.0, posinf=0.0, neginf=0.0)
    return np.maximum(lum, 0.0)


def _cell_corners(rows, cols, height, width) -> np.ndarray:
    """Corner directions of pixels (rows, cols): (n, 4, 3)."""
    du, dv = np.meshgrid([0.0, 1.0], [0.0, 1.0])
    u = (cols[:, None] + du.reshape(-1)) / width
    v = (rows[:, None] + dv.reshape(-1)) / height
    return equirect_direction(u, v)


def _spot(rows, cols, power, height, width):
    """(axis, half-angle, power) of the cone around the pixels (rows, cols) of `power` each:
    the axis is their power-weighted mean direction, the cone holds every corner."""
    centres = equirect_direction((cols + 0.5) / width, (rows + 0.5) / height)
    axis = (power[:, None] * centres).sum(0)
    axis /= np.linalg.norm(axis)
    corners = _cell_corners(rows, cols, height, width)
    half = float(np.arccos(np.clip(corners @ axis, -1.0, 1.0)).max())
    return axis, half, float(power.sum())


def image_spots(lum: np.ndarray, max_spots: int = MAX_SPOTS) -> list:
    """The bright spots of an equirectangular luminance image (H, W), brightest first: a list of
    (axis, half-angle, power), power the spot's irradiance at normal incidence (its luminance
    integrated over its solid angle, as a sun lamp's strength)."""
    lum = np.asarray(lum)
    return band_spots([(0, lum)], *lum.shape, max_spots=max_spots)


def band_spots(bands, height: int, width: int, max_spots: int = MAX_SPOTS) -> list:
    """image_spots of an image read in bands of rows: `bands` yields (first row, (rows, W)
    luminance), rows counted from the bottom, in any order. Holds one band and the bright
    pixels at a time, not the image: a pixel is bright against the world's mean, known only
    at the end, so after each band only the pixels over the mean seen so far are kept (a lower
    bound: a superset), 8 bytes each, and the final mean sorts them (the same pixels as the
    whole image's)."""
    omega = row_solid_angles(height, width)
    total, chunks = 0.0, []  # chunks: (flat pixel index int32, luminance float32) of bright pixels
    for first, band in bands:
        band = np.maximum(np.nan_to_num(np.asarray(band, dtype=np.float32), nan=0.0, posinf=0.0,
                                        neginf=0.0), 0.0)
        total += float(band.sum(1, dtype=np.float64) @ omega[first:first + len(band)])
        index = np.flatnonzero(band > _bright(total))
        chunks.append(((index + first * width).astype(np.int32), band.ravel()[index]))
        chunks = [(i[v > _bright(total)], v[v > _bright(total)]) for i, v in chunks]
    if not math.isfinite(total) or total <= 0.0:
        return []
    index = np.concatenate([i for i, _ in chunks]) if chunks else np.empty(0, np.int32)
    lum = np.concatenate([v for _, v in chunks]).astype(np.float64) if chunks else np.empty(0)
    rows, cols = np.divmod(index.astype(np.int64), width)
    return _group_spots(rows, cols, lum, omega, height, width, total, max_spots)


def _bright(total: float) -> float:
    """The luminance over which a pixel may belong to a spot, for a world of power `total`."""
    return SPOT_CONTRAST * total / (4.0 * math.pi)


def _group_spots(rows, cols, lum, omega, height, width, total, max_spots):
    """Spots from the bright pixels (rows, cols) of luminance `lum`: the brightest pixel and the
    bright pixels near it make a spot, while it carries enough of the world's power."""
    energy = lum * omega[rows]
    spots = []
    while len(rows) and len(spots) < max_spots:
        top = int(np.argmax(lum))
        centres = equirect_direction((cols + 0.5) / width, (rows + 0.5) / height)
        near = centres @ centres[top] >= math.cos(MAX_SPOT_HALF_ANGLE)
        axis, half, power = _spot(rows[near], cols[near], energy[near], height, width)
        if power < MIN_SPOT_SHARE * total:
            break
        spots.append((axis, half, power))
        rows, cols, lum, energy = rows[~near], cols[~near], lum[~near], energy[~near]
    return spots


def texel_box(axis, half: float, height: int, width: int):
    """(first column, first row, columns, rows) of the pixels that a Closest or Linear lookup
    (Cycles' interp_closest, interp_linear) of a direction inside the cone (axis, half-angle)
    may read, rows from the bottom, columns wrapping around; None where the cone holds a pole
    or the box has over MAX_TEXELS a side."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    elevation = math.asin(min(1.0, max(-1.0, float(a[2]))))
    if not 0.0 < half < math.pi / 2 - abs(elevation):
        return None
    # v = 1/2 + elevation / pi; the cone's widest longitude: sin(dphi) = sin(half) / cos(elevation)
    y_lo, y_hi = ((0.5 + (elevation + s * half) / math.pi) * height for s in (-1.0, 1.0))
    dphi = math.asin(min(1.0, math.sin(half) / math.cos(elevation)))
    u = 0.5 - math.atan2(float(a[1]), float(a[0])) / (2.0 * math.pi)
    x_lo, x_hi = ((u + s * dphi / (2.0 * math.pi)) * width for s in (-1.0, 1.0))
    # Linear reads floor(x - 1/2) and the next; Closest floor(x): both within these bounds.
    row0 = max(0, math.floor(y_lo - 0.5))
    rows = min(height - 1, math.floor(y_hi + 0.5)) - row0 + 1
    col0 = math.floor(x_lo - 0.5)
    cols = math.floor(x_hi + 0.5) - col0 + 1
    if rows > MAX_TEXELS or cols > min(MAX_TEXELS, width):
        return None
    return col0 % width, row0, cols, rows


def box_texels(box, rgb, width: int, height: int, linear: bool, rotation=None,
               scale: float = 1.0):
    """SpotTexels of the box's (rows, columns, 3) linear `rgb` times `scale`, or None where a
    value is not finite or none is positive."""
    rgb = np.asarray(rgb, dtype=np.float64) * scale
    if rgb.shape != (box[3], box[2], 3) or not np.isfinite(rgb).all() or not (rgb > 0).any():
        return None
    rotation = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    return SpotTexels(width, height, tuple(int(b) for b in box), bool(linear),
                      tuple(rotation.reshape(-1)), tuple(np.maximum(rgb, 0.0).reshape(-1)))


def spot_pixel(texels: SpotTexels, dirs) -> tuple:
    """Where the spot's image reads the world directions (n, 3): pixel coordinates (x, y)."""
    d = np.asarray(dirs, dtype=float) @ np.asarray(texels.rotation, dtype=float).reshape(3, 3).T
    x = (0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * math.pi)) * texels.width
    y = (np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) / math.pi + 0.5) * texels.height
    return x, y


def spot_sin_latitude(texels: SpotTexels, y):
    """sin(latitude) at the bottom edge of image rows y (row 0 at the bottom)."""
    return np.sin((np.asarray(y, dtype=float) / texels.height - 0.5) * math.pi)


def spot_texel_solid_angle(texels: SpotTexels, iy):
    """Solid angle of one texel of image rows iy: (2 pi / W) (sin lat_top - sin lat_bottom)."""
    return (2.0 * math.pi / texels.width) * (spot_sin_latitude(texels, np.asarray(iy) + 1)
                                             - spot_sin_latitude(texels, iy))


def spot_sample(texels: SpotTexels, u1, u2) -> np.ndarray:
    """World directions (n, 3) over the spot's texels (twin of osl/spots.h spot_sample): texel
    t with its share (SpotTexels.cumulative) by u1, uniform over its solid angle: u1's place
    within the share across its columns, u2 uniform in sin(latitude) across its row."""
    cum = np.asarray(texels.cumulative())
    col0, row0, cols, _ = texels.box
    u1 = np.asarray(u1, dtype=float)
    t = np.minimum(np.searchsorted(cum, u1, side="right"), len(cum) - 1)
    before = np.where(t > 0, cum[np.maximum(t - 1, 0)], 0.0)
    share = cum[t] - before
    fx = np.where(share > 0.0, np.clip((u1 - before) / np.where(share > 0, share, 1.0), 0, 1),
                  0.5)
    x = col0 + t % cols + fx
    y = row0 + t // cols
    s0, s1 = spot_sin_latitude(texels, y), spot_sin_latitude(texels, y + 1)
    sl = s0 + (s1 - s0) * np.asarray(u2, dtype=float)
    cl = np.sqrt(np.maximum(1.0 - sl * sl, 0.0))
    phi = (0.5 - x / texels.width) * 2.0 * math.pi
    d = np.stack([cl * np.cos(phi), cl * np.sin(phi), sl], -1)
    return d @ np.asarray(texels.rotation, dtype=float).reshape(3, 3)  # R^T d


def spot_pdf(texels: SpotTexels, dirs) -> np.ndarray:
    """spot_sample's density over solid angle toward world directions (n, 3) (twin of
    osl/spots.h spot_pdf): the share of the texel each falls in over its solid angle."""
    cum = np.asarray(texels.cumulative())
    col0, row0, cols, rows = texels.box
    x, y = spot_pixel(texels, dirs)
    ix, iy = np.floor(x).astype(int), np.floor(y).astype(int)
    c = (ix - col0) % texels.width
    r = np.clip(iy, 0, texels.height - 1) - row0
    inside = (c < cols) & (r >= 0) & (r < rows) & (iy >= 0) & (iy < texels.height)
    t = np.where(inside, r * cols + c, 0)
    share = cum[t] - np.where(t > 0, cum[np.maximum(t - 1, 0)], 0.0)
    omega = spot_texel_solid_angle(texels, np.clip(iy, 0, texels.height - 1))
    return np.where(inside, share / omega, 0.0)


def sky_sun_direction(elevation: float, rotation: float) -> np.ndarray:
    """Direction toward the Sky Texture's sun disc (Cycles' svm sky: spherical_to_direction(
    elevation - pi/2, rotation' - pi/2), rotation' = 2 pi - rotation as Cycles patches it)."""
    ce = math.cos(elevation)
    return np.array([ce * math.sin(rotation), ce * math.cos(rotation), math.sin(elevation)])


def spot_records(spots, rotation=None, scale: float = 1.0, texels=None) -> list:
    """LampRecords (kind "sun") of spots (axis, half-angle, power) found in texture space:
    `rotation` (3x3) maps a world direction to the texture's lookup direction (None: the same),
    `scale` multiplies the power (the Background's strength). `texels`, one per spot, SpotTexels
    (of the strength's radiance) or None: a spot with texels gets their mean as its predicted
    radiance, which the shaders read from them."""
    records = []
    for i, (axis, half, power) in enumerate(spots):
        d = np.asarray(axis, dtype=float)
        if rotation is not None:
            d = np.asarray(rotation, dtype=float).T @ d  # a rotation's inverse
        p = power * scale
        if not math.isfinite(p) or p <= 0.0:
            continue
        record = sun_record(tuple(d), 2.0 * half, min(p, 1e20))
        spot = None if texels is None else texels[i]
        if record is not None and spot is not None:
            mean = np.asarray(spot.rgb).reshape(-1, 3).mean(0)
            record = replace(record, texels=spot, radiance=tuple(np.minimum(mean, 1e20)))
        if record is not None:
            records.append(record)
    return records
