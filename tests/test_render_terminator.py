"""A delta reflection drawn under the geometric surface (osl/cycles.h `delta_reflection`,
docs/cycles-osl.md "The same trap for reflections").

Cycles turns a reflection closure's normal so that its mirror direction rises at least
min(0.9 wi.Ng, 0.01) above the horizon of the face's own normal Ng. Our deltas' normals are
microfacet normals, so a direction drawn under the face left along that line with the weight of
the direction drawn: where a lamp sat on a smooth-shaded face's horizon (Suzanne's brow under
the look-dev point lamp) single samples carried over 1,000 times a pixel's mean. The shaders
now drop a delta under the face, as Cycles' own closures reject such a direction.

Scene: a square whose shading normal N (a custom normal) leans BETA from its face normal Ng,
seen by an orthographic camera THETA from Ng on the other side, so that N's mirror direction of
the view lies on Ng's horizon and about half the lobe under it; a world of radiance 1 in a strip
from Ng's horizon up to STRIP (where Cycles' line lies), 0 elsewhere. Every pixel sees the same
incidence and the same world, so the pixels are independent estimates of one value.

Reference (numpy): the integral of f(wi, wo) (wo . N) over the strip (a fine grid in elevation
and azimuth; f from the reference in N's frame). A direction between the face and Cycles' line
is moved onto the line, which lies inside the strip: its radiance does not change.
What it catches: deltas under the face lifted into the strip (before the drop the square's mean
was 6 to 7 times the reference, 180 standard errors), and a drop rule that takes too
much (a white furnace at grazing incidence lost 25% with directions up to the line dropped) or
too little: a bias beyond the standard error of the pixels' mean, Sidak-corrected over the
channels and cases. The split models' native part follows Cycles' rules under the face (its
evaluation does not check Ng), so the cases are models without one: Cook-Torrance, Walter's
Beckmann and symmetric Lee.
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
STRIP = 0.05  # rad: the world's bright strip above Ng's horizon (Cycles' line: 0.01 here)
PX = 32
SAMPLES = 64
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


def _strip_world(scene):
    """Radiance 1 where the direction's z lies in [0, sin STRIP), else 0 (Generated = the
    direction in a world shader); no light sampling of the world (the deltas find it)."""
    world = harness.compat.new_node_world("Horizon strip")
    world.cycles.sampling_method = "NONE"
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    sep = tree.nodes.new("ShaderNodeSeparateXYZ")
    above = tree.nodes.new("ShaderNodeMath")
    above.operation = "GREATER_THAN"
    above.inputs[1].default_value = 0.0
    below = tree.nodes.new("ShaderNodeMath")
    below.operation = "LESS_THAN"
    below.inputs[1].default_value = math.sin(STRIP)
    both = tree.nodes.new("ShaderNodeMath")
    both.operation = "MULTIPLY"
    tree.links.new(coords.outputs["Generated"], sep.inputs[0])
    tree.links.new(sep.outputs["Z"], above.inputs[0])
    tree.links.new(sep.outputs["Z"], below.inputs[0])
    tree.links.new(above.outputs[0], both.inputs[0])
    tree.links.new(below.outputs[0], both.inputs[1])
    tree.links.new(both.outputs[0], background.inputs["Color"])
    background.inputs["Strength"].default_value = 1.0
    scene.world = world


def render(model_id, values, seed=0):
    scene = harness.new_scene()
    harness.configure_render(scene, grid.GridLayout(rows=1, cols=1, cell_px=PX), SAMPLES, seed)
    _strip_world(scene)
    _square(scene, harness.model_material(model_id, MODELS[model_id].resolve(values)))
    _camera(scene)
    harness.check_compiled()
    image, _ = harness.render(scene)
    return np.asarray(image)[..., :3]


def _frame_n():
    """Rows: t, b, N of the shading frame (t along x, normal to the plane of N and Ng)."""
    t = np.array([1.0, 0.0, 0.0])
    return np.stack([t, np.cross(N, t), N])


def reference(model_id, values, nodes=(32, 2048)):
    """The integral of f (wo . N) over the strip: midpoints in elevation and azimuth,
    d omega = cos(elevation) d elevation d azimuth."""
    edges = [np.linspace(0.0, STRIP, nodes[0] + 1), np.linspace(-np.pi, np.pi, nodes[1] + 1)]
    elev, azim = np.meshgrid(*[0.5 * (e[1:] + e[:-1]) for e in edges], indexing="ij")
    dirs = np.stack([np.cos(elev) * np.sin(azim), np.cos(elev) * np.cos(azim), np.sin(elev)], -1)
    d_omega = np.cos(elev) * (STRIP / nodes[0]) * (2.0 * np.pi / nodes[1])
    frame = _frame_n()
    local_wo = dirs.reshape(-1, 3) @ frame.T
    f_cos = make_bsdf(model_id, values).eval(frame @ WI, local_wo) * \
        np.maximum(local_wo[:, 2:3], 0.0)
    return (f_cos * d_omega.reshape(-1, 1)).sum(axis=0)


@pytest.mark.parametrize("model_id, values", CASES, ids=[c[0] for c in CASES])
def test_a_sun_on_the_horizon_of_a_tilted_face(model_id, values):
    image = render(model_id, values)
    assert np.isfinite(image).all()
    pixels = image.reshape(-1, 3)
    mean = pixels.mean(axis=0)
    stderr = pixels.std(axis=0, ddof=1) / math.sqrt(len(pixels))
    expected = reference(model_id, values)
    coarse = reference(model_id, values, nodes=(16, 1024))
    quad_err = np.abs(expected - coarse)
    z = grid.sidak_z(3 * len(CASES))
    assert expected.min() > 0.01, expected  # the strip lights the square
    assert (np.abs(mean - expected) <= z * stderr + quad_err + 1e-3 * expected).all(), \
        (model_id, mean, expected, stderr)
