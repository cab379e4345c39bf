"""The look-dev scene of `make demo`: Suzanne on a floor under a sky, a sun and an area lamp,
built from nodes and bmesh (no outside assets); each model beside Cycles' closest native
material, rendered for the same wall time (Cycles' time limit).

Pairs (ours from a shipped preset, native built from Cycles' nodes with the same numbers):
gold (Walter GGX, conductor) / Metallic BSDF with the same n, k; rough glass (Walter GGX) /
Glass BSDF; red plastic (Cook-Torrance) / Principled BSDF; rough Lee gold / Metallic BSDF with
multiscatter GGX (a different model: the closest Cycles has). The models with a Light Sampling
menu (Walter, Cook-Torrance) also render with Light Sampling = Stochastic, the estimator they had
before the split.
"""
from __future__ import annotations

import math

import numpy as np

from ..catalog import MODELS
from . import harness

SUN_ANGLE_DEG = 2.0
SUN_STRENGTH = 4.0
SUN_DIRECTION = (-0.45, -0.55, 0.70)  # toward the sun
AREA_POWER = 400.0  # W
AREA_SIZE = 1.5
POINT_POWER = 400.0  # W
POINT_RADIUS = 0.1  # m
LAMP_POSITION = (2.5, -1.0, 2.5)  # the area and point lamps, aimed at Suzanne


SKY_HORIZON = (0.55, 0.6, 0.65)  # at the horizon and below
SKY_ZENITH = (0.12, 0.25, 0.6)  # from SKY_ZENITH_Z up
SKY_ZENITH_Z = 0.6
SKY_STRENGTH = 0.6
HDRI_SIZE = (2048, 1024)  # the HDRI sky's pixels (0.18 degrees each at the horizon)
HDRI_SUN_ANGLE_DEG = 1.0


def add_sky(scene):
    """A sky from nodes: zenith blue to a bright horizon (by the direction's z)."""
    world = harness.compat.new_node_world("Look-dev sky")
    tree = world.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    coords = tree.nodes.new("ShaderNodeTexCoord")
    sep = tree.nodes.new("ShaderNodeSeparateXYZ")
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position = 0.0
    ramp.color_ramp.elements[0].color = SKY_HORIZON + (1.0,)
    ramp.color_ramp.elements[1].position = SKY_ZENITH_Z
    ramp.color_ramp.elements[1].color = SKY_ZENITH + (1.0,)
    background = tree.nodes.new("ShaderNodeBackground")
    background.inputs["Strength"].default_value = SKY_STRENGTH
    out = tree.nodes.new("ShaderNodeOutputWorld")
    tree.links.new(coords.outputs["Generated"], sep.inputs[0])
    tree.links.new(sep.outputs["Z"], ramp.inputs["Fac"])
    tree.links.new(ramp.outputs["Color"], background.inputs["Color"])
    tree.links.new(background.outputs[0], out.inputs["Surface"])
    scene.world = world


def hdri_sky_pixels(width: int = HDRI_SIZE[0], height: int = HDRI_SIZE[1],
                    angle_deg: float = HDRI_SUN_ANGLE_DEG) -> np.ndarray:
    """(height, width, 3) radiance of an equirectangular HDRI: add_sky's sky, and a sun of
    `angle_deg` toward SUN_DIRECTION drawn in the pixels whose centre it covers, with the
    radiance of a sun lamp of SUN_STRENGTH (the irradiance facing it, up to the pixels' edges)."""
    from ..world_spots import equirect_direction

    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    d = equirect_direction(u[None, :], v[:, None])
    t = np.clip(d[..., 2] / SKY_ZENITH_Z, 0.0, 1.0)[..., None]
    horizon, zenith = np.asarray(SKY_HORIZON), np.asarray(SKY_ZENITH)
    pixels = SKY_STRENGTH * (horizon + t * (zenith - horizon))
    sun = np.asarray(SUN_DIRECTION, dtype=float) / np.linalg.norm(SUN_DIRECTION)
    half = math.radians(angle_deg) / 2.0
    pixels[d @ sun >= math.cos(half)] = SUN_STRENGTH / (2.0 * math.pi * (1.0 - math.cos(half)))
    return pixels


def add_hdri_sky(scene):
    """The sky and a 1-degree sun as one HDRI (hdri_sky_pixels; no lamp): the add-on finds
    the sun in the pixels and hands it over (addon/world_spots.py)."""
    harness.add_image_world(scene, hdri_sky_pixels(), "Look-dev HDRI sky")


def _add_object(scene, name, mesh, location=(0.0, 0.0, 0.0)):
    import bpy

    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def add_suzanne(scene, material):
    """Suzanne, subdivided once and smooth, resting on the floor."""
    import bmesh
    import bpy

    bm = bmesh.new()
    bmesh.ops.create_monkey(bm)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges, cuts=1, use_grid_fill=True, smooth=1.0)
    for face in bm.faces:
        face.smooth = True
    mesh = bpy.data.meshes.new("Suzanne")
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    obj = _add_object(scene, "Suzanne", mesh, (0.0, 0.0, 0.75))
    obj.rotation_euler = (math.radians(-20.0), 0.0, math.radians(25.0))
    return obj


def add_floor(scene):
    s = 20.0
    harness.add_quad(scene, "Floor", [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)],
                     (0.35, 0.35, 0.33), roughness=0.8)


def add_sun(scene, angle_deg: float = SUN_ANGLE_DEG):
    import bpy
    import mathutils

    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = SUN_STRENGTH
    sun.angle = math.radians(angle_deg)
    obj = _add_object(scene, "Sun", sun)
    obj.rotation_euler = mathutils.Vector(SUN_DIRECTION).to_track_quat("Z", "Y").to_euler()
    return obj


def _aimed_lamp(scene, kind: str, energy: float, position):
    """A lamp at `position` aimed at Suzanne."""
    import bpy
    import mathutils

    lamp = bpy.data.lights.new(kind.title(), kind)
    lamp.energy = energy
    obj = _add_object(scene, kind.title(), lamp, tuple(position))
    target = mathutils.Vector((0.0, 0.0, 0.7))
    obj.rotation_euler = (target - mathutils.Vector(position)).to_track_quat("-Z", "Y").to_euler()
    return obj


def add_area(scene):
    obj = _aimed_lamp(scene, "AREA", AREA_POWER, LAMP_POSITION)
    obj.data.size = AREA_SIZE
    return obj


def add_point(scene):
    """A point lamp where the area lamp is, of the radius a point lamp added in Blender's
    viewport has (0.1 m; bpy.data.lights.new makes it 0, a point no ray can hit, which the
    residual cannot see: docs/light-sampling.md, "Where the result is not exact")."""
    obj = _aimed_lamp(scene, "POINT", POINT_POWER, LAMP_POSITION)
    obj.data.shadow_soft_size = POINT_RADIUS
    return obj


def add_lamps(scene):
    add_sun(scene)
    add_area(scene)


def add_camera(scene, width, height):
    import bpy
    import mathutils

    camera = bpy.data.cameras.new("Camera")
    camera.lens = 50.0
    position = mathutils.Vector((0.0, -5.2, 1.9))
    obj = _add_object(scene, "Camera", camera, tuple(position))
    target = mathutils.Vector((0.0, 0.0, 0.7))
    obj.rotation_euler = (target - position).to_track_quat("-Z", "Y").to_euler()
    scene.camera = obj
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100


# --- the materials ---------------------------------------------------------------------------

def native_material(kind: str, values: dict):
    """Cycles' closest native material for a pair (kind: metallic, glass or principled, the
    first two with _multiscatter or _beckmann for that distribution)."""
    import bpy

    material = bpy.data.materials.new(f"native {kind}")
    material.use_nodes = True
    tree = material.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    # kind: the node and its distribution (GGX unless named)
    distribution = {"multiscatter": "MULTI_GGX", "beckmann": "BECKMANN"}.get(
        kind.partition("_")[2], "GGX")
    if kind.startswith("metallic"):
        node = tree.nodes.new("ShaderNodeBsdfMetallic")
        node.fresnel_type = "PHYSICAL_CONDUCTOR"
        node.distribution = distribution
        node.inputs["IOR"].default_value = values["n"]
        node.inputs["Extinction"].default_value = values["k"]
    elif kind.startswith("glass"):
        node = tree.nodes.new("ShaderNodeBsdfGlass")
        node.distribution = distribution
        node.inputs["IOR"].default_value = values["ior"]
    else:
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.inputs["Base Color"].default_value = tuple(values["base_color"]) + (1.0,)
        node.inputs["IOR"].default_value = values["ior"]
        # Cook-Torrance's s F R_s + (1 - s) R_d: Principled scales its specular layer by
        # Specular IOR Level (0.5 = physical); the closest match to s = 0.3.
        node.inputs["Specular IOR Level"].default_value = values["specular"]
    node.inputs["Roughness"].default_value = values["roughness"]
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return material


def pairs():
    """(label, model id, our values, native kind, whether a Stochastic column is rendered: the
    models with a Light Sampling menu in the catalog)."""
    from .. import presets

    def preset(pid):
        p = presets.find(pid)
        return p.model_id, MODELS[p.model_id].resolve(p.params)

    rows = []
    for pid, label, kind in (
            ("gold", "Gold: Walter GGX", "metallic"),
            ("rough_glass", "Rough glass: Walter GGX", "glass"),
            ("red_plastic", "Red plastic: Cook-Torrance", "principled"),
            ("rough_gold_lee", "Rough gold: Lee V-grooves", "metallic_multiscatter"),
            ("rough_gold_heitz", "Rough gold: Heitz 2016 walk", "metallic_multiscatter")):
        model_id, values = preset(pid)
        stochastic = any(p.id == "estimator" for p in MODELS[model_id].params)
        rows.append((label, model_id, values, kind, stochastic))
    return rows


def build_view(material, width: int, height: int, seed: int = 0, lamps=add_lamps):
    """The look-dev scene with `material` on Suzanne (Blender's defaults otherwise: Clamp
    Indirect 10, Filter Glossy 1, light tree; no denoiser, so the noise shows); `lamps(scene)`
    adds the lamps (default: the sun and the area lamp)."""
    scene = harness.new_scene()
    cycles = scene.cycles
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.seed = seed
    render = scene.render
    render.film_transparent = False
    render.image_settings.file_format = "OPEN_EXR"
    render.image_settings.color_depth = "32"
    render.use_file_extension = False
    add_sky(scene)
    add_floor(scene)
    lamps(scene)
    add_camera(scene, width, height)
    add_suzanne(scene, material() if callable(material) else material)
    return scene


def render_view(material, seconds: float, width: int, height: int, seed: int = 0):
    """One look-dev render of `material` on Suzanne for `seconds` of wall time."""
    scene = build_view(material, width, height, seed)
    scene.cycles.samples = 1 << 16
    scene.cycles.time_limit = seconds
    harness.check_compiled()
    image, wall = harness.render(scene)
    return np.asarray(image), wall


def render_gallery(path, seconds: float = 5.0, width: int = 240, height: int = 180,
                   progress=print) -> list:
    """Every pair (and the Stochastic estimator of the models that have one) for `seconds` each;
    writes a labelled PNG to `path`. Returns one dict per render: label, column, wall time,
    mean pixel value."""
    columns = ("ours, default (Native + Residual\nwhere the model has it)", "ours, Stochastic",
               "Cycles' closest native")
    grid_images, log = [], []
    for label, model_id, values, kind, stochastic in pairs():
        has_menu = any(p.id == "estimator" for p in MODELS[model_id].params)
        makers = [lambda: harness.model_material(model_id, values, label),
                  (lambda: harness.model_material(model_id, {**values, "estimator": "stochastic"},
                                                  label + " stochastic")) if stochastic else None,
                  lambda: native_material(kind, values)]
        row = []
        for column, make in zip(columns, makers):
            if make is None:
                row.append(None)
                continue
            image, wall = render_view(make, seconds, width, height)
            name = column.split("\n")[0] if has_menu or column.startswith("Cycles") else "ours"
            log.append({"label": label, "column": name, "seconds": wall,
                        "mean": float(np.mean(image[..., :3]))})
            progress(f"[demo] look-dev {label} / {name}: {wall:.1f} s")
            row.append(image)
        grid_images.append(row)
    save_figure(path, grid_images, columns, seconds)
    return log


def save_figure(path, grid_images, columns, seconds):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [label for label, *_ in pairs()]
    rows, cols = len(grid_images), len(columns)
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.35 * rows + 0.6), dpi=110)
    for r, row in enumerate(grid_images):
        for c, image in enumerate(row):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            if image is None:
                ax.set_facecolor("0.92")
                ax.text(0.5, 0.5, "no Light Sampling menu:\nstochastic only", ha="center",
                        va="center", transform=ax.transAxes, fontsize=8)
            else:
                ax.imshow(np.clip(image[..., :3], 0.0, 1.0) ** (1.0 / 2.2))
            if r == 0:
                ax.set_title(columns[c], fontsize=9)
            if c == 0:
                ax.set_ylabel(labels[r], fontsize=9)
    fig.suptitle(f"Look-dev: sky, a {SUN_ANGLE_DEG:g} degree sun and an area lamp; every image "
                 f"rendered for {seconds:g} s (Blender's default clamps, no denoiser)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
