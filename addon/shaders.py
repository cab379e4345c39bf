"""OSL shader sources and their compilation into Script nodes.

`shader_source(model)` assembles one self-contained OSL text from `osl/<model.shader>.osl`:
the local headers are inlined (Cycles compiles INTERNAL scripts from a temporary file, where a
local #include is not found), enum codes and the parameter list are generated from the catalog
(so neither is written twice), and the documented clamps are inserted. The bpy part creates the
text datablock and compiles it into a Script node, refusing loudly when compilation fails.
"""
from __future__ import annotations

import re
from pathlib import Path

from . import lamps as lamp_table
from .catalog import COLOR, ENUM, ENUMS, FLOAT, Model

OSL_DIR = Path(__file__).resolve().parent.parent / "osl"
TEXT_PREFIX = "MicrofacetLab_"
_LOCAL_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)
_SYSTEM_HEADERS = {"stdcycles.h", "stdosl.h"}


def enum_defines() -> str:
    lines = ["// Generated from addon/catalog.py ENUMS."]
    for enum, items in ENUMS.items():
        for code, item in enumerate(items):
            lines.append(f"#define MFL_{enum.upper()}_{item.upper()} {code}")
    return "\n".join(lines) + "\n"


def version_defines() -> str:
    """What the shaders need to know of the Blender they run in (addon/compat.py): whether
    Cycles' conductor_bsdf is exact, and whether Cycles inverts a back face's IOR itself.
    Without bpy (numpy-only use): the current release's."""
    try:
        from .compat import CYCLES_INVERTS_BACKFACE_IOR, EXACT_CONDUCTOR_FRESNEL
    except ImportError:
        EXACT_CONDUCTOR_FRESNEL = CYCLES_INVERTS_BACKFACE_IOR = True
    return (f"#define MFL_EXACT_CONDUCTOR {int(EXACT_CONDUCTOR_FRESNEL)}\n"
            f"#define MFL_CYCLES_INVERTS_BACKFACE_IOR {int(CYCLES_INVERTS_BACKFACE_IOR)}\n")


def _osl_value(param, value) -> str:
    if param.kind == COLOR:
        return "color({:.9g}, {:.9g}, {:.9g})".format(*value)
    if param.kind == ENUM:
        return str(param.index(value))
    return f"{float(value):.9g}"


def osl_input_name(param) -> str:
    """OSL shader parameters are read-only, so the clamped value lives in a local named after
    the catalog id and the parameter (the Script node socket) carries this prefixed name."""
    return "in_" + param.id


# A float output that reads 1 wherever the shader runs and the Script node's default 0 where it
# does not: the node group's switch to its native branch (addon/fallback.py).
SWITCH_OUTPUT = "osl_runs"


def parameter_declarations(model: Model) -> str:
    lines = []
    for p in model.params:
        if p.kind == ENUM:
            meta = f'[[ int min = 0, int max = {len(p.items) - 1}, string help = "{" | ".join(p.items)}" ]]'
            lines.append(f"    int {osl_input_name(p)} = {_osl_value(p, p.default)} {meta},")
        else:
            osl_type = "color" if p.kind == COLOR else "float"
            lines.append(f"    {osl_type} {osl_input_name(p)} = {_osl_value(p, p.default)},")
    lines.append(f"    output float {SWITCH_OUTPUT} = 1.0,")
    return "\n".join(lines)


def clamp_statements(model: Model) -> str:
    """The catalog's clamp in OSL: NaN -> default, then [min, max] (per channel for colours)."""
    lines = []
    for p in model.params:
        src = osl_input_name(p)
        if p.kind == ENUM:
            lines.append(f"    int {p.id} = clamp({src}, 0, {len(p.items) - 1});")
        elif p.kind == FLOAT:
            lines.append(f"    float {p.id} = clamp(safe_nan({src}, {_osl_value(p, p.default)}), "
                         f"{p.min:.9g}, {p.max:.9g});")
        else:
            channels = ", ".join(f"clamp(safe_nan({src}[{c}], {p.default[c]:.9g}), {p.min:.9g}, {p.max:.9g})"
                                 for c in range(3))
            lines.append(f"    color {p.id} = color({channels});")
    return "\n".join(lines)


def _inline_headers(source: str, seen: set[str]) -> str:
    def replace(match: re.Match) -> str:
        name = match.group(1)
        if name in _SYSTEM_HEADERS:
            return match.group(0)
        if name in seen:
            return f"// {name}: already inlined"
        seen.add(name)
        header = (OSL_DIR / name).read_text()
        return f"// ---- begin {name}\n{_inline_headers(header, seen)}\n// ---- end {name}"

    return _LOCAL_INCLUDE.sub(replace, source)


def shader_source(model: Model, lamps=()) -> str:
    """`lamps`: the LampRecords the shader may aim its residual at (addon/lamps.py); none by
    default, which compiles the lamp code out."""
    source = (OSL_DIR / f"{model.shader}.osl").read_text()
    source = source.replace("    // @parameters", parameter_declarations(model))
    source = source.replace("    // @clamp_parameters", clamp_statements(model))
    source = _inline_headers(source, set())
    source = source.replace("// @lamps", lamp_table.osl_block(lamps))
    # The enum codes and version facts precede everything, headers included.
    return enum_defines() + version_defines() + source


def uses_lamps(model: Model) -> bool:
    """Whether the model's shader aims at the scene's lamps (includes lamps.h)."""
    return '#include "lamps.h"' in (OSL_DIR / f"{model.shader}.osl").read_text()


# --- bpy ------------------------------------------------------------------------------------

def text_name(model: Model) -> str:
    return f"{TEXT_PREFIX}{model.shader}.osl"


def ensure_text(model: Model, lamps=()):
    """The text datablock holding the model's OSL source (with the given lamp table), created
    or refreshed."""
    import bpy

    source = shader_source(model, lamps)
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

    text = ensure_text(model, lamps)
    node.mode = "INTERNAL"
    node.script = text
    messages = []

    def report(kind, message):
        messages.append(f"{kind}: {message}")

    try:
        from cycles import osl as cycles_osl
        cycles_osl.update_script_node(node, report)
    except ImportError:  # the Cycles add-on is absent: assigning the script compiled it already
        pass
    if not node.bytecode or len(node.outputs) == 0:
        raise ShaderCompileError(
            f"OSL compile of {text.name} produced no bytecode or no sockets"
            + (": " + "; ".join(messages) if messages else
               " (is Cycles OSL available? bpy.utils.expose_bundled_modules() missing?)"))
