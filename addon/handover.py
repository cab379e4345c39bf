"""Hand the scene's lamps to the Microfacet Lab shaders: the bpy half of addon/lamps.py
(docs/light-sampling.md, "The residual's direct light").

`hand_over(scene)` reads the lamps the scene renders (sun, point, spot, area, at the current
frame) and the world's bright spots (an HDRI's sun, the Sky Texture's sun disc:
addon/world_lights.py), writes their table into every Microfacet Lab text whose shader aims
at lamps, holds every other Microfacet Lab text to the add-on's source (a .blend compiled by
another Blender or add-on version), and recompiles the Script nodes that use a text that
changed. A render_pre handler runs it before every render: F12, `blender --background`, each
frame of an animation (so animated lamps are handed over per frame); the harness and
scripts/render_scene.py call it too.

The table only guides where the shaders' residual rays go and what their control variate
predicts (addon/lamps.py, osl/nee.h; the prediction is withheld where it could not pair: see
hand_over), so a .blend that renders without the add-on (its texts and bytecode are saved in the file) keeps the lamps of
the last hand-over: for animated lamps, those of the frame rendered or saved last. It still
converges to the same image, with more noise where the lamps have moved away.
"""
from __future__ import annotations

import dataclasses
import math
import sys

import bpy
from bpy.app.handlers import persistent
from mathutils import Vector

from . import fallback, lamps, shader_nodes, shaders, world_lights
from .catalog import MODELS


def _node_colour(light):
    """What a lamp's node tree multiplies its emission by: white without one (Blender 4.x by
    default); an Emission node's Color times Strength where that node, with nothing linked into
    it, feeds the active Light Output (Blender 5.x's default tree); None for anything else."""
    tree = light.node_tree if getattr(light, "use_nodes", False) else None
    if tree is None:
        return (1.0, 1.0, 1.0)
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputLight"]
    active = [n for n in outputs if getattr(n, "is_active_output", True)] or outputs
    surface = active[0].inputs.get("Surface") if active else None
    if surface is None or not surface.is_linked:
        return None
    node = surface.links[0].from_node
    if node.bl_idname != "ShaderNodeEmission" or any(i.is_linked for i in node.inputs):
        return None
    strength = float(node.inputs["Strength"].default_value)
    return tuple(float(c) * strength for c in node.inputs["Color"].default_value[:3])


def _radiance(obj, per_area: float):
    """The lamp's radiance as Cycles emits it (lamps.predicted_radiance), or zeros where the
    prediction would be a guess: a lamp whose nodes do more than an Emission node, or with
    light linking."""
    light = obj.data
    linking = getattr(obj, "light_linking", None)
    nodes = _node_colour(light)
    if (nodes is None or getattr(linking, "receiver_collection", None) is not None
            or getattr(linking, "blocker_collection", None) is not None):
        return (0.0, 0.0, 0.0)
    strength = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    colour = tuple(float(a) * b for a, b in zip(light.color, nodes))
    return lamps.predicted_radiance(strength, colour, per_area)


def _lamp_record(obj):
    light = obj.data
    m = obj.matrix_world
    power = lamps.guiding_power(light.energy, light.color)
    if light.type == "SUN":
        # Cycles: S / (pi sin^2(angle / 2)) over the sun's cone
        per_area = math.pi * math.sin(0.5 * float(light.angle)) ** 2
        return lamps.sun_record(tuple(m.col[2].xyz), float(light.angle), power,
                                _radiance(obj, per_area))
    position = tuple(m.translation)
    if light.type in ("POINT", "SPOT"):
        radius = float(light.shadow_soft_size)
        # Cycles: P / (4 pi r^2) / pi over the sphere or the disk facing P; a spot's cone is
        # not predicted
        radiance = (_radiance(obj, 4.0 * math.pi ** 2 * radius ** 2)
                    if light.type == "POINT" else (0.0, 0.0, 0.0))
        return lamps.sphere_record(position, radius, power,
                                   is_sphere=not getattr(light, "use_soft_falloff", True),
                                   radiance=radiance)
    if light.type == "AREA":
        size_x = float(light.size)
        size_y = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else size_x
        u = Vector(m.col[0].xyz) * (0.5 * size_x)
        v = Vector(m.col[1].xyz) * (0.5 * size_y)
        area = u.length * v.length * (math.pi if light.shape in ("DISK", "ELLIPSE") else 4.0)
        # Cycles: P / (pi A), or P / pi without Normalize; a narrowed Spread is not predicted
        normalized = getattr(light, "normalize", True)
        radiance = (_radiance(obj, math.pi * (area if normalized else 1.0))
                    if float(getattr(light, "spread", math.pi)) >= math.pi - 1e-6
                    else (0.0, 0.0, 0.0))
        return lamps.area_record(light.shape, position, tuple(-m.col[2].xyz), tuple(u),
                                 tuple(v), power, radiance)
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


def _nodes(kind: str, uses):
    """(tree, node) for each node of bl_idname `kind` in a material or node group for which
    uses(node) holds."""
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
    trees += list(bpy.data.node_groups)
    for tree in trees:
        for node in tree.nodes:
            if node.bl_idname == kind and uses(node):
                yield tree, node


def _script_nodes(text):
    """(tree, node) for each Script node that uses `text`."""
    return _nodes("ShaderNodeScript", lambda node: node.script == text)


def _renders_on_cpu(scene) -> bool:
    """Whether `scene` renders on the CPU: trace() does nothing on OptiX (docs/cycles-osl.md), so
    the shaders' control variate (osl/nee.h) is for the CPU only; a --cycles-device on the
    command line overrides the scene."""
    argv = list(sys.argv)
    if "--cycles-device" in argv[:-1]:
        return argv[argv.index("--cycles-device") + 1].upper().startswith("CPU")
    if getattr(scene.cycles, "device", "CPU") != "GPU":
        return True
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
        return prefs.compute_device_type == "NONE"
    except (AttributeError, KeyError):
        return False


# View-layer passes that would show the control variate's parts apart: its lamp light in
# Emission (signed, mean 0) and the delta's in the glossy passes, each as noisy as without it.
_SPLIT_PASSES = ("use_pass_emit", "use_pass_glossy_direct", "use_pass_glossy_indirect")


def _passes_combined_only(scene) -> bool:
    """Whether no view layer that renders asks for the glossy or emission passes or light
    groups: the control variate lowers the noise of Combined only (osl/nee.h)."""
    for layer in scene.view_layers:
        if not getattr(layer, "use", True):
            continue
        if any(getattr(layer, name, False) for name in _SPLIT_PASSES):
            return False
        if len(getattr(layer, "lightgroups", ())) > 0:
            return False
    return True


def _group_users(tree):
    """The group nodes that use node group `tree`, with the tree each sits in."""
    return _nodes("ShaderNodeGroup", lambda node: node.node_tree == tree)


def _feeds_surface_alone(tree, node, depth: int = 0) -> bool:
    """Whether every closure `node` outputs reaches a Material Output's Surface with nothing
    else beside it: through reroutes, the node group's own native switch (fallback.py) and group
    outputs only. The control variate pairs its subtraction with the delta, which holds only
    where Cycles can continue with no other closure (osl/nee.h)."""
    if depth > 16:
        return False
    for output in node.outputs:
        if output.type != "SHADER":
            continue
        for link in output.links:
            target = link.to_node
            if target.bl_idname == "ShaderNodeOutputMaterial":
                ok = link.to_socket.name == "Surface"
            elif target.bl_idname == "NodeReroute" or (
                    target.name == fallback.SWITCH_NODE_NAME
                    and link.to_socket == target.inputs[2]):
                ok = _feeds_surface_alone(tree, target, depth + 1)
            elif target.bl_idname == "NodeGroupOutput":
                ok = all(_feeds_surface_alone(parent, user, depth + 1)
                         for parent, user in _group_users(tree))
            else:
                ok = False
            if not ok:
                return False
    return True


# Cycles counts any OSL shader that calls emission() as a lamp (Emission Sampling "Auto": every
# face into the light tree, a guessed strength of 1), though the control variate's emission is 0
# off the camera's hits, where lamps are sampled; so a material whose surface is a paired shader
# alone gets "None" (rough gold Lee on the look-dev Suzanne under the sun: variance 2.99e-3 ->
# 2.40e-3), and gets its own setting back when it is no longer paired.
_SAMPLING_KEY = "microfacet_lab_emission_sampling"


def _materials_using(tree, depth: int = 0):
    """The materials whose node tree is `tree` or holds it as a (nested) node group."""
    for material in bpy.data.materials:
        if material.node_tree == tree:
            yield material
    if depth < 16:
        for parent, _ in _group_users(tree):
            yield from _materials_using(parent, depth + 1)


def _set_emission_sampling(material, paired: bool) -> None:
    settings = getattr(material, "cycles", None)
    if settings is None or not hasattr(settings, "emission_sampling"):
        return
    if paired and settings.emission_sampling != "NONE":
        material[_SAMPLING_KEY] = settings.emission_sampling
        settings.emission_sampling = "NONE"
    elif not paired and _SAMPLING_KEY in material:
        settings.emission_sampling = material[_SAMPLING_KEY]
        del material[_SAMPLING_KEY]


def _without_radiance(records) -> list:
    return [dataclasses.replace(r, radiance=(0.0, 0.0, 0.0), texels=None) for r in records]


def hand_over(scene, depsgraph=None, predict: bool = True) -> list[str]:
    """Write `scene`'s lamps and world spots into the lamp-aiming texts that exist and recompile
    their Script nodes; returns the names of the texts that changed (none when nothing did).
    A text gets the lamps' predicted radiance (osl/nee.h) only with `predict`, where the scene
    renders on the CPU, into Combined without the glossy and emission passes
    (_passes_combined_only), and every Script node using it feeds a material's Surface alone
    (_feeds_surface_alone).
    Every model's text is held to the add-on's source, so a .blend compiled by another Blender
    (the version facts of shaders.version_defines) or another add-on version is brought up to
    date at render time too."""
    records = scene_records(scene, depsgraph)
    estimate = predict and _renders_on_cpu(scene) and _passes_combined_only(scene)
    changed = []
    for model in MODELS.values():
        text = bpy.data.texts.get(shader_nodes.text_name(model))
        if text is None:
            continue
        users = list(_script_nodes(text))
        paired = estimate and all(_feeds_surface_alone(tree, node) for tree, node in users)
        for tree in {tree for tree, _ in users}:
            for material in set(_materials_using(tree)):
                _set_emission_sampling(material, paired)
        model_records = records if paired else _without_radiance(records)
        if not users or text.as_string() == shaders.shader_source(model, model_records):
            continue
        for _, node in users:
            shader_nodes.compile_script_node(node, model, model_records)
        changed.append(text.name)
    return changed


@persistent
def _on_render_pre(scene, depsgraph=None):
    try:
        hand_over(scene, depsgraph)
    except Exception as exc:  # never stop a render: the shaders stay exact without the table
        print(f"Microfacet Lab: lamps not handed over ({exc}); renders stay exact, noisier")


# After a render, and before a save, the prediction is withdrawn: the viewport (which runs no
# render_pre) and a file rendered without the add-on would otherwise keep it while the lamps
# move, exact but with the old lamp's light added and, rarely, taken away (a ghost highlight and
# negative samples). Without it they aim at the last lamps, as before.
@persistent
def _on_render_done(scene, depsgraph=None):
    try:
        hand_over(scene, depsgraph, predict=False)
    except Exception as exc:
        print(f"Microfacet Lab: lamp prediction not withdrawn ({exc})")


@persistent
def _on_save_pre(*_args):
    scene = getattr(bpy.context, "scene", None)
    if scene is not None:
        _on_render_done(scene)


_HANDLERS = (("render_pre", _on_render_pre), ("render_complete", _on_render_done),
             ("render_cancel", _on_render_done), ("save_pre", _on_save_pre))


def register():
    for name, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if handler not in handlers:
            handlers.append(handler)


def unregister():
    for name, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if handler in handlers:
            handlers.remove(handler)
