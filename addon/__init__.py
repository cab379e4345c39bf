"""Microfacet Lab add-on: node groups, Add menu entries, and the render harness.

Importing this package needs no bpy (so `addon.reference` and `addon.catalog` load with numpy
alone); `register()` imports the bpy-side modules.
"""


def register():
    from . import preset_ui, ui
    ui.register()
    preset_ui.register()


def unregister():
    from . import preset_ui, ui
    preset_ui.unregister()
    ui.unregister()
