"""One line at the start of a render whose Microfacet Lab materials will not run their exact
models (OSL off, a GPU backend without OSL, another engine): they render their native branch
(addon/fallback.py), and F12 or `blender --background` says so once per render job."""
from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from .specialize import lab_nodes, scene_materials
from .ui import osl_render_problem

PREFIX = "Microfacet Lab: "


def render_notice(scene) -> str | None:
    """The line to print for rendering `scene`, or None (exact models, or no Lab material)."""
    problem = osl_render_problem(scene)
    if problem is None or not any(lab_nodes(m) for m in scene_materials(scene)):
        return None
    return PREFIX + problem


@persistent
def _on_render_init(scene, depsgraph=None):
    try:
        line = render_notice(scene)
    except Exception as exc:  # never stop a render for a notice
        line = f"{PREFIX}could not check the render settings ({exc})"
    if line:
        print(line, flush=True)


def register():
    if _on_render_init not in bpy.app.handlers.render_init:
        bpy.app.handlers.render_init.append(_on_render_init)


def unregister():
    if _on_render_init in bpy.app.handlers.render_init:
        bpy.app.handlers.render_init.remove(_on_render_init)
