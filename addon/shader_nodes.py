"""The bpy half of the shaders: the text datablock that holds a model's assembled OSL source
(addon/shaders.py) and its compilation into an INTERNAL Script node, refusing loudly when
compilation fails."""
from __future__ import annotations

import shutil
import tempfile

import bpy

from . import shaders
from .catalog import Model

TEXT_PREFIX = "MicrofacetLab_"


def text_name(model: Model) -> str:
    return f"{TEXT_PREFIX}{model.shader}.osl"


def ensure_text(model: Model, lamps=()):
    """The text datablock holding the model's OSL source (with the given lamp table), created
    or refreshed."""
    source = shaders.shader_source(model, lamps)
    text = bpy.data.texts.get(text_name(model))
    if text is None:
        text = bpy.data.texts.new(text_name(model))
    if text.as_string() != source:
        text.clear()
        text.write(source)
    return text


class ShaderCompileError(RuntimeError):
    pass


def compile_script_node(node, model: Model, lamps=()) -> None:
    """Point an INTERNAL Script node at the model's text and compile it now.

    Uses the Cycles add-on's own compile function, which works headless (the UI operator does
    not). Without `bpy.utils.expose_bundled_modules()` the compile fails silently, leaving no
    sockets and no bytecode; that case is turned into a loud error here.
    """
    from . import compat

    compat.expose_bundled_modules()  # the wheel's oslquery, or the compile fails silently

    messages = []

    def report(kind, message):
        messages.append(f"{kind}: {message}")

    # Cycles' compile leaves its .oso in the temporary folder (1-4 MB a shader, every compile:
    # a hand-over recompiles before and after each render), so it compiles into a folder of our
    # own, removed after (the bytecode is in the node by then).
    private = tempfile.mkdtemp(prefix="microfacet-lab-osl-")
    saved, tempfile.tempdir = tempfile.tempdir, private
    try:
        text = ensure_text(model, lamps)
        node.mode = "INTERNAL"
        node.script = text
        try:
            from cycles import osl as cycles_osl
            cycles_osl.update_script_node(node, report)
        except ImportError:  # no Cycles add-on: assigning the script compiled it already
            pass
    finally:
        tempfile.tempdir = saved
        shutil.rmtree(private, ignore_errors=True)
    if not node.bytecode or len(node.outputs) == 0:
        raise ShaderCompileError(
            f"OSL compile of {text.name} produced no bytecode or no sockets"
            + (": " + "; ".join(messages) if messages else
               " (is Cycles OSL available? bpy.utils.expose_bundled_modules() missing?)"))
