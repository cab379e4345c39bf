"""Materials that set a preset's node group against its native branch (addon/fallback.py):
the preset as applied, its native branch built straight from constants, and the same group
without the branch (as before it). Used by tests/test_render_fallback.py and the report's
"fallback" section."""
from __future__ import annotations

import bpy

from .. import fallback, nodes, presets
from ..catalog import MODELS
from . import harness

PLAIN = "plain "  # + the group's name: the same group built without the native branch


def preset_material(preset: presets.Preset):
    """A callable making the preset's material (one Lab group node), as the harness takes."""
    return lambda: harness.model_material(preset.model_id, preset.params, preset.id)


def native_material(preset: presets.Preset):
    """A callable making the preset's native branch built straight into a material."""
    def make():
        material, tree, output = harness.new_material(preset.id)
        shader = fallback.build_native(tree, preset.model,
                                       fallback.constant_sources(preset.model, preset.params))
        tree.links.new(shader, output.inputs["Surface"])
        return material
    return make


def without_branch(make):
    """`make`'s material with its group node pointed at the model's group built without the
    native branch, its inputs set again to the values they had."""
    def wrapped():
        material = make()
        for node in material.node_tree.nodes:
            if node.bl_idname != "ShaderNodeGroup":
                continue
            model = next(m for m in MODELS.values() if nodes.group_name(m) == node.node_tree.name)
            values = {p.id: node.inputs[p.label].default_value for p in model.params}
            plain = bpy.data.node_groups.get(PLAIN + node.node_tree.name)
            if plain is None:
                node.node_tree.name = PLAIN + node.node_tree.name  # build_group makes a new one
                plain = nodes.build_group(model, native=False)
                plain.name, node.node_tree.name = node.node_tree.name, plain.name
            node.node_tree = plain
            for p in model.params:
                node.inputs[p.label].default_value = values[p.id]
        return material
    return wrapped


def correction_material(model_id: str, values: dict, distribution: str = "MULTI_GGX"):
    """A callable making a material of a model's correction lobe alone (fallback.correction),
    for catalog `values`; `distribution` as the branch passes it (MULTI_GGX or BECKMANN)."""
    model = MODELS[model_id]

    def make():
        material, tree, output = harness.new_material("correction")
        branch = fallback.Branch(tree, model, fallback.constant_sources(model, values))
        tree.links.new(fallback.correction(branch, distribution), output.inputs["Surface"])
        return material
    return make


def scale_material(model_id: str, values: dict, distribution: str = "MULTI_GGX"):
    """A callable making a material that emits a model's fitted scale (fallback.fitted_scale)
    as its colour: the factor the native closure is multiplied by, seen per pixel."""
    model = MODELS[model_id]

    def make():
        material, tree, output = harness.new_material("scale")
        branch = fallback.Branch(tree, model, fallback.constant_sources(model, values))
        emission = tree.nodes.new("ShaderNodeEmission")
        tree.links.new(fallback.fitted_scale(branch, distribution), emission.inputs["Color"])
        tree.links.new(emission.outputs[0], output.inputs["Surface"])
        return material
    return make

