"""The world's bright spots handed over to the shaders (addon/world_lights.py), headless Cycles.

What this catches: a spot handed over somewhere other than where Cycles draws it (read off a
mirror sphere: an HDRI's sun, the same through a rotating Mapping node, the Sky Texture's sun
disc in each Blender version's sky types), a world the add-on cannot read that breaks the
hand-over or hands a wrong spot over (a spot painted with math nodes, a linked strength, a
mirror-ball image), an artist's camera-ray trick (Mix Shader on Is Camera Ray) that hides the
lighting background, and a render that does not write the spot into the shaders' table."""
import math

import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

import osl_text  # noqa: E402
from addon import compat, handover, world_lights  # noqa: E402
from addon.lab import grid, harness  # noqa: E402
from addon.lab.report.lights import spot_image  # noqa: E402
from addon.lab.report.scenes import add_spot_world  # noqa: E402

SPOT = np.array([0.6, 0.48, 0.64]) / np.linalg.norm([0.6, 0.48, 0.64])
MIRROR = grid.GridLayout(1, 1, cell_px=200)


def _mirror_scene():
    scene = harness.new_scene()
    mats = [harness.model_material("walter_reflection",
                                   {"roughness": 0.0, "fresnel_type": "none"}, "mirror")]
    harness.build_grid_scene(MIRROR, mats, grid.Environment("black", 0.0), 1, 0)
    return scene


def _drawn_direction(scene) -> np.ndarray:
    """Mean mirror direction of the sphere's brightest pixels (over half the maximum)."""
    image, _ = harness.render(scene)
    index, normal, _ = MIRROR.pixel_geometry()
    wo = 2.0 * normal[..., 2:3] * normal - grid.VIEW
    lum = image[..., :3].mean(-1)
    sel = index == 0
    top = lum[sel] > 0.5 * lum[sel].max()
    d = wo[sel][top].mean(0)
    return d / np.linalg.norm(d)


def _angle_deg(a, b) -> float:
    return math.degrees(math.acos(min(1.0, float(np.dot(a, b)))))


def _tree(scene):
    tree = scene.world.node_tree
    return tree, next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")


def _rotate_lookup(scene, rotation):
    tree, _ = _tree(scene)
    texture = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = rotation
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])


def _sky_world(scene):
    world = compat.new_node_world("sky")
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    sky = tree.nodes.new("ShaderNodeTexSky")
    types = {i.identifier for i in sky.bl_rna.properties["sky_type"].enum_items}
    sky.sky_type = sorted(types & compat.SKY_TYPES_WITH_SUN_DISC)[0]
    sky.sun_size = math.radians(8.0)
    sky.sun_elevation = math.radians(35.0)
    sky.sun_rotation = math.radians(200.0)
    tree.links.new(sky.outputs["Color"], background.inputs["Color"])
    scene.world = world


@pytest.mark.parametrize("world", ["image", "rotated image", "sky"])
def test_a_world_spot_is_handed_over_where_cycles_draws_it(world):
    scene = _mirror_scene()
    if world == "sky":
        _sky_world(scene)
    else:
        harness.add_image_world(scene, spot_image(128, 64, SPOT, math.radians(5.0), 100.0))
        if world == "rotated image":
            _rotate_lookup(scene, (0.3, -0.2, 1.1))
    (record,) = world_lights.world_records(scene)
    drawn = _drawn_direction(scene)
    # The mirror's pixels step by about 1 degree in reflected direction near this spot.
    assert _angle_deg(np.array(record.axis), drawn) < 1.5, (record.axis, drawn)
    half = math.degrees(math.acos(1.0 - record.size))
    assert 3.5 < half < 8.0 if world != "sky" else abs(half - 4.0) < 1e-3


def test_worlds_the_add_on_cannot_read_hand_nothing_over():
    scene = _mirror_scene()
    add_spot_world(scene, 100.0, math.radians(3.0))  # painted with math nodes
    assert world_lights.world_records(scene) == []
    harness.add_image_world(scene, spot_image(64, 32, SPOT, math.radians(5.0), 100.0))
    tree, background = _tree(scene)
    value = tree.nodes.new("ShaderNodeValue")
    tree.links.new(value.outputs[0], background.inputs["Strength"])
    assert world_lights.world_records(scene) == []  # a linked strength
    tree.links.remove(background.inputs["Strength"].links[0])
    texture = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    texture.projection = "MIRROR_BALL"
    assert world_lights.world_records(scene) == []
    scene.world = None
    assert world_lights.world_records(scene) == []


def test_a_camera_ray_mix_still_finds_the_lighting_background():
    scene = _mirror_scene()
    harness.add_image_world(scene, spot_image(64, 32, SPOT, math.radians(6.0), 100.0))
    tree, background = _tree(scene)
    output = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld")
    plain = tree.nodes.new("ShaderNodeBackground")
    mix = tree.nodes.new("ShaderNodeMixShader")
    path = tree.nodes.new("ShaderNodeLightPath")
    tree.links.new(path.outputs["Is Camera Ray"], mix.inputs[0])
    tree.links.new(background.outputs[0], mix.inputs[1])
    tree.links.new(plain.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])
    (record,) = world_lights.world_records(scene)
    assert np.dot(record.axis, SPOT) > math.cos(math.radians(3.0))


def test_a_render_writes_the_world_spot_into_the_shaders():
    scene = _mirror_scene()
    harness.add_image_world(scene, spot_image(64, 32, SPOT, math.radians(6.0), 100.0))
    assert handover.scene_lamps(scene) == [] and len(handover.scene_records(scene)) == 1
    changed = handover.hand_over(scene)
    assert changed and all(name.startswith("MicrofacetLab_") for name in changed)
    # ... with the spot's pixels, for the control variate's prediction of its light
    text = bpy.data.texts[changed[0]].as_string()
    assert osl_text.define(text, "MFL_SPOT_TEXELS") == "1"
    assert osl_text.define(text, "MFL_PREDICTED_LAMP_COUNT") == "1"
    assert handover.hand_over(scene) == []  # nothing changed: nothing recompiled


# Cycles' I points toward the camera: the world direction a camera ray sees is -I.
PROBE = """shader probe(output closure color Emission = 0)
{
    float dist;
    Emission = lamp_radiance(0, P, normalize(-I), dist) * emission();
}
"""


def _probe_material(records):
    """A material whose emission is the shaders' predicted radiance of lamp 0 toward the ray
    (osl/nee.h lamp_radiance, with the hand-over's table)."""
    from addon import shaders
    source = shaders.assemble('#include "nee.h"\n' + PROBE, records)
    compat.expose_bundled_modules()
    material = harness.osl_material(source, "spot probe")
    harness.check_compiled()
    return material


def _look_at(scene, axis, fov_deg, px):
    from mathutils import Vector

    camera = bpy.data.cameras.new("probe camera")
    camera.angle = math.radians(fov_deg)
    obj = bpy.data.objects.new("probe camera", camera)
    obj.rotation_euler = Vector(tuple(axis)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj
    harness.configure_render(scene, grid.GridLayout(1, 1, cell_px=px), 1, 0)


def _enclose(scene, material):
    """A sphere of radius 50 around the camera, of `material`."""
    import bmesh

    mesh = bpy.data.meshes.new("probe sphere")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=50.0)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    obj = bpy.data.objects.new("probe sphere", mesh)
    scene.collection.objects.link(obj)
    return obj


# Cycles' own image lookup against the shaders' maths, to float rounding: like the lamps' maths
# (tests/conftest.py), on the oldest supported Blender and the pinned release; the hand-over
# that reads the world (the tests above) runs on every version.
@pytest.mark.oldest_only
@pytest.mark.parametrize("interpolation", ["Closest", "Linear", "Linear rotated"])
def test_the_shaders_read_a_world_spots_radiance_as_cycles_draws_it(interpolation, tmp_path):
    """A camera looking into the spot renders the world, then a sphere around it whose emission
    is the shaders' prediction toward each camera ray (lamp_radiance, from the texels the
    hand-over writes): the two pictures agree pixel by pixel. Catches a texel box that misses
    pixels a lookup reads, a flipped or shifted u or v, Closest read as Linear, a rotation
    applied the wrong way, the strength left out."""
    rng = np.random.default_rng(3)
    image = spot_image(256, 128, SPOT, math.radians(4.0), 1.0)
    image = np.where(image[..., None] > 0, rng.uniform(40.0, 160.0, (*image.shape, 3)), 0.5)
    scene = harness.new_scene()
    harness.add_image_world(scene, image)
    tree, background = _tree(scene)
    background.inputs["Strength"].default_value = 1.5
    texture = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    texture.interpolation = interpolation.split()[0]
    if interpolation.endswith("rotated"):
        _rotate_lookup(scene, (0.3, -0.2, 1.1))
    (record,) = world_lights.world_records(scene)
    assert record.texels is not None and sum(record.radiance) > 0.0
    # 6 degrees across: every pixel's rays within the spot's cone (4.8 degrees about its axis),
    # where the shaders predict its light; the view holds sky texels of the box too.
    _look_at(scene, record.axis, 6.0, 48)
    # The world seen through the sphere made transparent: the two renders differ only in the
    # sphere's material.
    clear, tree, output = harness.new_material("clear")
    tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0],
                   output.inputs["Surface"])
    sphere = _enclose(scene, clear)
    drawn, _ = harness.render(scene, str(tmp_path / "world.exr"))
    sphere.data.materials[0] = _probe_material([record])
    predicted, _ = harness.render(scene, str(tmp_path / "predicted.exr"))

    drawn, predicted = drawn[..., :3], predicted[..., :3]
    # the view holds spot texels (60-240) and sky texels (0.75), or their Linear blend
    assert drawn.max() > 60.0 and drawn.min() < 40.0
    rel = np.abs(predicted - drawn) / np.maximum(drawn, 1e-3)
    print(f"\n[spot texels] {interpolation}: median {np.median(rel):.2e}, "
          f"99th percentile {np.percentile(rel, 99):.2e}, max {rel.max():.2e}")
    # Float rounding only (measured: Closest and Linear 3e-7 at most; rotated 2.6e-5, Cycles'
    # Mapping matrix in float32, about 1e-7 rad, across texels that differ by up to 4 times).
    # A texel off by one, or a lookup written otherwise than Cycles' OSL node (acos for the
    # atan2: 5e-4 in the median), is far over.
    assert rel.max() < 1e-4 and np.median(rel) < 1e-6
