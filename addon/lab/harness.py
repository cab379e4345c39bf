"""Render harness: the sphere grid of addon/lab/grid.py built and rendered headless in Cycles.

One function builds the scene (`build_grid_scene`), one renders it and reads the EXR back
(`render`, through addon/lab/images.py: the OpenImageIO bundled in bpy, or Blender's image loader
where the wheel has none). Settings that silently change results (docs/cycles-osl.md) are
pinned: no Filter Glossy, no clamping, caustics on, no adaptive sampling, no denoising, and a
0.01 px pixel filter so that a pixel sees one normal.
"""
from __future__ import annotations

import os
import tempfile
import time

import bpy
import numpy as np

from .. import compat
from .. import handover, nodes, shader_nodes
from . import images
from .grid import Environment, GridLayout

compat.expose_bundled_modules()  # oslquery (osl_material compiles raw OSL), OpenImageIO (render)

SPHERE_GROUP = "Microfacet Lab: sphere"
# The analytic worlds' importance map. Cycles' Automatic method builds a 4096 x 2048 map for a
# world without an image: 8M evaluations of the world shader before every render, most of a
# small test render's time (measured: 0.7-1.3 s against 0.12 s at 256). The map is only the
# world light's sampling density, used alike in both MIS weights, so its size changes the
# noise, never the expected image; a smooth gradient needs no more.
WORLD_MAP_RESOLUTION = 256


def new_scene():
    """An empty file with Cycles and OSL on the CPU (OSL runs on CPU and OptiX only)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.shading_system = True
    scene.cycles.device = "CPU"
    return scene


def configure_render(scene, layout: GridLayout, samples: int, seed: int, max_bounces: int = 4):
    cycles = scene.cycles
    cycles.samples = samples
    cycles.seed = seed
    cycles.use_animated_seed = False
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.pixel_filter_type = "BLACKMAN_HARRIS"
    cycles.filter_width = 0.01
    cycles.blur_glossy = 0.0
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.caustics_reflective = True
    cycles.caustics_refractive = True
    cycles.max_bounces = max_bounces
    cycles.glossy_bounces = max_bounces
    cycles.diffuse_bounces = max_bounces
    cycles.transmission_bounces = max_bounces
    cycles.transparent_max_bounces = max_bounces
    render = scene.render
    render.resolution_x, render.resolution_y = layout.width, layout.height
    render.resolution_percentage = 100
    render.film_transparent = False
    render.image_settings.file_format = "OPEN_EXR"
    render.image_settings.color_depth = "32"
    render.image_settings.exr_codec = "ZIP"
    render.use_file_extension = False
    scene.view_settings.view_transform = "Standard"


def add_world(scene, env: Environment, light_sampling: bool = True):
    """L(w) = constant + gradient (w . d): Texture Coordinate > Generated is the world direction
    in a world shader (checked against an analytic mirror sphere in the tests).

    `light_sampling=False` turns off next-event estimation of the world, leaving BSDF sampling
    alone: measured, Cycles' native rough glass returns more than 1 in a white furnace with it on
    (1.007 at roughness 0.7, single interface) and matches its own BSDF-only result, and ours,
    with it off."""
    world = compat.new_node_world(f"Microfacet Lab: {env.name}")
    if light_sampling:
        world.cycles.sampling_method = "MANUAL"
        world.cycles.sample_map_resolution = WORLD_MAP_RESOLUTION
    else:
        world.cycles.sampling_method = "NONE"
    scene.world = world
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    dot = tree.nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    dot.inputs[1].default_value = tuple(env.unit_direction())
    scale = tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY_ADD"
    scale.inputs[1].default_value = env.gradient
    scale.inputs[2].default_value = env.constant
    tree.links.new(coords.outputs["Generated"], dot.inputs[0])
    tree.links.new(dot.outputs["Value"], scale.inputs[0])
    tree.links.new(scale.outputs["Value"], background.inputs["Color"])
    background.inputs["Strength"].default_value = 1.0
    return world


def add_image_world(scene, radiance, name="Microfacet Lab image world"):
    """Set the scene's world to an Environment Texture of the `radiance` image ((H, W) grey or
    (H, W, 3) RGB, equirectangular), Closest interpolation (each pixel a cell of constant
    radiance, as the report's reference assumes)."""
    import bpy

    radiance = np.asarray(radiance, dtype=np.float32)
    if radiance.ndim == 2:
        radiance = np.repeat(radiance[..., None], 3, axis=-1)
    height, width = radiance.shape[:2]
    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True)
    rgba = np.concatenate([radiance, np.ones((height, width, 1), np.float32)], axis=-1)
    image.pixels.foreach_set(rgba.reshape(-1))
    world = compat.new_node_world(name)
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    texture.interpolation = "Closest"
    tree.links.new(texture.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    return world


def add_camera(scene, layout: GridLayout):
    camera = bpy.data.cameras.new("Microfacet Lab camera")
    camera.type = "ORTHO"
    camera.ortho_scale = layout.ortho_scale
    camera.sensor_fit = "AUTO"
    obj = bpy.data.objects.new("Microfacet Lab camera", camera)
    obj.location = (0.0, 0.0, 10.0)
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def _sphere_node_group(radius: float):
    """Geometry nodes: one vertex -> one point-cloud point (an exact sphere in Cycles) with the
    material given on the modifier."""
    group = bpy.data.node_groups.get(SPHERE_GROUP)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(SPHERE_GROUP, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Material", in_out="INPUT", socket_type="NodeSocketMaterial")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in = group.nodes.new("NodeGroupInput")
    group_out = group.nodes.new("NodeGroupOutput")
    to_points = group.nodes.new("GeometryNodeMeshToPoints")
    to_points.inputs["Radius"].default_value = radius
    set_material = group.nodes.new("GeometryNodeSetMaterial")
    group.links.new(group_in.outputs["Geometry"], to_points.inputs["Mesh"])
    group.links.new(to_points.outputs["Points"], set_material.inputs["Geometry"])
    group.links.new(group_in.outputs["Material"], set_material.inputs["Material"])
    group.links.new(set_material.outputs["Geometry"], group_out.inputs["Geometry"])
    return group


def add_spheres(scene, layout: GridLayout, materials: list, solid: bool = False):
    """One exact sphere per material, row-major; invisible to every secondary ray so that each
    sees only the environment (a single interface: a transmitted ray leaves unchanged). With
    `solid`, spheres are visible to glossy and transmission rays, so neighbours can be seen
    (alike in every render). Not closed balls: Cycles never hits a point-cloud sphere from
    inside (measured, a refracted ray left a sphere whose back face would have emitted red
    without meeting it), so a refracted ray still leaves unchanged; real back faces need a
    mesh (addon/lab/glass_shapes.py)."""
    if len(materials) > layout.count:
        raise ValueError(f"{len(materials)} materials for a grid of {layout.count} spheres")
    group = _sphere_node_group(layout.radius)
    socket_id = group.interface.items_tree["Material"].identifier
    objects = []
    for i, (material, (x, y)) in enumerate(zip(materials, layout.centers())):
        if material is None:
            continue
        mesh = bpy.data.meshes.new(sphere_name(i))
        mesh.vertices.add(1)
        obj = bpy.data.objects.new(sphere_name(i), mesh)
        obj.location = (float(x), float(y), 0.0)
        modifier = obj.modifiers.new("sphere", "NODES")
        modifier.node_group = group
        compat.set_modifier_input(modifier, socket_id, material)
        hidden = ("diffuse", "shadow", "volume_scatter")
        for ray in hidden if solid else hidden + ("glossy", "transmission"):
            setattr(obj, f"visible_{ray}", False)
        scene.collection.objects.link(obj)
        objects.append(obj)
    return objects


OUT_OF_THE_WAY_Z = -1000.0  # render_row_alone's place for the other rows' spheres


def sphere_name(index: int) -> str:
    return f"sphere {index:03d}"


def render_row_alone(scene, layout: GridLayout, row: int):
    """Render only grid row `row` (0 at the top): a render border around it, and the other rows'
    spheres moved far below (OUT_OF_THE_WAY_Z), out of the band's camera rays and of every ray
    toward the report's lamps, which all lie above the grid. The other spheres are invisible to
    Cycles' own secondary rays, but OSL's trace() sees every object (it traces with all visibility
    flags), so from a far row they would block the shaders' view of a lamp that the light itself
    reaches, and leave its light to the rare delta ray that hits it (docs/light-sampling.md, "What
    trace() sees"). Moved, not hidden: Cycles drops a hidden object's shaders and compiles them
    again when it returns (up to 4 s a row, measured); a move only refits the BVH."""
    r = scene.render
    r.use_border = True
    r.use_crop_to_border = False
    r.border_min_x, r.border_max_x = 0.0, 1.0
    r.border_max_y = 1.0 - row / layout.rows
    r.border_min_y = 1.0 - (row + 1) / layout.rows
    first = row * layout.cols
    for i in range(layout.count):
        obj = scene.objects.get(sphere_name(i))
        if obj is not None:
            obj.location.z = 0.0 if first <= i < first + layout.cols else OUT_OF_THE_WAY_Z


def new_material(name: str):
    material = compat.new_node_material(name)
    tree = material.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.target = "CYCLES"
    return material, tree, output


def add_quad(scene, name: str, corners, base_color, roughness=0.5, specular=0.5):
    """A one-face mesh object with a plain Principled material (floors, occluders)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2, 3)])
    material = compat.new_node_material(name)
    bsdf = material.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = tuple(base_color) + (1.0,)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Specular IOR Level"].default_value = specular
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def model_material(model_id: str, values: dict | None = None, name: str | None = None):
    """A material made of one Microfacet Lab node group."""
    material, tree, output = new_material(name or model_id)
    node = nodes.add_group_node(tree, model_id, values)
    tree.links.new(node.outputs["BSDF"], output.inputs["Surface"])
    return material


def linked_model_material(model_id: str, values: dict, name: str):
    """A model's material whose numeric inputs come through links from Value (and Combine XYZ)
    nodes, so any value, NaN or out of range, reaches the shader unclamped by the sockets: the
    way to test the OSL clamps. Enum values are set on the group node (validated)."""
    from ..catalog import COLOR, ENUM, MODELS

    model = MODELS[model_id]
    material, tree, output = new_material(name)
    enums = {k: v for k, v in values.items() if model.param(k).kind == ENUM}
    group = nodes.add_group_node(tree, model_id, enums)
    for key, value in values.items():
        param = model.param(key)
        if param.kind == ENUM:
            continue
        channels = value if param.kind == COLOR else (value,)
        sources = []
        for channel in channels:
            source = tree.nodes.new("ShaderNodeValue")
            source.outputs[0].default_value = channel
            sources.append(source.outputs[0])
        if param.kind == COLOR:
            combine = tree.nodes.new("ShaderNodeCombineXYZ")
            for i, socket in enumerate(sources):
                tree.links.new(socket, combine.inputs[i])
            sources = [combine.outputs[0]]
        tree.links.new(sources[0], group.inputs[param.label])
    tree.links.new(group.outputs["BSDF"], output.inputs["Surface"])
    return material


ATTRIBUTE_PREFIX = "mfl_"  # attribute_model_material: the objects' custom property names


def attribute_model_material(model_id: str, enums: dict, keys, name: str):
    """A model's material whose numeric inputs `keys` are read per object (an Attribute node of
    type Object: the custom property ATTRIBUTE_PREFIX + key, set with set_object_values), so one
    material, one shader group, serves objects with different values, and any value reaches the
    shader unclamped by the sockets and unknown to the shader optimizer. Enums are set on the
    group node (validated)."""
    from ..catalog import COLOR, MODELS

    if not compat.OBJECT_ATTRIBUTES_ON_POINT_CLOUDS:
        raise RuntimeError(f"Blender {bpy.app.version_string} does not pass object attributes "
                           "to the spheres' shaders (4.5 and later do)")
    model = MODELS[model_id]
    material, tree, output = new_material(name)
    group = nodes.add_group_node(tree, model_id, enums)
    for key in keys:
        source = tree.nodes.new("ShaderNodeAttribute")
        source.attribute_type = "OBJECT"
        source.attribute_name = ATTRIBUTE_PREFIX + key
        out = source.outputs["Vector" if model.param(key).kind == COLOR else "Fac"]
        tree.links.new(out, group.inputs[model.param(key).label])
    tree.links.new(group.outputs["BSDF"], output.inputs["Surface"])
    return material


def set_object_values(obj, values: dict):
    """The values an attribute_model_material reads on `obj` (floats, or colours as triples)."""
    for key, value in values.items():
        obj[ATTRIBUTE_PREFIX + key] = tuple(map(float, value)) if hasattr(value, "__len__") \
            else float(value)


def osl_material(source: str, name: str):
    """A material made of a raw OSL script (used for Cycles' native closures in tests)."""
    material, tree, output = new_material(name)
    text = bpy.data.texts.new(name + ".osl")
    text.write(source)
    script = tree.nodes.new("ShaderNodeScript")
    shader_nodes.compile_text(script, text)
    tree.links.new(script.outputs[0], output.inputs["Surface"])
    return material


def uncompiled_script_nodes() -> list[str]:
    """Every Script node (in materials and node groups) without bytecode or without sockets."""
    trees = [(m.name, m.node_tree) for m in bpy.data.materials if m.node_tree]
    trees += [(g.name, g) for g in bpy.data.node_groups if g.bl_idname == "ShaderNodeTree"]
    return [f"{owner}/{node.name}" for owner, tree in trees for node in tree.nodes
            if node.bl_idname == "ShaderNodeScript" and node.mode == "INTERNAL"
            and (not node.bytecode or len(node.outputs) == 0)]


def check_compiled():
    """The guard: fail loudly rather than render a silently empty shader."""
    bad = uncompiled_script_nodes()
    if bad:
        raise RuntimeError(f"Script nodes with no bytecode or no sockets: {bad}")


def build_grid_scene(layout: GridLayout, materials: list, env: Environment,
                     samples: int, seed: int = 0, max_bounces: int = 4, solid: bool = False,
                     light_sampling: bool = True):
    """The sphere-grid scene. `materials` is a list of bpy materials (None leaves a gap) made
    in the current file, e.g. with model_material() after new_scene()."""
    scene = bpy.context.scene
    configure_render(scene, layout, samples, seed, max_bounces)
    add_world(scene, env, light_sampling)
    add_camera(scene, layout)
    add_spheres(scene, layout, materials, solid)
    check_compiled()
    return scene


def render(scene, path: str | None = None) -> tuple[np.ndarray, float]:
    """Render to an EXR (a temporary one unless `path`), read it back as float32 (H, W, 4),
    row 0 at the top. Returns the image and the render wall time in seconds."""
    tmp = None
    if path is None:
        tmp = tempfile.NamedTemporaryFile(suffix=".exr", delete=False)
        tmp.close()
        path = tmp.name
    scene.render.filepath = path
    handover.hand_over(scene)  # what the add-on's render_pre handler does for F12
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - start
    pixels = images.read_image(path)
    if tmp is not None:
        os.unlink(path)
    return pixels, seconds


def render_specs(specs: list, env: Environment, samples: int, seed: int = 0, cols: int = 4,
                 cell_px: int = 32, path: str | None = None, materials: list | None = None,
                 solid: bool = False, max_bounces: int = 4, light_sampling: bool = True,
                 osl: bool = True, lamps=None):
    """Build and render a grid of SphereSpecs (or of ready-made `materials`, made by a callable
    run after the scene is reset). Returns (layout, image, seconds). `osl` False renders with
    Open Shading Language off (the node groups' native branches, addon/fallback.py); `lamps`,
    a callable, adds lamps to the scene."""
    scene, layout = _spec_scene(specs, env, samples, seed, cols, cell_px, materials, solid,
                                max_bounces, light_sampling, osl)
    if lamps is not None:
        lamps(scene)
    image, seconds = render(scene, path)
    return layout, image, seconds


def render_seeds(specs: list, env: Environment, samples: int, seeds, **kwargs):
    """render_specs at each of `seeds` in one scene: Cycles' persistent data keeps the scene
    and its compiled OSL between the renders, so the shaders are compiled once (the pixels are
    those of separate renders). Returns (layout, [image per seed])."""
    layout, by_env = render_seeds_envs(specs, [env], samples, seeds, **kwargs)
    return layout, by_env[env.name]


def render_seeds_envs(specs: list, envs: list, samples: int, seeds, **kwargs):
    """render_seeds under each of `envs` in turn, in one scene: only the world changes between
    them, and Cycles' persistent data recompiles only its shader, so the spheres' OSL is
    compiled once for all (most of a grid's time). Returns (layout, {env name: [image per
    seed]})."""
    scene, layout = _spec_scene(specs, envs[0], samples, seeds[0], **kwargs)
    by_env = {}
    # On throughout: turning persistent data off frees it, and the next world would recompile
    # every sphere's OSL (the Lee suite at 16 spp: 3.2 s with it on, 5.4 s off between worlds).
    scene.render.use_persistent_data = True
    try:
        for env in envs:
            if env is not envs[0]:
                add_world(scene, env, kwargs.get("light_sampling", True))
            by_env[env.name] = render_each_seed(scene, seeds)
    finally:
        scene.render.use_persistent_data = False
    return layout, by_env


def render_each_seed(scene, seeds) -> list:
    """The scene rendered at each of `seeds` with Cycles' persistent data on: the scene and its
    compiled OSL are kept between the renders, so the shaders are compiled once (the pixels are
    those of separate renders: tests/test_harness.py). Leaves persistent data as it found it.
    Returns [image per seed]."""
    was = scene.render.use_persistent_data
    scene.render.use_persistent_data = True
    try:
        images = []
        for seed in seeds:
            scene.cycles.seed = seed
            images.append(render(scene)[0])
        return images
    finally:
        scene.render.use_persistent_data = was


def _spec_scene(specs, env, samples, seed, cols=4, cell_px=32, materials=None, solid=False,
                max_bounces=4, light_sampling=True, osl=True):
    count = len(specs if materials is None else materials)
    layout = GridLayout(rows=-(-count // cols), cols=cols, cell_px=cell_px)
    scene = new_scene()
    if materials is None:
        mats = [None if s is None else model_material(s.model_id, s.values, f"{i:03d} {s.label}")
                for i, s in enumerate(specs)]
    else:
        mats = [None if make is None else make() for make in materials]
    build_grid_scene(layout, mats, env, samples, seed, max_bounces, solid, light_sampling)
    scene.cycles.shading_system = osl
    return scene, layout
