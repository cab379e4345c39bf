"""The world's bright spots found in an equirectangular image (addon/world_spots.py, numpy only).

What this catches: a direction convention that does not invert the image mapping (the spot
would be handed over where it is not: noise, not bias, so only this test and the render test
in tests/test_handover.py see it), pixel solid angles that do not sum to the sphere (a wrong
spot power against the lamps'), a cone that does not hold the spot's pixels, spots split at
the image's seam or pole, a uniform or faint world handed over as spots, and NaN, infinite or
negative pixels that reach the records. Tolerances: exact identities to rounding, and the
pixel size for directions."""
import math

import numpy as np
import pytest

from addon import world_spots as ws
from addon.lamps import SPOT_HEADER_SIZE

W, H = 128, 64


def _spot(direction, half, radiance=100.0, background=0.1):
    u = (np.arange(W) + 0.5) / W
    v = (np.arange(H) + 0.5) / H
    centres = ws.equirect_direction(u[None, :], v[:, None])
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    inside = centres @ d >= math.cos(half)
    return np.where(inside, radiance, background), inside, centres


def test_equirect_direction_inverts_cycles_mapping():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # Cycles' direction_to_equirectangular_range with range (-2 pi, pi, -pi, pi).
    u = (np.arctan2(d[:, 1], d[:, 0]) - math.pi) / (-2.0 * math.pi)
    v = (np.arccos(d[:, 2]) - math.pi) / (-math.pi)
    assert np.abs(ws.equirect_direction(u, v) - d).max() < 1e-12


def test_pixel_solid_angles_sum_to_the_sphere():
    omega = ws.row_solid_angles(H, W)
    assert (omega > 0).all()
    assert abs(omega.sum() * W - 4.0 * math.pi) < 1e-12
    assert np.allclose(omega, omega[::-1])  # symmetric about the horizon


@pytest.mark.parametrize("direction", [(0.6, 0.48, 0.64), (-1.0, 0.0, 0.1), (0.0, 0.1, 1.0)],
                         ids=["sun", "seam", "pole"])
def test_a_spot_is_found_where_it_is_drawn(direction):
    half = math.radians(4.0)
    image, inside, centres = _spot(direction, half)
    (axis, found_half, power), = ws.image_spots(ws.luminance(np.repeat(image[..., None], 3, -1)))
    d = np.asarray(direction) / np.linalg.norm(direction)
    pixel = math.pi / H
    assert math.acos(min(1.0, float(axis @ d))) < pixel
    # The cone holds every drawn pixel's centre, and is not much wider than the spot.
    assert (centres[inside] @ axis >= math.cos(found_half)).all()
    assert found_half < half + 2.0 * pixel
    omega = ws.row_solid_angles(H, W)[:, None] * np.ones((1, W))
    assert power == pytest.approx(float((image * omega)[inside].sum()), rel=1e-12)


def test_two_spots_brightest_first_and_faint_or_uniform_worlds_none():
    a, _, _ = _spot((0.6, 0.48, 0.64), math.radians(3.0), radiance=50.0, background=0.0)
    b, _, _ = _spot((-0.5, 0.2, 0.3), math.radians(5.0), radiance=80.0, background=0.0)
    spots = ws.image_spots(a + b)
    assert len(spots) == 2 and spots[0][2] > spots[1][2]
    assert spots[0][0] @ (np.array([-0.5, 0.2, 0.3]) / np.linalg.norm([-0.5, 0.2, 0.3])) > 0.99
    assert ws.image_spots(np.full((H, W), 3.0)) == []
    faint, _, _ = _spot((0.6, 0.48, 0.64), math.radians(1.0), radiance=25.0, background=1.0)
    assert ws.image_spots(faint) == []  # bright enough, but under 5% of the world's power


def test_bad_pixels_never_reach_the_records():
    image, _, _ = _spot((0.6, 0.48, 0.64), math.radians(4.0))
    rgb = np.repeat(image[..., None], 3, -1)
    rgb[0, 0] = np.nan
    rgb[1, 1] = np.inf
    rgb[2, 2] = -1e30
    lum = ws.luminance(rgb)
    assert np.isfinite(lum).all() and (lum >= 0).all()
    (record,) = ws.spot_records(ws.image_spots(lum), scale=2.0)
    assert record.kind == "sun" and all(math.isfinite(x) for x in record.floats())
    assert ws.spot_records(ws.image_spots(lum), scale=float("nan")) == []
    assert ws.image_spots(np.zeros((H, W))) == []


def test_a_rotation_maps_the_spot_back_to_the_world():
    """The texture looks up R d: a spot drawn at t in the image lies at R^T t in the world."""
    c, s = math.cos(0.7), math.sin(0.7)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([0.6, 0.48, 0.64])
    (record,) = ws.spot_records([(t, 0.05, 1.0)], rotation=rot)
    assert np.allclose(rot @ np.array(record.axis), t)


def test_sky_sun_direction():
    assert np.allclose(ws.sky_sun_direction(math.pi / 2, 1.0), [0.0, 0.0, 1.0])
    assert np.allclose(ws.sky_sun_direction(0.0, 0.0), [0.0, 1.0, 0.0])  # rotation 0: +Y
    assert np.allclose(ws.sky_sun_direction(0.0, math.pi / 2), [1.0, 0.0, 0.0])


def _cone_directions(axis, half, n, rng):
    """n directions uniform in the cone (axis, half-angle)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    t = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(a, t)
    ct = 1.0 - rng.uniform(0.0, 1.0, n) * (1.0 - math.cos(half))
    st, phi = np.sqrt(1.0 - ct * ct), rng.uniform(0.0, 2.0 * math.pi, n)
    return ct[:, None] * a + st[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b)


def test_a_texel_box_holds_every_pixel_a_lookup_in_the_cone_reads():
    """Cycles' Closest reads pixel floor(u W, v H), Linear floor(x - 1/2) and the next: for
    cones anywhere, seams included, every read of 2,000 directions in the cone falls in the box
    (else the shaders' prediction is 0 where the world is not: noise, never bias, so only this
    test sees it). Cones holding a pole, or too wide, get no box."""
    rng = np.random.default_rng(1)
    height, width = 512, 1024
    boxes = 0
    for _ in range(300):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        half = rng.uniform(0.002, 0.06)
        box = ws.texel_box(axis, half, height, width)
        if box is None:
            assert abs(math.asin(axis[2])) + half >= math.pi / 2 or \
                2.0 * half / math.pi * height > ws.MAX_TEXELS - 3 or \
                half / math.cos(math.asin(axis[2])) / math.pi * width > ws.MAX_TEXELS - 3
            continue
        boxes += 1
        col0, row0, cols, rows = box
        d = _cone_directions(axis, half, 2000, rng)
        x = (0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * math.pi)) * width
        y = (1.0 - np.arccos(np.clip(d[:, 2], -1.0, 1.0)) / math.pi) * height
        for ix, iy in ((np.floor(x), np.floor(y)), (np.floor(x - 0.5), np.floor(y - 0.5)),
                       (np.floor(x - 0.5) + 1, np.floor(y - 0.5) + 1)):
            c = (ix - col0) % width
            r = np.clip(iy, 0, height - 1) - row0
            assert (c < cols).all() and (r >= 0).all() and (r < rows).all(), (axis, half, box)
    assert boxes > 150
    assert ws.texel_box([0.0, 0.1, 0.99], 0.2, height, width) is None  # holds the pole
    assert ws.texel_box([1.0, 0.0, 0.0], 0.3, height, width) is None  # too many texels


def test_texels_carry_the_strength_and_refuse_bad_pixels():
    box = (126, 10, 4, 3)  # across the seam
    rgb = np.full((3, 4, 3), 2.0)
    texels = ws.box_texels(box, rgb, W, H, linear=True, scale=1.5)
    assert texels.box == box and texels.linear and np.allclose(texels.rgb, 3.0)
    assert len(texels.floats()) == SPOT_HEADER_SIZE + 4 * 4 * 3  # RGB and sampling shares
    (record,) = ws.spot_records([((0.6, 0.48, 0.64), 0.05, 1.0)], texels=[texels])
    assert record.texels is texels and np.allclose(record.radiance, 3.0)
    rgb[0, 0, 0] = np.nan
    assert ws.box_texels(box, rgb, W, H, linear=False) is None
    assert ws.box_texels(box, np.zeros((3, 4, 3)), W, H, linear=False) is None
    assert ws.box_texels(box, np.ones((4, 4, 3)), W, H, linear=False) is None  # wrong shape


@pytest.mark.parametrize("linear", [False, True])
def test_spot_sampling_draws_what_its_density_says(linear):
    """The shaders' sampling over a spot's texels (osl/spots.h, twin spot_sample / spot_pdf):
    draws fall in each texel as its share says, the density integrates to 1 over the sphere,
    and every direction a lookup finds light in has a density (else the control variate would
    leave that light to the delta alone: exact, but the noise this sampling removes). Would
    catch a share not matching its texel, a density off by the texel's solid angle or a
    rotation applied the wrong way round."""
    rng = np.random.default_rng(7)
    box = (126, 40, 5, 4)  # across the seam, high in the sky (large cos of latitude change)
    rgb = np.zeros((4, 5, 3))
    rgb[1:3, 1:4] = rng.uniform(1.0, 50.0, (2, 3, 3))
    rgb[0, 0] = 0.01  # a faint sky texel
    angle = 0.7
    rotation = np.array([[math.cos(angle), -math.sin(angle), 0.0],
                         [math.sin(angle), math.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    texels = ws.box_texels(box, rgb, W, H, linear=linear, rotation=rotation)
    n = 200_000
    dirs = ws.spot_sample(texels, rng.random(n), rng.random(n))
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert (ws.spot_pdf(texels, dirs) > 0.0).all()
    x, y = ws.spot_pixel(texels, dirs)
    t = (np.floor(y).astype(int) - box[1]) * box[2] + (np.floor(x).astype(int) - box[0]) % W
    shares = np.diff(np.concatenate([[0.0], texels.cumulative()]))
    counts = np.bincount(t, minlength=len(shares))
    sigma = np.sqrt(n * shares * (1.0 - shares)) + 1e-9
    assert (np.abs(counts - n * shares) < 5.0 * sigma + 0.5).all()
    # The integral over the box by midpoint quadrature in (x, y): dOmega = cos(lat) (2 pi / W)
    # (pi / H) dx dy.
    k = 64
    gx, gy = np.meshgrid((np.arange(box[2] * k) + 0.5) / k + box[0],
                         (np.arange(box[3] * k) + 0.5) / k + box[1])
    lat = (gy / H - 0.5) * math.pi
    phi = (0.5 - gx / W) * 2.0 * math.pi
    d = np.stack([np.cos(lat) * np.cos(phi), np.cos(lat) * np.sin(phi), np.sin(lat)], -1)
    world = d.reshape(-1, 3) @ rotation  # the lookup direction d = R w
    pdf = ws.spot_pdf(texels, world).reshape(gx.shape)
    total = (pdf * np.cos(lat)).sum() * (2.0 * math.pi / W) * (math.pi / H) / k ** 2
    assert abs(total - 1.0) < 2e-3, total
    # Light somewhere in a texel (what a Closest or Linear lookup there reads) has a density.
    bright = rgb.sum(-1) > 0.0
    if linear:
        padded = np.pad(bright, 1)
        bright = np.any([padded[1 + dr:1 + dr + 4, 1 + dc:1 + dc + 5]
                         for dr in (-1, 0, 1) for dc in (-1, 0, 1)], axis=0)
    cells = (np.floor(gy).astype(int) - box[1], (np.floor(gx).astype(int) - box[0]) % W)
    assert (pdf[bright[cells]] > 0.0).all()
