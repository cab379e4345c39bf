"""Microfacet Lab add-on: the package the extension ships (catalog, shader assembly, node groups,
presets, UI and operators, scene specialization, the lamps' hand-over).

`lab/` beside these modules is the verification lab (numpy reference, sphere-grid harness,
report, stability sweep, benchmarks). It is left out of the built extension (the manifest's
[build] paths_exclude_pattern); it may import the modules here, never the other way round.

Importing this package needs no bpy (so `addon.lab.reference` and `addon.catalog` load with numpy
alone); `register()` imports the bpy-side modules.
"""


def register():
    from . import adopt, asset_browser, handover, notice, preset_ui, ui
    ui.register()
    preset_ui.register()
    asset_browser.register()
    handover.register()
    adopt.register()
    notice.register()


def unregister():
    from . import adopt, asset_browser, handover, notice, preset_ui, ui
    notice.unregister()
    adopt.unregister()
    handover.unregister()
    asset_browser.unregister()
    preset_ui.unregister()
    ui.unregister()
