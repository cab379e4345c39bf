"""The bpy half of the shaders: the text datablock that holds a model's assembled OSL source
(addon/shaders.py) and its compilation into an INTERNAL Script node, refusing loudly when
compilation fails."""
from __future__ import annotations

import collections
import contextlib
import dataclasses
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


# What oslc made of each assembled source lately, this Blender session: a hand-over recompiles
# every Script node before each render (the lamps' table in) and after it (the prediction out),
# so the same few sources come back on every render (0.07-0.16 s each here, half of it twice:
# the script assignment makes Cycles compile too). An entry is reused only on a node whose sockets
# are those the compile left (a model's sockets do not depend on the lamps' table); bounded, as
# each bytecode is 0.2-1.4 MB.
_COMPILED: collections.OrderedDict = collections.OrderedDict()
_COMPILED_MAX = 24


@dataclasses.dataclass(frozen=True)
class _Compiled:
    bytecode: str
    bytecode_hash: str
    sockets: tuple


def _sockets(node) -> tuple:
    return tuple((s.identifier, s.bl_idname) for s in node.inputs), \
        tuple((s.identifier, s.bl_idname) for s in node.outputs)


def _reuse(node, source: str) -> bool:
    """Give `node` the bytecode oslc made of `source` before, where its sockets match."""
    done = _COMPILED.get(source)
    if done is None or done.sockets != _sockets(node):
        return False
    _COMPILED.move_to_end(source)
    if node.bytecode != done.bytecode or node.bytecode_hash != done.bytecode_hash:
        node.bytecode = done.bytecode
        node.bytecode_hash = done.bytecode_hash
    return True


def _remember(node, source: str) -> None:
    _COMPILED[source] = _Compiled(node.bytecode, node.bytecode_hash, _sockets(node))
    _COMPILED.move_to_end(source)
    while len(_COMPILED) > _COMPILED_MAX:
        _COMPILED.popitem(last=False)


@contextlib.contextmanager
def _private_temporary_folder():
    """Cycles' compile of an INTERNAL script writes its .oso into the temporary folder and never
    removes it (0.1-1.4 MB a compile; a day of make test left 11,854 of them, 4.4 GB), and
    assigning a Script node's mode or script runs that compile too (the property's update): both
    run inside a folder of our own, removed after (the bytecode is in the node by then)."""
    private = tempfile.mkdtemp(prefix="microfacet-lab-osl-")
    saved, tempfile.tempdir = tempfile.tempdir, private
    try:
        yield
    finally:
        tempfile.tempdir = saved
        shutil.rmtree(private, ignore_errors=True)


def point_at(node, text) -> None:
    """Make `node` an INTERNAL script reading `text`, leaving no file behind. Each assignment
    makes Cycles compile the node (the property's update), so only changes are assigned."""
    with _private_temporary_folder():
        if node.mode != "INTERNAL":
            node.mode = "INTERNAL"
        if node.script != text:
            node.script = text


def compile_text(node, text, report=lambda kind, message: None) -> None:
    """Point `node` at `text` and compile it now with the Cycles add-on's own compile, which works
    headless (the UI operator does not), leaving no file behind; without the Cycles add-on the
    script's assignment compiles it. Failures go to `report(kind, message)`."""
    point_at(node, text)
    with _private_temporary_folder():
        try:
            from cycles import osl as cycles_osl
            cycles_osl.update_script_node(node, report)
        except ImportError:
            node.script = text


def compile_script_node(node, model: Model, lamps=()) -> None:
    """Point an INTERNAL Script node at the model's text and compile it now (or give it the
    bytecode of the same source compiled before, _COMPILED).

    Without `bpy.utils.expose_bundled_modules()` the compile fails silently, leaving no sockets
    and no bytecode; that case is turned into a loud error here.
    """
    from . import compat

    text = ensure_text(model, lamps)
    point_at(node, text)
    source = text.as_string()
    if _reuse(node, source):
        return
    compat.expose_bundled_modules()  # the wheel's oslquery, or the compile fails silently

    messages = []
    compile_text(node, text, lambda kind, message: messages.append(f"{kind}: {message}"))
    if not node.bytecode or len(node.outputs) == 0:
        raise ShaderCompileError(
            f"OSL compile of {text.name} produced no bytecode or no sockets"
            + (": " + "; ".join(messages) if messages else
               " (is Cycles OSL available? bpy.utils.expose_bundled_modules() missing?)"))
    _remember(node, source)
