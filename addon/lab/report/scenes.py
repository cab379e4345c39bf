"""Blender scenes of the report: the sun lamp and its calibration, one grid scene per
environment rendered row by row through a render border, and the GPU (OptiX) device."""
from __future__ import annotations

import math

import numpy as np

from .. import grid
from ..native import native_source
from .config import AREA_LAMP, CONE_LIGHTS, POINT_LAMP, SUN_ANGLE_DEG, SUN_STRENGTH, SUN_WORLD
from .lights import area_lamp_axes, cone_radiance, hdri_spot, sun_unit


def add_sun(scene, strength=SUN_STRENGTH, angle_deg=SUN_ANGLE_DEG):
    import bpy
    import mathutils

    light = bpy.data.lights.new("Microfacet Lab sun", "SUN")
    light.energy = strength
    light.angle = math.radians(angle_deg)
    obj = bpy.data.objects.new("Microfacet Lab sun", light)
    # A sun lamp shines along its local -Z: point +Z at the sun.
    obj.rotation_euler = mathutils.Vector(tuple(sun_unit())).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    return obj


def add_point_lamp(scene, position=(0.0, 0.0, POINT_LAMP["height"]),
                   radius=POINT_LAMP["radius"], power=POINT_LAMP["power"]):
    """A point lamp with Blender's defaults (Soft Falloff)."""
    import bpy

    light = bpy.data.lights.new("Microfacet Lab point", "POINT")
    light.energy = power
    light.shadow_soft_size = radius
    obj = bpy.data.objects.new("Microfacet Lab point", light)
    obj.location = position
    scene.collection.objects.link(obj)
    return obj


def add_area_lamp(scene):
    """A rectangular area lamp (Cycles: radiance P / (pi A) on its front, the lamp's -Z)."""
    import bpy

    light = bpy.data.lights.new("Microfacet Lab area", "AREA")
    light.shape = "RECTANGLE"
    light.size, light.size_y = AREA_LAMP["size"]
    light.energy = AREA_LAMP["power"]
    obj = bpy.data.objects.new("Microfacet Lab area", light)
    obj.location = area_lamp_axes()[0]
    obj.rotation_euler = (AREA_LAMP["tilt"], 0.0, 0.0)
    scene.collection.objects.link(obj)
    return obj


def env_for(env_key):
    return grid.ENVIRONMENTS.get(env_key) or grid.Environment("sun over a dim world", SUN_WORLD)


def add_spot_world(scene, radiance: float, half: float):
    """Add a uniform disk of `radiance` around sun_unit() to the scene's world (dim uniform
    SUN_WORLD elsewhere): world light only, no lamp."""
    tree = scene.world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    dot = tree.nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    dot.inputs[1].default_value = tuple(sun_unit())
    inside = tree.nodes.new("ShaderNodeMath")
    inside.operation = "GREATER_THAN"
    inside.inputs[1].default_value = math.cos(half)
    level = tree.nodes.new("ShaderNodeMath")
    level.operation = "MULTIPLY_ADD"
    level.inputs[1].default_value = radiance
    level.inputs[2].default_value = SUN_WORLD
    tree.links.new(coords.outputs["Generated"], dot.inputs[0])
    tree.links.new(dot.outputs["Value"], inside.inputs[0])
    tree.links.new(inside.outputs["Value"], level.inputs[0])
    tree.links.new(level.outputs["Value"], background.inputs["Color"])


def calibrate_sun(progress) -> dict:
    """Radiance of the sun lamp as Cycles renders it, read off a mirror sphere (roughness 0,
    F = 1: deterministic, one sample): pixels whose mirror direction lies in the sun's cone
    see L_sun + nothing else. Compared with strength / (2 pi (1 - cos(angle / 2)))."""
    from .. import harness

    half = math.radians(SUN_ANGLE_DEG) / 2.0
    layout = grid.GridLayout(1, 1, cell_px=160)
    scene = harness.new_scene()
    mats = [harness.model_material("walter_reflection", {"roughness": 0.0, "fresnel_type": "none"},
                                   "sun mirror")]
    harness.build_grid_scene(layout, mats, env_for("sun"), 1, 0)
    add_sun(scene)
    image, _ = harness.render(scene)
    index, normal, _ = layout.pixel_geometry()
    wo = 2.0 * normal[..., 2:3] * normal - grid.VIEW
    cosang = wo @ sun_unit()
    inside = (index == 0) & (cosang > math.cos(half * 0.95))
    outside = (index == 0) & (cosang < math.cos(half * 1.05))
    vals = image[..., 0][inside] - SUN_WORLD
    formula = SUN_STRENGTH / (2.0 * math.pi * (1.0 - math.cos(half)))
    result = {"pixels_inside": int(inside.sum()), "formula": formula,
              "radiance": float(np.median(vals)) if len(vals) else formula,
              "spread": float(vals.max() - vals.min()) if len(vals) else 0.0,
              "outside_max": float(np.abs(image[..., 0][outside] - SUN_WORLD).max()),
              "half_angle": half}
    progress(f"sun calibration: radiance {result['radiance']:.3f} over {result['pixels_inside']} "
             f"mirror pixels (2 pi (1 - cos) formula: {formula:.3f})")
    return result


def build_env_scene(rows, cfg, env_key, device="CPU", sun_cal=None):
    """One scene per environment: row r of the grid is rows[r], one sphere per roughness."""
    from .. import harness

    layout = grid.GridLayout(len(rows), len(cfg.roughness), cell_px=cfg.cell_px)
    scene = harness.new_scene()
    mats = []
    for row in rows:
        for r in cfg.roughness:
            name = f"{row.key} r={r}"
            if row.model_id is None:
                mats.append(harness.osl_material(native_source(row.native_kind, r), name))
            else:
                mats.append(harness.model_material(row.model_id, {**row.values, "roughness": r},
                                                   name))
    harness.build_grid_scene(layout, mats, env_for(env_key), 1, cfg.seed)
    if env_key in CONE_LIGHTS and CONE_LIGHTS[env_key][0] == "lamp":
        add_sun(scene, angle_deg=CONE_LIGHTS[env_key][1])
    elif env_key in CONE_LIGHTS and CONE_LIGHTS[env_key][0] == "image":
        harness.add_image_world(scene, SUN_WORLD + hdri_spot(env_key, sun_cal))
    elif env_key in CONE_LIGHTS:
        add_spot_world(scene, *cone_radiance(env_key, sun_cal))
    elif env_key == "point":
        add_point_lamp(scene)
    elif env_key == "area":
        add_area_lamp(scene)
    if device != "CPU":
        set_gpu(scene, device)
    scene.render.use_persistent_data = True
    return scene, layout


def optix_devices() -> list:
    """Names of OptiX devices bpy reports (none on a machine without an NVIDIA GPU)."""
    try:
        import bpy

        prefs = bpy.context.preferences.addons["cycles"].preferences
        prefs.refresh_devices()
        return [d.name for d in prefs.get_devices_for_type("OPTIX")]
    except Exception:  # noqa: BLE001
        return []


def set_gpu(scene, kind="OPTIX"):
    import bpy

    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.compute_device_type = kind
    for d in prefs.get_devices_for_type(kind):
        d.use = True
    scene.cycles.device = "GPU"
