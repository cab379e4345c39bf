"""Node groups, one per model, built from the catalog.

Each group exposes the model's parameters as sockets (enums as integer sockets whose tooltip
lists the items) and wraps a compiled INTERNAL Script node. Unlinked group inputs reach OSL as
constants, so switches on them are folded away by the OSL compiler.
"""
from __future__ import annotations

import bpy

from . import shaders
from .catalog import COLOR, ENUM, MODELS, Model

GROUP_PREFIX = "Microfacet Lab: "
SCRIPT_NODE_NAME = "Microfacet Lab OSL"


def group_name(model: Model) -> str:
    return GROUP_PREFIX + model.label


def _new_input(group, param):
    if param.kind == COLOR:
        sock = group.interface.new_socket(param.label, in_out="INPUT", socket_type="NodeSocketColor")
        sock.default_value = (*param.default, 1.0)
    elif param.kind == ENUM:
        sock = group.interface.new_socket(param.label, in_out="INPUT", socket_type="NodeSocketInt")
        sock.default_value = param.index(param.default)
        sock.min_value, sock.max_value = 0, len(param.items) - 1
    else:
        sock = group.interface.new_socket(param.label, in_out="INPUT", socket_type="NodeSocketFloat")
        sock.default_value = param.default
        sock.min_value, sock.max_value = param.min, param.max
    codes = ", ".join(f"{i} {item}" for i, item in enumerate(param.items))
    sock.description = (param.doc + (f" ({codes})" if codes else "")).strip()
    return sock


def build_group(model: Model):
    """Create the model's node group from scratch (replacing one of the same name)."""
    old = bpy.data.node_groups.get(group_name(model))
    if old is not None:
        bpy.data.node_groups.remove(old)
    group = bpy.data.node_groups.new(group_name(model), "ShaderNodeTree")
    group.description = model.doc
    for param in model.params:
        _new_input(group, param)
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")

    group_in = group.nodes.new("NodeGroupInput")
    group_out = group.nodes.new("NodeGroupOutput")
    script = group.nodes.new("ShaderNodeScript")
    script.name = script.label = SCRIPT_NODE_NAME
    group_in.location, script.location, group_out.location = (-400, 0), (0, 0), (300, 0)
    shaders.compile_script_node(script, model)
    for param in model.params:
        group.links.new(group_in.outputs[param.label], script.inputs[shaders.osl_input_name(param)])
    group.links.new(script.outputs["BSDF"], group_out.inputs["BSDF"])
    return group


def ensure_group(model_id: str):
    """The model's node group, built once per file and reused."""
    model = MODELS[model_id]
    group = bpy.data.node_groups.get(group_name(model))
    if group is None or not _is_valid(group):
        group = build_group(model)
    return group


def _is_valid(group) -> bool:
    script = group.nodes.get(SCRIPT_NODE_NAME)
    return script is not None and bool(script.bytecode) and len(script.outputs) > 0


def add_group_node(node_tree, model_id: str, values: dict | None = None):
    """Add a group node for `model_id` to `node_tree`, with socket values from `values`.

    Values are validated and clamped by the catalog (unknown keys raise KeyError).
    """
    model = MODELS[model_id]
    resolved = model.resolve(values)
    node = node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = ensure_group(model_id)
    node.label = model.label
    set_inputs(node, model, resolved)
    return node


def set_inputs(node, model: Model, resolved: dict) -> None:
    for param in model.params:
        value = resolved[param.id]
        if param.kind == COLOR:
            node.inputs[param.label].default_value = (*value, 1.0)
        elif param.kind == ENUM:
            node.inputs[param.label].default_value = param.index(value)
        else:
            node.inputs[param.label].default_value = value
