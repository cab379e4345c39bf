"""Presets in the UI, the bpy half of addon/presets.py: Material Properties panel (Cycles),
"Apply Microfacet Lab preset", and "Specialize scene for render" (addon/specialize.py).

Apply creates or updates the active object's active material: a material whose Material Output
is fed by a Microfacet Lab group gets that group node's inputs changed (or its group swapped
when the preset's model differs); any other material (or none) is replaced, in the active slot,
by a new material made of one Microfacet Lab group node. The preset file is read and validated
before anything changes, so a malformed preset is reported and the scene stays untouched. The
redo panel (REGISTER | UNDO) switches the preset.

Registered with register()/unregister() (called from addon/__init__.py); unregister removes
every class, the WindowManager property and the thumbnail previews it added.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import bpy

from . import asset_library, asset_browser, compat, fallback, nodes, presets
from .ui import osl_render_problem

PRESET_PROP = "microfacet_lab_preset"  # on WindowManager: the panel's gallery selection
MATERIAL_KEY = "microfacet_lab_preset"  # custom property: the preset a material was made from
NAME_PREFIX = "Microfacet Lab "

_previews = None  # bpy.utils.previews collection, created on first use
_cache = {"key": None, "items": [], "presets": {}, "errors": []}


# --- applying (no UI) -------------------------------------------------------------------------

def lab_node(material):
    """The Microfacet Lab group node feeding the material's active Cycles output, or None."""
    tree = material.node_tree if material is not None else None
    if tree is None:
        return None
    output = tree.get_output_node("CYCLES") or tree.get_output_node("ALL")
    if output is None or not output.inputs["Surface"].is_linked:
        return None
    node = output.inputs["Surface"].links[0].from_node
    group = getattr(node, "node_tree", None)
    if node.bl_idname == "ShaderNodeGroup" and group is not None \
            and group.name.startswith(nodes.GROUP_PREFIX) and nodes.SCRIPT_NODE_NAME in group.nodes:
        return node
    return None


def _material_name(preset) -> str:
    return NAME_PREFIX + preset.label


def new_material(preset):
    """A new material made of one group node with the preset's values, tagged with the preset
    (what Apply creates, and what the asset library holds: addon/lab/assets.py)."""
    material = compat.new_node_material(_material_name(preset))
    tree = material.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.location = (300, 0)
    node = nodes.add_group_node(tree, preset.model_id, preset.params)
    tree.links.new(node.outputs["BSDF"], output.inputs["Surface"])
    material[MATERIAL_KEY] = preset.id
    return material


def apply_preset(obj, preset) -> tuple:
    """Create or update `obj`'s active material from `preset`. Returns (material, action),
    action one of "created", "updated", "swapped"."""
    model = preset.model
    resolved = preset.resolved()
    nodes.ensure_group(model.id)  # compile first: a compile error changes no material
    material = obj.active_material
    node = lab_node(material)
    if node is None:
        material = new_material(preset)
        if len(obj.material_slots) == 0:
            obj.data.materials.append(material)
        else:
            obj.active_material = material
        action = "created"
    else:
        old_preset = material.get(MATERIAL_KEY)
        action = "updated"
        if node.node_tree.name != nodes.group_name(model):
            node.node_tree = nodes.ensure_group(model.id)
            node.label = model.label
            output = material.node_tree.get_output_node("CYCLES") or material.node_tree.get_output_node("ALL")
            material.node_tree.links.new(node.outputs["BSDF"], output.inputs["Surface"])
            action = "swapped"
        nodes.set_inputs(node, model, resolved)
        if old_preset is not None:
            try:
                old_label = presets.find(old_preset).label
            except presets.PresetError:
                old_label = None
            if old_label is not None and material.name == NAME_PREFIX + old_label:
                material.name = _material_name(preset)
    material[MATERIAL_KEY] = preset.id
    return material, action


# --- enum items and thumbnails ----------------------------------------------------------------

def _dir_key(directory: Path):
    try:
        return tuple(sorted((p.name, p.stat().st_mtime_ns) for p in directory.glob("*.toml")))
    except OSError:
        return ()


def preview(preset_id: str):
    """The preset's preview (an ImagePreview of its shipped PNG, the pixels its asset carries),
    loaded once; None when there is no picture or previews are unavailable."""
    global _previews
    for folder in asset_library.preview_dirs():
        path = folder / f"{preset_id}.png"
        if path.is_file():
            try:
                if _previews is None:
                    from bpy.utils import previews
                    _previews = previews.new()
                key = str(path)
                if key not in _previews:
                    _previews.load(key, key, "IMAGE")
                return _previews[key]
            except Exception:  # previews unavailable (e.g. some headless builds): text only
                return None
    return None


def _icon(preset_id: str) -> int:
    found = preview(preset_id)
    return found.icon_id if found is not None else 0


def refresh(force: bool = False):
    """Re-scan presets/ when a file changed; cache the enum items (Blender needs the strings
    kept alive while the enum is shown)."""
    key = _dir_key(presets.PRESETS_DIR)
    if force or key != _cache["key"]:
        found, errors = presets.scan(presets.PRESETS_DIR)
        items = []
        for i, p in enumerate(found.values()):
            doc = f"{p.description} [{p.model.label}] Source: {p.citation()}"
            items.append((p.id, p.label, doc, _icon(p.id), i))
        if not items:
            items = [("NONE", "No presets", "No valid preset in " + str(presets.PRESETS_DIR), 0, 0)]
        _cache.update(key=key, items=items, presets=found, errors=errors)
    return _cache


def preset_items(self, context):
    return refresh()["items"]


# --- operators and panel ----------------------------------------------------------------------

class MATERIAL_OT_microfacet_lab_apply_preset(bpy.types.Operator):
    """Create or update the active material from a Microfacet Lab preset"""

    bl_idname = "material.microfacet_lab_apply_preset"
    bl_label = "Apply Microfacet Lab preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: bpy.props.EnumProperty(name="Preset", items=preset_items)
    filepath: bpy.props.StringProperty(
        name="Preset file", description="Apply this preset file instead (any folder)",
        subtype="FILE_PATH", options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and hasattr(obj.data, "materials")

    def execute(self, context):
        try:
            if self.filepath:
                preset = presets.load_preset(bpy.path.abspath(self.filepath))
            else:
                preset = presets.find(self.preset, presets.PRESETS_DIR)
        except presets.PresetError as error:
            self.report({"ERROR"}, f"Microfacet Lab preset: {error}")
            return {"CANCELLED"}
        try:
            material, action = apply_preset(context.object, preset)
        except Exception as error:  # a shader that does not compile: reported, not raised
            self.report({"ERROR"}, f"Microfacet Lab preset {preset.id}: {error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"{action} {material.name!r} from preset {preset.id!r}")
        problem = osl_render_problem(context.scene)
        if problem:
            self.report({"WARNING"}, f"{problem}. {preset.label} "
                                     f"{fallback.approximation(preset.model_id, preset.id)}")
        return {"FINISHED"}


class SCENE_OT_microfacet_lab_specialize(bpy.types.Operator):
    """Compile only the Microfacet Lab shaders this scene uses, remove unused ones, and set the
    light-path bounces to what its materials need"""

    bl_idname = "scene.microfacet_lab_specialize"
    bl_label = "Specialize scene for render"
    bl_options = {"REGISTER", "UNDO"}

    prune: bpy.props.BoolProperty(name="Prune shaders", default=True,
                                  description="Compile used shaders; remove unused groups and texts")
    bounces: bpy.props.BoolProperty(name="Set bounces", default=True,
                                    description="Light-path bounces to what the materials need")

    def execute(self, context):
        from . import specialize

        try:
            report = specialize.specialize(context.scene, prune=self.prune, bounces=self.bounces)
        except Exception as error:
            self.report({"ERROR"}, f"Specialize: {error}")
            return {"CANCELLED"}
        for line in report.lines():
            self.report({"WARNING"} if line.startswith("WARNING") else {"INFO"}, line)
        return {"FINISHED"}


class MATERIAL_PT_microfacet_lab_presets(bpy.types.Panel):
    bl_label = "Microfacet Lab Presets"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"
    COMPAT_ENGINES = {"CYCLES"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and context.object is not None

    def draw(self, context):
        layout = self.layout
        cache = refresh()
        wm = context.window_manager
        problem = osl_render_problem(context.scene)
        if problem:
            box = layout.box().column(align=True)
            for i, line in enumerate(textwrap.wrap(problem, 48)):
                box.label(text=line, icon="ERROR" if i == 0 else "BLANK1")
        if any(item[3] for item in cache["items"]):
            layout.template_icon_view(wm, PRESET_PROP, show_labels=True, scale=5.0)
        layout.prop(wm, PRESET_PROP, text="")
        preset = cache["presets"].get(getattr(wm, PRESET_PROP, ""))
        if preset is not None:
            col = layout.column(align=True)
            col.label(text=preset.model.label, icon="NODE_MATERIAL")
            col.label(text="Source: " + preset.citation()[:90])
            if problem:
                note = f"{preset.label} {fallback.approximation(preset.model_id, preset.id)}"
                box = layout.box().column(align=True)
                for i, line in enumerate(textwrap.wrap(note, 48)):
                    box.label(text=line, icon="INFO" if i == 0 else "BLANK1")
        op = layout.operator(MATERIAL_OT_microfacet_lab_apply_preset.bl_idname, icon="CHECKMARK")
        if preset is not None:
            op.preset = preset.id
        for error in cache["errors"]:
            layout.label(text=str(error)[:120], icon="ERROR")
        asset_browser.draw(layout, context)
        layout.separator()
        layout.operator(SCENE_OT_microfacet_lab_specialize.bl_idname, icon="RENDER_STILL")


classes = (MATERIAL_OT_microfacet_lab_apply_preset, SCENE_OT_microfacet_lab_specialize,
           MATERIAL_PT_microfacet_lab_presets)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    setattr(bpy.types.WindowManager, PRESET_PROP,
            bpy.props.EnumProperty(name="Microfacet Lab preset", items=preset_items))


def unregister():
    global _previews
    if hasattr(bpy.types.WindowManager, PRESET_PROP):
        delattr(bpy.types.WindowManager, PRESET_PROP)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    if _previews is not None:
        from bpy.utils import previews
        previews.remove(_previews)
        _previews = None
    _cache.update(key=None, items=[], presets={}, errors=[])
