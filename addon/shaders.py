"""OSL shader sources, assembled as text (no bpy: addon/shader_nodes.py puts them into text
datablocks and compiles them into Script nodes).

`shader_source(model)` assembles one self-contained OSL text from `osl/<model.shader>.osl`:
the local headers are inlined (Cycles compiles INTERNAL scripts from a temporary file, where a
local #include is not found), nested ones too, each header once and after the headers it
includes; enum codes and the parameter list are generated from the catalog (so neither is
written twice), and the documented clamps are inserted.
"""
from __future__ import annotations

import re
from pathlib import Path

from . import lamps as lamp_table
from .catalog import COLOR, ENUM, ENUMS, FLOAT, Model

OSL_DIR = Path(__file__).resolve().parent.parent / "osl"
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


def local_includes(text: str) -> list[str]:
    """The local headers a text #includes, in order (stdcycles.h and stdosl.h are Cycles' own)."""
    return [name for name in _LOCAL_INCLUDE.findall(text) if name not in _SYSTEM_HEADERS]


def included_headers(name: str) -> list[str]:
    """Every local header osl/<name> needs, nested includes too, each once and after the headers
    it includes: the order shader_source inlines them in. An include cycle is refused."""
    order: list[str] = []

    def visit(current: str, path: tuple) -> None:
        for header in local_includes((OSL_DIR / current).read_text()):
            if header in path:
                raise ValueError("OSL include cycle: " + " -> ".join(path + (header,)))
            if header not in order:
                visit(header, path + (header,))
                order.append(header)

    visit(name, (name,))
    return order


def inline_headers(source: str) -> str:
    """`source` with each local #include replaced by the header's text, nested includes first,
    each header once (a later #include of it becomes a comment)."""
    seen: set[str] = set()

    def inline(text: str, path: tuple) -> str:
        def replace(match: re.Match) -> str:
            name = match.group(1)
            if name in _SYSTEM_HEADERS:
                return match.group(0)
            if name in path:
                raise ValueError("OSL include cycle: " + " -> ".join(path + (name,)))
            if name in seen:
                return f"// {name}: already inlined"
            seen.add(name)
            header = inline((OSL_DIR / name).read_text(), path + (name,))
            return f"// ---- begin {name}\n{header}\n// ---- end {name}"

        return _LOCAL_INCLUDE.sub(replace, text)

    return inline(source, ())


def lamp_table_block(records) -> str:
    """The generated table that replaces `// @lamps` in osl/lamps.h."""
    records = list(records)[:lamp_table.MAX_LAMPS]
    predicted = sum(1 for r in records if sum(r.radiance) > 0.0)
    offsets, texels = [], []  # a world spot's texels, where the shader predicts its radiance
    for r in records:
        read = r.texels is not None and sum(r.radiance) > 0.0
        offsets.append(len(texels) if read else -1)
        texels += r.texels.floats() if read else []
    # The kinds present: the shaders' kind dispatch folds on them (osl/lamps.h lamp_is).
    kinds = sorted({lamp_table.KINDS.index(r.kind) for r in records})
    one_kind = kinds[0] if len(kinds) == 1 else -1
    lines = ["// Generated by the add-on from the scene's lamps (addon/lamps.py).",
             f"#define MFL_LAMP_COUNT {len(records)}",
             f"#define MFL_PREDICTED_LAMP_COUNT {predicted}",
             f"#define MFL_SPOT_TEXELS {int(bool(texels))}",
             f"#define MFL_SPOT_HEADER {lamp_table.SPOT_HEADER_SIZE}",
             f"#define MFL_LAMP_ONE_KIND {one_kind}",
             "#define MFL_LAMP_KINDS " + ", ".join(str(int(k in kinds)) for k in range(4))]
    if records:
        data = ", ".join(f"{x:.9g}" for r, o in zip(records, offsets) for x in r.floats(o))
        # One lamp: its data are constants wherever a call names the slot (j), which the
        # shader optimizer folds, though OSL's loops over the lamps leave i a variable.
        lines += _table_function("lamp_datum(int i, int j)", data,
                                 len(records) * lamp_table.RECORD_SIZE,
                                 "j" if len(records) == 1 else f"{lamp_table.RECORD_SIZE} * i + j")
    if texels:
        lines += _table_function("spot_datum(int k)", ", ".join(f"{x:.9g}" for x in texels),
                                 len(texels), "k")
    return "\n".join(lines)


def _table_function(signature: str, data: str, size: int, index: str) -> list[str]:
    return [f"float {signature}", "{", f"    float table[{size}] = {{{data}}};",
            f"    return table[{index}];", "}"]


def shader_source(model: Model, lamps=()) -> str:
    """`lamps`: the LampRecords the shader may aim its residual at (addon/lamps.py); none by
    default, which compiles the lamp code out."""
    source = (OSL_DIR / f"{model.shader}.osl").read_text()
    source = source.replace("    // @parameters", parameter_declarations(model))
    source = source.replace("    // @clamp_parameters", clamp_statements(model))
    return assemble(source, lamps)


def assemble(source: str, lamps=()) -> str:
    """An OSL text made self-contained: its headers inlined, the lamp table written, the enum
    codes and version facts before everything (a model's shader, or a test's probe)."""
    source = inline_headers(source).replace("// @lamps", lamp_table_block(lamps))
    return enum_defines() + version_defines() + source


def uses_lamps(model: Model) -> bool:
    """Whether the model's shader aims at the scene's lamps (includes lamps.h, maybe through
    another header)."""
    return "lamps.h" in included_headers(f"{model.shader}.osl")

