"""The report's lights as numbers (numpy, no bpy): the sun's direction, a cone light's radiance,
the point and area lamps' geometry, an HDRI's spot as an image. scenes.py builds them in Blender,
references.py integrates them; both read them here."""
from __future__ import annotations

import math

import numpy as np

from ...world_spots import equirect_direction
from .config import (AREA_LAMP, CONE_LIGHTS, HDRI_SIZE, POINT_LAMP, SPOT_STRENGTH, SUN_DIRECTION,
                     SUN_STRENGTH)


def sun_unit() -> np.ndarray:
    d = np.asarray(SUN_DIRECTION, dtype=float)
    return d / np.linalg.norm(d)


def cone_radiance(env_key, sun_cal) -> tuple:
    """(radiance, half-angle) of a cone light: a lamp's from the 4-degree sun's calibration
    (the measured over the formula's radiance, the same factor at every angle), the world
    spot's exactly."""
    kind, angle = CONE_LIGHTS[env_key]
    half = math.radians(angle) / 2.0
    formula = 1.0 / (2.0 * math.pi * (1.0 - math.cos(half)))
    if kind in ("world", "image"):
        return SPOT_STRENGTH * formula, half
    return SUN_STRENGTH * formula * sun_cal["radiance"] / sun_cal["formula"], half


def point_radiance(power=POINT_LAMP["power"], radius=POINT_LAMP["radius"]) -> float:
    """Cycles' point lamp radiance P / (4 pi^2 r^2) (scene/light.cpp: flux over the sphere's
    area times 1/pi), uniform over the disk it shows."""
    return power / (4.0 * math.pi ** 2 * radius ** 2)


def area_lamp_axes():
    """(centre, u, v) of the report's area lamp: half-extents along its X and Y, world space."""
    c, s = math.cos(AREA_LAMP["tilt"]), math.sin(AREA_LAMP["tilt"])
    sx, sy = AREA_LAMP["size"]
    return ((0.0, 0.0, AREA_LAMP["height"]), (0.5 * sx, 0.0, 0.0), (0.0, 0.5 * sy * c, 0.5 * sy * s))


def spot_image(width: int, height: int, direction, half: float, radiance: float):
    """(H, W) radiance of an equirectangular world that is black but for the pixels whose
    centre lies within `half` of `direction` (an HDRI's sun, drawn in pixels)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    centres = equirect_direction(u[None, :], v[:, None])
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.where(centres @ d >= math.cos(half), float(radiance), 0.0)


def hdri_spot(env_key, sun_cal) -> np.ndarray:
    """The spot of an "image" cone light in pixels (HDRI_SIZE), black around it."""
    radiance, half = cone_radiance(env_key, sun_cal)
    return spot_image(*HDRI_SIZE, sun_unit(), half, radiance)
