"""Microfacet Lab: the extension's entry point; the add-on itself lives in addon/.

The import sits inside the functions: pytest imports this file on its own (as a top-level
module when the clone's folder name is not a valid package name), where a module-level relative
import would fail.
"""


def register():
    from . import addon
    addon.register()


def unregister():
    from . import addon
    addon.unregister()
