"""Hand the scene's lamps to the Microfacet Lab shaders: the bpy half of addon/lamps.py
(docs/light-sampling.md, "The residual's direct light").

`hand_over(scene)` reads the lamps the scene renders (sun, point, spot, area, at the current
frame) and the world's bright spots (an HDRI's sun, the Sky Texture's sun disc:
addon/world_lights.py), writes their table into every Microfacet Lab text whose shader aims
at lamps, holds every other Microfacet Lab text to the add-on's source (a .blend compiled by
another Blender or add-on version), and recompiles the Script nodes that use a text that
changed. A render_pre handler
runs it before every render: F12, `blender --background`, each frame of an animation (so animated lamps are
handed over per frame); the harness and scripts/render_scene.py call it too.

The table only guides where the shaders' residual rays go (addon/lamps.py), so a .blend that
renders without the add-on (its texts and bytecode are saved in the file) keeps the lamps of
the last hand-over: for animated lamps, those of the frame rendered or saved last. It still
converges to the same image, with more noise where the lamps have moved away.
"""
from __future__ import annotations

import bpy
from bpy.app.handlers import persistent
from mathutils import Vector

from . import lamps, shader_nodes, shaders, world_lights
from .catalog import MODELS


def _lamp_record(obj):
    light = obj.data
    m = obj.matrix_world
    power = lamps.guiding_power(light.energy, light.color)
    if light.type == "SUN":
        return lamps.sun_record(tuple(m.col[2].xyz), float(light.angle), power)
    position = tuple(m.translation)
    if light.type in ("POINT", "SPOT"):
        return lamps.sphere_record(position, float(light.shadow_soft_size), power,
                                   is_sphere=not getattr(light, "use_soft_falloff", True))
    if light.type == "AREA":
        size_x = float(light.size)
        size_y = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else size_x
        u = Vector(m.col[0].xyz) * (0.5 * size_x)
        v = Vector(m.col[1].xyz) * (0.5 * size_y)
        return lamps.area_record(light.shape, position, tuple(-m.col[2].xyz), tuple(u),
                                 tuple(v), power)
    return None


def _evaluated(obj, depsgraph):
    """The object as evaluated for the current frame (its matrix_world is stale on an object
    whose transform was set and never evaluated, as in scripts), else the original."""
    if depsgraph is None:
        return obj
    try:
        return obj.evaluated_get(depsgraph)
    except (ReferenceError, RuntimeError):
        return obj


def _depsgraph():
    try:
        return bpy.context.evaluated_depsgraph_get()
    except (AttributeError, RuntimeError):  # no context in this thread
        return None


def scene_lamps(scene, depsgraph=None) -> list:
    """LampRecords of the lamps `scene` renders that a reflected ray can meet (visible to glossy
    rays), at most lamps.MAX_LAMPS, brightest first. `depsgraph`: the evaluated state to read
    transforms and animated values from (the context's when None and available)."""
    lights = [obj for obj in scene.objects if obj.type == "LIGHT" and not obj.hide_render
              and getattr(obj, "visible_glossy", True)]
    if not lights:
        return []
    depsgraph = depsgraph or _depsgraph()
    records = []
    for obj in lights:
        record = _lamp_record(_evaluated(obj, depsgraph))
        if record is not None:
            records.append(record)
    records.sort(key=lambda r: -r.power)
    return records[:lamps.MAX_LAMPS]


def scene_records(scene, depsgraph=None) -> list:
    """What the shaders aim at: the scene's lamps and its world's bright spots, brightest
    first, at most lamps.MAX_LAMPS."""
    records = scene_lamps(scene, depsgraph) + world_lights.world_records(scene)
    records.sort(key=lambda r: -r.power)
    return records[:lamps.MAX_LAMPS]


def _script_nodes(text):
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
    trees += list(bpy.data.node_groups)
    for tree in trees:
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeScript" and node.script == text:
                yield node


def hand_over(scene, depsgraph=None) -> list[str]:
    """Write `scene`'s lamps and world spots into the lamp-aiming texts that exist and recompile
    their Script nodes; returns the names of the texts that changed (none when nothing did).
    Every model's text is held to the add-on's source, so a .blend compiled by another Blender
    (the version facts of shaders.version_defines) or another add-on version is brought up to
    date at render time too."""
    records = scene_records(scene, depsgraph)
    changed = []
    for model in MODELS.values():
        text = bpy.data.texts.get(shader_nodes.text_name(model))
        if text is None or text.as_string() == shaders.shader_source(model, records):
            continue
        users = list(_script_nodes(text))
        if not users:
            continue
        for node in users:
            shader_nodes.compile_script_node(node, model, records)
        changed.append(text.name)
    return changed


@persistent
def _on_render_pre(scene, depsgraph=None):
    try:
        hand_over(scene, depsgraph)
    except Exception as exc:  # never stop a render: the shaders stay exact without the table
        print(f"Microfacet Lab: lamps not handed over ({exc}); renders stay exact, noisier")


def register():
    if _on_render_pre not in bpy.app.handlers.render_pre:
        bpy.app.handlers.render_pre.append(_on_render_pre)


def unregister():
    if _on_render_pre in bpy.app.handlers.render_pre:
        bpy.app.handlers.render_pre.remove(_on_render_pre)
