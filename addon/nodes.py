"""Node groups, one per model, built from the catalog.

Each group exposes the model's parameters as sockets and wraps a compiled INTERNAL Script node:

- enums as menus of the items' display labels where Blender has menu sockets in shader node
  groups (5.0+, `compat.MENU_SOCKETS`): the group's Menu input feeds a Menu Switch (data type
  INT) whose items hold the OSL int codes, and its output feeds the Script node's int input.
  Older versions get integer sockets whose tooltip lists the codes;
- 0-1 parameters (Param.socket FACTOR) as factor sliders, the others as plain floats with the
  catalog's range as the socket's min/max;
- N and K (Param.socket VECTOR) as vectors, as Blender's Metallic BSDF shows its complex IOR
  (the OSL parameter stays a color; the link converts), colours as colour swatches.

A menu socket is always a constant: Blender resolves the Menu Switch before Cycles sees the tree,
so the Script node gets the same constant int as an unlinked integer socket and the OSL compiler
folds the switches on it (measured: identical OSL runtime-optimizer statistics and pixels,
tests/test_nodes.py). Typed-in values outside the range are not refused by Blender; the shader
clamps them (addon/shaders.py).
"""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile

import bpy

from . import compat, fallback, shader_nodes, shaders
from .catalog import COLOR, ENUM, FACTOR, MODELS, VECTOR, Model, Param

GROUP_PREFIX = "Microfacet Lab: "
MODEL_KEY = "microfacet_lab_model"  # custom property: the catalog model a group was built for
SCRIPT_NODE_NAME = "Microfacet Lab OSL"
MENU_NODE_PREFIX = "Microfacet Lab menu: "  # + the parameter id


def group_name(model: Model) -> str:
    return GROUP_PREFIX + model.label


def socket_type(param: Param, menus: bool | None = None) -> str:
    """The interface socket type that shows `param` (menus: None follows compat.MENU_SOCKETS)."""
    if param.kind == ENUM:
        return "NodeSocketMenu" if (compat.MENU_SOCKETS if menus is None else menus) \
            else "NodeSocketInt"
    if param.kind == COLOR:
        return "NodeSocketVector" if param.socket == VECTOR else "NodeSocketColor"
    return "NodeSocketFloat"


def _new_input(group, param: Param, menus: bool):
    kind = socket_type(param, menus)
    sock = group.interface.new_socket(param.label, in_out="INPUT", socket_type=kind)
    description = param.doc
    if kind == "NodeSocketColor":
        sock.default_value = (*param.default, 1.0)
    elif kind == "NodeSocketVector":
        sock.default_value = tuple(param.default)
        sock.min_value, sock.max_value = param.min, param.max
    elif kind == "NodeSocketInt":
        sock.default_value = param.index(param.default)
        sock.min_value, sock.max_value = 0, len(param.items) - 1
        codes = ", ".join(f"{i} {label}" for i, label in enumerate(param.item_labels))
        description = f"{description} ({codes})"
    elif kind == "NodeSocketFloat":
        if param.socket == FACTOR:
            sock.subtype = "FACTOR"
        sock.default_value = param.default
        sock.min_value, sock.max_value = param.min, param.max
    # NodeSocketMenu: its items come from the Menu Switch it feeds, so its default is set once
    # that link exists (build_group).
    sock.description = description.strip()
    return sock


def _menu_switch(group, param: Param):
    """A Menu Switch (INT) with one item per enum item, named by its label, holding its code."""
    switch = group.nodes.new("GeometryNodeMenuSwitch")
    switch.name = MENU_NODE_PREFIX + param.id
    switch.label = param.label
    switch.data_type = "INT"
    items = switch.enum_items
    while len(items) > len(param.items):
        items.remove(items[len(items) - 1])
    while len(items) < len(param.items):
        items.new(param.item_labels[len(items)])
    for code, (item, label) in enumerate(zip(param.items, param.item_labels)):
        items[code].name = label
        items[code].description = param.item_doc(item)
    for code, sock in enumerate(s for s in switch.inputs if s.identifier.startswith("Item_")):
        sock.default_value = code
    return switch


def build_group(model: Model, menus: bool | None = None, native: bool = True):
    """Build the model's node group from the catalog. A group of the same name is rebuilt in
    place, so group nodes already using it stay attached to it.

    `menus` (None: compat.MENU_SOCKETS) chooses menu or integer sockets for the enums; menus
    need Blender 5.0+. `native` adds the branch rendered where OSL does not run
    (addon/fallback.py); without it such renders are black (the lab compares the two)."""
    menus = compat.MENU_SOCKETS if menus is None else menus
    group = bpy.data.node_groups.get(group_name(model))
    if group is None:
        group = bpy.data.node_groups.new(group_name(model), "ShaderNodeTree")
    else:
        group.nodes.clear()
        group.interface.clear()
    group.description = model.doc
    group.color_tag = "SHADER"
    group[MODEL_KEY] = model.id
    for param in model.params:
        _new_input(group, param, menus)
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")

    group_in = group.nodes.new("NodeGroupInput")
    group_out = group.nodes.new("NodeGroupOutput")
    script = group.nodes.new("ShaderNodeScript")
    script.name = script.label = SCRIPT_NODE_NAME
    group_in.location, script.location, group_out.location = (-500, 0), (0, 0), (300, 0)
    shader_nodes.compile_script_node(script, model)
    menu_row, sources = 0, {}
    for param in model.params:
        source = group_in.outputs[param.label]
        if param.kind == ENUM and menus:
            switch = _menu_switch(group, param)
            switch.location = (-250, 200 - 120 * menu_row)
            menu_row += 1
            group.links.new(source, switch.inputs["Menu"])
            source = switch.outputs[0]
        group.links.new(source, script.inputs[shaders.osl_input_name(param)])
        sources[param.id] = source
    if native:
        # OSL's closure where the shader runs, the native branch elsewhere (addon/fallback.py).
        switch = group.nodes.new("ShaderNodeMixShader")
        switch.name = switch.label = fallback.SWITCH_NODE_NAME
        switch.location = (200, 0)
        switch.inputs[0].default_value = 0.0
        group.links.new(script.outputs[shaders.SWITCH_OUTPUT], switch.inputs[0])
        group.links.new(fallback.build_native(group, model, sources), switch.inputs[1])
        group.links.new(script.outputs["BSDF"], switch.inputs[2])
        group_out.location = (400, 0)
        group.links.new(switch.outputs[0], group_out.inputs["BSDF"])
    else:
        group.links.new(script.outputs["BSDF"], group_out.inputs["BSDF"])
    if menus:  # the menus know their items now
        for param in model.params:
            if param.kind == ENUM:
                group.interface.items_tree[param.label].default_value = param.item_label(param.default)
    return group


def ensure_group(model_id: str):
    """The model's node group, built once per file and reused (in a file without it, appended
    from the copy built earlier in this Blender session where there is one: _append_built)."""
    model = MODELS[model_id]
    group = bpy.data.node_groups.get(group_name(model))
    if group is None:
        group = _append_built(model)
    if group is None or not _is_valid(group, model):
        group = build_group(model)
        _keep_built(model, group)
    return group


# The groups built in this Blender session, each written to a .blend of its own in a private
# temporary folder (removed at exit). A new file gets a group appended from it (about 15 ms)
# instead of built again (0.2-1.5 s: Blender updates the tree after each of its 150-600 nodes
# and links: rebuilding them in fresh files took 24.7 of the 213 s of two render-test modules).
_BUILT: dict = {}
_BUILT_FOLDER: list = []


def _keep_built(model: Model, group) -> None:
    """Write the group just built to its .blend (where that fails, later files build it)."""
    _BUILT.pop(model.id, None)
    try:
        if not _BUILT_FOLDER:
            _BUILT_FOLDER.append(tempfile.mkdtemp(prefix="microfacet-lab-groups-"))
            atexit.register(shutil.rmtree, _BUILT_FOLDER[0], True)
        path = os.path.join(_BUILT_FOLDER[0], model.id + ".blend")
        bpy.data.libraries.write(path, {group}, fake_user=False)
    except (OSError, RuntimeError):
        return
    _BUILT[model.id] = path


def _append_built(model: Model):
    """The group built before, appended, into a file that holds neither it nor its text (so
    nothing there to keep attached or to clash with); None where there is none."""
    path = _BUILT.get(model.id)
    if path is None or not os.path.exists(path) or shader_nodes.text_name(model) in bpy.data.texts:
        return None
    try:
        with bpy.data.libraries.load(path, link=False) as (source, target):
            target.node_groups = [group_name(model)]
    except (OSError, RuntimeError):
        return None
    for library in [lib for lib in bpy.data.libraries
                    if os.path.normpath(bpy.path.abspath(lib.filepath)) == os.path.normpath(path)]:
        bpy.data.libraries.remove(library)  # appended, not linked: the file keeps no reference
    return bpy.data.node_groups.get(group_name(model))


def _is_valid(group, model: Model) -> bool:
    """Compiled, and with an input for every catalog label (a group saved before a label
    changed is rebuilt; one with integer instead of menu sockets still works, see set_inputs)."""
    script = group.nodes.get(SCRIPT_NODE_NAME)
    if script is None or not script.bytecode or len(script.outputs) == 0:
        return False
    if fallback.SWITCH_NODE_NAME not in group.nodes:  # saved before the native branch
        return False
    inputs = [s.name for s in group.interface.items_tree
              if getattr(s, "in_out", None) == "INPUT"]
    return inputs == [p.label for p in model.params]


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


def socket_value(sock, param: Param, value):
    """What `sock` holds for the catalog value `value` (resolved: enum items by id): the item's
    label on a menu socket, its int code on an integer socket; RGB on a vector socket, RGBA on a
    colour socket."""
    if param.kind == ENUM:
        return param.item_label(value) if sock.type == "MENU" else param.index(value)
    if param.kind == COLOR:
        return tuple(value) if sock.type == "VECTOR" else (*value, 1.0)
    return value


def input_value(sock, param: Param):
    """The catalog value a group input holds (socket_value's inverse): an enum's item id from a
    menu's label or an integer's code, RGB from a colour or vector, a float."""
    value = sock.default_value
    if param.kind == ENUM:
        if sock.type == "MENU":
            return param.items[param.item_labels.index(value)]
        return param.items[min(max(int(value), 0), len(param.items) - 1)]
    if param.kind == COLOR:
        return tuple(float(c) for c in tuple(value)[:3])
    return float(value)


def read_inputs(node, model: Model) -> dict:
    """Catalog values (enum items by id) of a Microfacet Lab group node's inputs."""
    return {param.id: input_value(node.inputs[param.label], param) for param in model.params}


def model_of(group) -> Model | None:
    """The catalog model a Microfacet Lab group was built for (by its tag, or by its name for a
    group saved before the tag), or None for any other group."""
    model = MODELS.get(group.get(MODEL_KEY, ""))
    if model is not None:
        return model
    name = group.name.rsplit(".", 1)[0] if group.name[-4:-3] == "." else group.name
    return next((m for m in MODELS.values() if group_name(m) == name), None)


def set_inputs(node, model: Model, resolved: dict) -> None:
    """Set a group node's inputs from resolved catalog values (enum items by id, e.g.
    "beckmann"), whichever socket types its group has (menus or integers)."""
    for param in model.params:
        sock = node.inputs[param.label]
        sock.default_value = socket_value(sock, param, resolved[param.id])
