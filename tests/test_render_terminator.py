"""A delta reflection drawn under the geometric surface (osl/cycles.h `delta_reflection`,
docs/light-sampling.md "Where the result is not exact").

Cycles turns a reflection closure's normal so that its mirror direction rises at least 0.01
above the face's own normal Ng's horizon. Our deltas' normals are microfacet normals, so a
direction drawn under that line left along it with the weight of the direction drawn: where a
lamp sat on a smooth-shaded face's horizon (Suzanne's brow under the look-dev point lamp) single
samples carried thousands of times a pixel's mean. The shaders now drop such a delta.

Scene: a square whose shading normal N (a custom normal) leans BETA from its face normal Ng,
seen by an orthographic camera THETA from Ng on the other side, so that N's mirror direction of
the view lies on Ng's horizon; a sun across that horizon, its centre SUN_ELEVATION above it; a
black world. Every pixel sees the same incidence and the same sun, so the pixels are
independent estimates of one value.

Reference (numpy): the sun's radiance times the integral of f(wi, wo) (wo . N) over the part of
its disc at least LIFT above Ng's horizon (a fine grid on the disc; f from the reference in N's
frame); Cycles' own closures lose the directions under the surface too.
What it catches: deltas lifted onto the horizon and into the sun (before the drop the square's
mean was 7 to 12 times the reference, 50 standard errors and more), and a drop rule that takes
too much or too little (a bias beyond the standard error of the pixels' mean, Sidak-corrected
over the channels and cases). The split models' native part follows Cycles' rules under the
surface (its evaluation does not check Ng), so the cases are models without one: Cook-Torrance,
Walter's Beckmann and symmetric Lee.
"""
import math

import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

import mathutils  # noqa: E402 (bpy first)

from addon.catalog import MODELS  # noqa: E402
from addon.lab import grid, harness  # noqa: E402
from addon.lab.reference import make_bsdf  # noqa: E402

THETA = math.radians(30.0)  # the camera from Ng, on the -y side
BETA = math.radians(30.0)  # N from Ng, toward +y: N's mirror of the view is at 2 BETA + THETA
SUN_HALF = 0.025  # rad
SUN_ELEVATION = 0.02  # the sun's centre above Ng's horizon, toward +y
SUN_STRENGTH = 1.0
LIFT = 0.01  # Cycles' least rise of a reflection above Ng's horizon (wi.Ng > 0.011 here)
PX = 40
SAMPLES = 128
CASES = (
    ("cook_torrance", {"roughness": 0.55, "fresnel_type": "conductor", "specular": 1.0}),
    ("walter_reflection", {"roughness": 0.5, "fresnel_type": "conductor",
                           "distribution": "beckmann", "masking": "separable"}),
    ("lee_vgroove", {"roughness": 0.6, "groove": "symmetric", "fresnel_type": "conductor"}),
)


def _unit(theta, toward_y):
    return np.array([0.0, math.sin(theta) * toward_y, math.cos(theta)])


WI = _unit(THETA, -1.0)  # toward the camera, world = Ng's frame
N = _unit(BETA, 1.0)
SUN = np.array([0.0, math.cos(SUN_ELEVATION), math.sin(SUN_ELEVATION)])


def _square(scene, material):
    mesh = bpy.data.meshes.new("Tilted square")
    mesh.from_pydata([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], [], [(0, 1, 2, 3)])
    mesh.polygons[0].use_smooth = True
    mesh.normals_split_custom_set([tuple(N)] * 4)
    mesh.materials.append(material)
    obj = bpy.data.objects.new("Tilted square", mesh)
    scene.collection.objects.link(obj)


def _camera(scene):
    camera = bpy.data.cameras.new("Camera")
    camera.type = "ORTHO"
    camera.ortho_scale = 1.0
    obj = bpy.data.objects.new("Camera", camera)
    obj.location = tuple(5.0 * WI)
    obj.rotation_euler = mathutils.Vector(tuple(-WI)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj


def _sun(scene):
    light = bpy.data.lights.new("Sun", "SUN")
    light.energy = SUN_STRENGTH
    light.angle = 2.0 * SUN_HALF
    obj = bpy.data.objects.new("Sun", light)
    obj.rotation_euler = mathutils.Vector(tuple(SUN)).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(obj)


def render(model_id, values, seed=0):
    scene = harness.new_scene()
    harness.configure_render(scene, grid.GridLayout(rows=1, cols=1, cell_px=PX), SAMPLES, seed)
    harness.add_world(scene, grid.Environment("black", 0.0))
    _square(scene, harness.model_material(model_id, MODELS[model_id].resolve(values)))
    _camera(scene)
    _sun(scene)
    harness.check_compiled()
    image, _ = harness.render(scene)
    return np.asarray(image)[..., :3]


def _frame_n():
    """Rows: t, b, N of the shading frame (t along x, normal to the plane of N and Ng)."""
    t = np.array([1.0, 0.0, 0.0])
    return np.stack([t, np.cross(N, t), N])


def reference(model_id, values, nodes=400):
    """L times the integral of f (wo . N) over the sun's disc above LIFT: a midpoint grid on the
    disc's tangent plane, mapped to the sphere (d omega = cos^3 of the offset's angle dA)."""
    frame = _frame_n()
    side = np.linspace(-SUN_HALF, SUN_HALF, nodes + 1)
    mid = 0.5 * (side[1:] + side[:-1])
    dx = side[1] - side[0]
    u, v = np.meshgrid(mid, mid, indexing="ij")
    tan_r = np.hypot(u, v)
    inside = np.arctan(tan_r) <= SUN_HALF
    up = np.array([0.0, -math.sin(SUN_ELEVATION), math.cos(SUN_ELEVATION)])  # toward +z on disc
    side_axis = np.cross(SUN, up)
    dirs = SUN + u[..., None] * side_axis + v[..., None] * up
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    d_omega = dx * dx / (1.0 + tan_r ** 2) ** 1.5
    keep = inside & (dirs[..., 2] >= LIFT)
    local_wi = frame @ WI
    local_wo = dirs[keep] @ frame.T
    f_cos = make_bsdf(model_id, values).eval(local_wi, local_wo) * local_wo[:, 2:3]
    radiance = SUN_STRENGTH / (math.pi * math.sin(SUN_HALF) ** 2)
    return radiance * (f_cos * d_omega[keep][:, None]).sum(axis=0)


@pytest.mark.parametrize("model_id, values", CASES, ids=[c[0] for c in CASES])
def test_a_sun_on_the_horizon_of_a_tilted_face(model_id, values):
    image = render(model_id, values)
    assert np.isfinite(image).all()
    pixels = image.reshape(-1, 3)
    mean = pixels.mean(axis=0)
    stderr = pixels.std(axis=0, ddof=1) / math.sqrt(len(pixels))
    expected = reference(model_id, values)
    coarse = reference(model_id, values, nodes=200)
    quad_err = np.abs(expected - coarse)
    z = grid.sidak_z(3 * len(CASES))
    assert expected.min() > 0.05, expected  # the sun's upper part lights the square
    assert (np.abs(mean - expected) <= z * stderr + quad_err + 1e-3 * expected).all(), \
        (model_id, mean, expected, stderr)
