"""The presets in the Asset Browser (the bpy half of addon/asset_library.py): two operators that
add the shipped `assets/` folder to Preferences > File Paths > Asset Libraries, or remove it,
and the row the presets panel draws for them.

Nothing is registered without the artist asking: the library is a user preference, and it
stays after the add-on is disabled (its materials render without the add-on). Dropped presets
become the add-on's own groups (addon/adopt.py).
"""
from __future__ import annotations

import os

import bpy

from . import asset_library, compat


def _same_folder(a: str, b) -> bool:
    norm = lambda p: os.path.normcase(os.path.realpath(bpy.path.abspath(str(p))))  # noqa: E731
    return norm(a) == norm(b)


def find_library(context=None):
    """The user asset library that points at the shipped `assets/` folder, or None."""
    prefs = (context or bpy.context).preferences
    for library in prefs.filepaths.asset_libraries:
        if _same_folder(library.path, asset_library.ASSETS_DIR):
            return library
    return None


class PREFERENCES_OT_microfacet_lab_add_asset_library(bpy.types.Operator):
    """Add the Microfacet Lab presets to the Asset Browser (a user asset library, kept in the
    preferences): drag a preset onto an object to assign it"""

    bl_idname = "preferences.microfacet_lab_add_asset_library"
    bl_label = "Add presets to the Asset Browser"
    bl_options = {"REGISTER"}

    def execute(self, context):
        blend = asset_library.ASSETS_DIR / asset_library.BLEND_NAME
        if not blend.is_file():
            self.report({"ERROR"}, f"Microfacet Lab: the asset library {blend} is missing from "
                                   "this installation (in a clone: make assets)")
            return {"CANCELLED"}
        library = find_library(context)
        if library is None:
            library = context.preferences.filepaths.asset_libraries.new(
                name=asset_library.LIBRARY_NAME, directory=str(asset_library.ASSETS_DIR))
        compat.append_on_import(library)  # a dropped preset must be local data (addon/adopt.py)
        self.report({"INFO"}, f"Asset library {library.name!r} -> {asset_library.ASSETS_DIR}; it "
                              "is kept when Blender saves its preferences")
        return {"FINISHED"}


class PREFERENCES_OT_microfacet_lab_remove_asset_library(bpy.types.Operator):
    """Remove the Microfacet Lab presets from the Asset Browser (materials already assigned stay)"""

    bl_idname = "preferences.microfacet_lab_remove_asset_library"
    bl_label = "Remove presets from the Asset Browser"
    bl_options = {"REGISTER"}

    def execute(self, context):
        library = find_library(context)
        if library is None:
            self.report({"INFO"}, "The Microfacet Lab asset library was not registered")
            return {"CANCELLED"}
        context.preferences.filepaths.asset_libraries.remove(library)
        return {"FINISHED"}


def draw(layout, context):
    """The presets panel's row: add the library, or say it is there and offer to remove it."""
    row = layout.row(align=True)
    if find_library(context) is None:
        row.operator(PREFERENCES_OT_microfacet_lab_add_asset_library.bl_idname, icon="ASSET_MANAGER")
    else:
        row.label(text="Presets are in the Asset Browser", icon="ASSET_MANAGER")
        row.operator(PREFERENCES_OT_microfacet_lab_remove_asset_library.bl_idname, text="", icon="X")


classes = (PREFERENCES_OT_microfacet_lab_add_asset_library,
           PREFERENCES_OT_microfacet_lab_remove_asset_library)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
