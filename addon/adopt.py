"""Microfacet Lab groups brought in from another file become the add-on's own.

Dropping a preset from the asset library (addon/asset_library.py), or File > Append of a
material made with Microfacet Lab, brings the material's node group and OSL text with it.
Left as they come, such groups differ from what "Apply Microfacet Lab preset" makes:

- where the file already has the model's group, Blender renames the newcomer ("... .001") and
  its text too, and the lamps' hand-over (addon/handover.py) only writes the add-on's own text;
- the library is written by Blender 4.2 (asset_library.py), so on 5.0+ its enums arrive as
  integer sockets where the add-on's groups have menus;
- a file from another add-on version carries that version's shader.

So each appended Microfacet Lab group (Blender marks an appended ID with a weak reference to
its library file; a group built here has none) is replaced, in every node that uses it, by the
group `nodes.ensure_group` gives, with the same input values and links, and is then removed
with its text. A dropped preset is then the material Apply makes.

A depsgraph_update_post handler runs it when the number of node groups changed (appending is
the only way a group arrives without the add-on building it), so the check costs nothing on
the many updates that add no group.
"""
from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import nodes

_state = {"groups": -1}  # len(bpy.data.node_groups) when the handler last looked


def appended_groups() -> list:
    """Microfacet Lab groups appended from another file (not linked, not built here)."""
    return [g for g in bpy.data.node_groups
            if g.library is None and g.library_weak_reference is not None
            and nodes.model_of(g) is not None]


def _users(group):
    """(tree, node) for every group node that uses `group`, in materials and node groups."""
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None and m.library is None]
    trees += [g for g in bpy.data.node_groups if g.library is None and g != group]
    for tree in trees:
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeGroup" and node.node_tree == group:
                yield tree, node


def _adopt(group) -> int:
    """Move every user of `group` to the add-on's group of the same model; returns how many."""
    model = nodes.model_of(group)
    script = group.nodes.get(nodes.SCRIPT_NODE_NAME)
    text = getattr(script, "script", None)
    name = group.name
    if name == nodes.group_name(model):  # free the name for the add-on's own group
        group.name = name + " (appended)"
    try:
        own = nodes.ensure_group(model.id)
    except Exception:  # the add-on's group does not compile here: leave the appended one as it was
        group.name = name
        raise
    moved = 0
    for tree, node in list(_users(group)):
        values = nodes.read_inputs(node, model)
        links = [(sock.name, link.from_socket) for sock in node.inputs for link in sock.links]
        outputs = [link.to_socket for sock in node.outputs for link in sock.links]
        node.node_tree = own
        nodes.set_inputs(node, model, values)
        for label, source in links:  # sockets are matched by name: keep what fed them
            if not node.inputs[label].is_linked:
                tree.links.new(source, node.inputs[label])
        for target in outputs:
            if not target.is_linked:
                tree.links.new(node.outputs["BSDF"], target)
        moved += 1
    bpy.data.node_groups.remove(group)
    if text is not None and text.users == 0 and text != own.nodes[nodes.SCRIPT_NODE_NAME].script:
        bpy.data.texts.remove(text)
    return moved


def adopt_appended() -> int:
    """Replace every appended Microfacet Lab group by the add-on's own; returns the number of
    group nodes moved."""
    moved = sum(_adopt(group) for group in appended_groups())
    _state["groups"] = len(bpy.data.node_groups)
    return moved


@persistent
def _on_depsgraph_update(scene, depsgraph=None):
    if len(bpy.data.node_groups) == _state["groups"]:
        return
    try:
        adopt_appended()
    except Exception as exc:  # never break the artist's edit: the appended group still renders
        _state["groups"] = len(bpy.data.node_groups)
        print(f"Microfacet Lab: an appended group was left as it came ({exc})")


def register():
    _state["groups"] = -1
    if _on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph_update)


def unregister():
    if _on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_on_depsgraph_update)
