"""Operators and menus: Add > Shader > Microfacet Lab (pattern of Blender's node_wrangler:
classes in one tuple, a draw function appended to a built-in menu, both undone on unregister).
"""
import bpy

from . import fallback, nodes
from .catalog import MODELS

# Cycles runs OSL on the CPU and on OptiX only; on these GPU backends a Script node does not run.
GPU_WITHOUT_OSL = {"CUDA": "CUDA", "HIP": "HIP", "METAL": "Metal", "ONEAPI": "oneAPI"}
# Where OSL does not run, every node group renders its native branch (addon/fallback.py).
APPROXIMATION = ("Microfacet Lab materials show Cycles' nearest built-in BSDF, an approximation "
                 "(exact only for Walter's models with Height-correlated masking)")


def _compute_device_type():
    """Cycles' GPU backend from the preferences ("NONE", "CUDA", "OPTIX", ...), None if unknown."""
    addon = bpy.context.preferences.addons.get("cycles")
    return getattr(getattr(addon, "preferences", None), "compute_device_type", None)


def osl_render_problem(scene, compute_device_type: str | None = None) -> str | None:
    """Why Microfacet Lab nodes would not render their exact models with `scene`'s render
    settings, and how to fix it, in one sentence; None when they do. The one check behind every
    warning (the Add and Apply operators, the presets panel, the render's own line).
    `compute_device_type` defaults to Cycles' preference."""
    if scene.render.engine != "CYCLES":
        return (f"The exact models are OSL and run only in Cycles, so here {APPROXIMATION}: set "
                "Render Properties > Render Engine to Cycles and turn on Open Shading Language")
    cycles = scene.cycles
    if not cycles.shading_system:
        return (f"Open Shading Language is off, so {APPROXIMATION}: turn on "
                "Render Properties > Open Shading Language for the exact models")
    if cycles.device == "GPU":
        backend = compute_device_type if compute_device_type is not None else _compute_device_type()
        if backend in GPU_WITHOUT_OSL:
            return (f"Cycles cannot run OSL on {GPU_WITHOUT_OSL[backend]} GPUs, so "
                    f"{APPROXIMATION}: for the exact models switch Device to CPU or OptiX (Render "
                    "Properties > Device; the GPU backend is in Preferences > System)")
    return None


class NODE_OT_microfacet_lab_add(bpy.types.Operator):
    """Add a Microfacet Lab BSDF node group to the active shader node tree"""

    bl_idname = "node.microfacet_lab_add"
    bl_label = "Add Microfacet Lab BSDF"
    bl_options = {"REGISTER", "UNDO"}

    model: bpy.props.EnumProperty(
        name="Model",
        items=[(m.id, m.label, m.doc) for m in MODELS.values()],
    )

    @classmethod
    def poll(cls, context):
        space = context.space_data
        return space is not None and getattr(space, "tree_type", "") == "ShaderNodeTree" \
            and space.edit_tree is not None

    def execute(self, context):
        tree = context.space_data.edit_tree
        try:
            node = nodes.add_group_node(tree, self.model)
        except Exception as error:  # compile failure: report, leave the tree as it was
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        problem = osl_render_problem(context.scene)
        if problem:
            model = MODELS[self.model]
            self.report({"WARNING"}, f"{problem}. {model.label} "
                                     f"{fallback.approximation(model.id)}")
        for other in tree.nodes:
            other.select = False
        node.select = True
        tree.nodes.active = node
        node.location = context.space_data.cursor_location
        return {"FINISHED"}


class NODE_MT_microfacet_lab(bpy.types.Menu):
    bl_idname = "NODE_MT_microfacet_lab"
    bl_label = "Microfacet Lab"

    def draw(self, context):
        for model in MODELS.values():
            op = self.layout.operator(NODE_OT_microfacet_lab_add.bl_idname, text=model.label)
            op.model = model.id


def draw_add_menu(self, context):
    if getattr(context.space_data, "tree_type", "") == "ShaderNodeTree":
        self.layout.separator()
        self.layout.menu(NODE_MT_microfacet_lab.bl_idname)


classes = (NODE_OT_microfacet_lab_add, NODE_MT_microfacet_lab)
# Add > Shader in Blender 4.2 to 5.x.
ADD_MENU = "NODE_MT_category_shader_shader"


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    menu = getattr(bpy.types, ADD_MENU, None)
    if menu is not None:
        menu.append(draw_add_menu)


def unregister():
    menu = getattr(bpy.types, ADD_MENU, None)
    if menu is not None:
        menu.remove(draw_add_menu)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
