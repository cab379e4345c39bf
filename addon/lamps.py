"""The scene's lamps as the shaders see them: records (no bpy; addon/shaders.py writes them into
the shader text as an OSL table, `lamp_table_block`).

The add-on hands each lamp to the Microfacet Lab shaders (addon/handover.py reads the scene);
a shader aims part of its stochastic residual at them (osl/lamps.h, docs/light-sampling.md,
"The residual's direct light"). A record only guides where the residual's rays go: the shader
divides by the density it really sampled with, so a stale, wrong or missing record changes the
noise, never the converged image.

Record slots (RECORD_SIZE floats, world space):
  0      kind (KINDS index)
  1-3    position: sphere and area centre (unused for the sun)
  4-6    axis: sun, unit direction toward the light; area, unit emitting normal (the lamp's -Z)
  7-9    u: area half-extent along the lamp's X (world length)
  10-12  v: area half-extent along the lamp's Y
  13     size: sun, 1 - cos(half-angle); sphere, radius
  14     power: guiding weight (strength times the colour's luminance), finite, > 0
  15     shape of a point or spot lamp: 1 a sphere, 0 a disk of that radius facing the shading
         point (Blender's Soft Falloff, the default; Cycles' "is_sphere" off); a world spot
         with texels (below): 1 + their offset in the shader's texel table (0: none)
  16-18  radiance: the lamp's radiance as Cycles emits it (RGB), 0 where not predicted (a
         spot's cone, an area lamp's spread, a lamp with nodes or light linking). A world
         spot's is its texels' mean, and the shader reads its texels instead.
         It drives the shaders' control variate (osl/nee.h), whose mean is 0 whatever it says:
         it too only moves noise.

A world spot's texels (SpotTexels) are the equirectangular image's own pixels about the spot,
times the Background's strength, which the shader reads as Cycles reads the image (osl/spots.h
spot_radiance); their table's slots, from the record's offset:
  0-1    the image's width and height
  2-5    the box: first column, first row (row 0 at the bottom), columns, rows (columns wrap)
  6      1 for Linear interpolation, 0 for Closest
  7-15   the rotation taking a world direction to the image's lookup direction, row by row
  16-    the box's linear RGB, row by row from its first row
  then   the box's texels' cumulative shares in the shaders' sampling (SpotTexels.cumulative)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

KINDS = ("sun", "sphere", "rect", "ellipse")
RECORD_SIZE = 19
SPOT_HEADER_SIZE = 16  # a world spot's texel slots before its RGB (osl/spots.h MFL_SPOT_HEADER)
# Lamps beyond this many are not handed over (the shader loops over every record per sample).
MAX_LAMPS = 128
# A guiding weight is clamped to this, so that sums over 100 lamps stay finite in float.
MAX_POWER = 1e20
# Rec. 709 luminance weights, for the guiding weight of a coloured lamp.
LUMINANCE = (0.2126, 0.7152, 0.0722)


@dataclass(frozen=True)
class SpotTexels:
    """A world spot's pixels as the shader reads them (the table's slots: module docstring)."""
    width: int
    height: int
    box: tuple  # (first column, first row, columns, rows)
    linear: bool
    rotation: tuple  # 9 floats, row by row
    rgb: tuple  # columns * rows * 3 floats

    def floats(self) -> list[float]:
        header = [float(self.width), float(self.height), *map(float, self.box),
                  float(self.linear), *map(float, self.rotation)]
        assert len(header) == SPOT_HEADER_SIZE
        return header + [float(x) for x in self.rgb] + self.cumulative()

    def texel_solid_angle(self, row: int) -> float:
        """Solid angle of one texel of image row `row` (row 0 at the bottom)."""
        s0, s1 = (math.sin((y / self.height - 0.5) * math.pi) for y in (row, row + 1))
        return 2.0 * math.pi / self.width * (s1 - s0)

    def cumulative(self) -> list[float]:
        """The box's texels' cumulative shares in the shaders' sampling (osl/spots.h
        spot_sample), row by row: luminance times solid angle, the luminance for Linear the
        largest of the texel's 3 x 3 neighbours (a Linear lookup inside a texel reads those), so
        that every direction with light has a density; the last share is 1."""
        cols, rows = self.box[2], self.box[3]
        lum = [[sum(w * self.rgb[3 * (r * cols + c) + k] for k, w in enumerate(LUMINANCE))
                for c in range(cols)] for r in range(rows)]
        if self.linear:
            lum = [[max(lum[rr][cc] for rr in range(max(r - 1, 0), min(r + 2, rows))
                        for cc in range(max(c - 1, 0), min(c + 2, cols)))
                    for c in range(cols)] for r in range(rows)]
        total, out = 0.0, []
        for r in range(rows):
            omega = self.texel_solid_angle(self.box[1] + r)
            for c in range(cols):
                total += max(lum[r][c], 0.0) * omega
                out.append(total)
        return [x / total for x in out] if total > 0.0 else [(i + 1.0) / len(out)
                                                             for i in range(len(out))]


@dataclass(frozen=True)
class LampRecord:
    kind: str
    position: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    u: tuple = (0.0, 0.0, 0.0)
    v: tuple = (0.0, 0.0, 0.0)
    size: float = 0.0
    power: float = 1.0
    is_sphere: bool = False
    radiance: tuple = (0.0, 0.0, 0.0)
    texels: SpotTexels | None = None  # a world spot's pixels (suns only)

    def floats(self, texel_offset: int = -1) -> list[float]:
        """The record's slots; `texel_offset`, where its texels start in the shader's table."""
        shape = float(self.is_sphere) if self.texels is None else float(texel_offset + 1)
        return ([float(KINDS.index(self.kind)), *self.position, *self.axis, *self.u, *self.v,
                 self.size, self.power, shape, *self.radiance])


def _finite(values) -> bool:
    return all(math.isfinite(float(x)) for x in values)


def _unit(v):
    n = math.sqrt(sum(float(x) * float(x) for x in v))
    return tuple(float(x) / n for x in v) if n > 0 and math.isfinite(n) else None


def guiding_power(strength: float, colour) -> float:
    """Strength times luminance, or 0 for a lamp not worth aiming at (zero, negative, NaN)."""
    try:
        p = float(strength) * sum(w * float(c) for w, c in zip(LUMINANCE, colour))
    except (TypeError, ValueError):
        return 0.0
    if not math.isfinite(p) or p <= 0.0:
        return 0.0
    return min(p, MAX_POWER)


def predicted_radiance(strength: float, colour, per_area: float) -> tuple:
    """strength times colour over `per_area` (the lamp's Cycles normalisation: pi sin^2 of the
    sun's half-angle, 4 pi^2 r^2 for a point lamp, pi A for an area lamp), or zeros where any
    of it is not finite and positive."""
    try:
        values = tuple(float(strength) * float(c) / float(per_area) for c in colour[:3])
    except (TypeError, ValueError, ZeroDivisionError):
        return (0.0, 0.0, 0.0)
    if not all(math.isfinite(x) and x >= 0.0 for x in values) or not sum(values) > 0.0:
        return (0.0, 0.0, 0.0)
    return tuple(min(x, MAX_POWER) for x in values)


def sun_record(toward_light, angle: float, power: float, radiance=(0.0, 0.0, 0.0)):
    """A sun of full angle `angle` (radians) whose light comes from `toward_light`; None when
    it cannot be aimed at (zero angle: a direction, no solid angle to hit; bad values)."""
    d = _unit(toward_light)
    if d is None or power <= 0.0 or not math.isfinite(angle) or angle <= 0.0:
        return None
    half = min(angle, math.pi) / 2.0
    one_minus_cos = 2.0 * math.sin(half / 2.0) ** 2  # 1 - cos(half), without cancellation
    if one_minus_cos <= 1e-12:
        return None
    return LampRecord("sun", axis=d, size=one_minus_cos, power=power, radiance=tuple(radiance))


def sphere_record(position, radius: float, power: float, is_sphere: bool = False,
                  radiance=(0.0, 0.0, 0.0)):
    """A point or spot lamp of `radius`: with Soft Falloff (Blender's default) Cycles makes it a
    disk facing the shading point, without it a sphere; None for radius 0 (a point cannot be hit
    by a ray) and bad values."""
    if power <= 0.0 or not _finite(position) or not math.isfinite(radius) or radius <= 0.0:
        return None
    return LampRecord("sphere", position=tuple(map(float, position)), size=float(radius),
                      power=power, is_sphere=bool(is_sphere), radiance=tuple(radiance))


def area_record(shape: str, position, normal, u, v, power: float, radiance=(0.0, 0.0, 0.0)):
    """A rectangle or ellipse with half-extent axes u, v, emitting along `normal`; None when
    degenerate."""
    n = _unit(normal)
    if (n is None or power <= 0.0 or not _finite((*position, *u, *v))
            or _unit(u) is None or _unit(v) is None):
        return None
    kind = "ellipse" if shape in ("DISK", "ELLIPSE") else "rect"
    return LampRecord(kind, position=tuple(map(float, position)), axis=n,
                      u=tuple(map(float, u)), v=tuple(map(float, v)), power=power,
                      radiance=tuple(radiance))
