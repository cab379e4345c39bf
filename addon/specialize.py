"""Specialize a scene: leave out what its materials do not need.

`specialize(scene)` scans the materials the scene renders and

(a) compiles only the Microfacet Lab shaders they use (from the add-on's current OSL, when the
    file's text differs from it or the bytecode is missing; current ones are left as they are), and
    removes Microfacet Lab node groups that no material or node tree references (orphans kept
    only by a fake user) and `MicrofacetLab_*` texts that no Script node uses any more. A group
    referenced by a material outside this scene is kept (never breaks a material) but not
    compiled;
(b) sets Cycles' light-path bounces to what the materials can use. The rules:
    - a lobe kind no material has gets 0 bounces: transmission (refraction, glass), glossy
      (reflection, microfacet, metal), diffuse (diffuse, subsurface, translucent, sheen), volume
      (a Volume output linked, or a world volume), transparent (Transparent BSDF);
    - depth: when no renderable object is visible to secondary rays (diffuse, glossy,
      transmission, volume scatter) every path meets the world after its first scatter, so each
      remaining kind and the total are capped at 1 (the sphere-grid case); otherwise the
      remaining counts keep the scene's values (never raised);
    - what silently changes results is not touched: caustics, Filter Glossy, clamping, seeds,
      light sampling.
    Lobe kinds are read conservatively: every node of a material's tree (and nested groups)
    counts, linked or not; a Script node that is not Microfacet Lab's, or an unknown shader
    node, counts as every kind. Microfacet Lab groups count as the lobes their catalog model's
    tags name (a model without lobe tags, or an unknown model, counts as every kind);
(c) checks that the model switches (enum inputs) of every Microfacet Lab group node are
    unlinked constants, which the OSL compiler folds away; linked ones are reported.

`scan(scene)` does the reading without changing anything. Both return a `Report`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy

from . import compat, handover, nodes, shader_nodes, shaders
from .catalog import ENUM, MODELS

DIFFUSE, GLOSSY, TRANSMISSION, VOLUME, TRANSPARENT = (
    "diffuse", "glossy", "transmission", "volume", "transparent")
ALL = frozenset((DIFFUSE, GLOSSY, TRANSMISSION, VOLUME, TRANSPARENT))
LOBE_KINDS = (DIFFUSE, GLOSSY, TRANSMISSION, VOLUME, TRANSPARENT)

# Cycles shader nodes by bl_idname -> lobe kinds (Blender 4.2 to 5.x names).
NATIVE_LOBES = {
    "ShaderNodeBsdfDiffuse": {DIFFUSE},
    "ShaderNodeBsdfSheen": {DIFFUSE},
    "ShaderNodeBsdfTranslucent": {DIFFUSE},  # Cycles counts it as a diffuse bounce
    "ShaderNodeSubsurfaceScattering": {DIFFUSE},
    "ShaderNodeBsdfToon": {DIFFUSE, GLOSSY},
    "ShaderNodeBsdfGlossy": {GLOSSY},
    "ShaderNodeBsdfAnisotropic": {GLOSSY},
    "ShaderNodeBsdfMetallic": {GLOSSY},
    "ShaderNodeBsdfRefraction": {TRANSMISSION},
    "ShaderNodeBsdfGlass": {GLOSSY, TRANSMISSION},
    "ShaderNodeBsdfHair": {GLOSSY, TRANSMISSION},
    "ShaderNodeBsdfHairPrincipled": {GLOSSY, TRANSMISSION},
    "ShaderNodeBsdfRayPortal": {TRANSPARENT},
    "ShaderNodeBsdfTransparent": {TRANSPARENT},
    "ShaderNodeVolumeAbsorption": {VOLUME},
    "ShaderNodeVolumeScatter": {VOLUME},
    "ShaderNodeVolumePrincipled": {VOLUME},
    "ShaderNodeVolumeCoefficients": {VOLUME},
    "ShaderNodeEmission": set(),
    "ShaderNodeBackground": set(),
    "ShaderNodeHoldout": set(),
    "ShaderNodeAddShader": set(),
    "ShaderNodeMixShader": set(),
}
RENDERABLE = {"MESH", "CURVE", "CURVES", "SURFACE", "META", "FONT", "POINTCLOUD", "VOLUME"}
SECONDARY_RAYS = ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter")
BOUNCES = {DIFFUSE: "diffuse_bounces", GLOSSY: "glossy_bounces",
           TRANSMISSION: "transmission_bounces", VOLUME: "volume_bounces",
           TRANSPARENT: "transparent_max_bounces"}


@dataclass
class Report:
    scene: str
    materials: list = field(default_factory=list)  # names the scene renders
    models: dict = field(default_factory=dict)  # model id -> material names
    lobes: set = field(default_factory=set)
    secondary_hits: bool = True
    compiled: list = field(default_factory=list)  # model ids (re)compiled: stale or no bytecode
    up_to_date: list = field(default_factory=list)  # model ids used, bytecode already current
    removed_groups: list = field(default_factory=list)
    removed_texts: list = field(default_factory=list)
    kept_groups: list = field(default_factory=list)  # used only outside this scene
    linked_enums: list = field(default_factory=list)  # "material / node / socket"
    bounces_before: dict = field(default_factory=dict)
    bounces_after: dict = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"scene {self.scene!r}: {len(self.materials)} material(s), "
               f"models {sorted(self.models) or 'none'}, lobes {sorted(self.lobes)}",
               f"secondary rays can hit objects: {self.secondary_hits}"]
        if self.compiled or self.up_to_date:
            out.append(f"compiled: {self.compiled}, already up to date: {self.up_to_date}")
        if self.removed_groups or self.removed_texts:
            out.append(f"removed groups {self.removed_groups}, texts {self.removed_texts}")
        if self.kept_groups:
            out.append(f"kept (used by materials outside this scene): {self.kept_groups}")
        changed = {k: (self.bounces_before[k], v) for k, v in self.bounces_after.items()
                   if self.bounces_before.get(k) != v}
        if changed:
            out.append("bounces " + ", ".join(f"{k} {a} -> {b}" for k, (a, b) in changed.items()))
        for item in self.linked_enums:
            out.append(f"WARNING linked model switch (not constant-folded): {item}")
        return out

    def __str__(self) -> str:
        return "\n".join(self.lines())


# --- reading ----------------------------------------------------------------------------------

def is_lab_group(tree) -> bool:
    return (tree is not None and tree.bl_idname == "ShaderNodeTree"
            and tree.name.startswith(nodes.GROUP_PREFIX) and nodes.SCRIPT_NODE_NAME in tree.nodes)


def group_model(tree):
    """The catalog model of a Microfacet Lab group (by its script's text or its name), or None."""
    script = tree.nodes.get(nodes.SCRIPT_NODE_NAME)
    for model in MODELS.values():
        if script is not None and script.script is not None \
                and script.script.name == shader_nodes.text_name(model):
            return model
        if tree.name == nodes.group_name(model):
            return model
    return None


def model_lobes(model) -> frozenset:
    if model is None:
        return ALL
    tagged = frozenset(t for t in model.tags if t in ALL)
    return tagged or ALL


def scene_materials(scene) -> list:
    """Materials the scene renders: object and data slots, and materials given to geometry-nodes
    modifiers (inputs and Set Material nodes), for every object of the scene."""
    found = {}

    def add(mat):
        if isinstance(mat, bpy.types.Material):
            found.setdefault(mat.name_full, mat)

    def walk_geometry_tree(tree, seen):
        if tree is None or tree.name_full in seen:
            return
        seen.add(tree.name_full)
        for node in tree.nodes:
            if node.bl_idname == "GeometryNodeSetMaterial":
                sock = node.inputs.get("Material")
                if sock is not None and not sock.is_linked:
                    add(sock.default_value)
            elif node.bl_idname == "GeometryNodeGroup":
                walk_geometry_tree(node.node_tree, seen)
            for sock in node.inputs:
                if sock.bl_idname == "NodeSocketMaterial" and not sock.is_linked:
                    add(sock.default_value)

    for obj in scene.objects:
        for slot in obj.material_slots:
            add(slot.material)
        data_mats = getattr(obj.data, "materials", None)
        if data_mats is not None:
            for mat in data_mats:
                add(mat)
        for mod in obj.modifiers:
            if mod.type == "NODES":
                for value in compat.modifier_input_values(mod):
                    add(value)
                walk_geometry_tree(mod.node_group, set())
    return list(found.values())


def _walk_shader_tree(tree, visit, seen=None):
    seen = set() if seen is None else seen
    if tree is None or tree.name_full in seen:
        return
    seen.add(tree.name_full)
    for node in tree.nodes:
        visit(tree, node)
        if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None \
                and not is_lab_group(node.node_tree):
            _walk_shader_tree(node.node_tree, visit, seen)


def _node_lobes(node) -> set:
    if node.bl_idname == "ShaderNodeGroup":
        return set(model_lobes(group_model(node.node_tree))) if is_lab_group(node.node_tree) else set()
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        lobes = {DIFFUSE, GLOSSY}
        weight = node.inputs.get("Transmission Weight") or node.inputs.get("Transmission")
        if weight is None or weight.is_linked or weight.default_value > 0.0:
            lobes.add(TRANSMISSION)
        alpha = node.inputs.get("Alpha")
        if alpha is None or alpha.is_linked or alpha.default_value < 1.0:
            lobes.add(TRANSPARENT)
        return lobes
    if node.bl_idname in NATIVE_LOBES:
        return set(NATIVE_LOBES[node.bl_idname])
    if node.bl_idname == "ShaderNodeScript" or any(s.type == "SHADER" for s in node.outputs):
        return set(ALL)  # foreign OSL or an unknown closure node: assume anything
    if node.bl_idname == "ShaderNodeOutputMaterial":
        volume = node.inputs.get("Volume")
        return {VOLUME} if volume is not None and volume.is_linked else set()
    return set()


def material_lobes(material) -> set:
    lobes = set()
    tree = compat.node_tree_of(material)
    if tree is not None:
        _walk_shader_tree(tree, lambda tree, node: lobes.update(_node_lobes(node)))
    else:
        lobes.update({DIFFUSE, GLOSSY})
    return lobes


def lab_nodes(material):
    """(tree, group node) of every Microfacet Lab group a material uses, nested groups too."""
    found = []

    def visit(tree, node):
        if node.bl_idname == "ShaderNodeGroup" and is_lab_group(node.node_tree):
            found.append((tree, node))

    if material.node_tree is not None:
        _walk_shader_tree(material.node_tree, visit)
    return found


def linked_enum_inputs(material) -> list[str]:
    out = []
    for tree, node in lab_nodes(material):
        model = group_model(node.node_tree)
        if model is None:
            continue
        for param in model.params:
            sock = node.inputs.get(param.label)
            if param.kind == ENUM and sock is not None and sock.is_linked:
                out.append(f"{material.name} / {node.name} / {param.label}")
    return out


def secondary_hits_possible(scene) -> bool:
    """Can a ray after the first scatter hit any renderable object of the scene?"""
    for obj in scene.objects:
        if obj.type not in RENDERABLE or obj.hide_render:
            continue
        if any(getattr(obj, attr, True) for attr in SECONDARY_RAYS):
            return True
    return False


def world_has_volume(scene) -> bool:
    tree = compat.node_tree_of(scene.world)
    if tree is None:
        return False
    return any(n.bl_idname == "ShaderNodeOutputWorld" and n.inputs["Volume"].is_linked
               for n in tree.nodes)


def bounce_settings(scene) -> dict:
    c = scene.cycles
    return {name: getattr(c, name) for name in ("max_bounces", *BOUNCES.values())}


def scan(scene) -> Report:
    report = Report(scene=scene.name)
    mats = scene_materials(scene)
    report.materials = [m.name for m in mats]
    for mat in mats:
        report.lobes |= material_lobes(mat)
        for _, node in lab_nodes(mat):
            model = group_model(node.node_tree)
            key = model.id if model is not None else node.node_tree.name
            report.models.setdefault(key, [])
            if mat.name not in report.models[key]:
                report.models[key].append(mat.name)
        report.linked_enums += linked_enum_inputs(mat)
    if world_has_volume(scene):
        report.lobes.add(VOLUME)
    report.secondary_hits = secondary_hits_possible(scene)
    report.bounces_before = bounce_settings(scene)
    report.bounces_after = needed_bounces(report.lobes, report.secondary_hits, report.bounces_before)
    return report


def needed_bounces(lobes: set, secondary_hits: bool, current: dict) -> dict:
    """The rules of (b) (module docstring) applied to the scene's current settings."""
    out = {}
    for kind, name in BOUNCES.items():
        if kind not in lobes:
            out[name] = 0
        elif not secondary_hits and kind != TRANSPARENT:
            out[name] = min(current[name], 1)
        else:
            out[name] = current[name]
    out["max_bounces"] = current["max_bounces"] if secondary_hits else min(current["max_bounces"], 1)
    return out


# --- changing ---------------------------------------------------------------------------------

def _referenced_groups() -> set:
    """Names of node groups referenced by a group node in any material, world, light or group."""
    used = set()
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
    trees += [w.node_tree for w in bpy.data.worlds if w.node_tree is not None]
    trees += [l.node_tree for l in bpy.data.lights if getattr(l, "node_tree", None) is not None]
    trees += [g for g in bpy.data.node_groups]
    for tree in trees:
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
                used.add(node.node_tree.name_full)
    return used


def prune_and_compile(scene, report: Report) -> None:
    """(a): recompile the models the scene uses; remove unreferenced groups and texts."""
    scene_groups = set()
    for name in report.materials:
        mat = bpy.data.materials.get(name)
        for _, node in lab_nodes(mat) if mat is not None else []:
            scene_groups.add(node.node_tree.name_full)
    compiled, up_to_date = set(), set()
    records = handover.scene_records(scene)
    for name in sorted(scene_groups):
        group = bpy.data.node_groups[name]
        model = group_model(group)
        if model is None:
            continue
        script = group.nodes[nodes.SCRIPT_NODE_NAME]
        current = script.script is not None and script.bytecode \
            and script.script.as_string() == shaders.shader_source(model, records)
        if current:
            up_to_date.add(model.id)
        else:  # stale or missing bytecode: compile from the add-on's current OSL and lamps
            shader_nodes.compile_script_node(script, model, records)
            compiled.add(model.id)
    report.compiled, report.up_to_date = sorted(compiled), sorted(up_to_date)
    referenced = _referenced_groups()
    for group in list(bpy.data.node_groups):
        if not is_lab_group(group):
            continue
        if group.name_full not in referenced:
            report.removed_groups.append(group.name)
            bpy.data.node_groups.remove(group)
        elif group.name_full not in scene_groups:
            report.kept_groups.append(group.name)
    used_texts = set()
    for tree in [m.node_tree for m in bpy.data.materials if m.node_tree is not None] + \
            list(bpy.data.node_groups):
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeScript" and node.script is not None:
                used_texts.add(node.script.name_full)
    for text in list(bpy.data.texts):
        if text.name.startswith(shader_nodes.TEXT_PREFIX) and text.name_full not in used_texts:
            report.removed_texts.append(text.name)
            bpy.data.texts.remove(text)


def apply_bounces(scene, report: Report) -> None:
    for name, value in report.bounces_after.items():
        setattr(scene.cycles, name, value)


def specialize(scene=None, prune: bool = True, bounces: bool = True) -> Report:
    """Scan `scene` (the context scene by default) and apply (a) and (b); (c) is reported."""
    scene = scene or bpy.context.scene
    report = scan(scene)
    if prune:
        prune_and_compile(scene, report)
    if bounces:
        apply_bounces(scene, report)
    else:
        report.bounces_after = dict(report.bounces_before)
    return report
