"""Microfacet Lab: the extension's entry point; the add-on itself lives in addon/."""
from . import addon


def register():
    addon.register()


def unregister():
    addon.unregister()
