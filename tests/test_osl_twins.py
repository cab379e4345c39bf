"""The OSL headers and their numpy twins, file for file: the first line of each osl/*.h names
its twin, a module of addon/lab/reference/ (`// Twin: addon/lab/reference/<module>.py`) or a
pure module of the add-on (`// Twin: addon/<module>.py`: a world spot's texels, which the add-on
finds), or says that it has none and why (`// Twin: none. <why>`); every function the header
defines has a function of the same name in that module (a module-level function or a method of
a class defined there), but for the few listed in OSL_ONLY. And the text each shader is
compiled from (addon/shaders.py shader_source) is self-contained: no local #include left, no
function defined twice with one signature.

What this catches: a function renamed on one side only, moved to another header or module, or
added to a header without its twin; a header whose first line names a module that does not
exist; a nested #include the assembly does not inline, or a header inlined twice (OSL refuses a
second definition). Numpy only (bpy is neither needed nor imported for the assembly).
"""
from __future__ import annotations

import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

from addon import shaders
from addon.catalog import MODELS
from addon.lamps import sphere_record, sun_record

ROOT = Path(__file__).resolve().parent.parent
HEADERS = sorted(p.name for p in shaders.OSL_DIR.glob("*.h"))
SHADERS = sorted({model.shader for model in MODELS.values()})
TWIN_LINE = re.compile(r"^// Twin: (?:none\. (?P<why>\S.*)"
                       r"|(?P<module>addon/(?:lab/reference/)?\w+)\.py\b)")
# Return type, name, '(' at the start of a line: a function definition (calls are indented).
DEFINITION = re.compile(r"^((?:closure\s+)?(?:void|int|float|color|vector|normal|point|matrix"
                        r"|string))\s+(\w+)\s*\(", re.M)

# Header functions with no numpy twin, and why.
OSL_ONLY = {
    ("bsdf.h", "sample_reflection"):
        "G2 times sample_reflection_factor, the stochastic branch's weight; numpy: "
        "MicrofacetBRDF.sample, which also applies F and the tint",
    ("split.h", "residual_factor"):
        "F G2 - c F_n G2_hc, the residual per unit of D / (4 wi.n); numpy: "
        "split.residual_weight_reflection, which also applies the sampler's factor, the tint "
        "and the clamp, and eval_residual",
    ("lamps.h", "lamp_vector"): "reads the generated lamp table; numpy reads LampRecord fields",
    ("lamps.h", "lamp_kind"): "reads the generated lamp table; numpy reads LampRecord.kind",
    ("lamps.h", "lamp_is"): "lamp_kind compared, folded where the table has no such lamp; "
                            "numpy compares LampRecord.kind",
    ("lamps.h", "lamp_is_area"): "lamp_is for both area shapes; numpy compares LampRecord.kind",
    ("lamps.h", "lamp_u"): "reads an area lamp's enlarged axis from the table; numpy: extents",
    ("lamps.h", "lamp_v"): "reads an area lamp's enlarged axis from the table; numpy: extents",
    ("lamps.h", "sample_lamps_local"): "sample_lamps in the shading frame; numpy's frame is the "
                                       "world's",
    ("lamps.h", "lamps_density_local"): "lamps_pdf in the shading frame; numpy's frame is the "
                                        "world's",
    ("lamps.h", "lamp_predicted"): "reads the table's radiance slots; numpy reads "
                                   "LampRecord.radiance",
    ("lamps.h", "lamps_estimated_here"): "reads Cycles' path:ray_depth; numpy has no paths "
                                         "(its lamp_share models the hits off the camera's)",
    ("lamps.h", "nee_horizon"): "the control variate's horizon (nee.h, no twin): reads I and Ng",
    ("lamps.h", "lamp_estimable"): "the control variate's horizon rule (nee.h, no twin)",
    ("lamps.h", "lamp_estimated"): "the control variate's lamps (nee.h, no twin); numpy's "
                                   "lamp_share models the hits off the camera's",
    ("lamps.h", "lamp_site"): "fills the shading point's LampSite, what lamp_weight, "
                              "lamp_bounding_cone, lamp_cone and lamp_estimated give there, "
                              "computed once (OSL inlines every call); numpy calls them",
    ("lamps.h", "lamp_texels"): "reads a world spot's texel offset from the table; the "
                                "reference's records sample a spot's cone, its texels' sampling "
                                "has its twin in addon/world_spots.py (spots.h)",
    ("spots.h", "spot_texel_index"): "reads the generated spot table; numpy reads SpotTexels",
    ("spots.h", "spot_texel"): "reads the generated spot table; numpy reads SpotTexels",
    ("spots.h", "spot_cumulative"): "reads the table's shares; numpy: SpotTexels.cumulative",
    ("spots.h", "spot_radiance"): "Cycles' own image lookup, held to Cycles' render of the "
                                  "image by tests/test_world_handover.py",
}


def first_line(header: str) -> str:
    return (shaders.OSL_DIR / header).read_text().split("\n", 1)[0]


def twin_module(header: str):
    """The numpy module the header's first line names, or None (no twin)."""
    match = TWIN_LINE.match(first_line(header))
    assert match, f"osl/{header}: the first line must name its twin: {first_line(header)!r}"
    if match.group("module") is None:
        return None
    return importlib.import_module(match.group("module").replace("/", "."))


def header_functions(header: str) -> list[str]:
    return [name for _, name in DEFINITION.findall((shaders.OSL_DIR / header).read_text())]


def numpy_functions(module) -> set[str]:
    """The functions a module defines: its own module-level functions and the methods (static
    ones too) of the classes it defines."""
    names = set()
    for name, obj in vars(module).items():
        if getattr(obj, "__module__", None) != module.__name__:
            continue
        if inspect.isfunction(obj):
            names.add(name)
        elif inspect.isclass(obj):
            names |= {n for n, v in vars(obj).items()
                      if inspect.isfunction(v) or isinstance(v, (staticmethod, classmethod))}
    return names


def test_the_headers_are_there():
    assert {"cycles.h", "special.h", "fresnel.h", "microfacet.h", "bsdf.h", "split.h",
            "lamps.h", "controls.h"} <= set(HEADERS), HEADERS


@pytest.mark.parametrize("header", HEADERS)
def test_every_header_function_has_its_numpy_twin(header):
    module = twin_module(header)
    functions = header_functions(header)
    assert functions, f"osl/{header} defines no function"
    if module is None:
        assert not [key for key in OSL_ONLY if key[0] == header], "a header without twin lists none"
        return
    twins = numpy_functions(module)
    missing = [f for f in functions if f not in twins and (header, f) not in OSL_ONLY]
    assert not missing, f"osl/{header}: no function of that name in {module.__name__}: {missing}"


def test_the_osl_only_list_is_current():
    """Each listed function is defined in its header, has a reason, and really has no twin."""
    for (header, name), why in OSL_ONLY.items():
        assert name in header_functions(header), (header, name)
        assert why.strip()
        module = twin_module(header)
        assert module is not None and name not in numpy_functions(module), (header, name)


def test_a_function_name_means_one_thing_across_the_headers():
    """No name is defined in two headers (OSL overloads on argument types; within one header an
    overload, such as fresnel_conductor's per-channel form, is the same function)."""
    where: dict[str, set] = {}
    for header in HEADERS:
        for name in header_functions(header):
            where.setdefault(name, set()).add(header)
    twice = {name: sorted(h) for name, h in where.items() if len(h) > 1}
    assert not twice, twice


def _signatures(text: str) -> list[tuple]:
    """(return type, name, parameter types) of every function definition in an OSL text."""
    out = []
    for match in DEFINITION.finditer(text):
        depth, i = 1, match.end()
        while depth:
            depth += {"(": 1, ")": -1}.get(text[i], 0)
            i += 1
        params = text[match.end():i - 1]
        types = []
        for param in filter(None, (p.strip() for p in params.split(","))):
            param = param.split("=")[0].strip()
            words = re.sub(r"\[.*?\]", "[]", param).split()
            name = words[-1]
            types.append(" ".join(words[:-1]) + ("[]" if name.endswith("[]") else ""))
        out.append((" ".join(match.group(1).split()), match.group(2), tuple(types)))
    return out


LAMPS = [sun_record((0.3, 0.2, 1.0), 0.05, 1.0), sphere_record((1.0, 0.0, 2.0), 0.2, 10.0)]


@pytest.mark.parametrize("shader", SHADERS)
def test_the_assembled_shader_is_self_contained(shader):
    model = next(m for m in MODELS.values() if m.shader == shader)
    for lamps in ((), LAMPS):
        text = shaders.shader_source(model, lamps)
        assert not shaders.local_includes(text), shader
        for header in shaders.included_headers(f"{shader}.osl"):
            assert text.count(f"// ---- begin {header}\n") == 1, (shader, header)
        signatures = _signatures(text)
        twice = sorted({s for s in signatures if signatures.count(s) > 1})
        assert not twice, (shader, twice)


def test_headers_come_after_the_headers_they_include():
    for shader in SHADERS:
        order = shaders.included_headers(f"{shader}.osl")
        for i, header in enumerate(order):
            needs = shaders.local_includes((shaders.OSL_DIR / header).read_text())
            assert set(needs) <= set(order[:i]), (shader, header, needs, order)


def test_shader_assembly_imports_no_bpy():
    """addon/shaders.py assembles every shader with bpy out of reach (its bpy half is
    addon/shader_nodes.py)."""
    code = ("import sys; sys.modules['bpy'] = None\n"
            "from addon import shaders\nfrom addon.catalog import MODELS\n"
            "for m in MODELS.values(): shaders.shader_source(m)\n"
            "assert 'addon.shader_nodes' not in sys.modules\n")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
