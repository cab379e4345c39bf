"""Expose the modules the bpy wheel bundles (oslquery, OpenImageIO) on sys.path.

`bpy.utils.expose_bundled_modules` exists from Blender 4.4; inside a Blender executable the
modules are already importable, so older versions need nothing. Never install the PyPI
OpenImageIO wheel beside bpy: a second OpenImageIO breaks oslquery (docs/cycles-osl.md).
"""
import bpy

if hasattr(bpy.utils, "expose_bundled_modules"):
    bpy.utils.expose_bundled_modules()
