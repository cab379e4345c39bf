"""The add-on's two kinds of module, by one rule (docs/README.md, "Two rooms"): a bpy module
imports bpy, or another bpy module, at its top; a pure module never imports bpy, directly or
through a bpy module at its top, and imports with numpy alone. The pure half of a topic keeps the topic's name (`shaders`, `lamps`,
`world_spots`, `presets`); its bpy half names what it does in Blender (`shader_nodes`,
`handover`, `world_lights`, `preset_ui`) and names it in its docstring's first paragraph.

What this catches: a bpy import slipped into a pure module (the lab and the tests that use it
without Blender would break), a pure module reaching bpy through a top-level import of a bpy
module, and a bpy half that no longer names its pure half.
"""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ADDON = ROOT / "addon"
# bpy half -> its pure half.
HALVES = {"shader_nodes": "shaders", "handover": "lamps", "world_lights": "world_spots",
          "preset_ui": "presets", "asset_browser": "asset_library"}


def _tree(name):
    return ast.parse((ADDON / f"{name}.py").read_text())


def _top_level_imports(tree):
    """Module names imported at the top of a module (relative imports as `.name`)."""
    names = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level and node.module:
                names.add("." + node.module)
            elif node.level:
                names |= {"." + a.name for a in node.names}
            else:
                names.add(node.module)
    return names


def _modules():
    return sorted(p.stem for p in ADDON.glob("*.py") if p.stem != "__init__")


def _bpy_modules():
    """Modules importing bpy at their top, then those importing one of them, to a fixed point."""
    imports = {m: _top_level_imports(_tree(m)) for m in _modules()}
    found = {m for m, names in imports.items() if "bpy" in {n.split(".")[0] for n in names}}
    while True:
        more = {m for m, names in imports.items() if {"." + b for b in found} & names} - found
        if not more:
            return found
        found |= more


def test_pure_modules_never_import_bpy():
    bpy_mods = _bpy_modules()
    pure = [m for m in _modules() if m not in bpy_mods]
    assert {"catalog", "shaders", "lamps", "world_spots", "presets"} <= set(pure), pure
    for m in pure:
        tree = _tree(m)
        anywhere = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert "bpy" not in anywhere, f"addon/{m}.py imports bpy"


def test_pure_modules_import_without_bpy():
    bpy_mods = _bpy_modules()
    pure = [m for m in _modules() if m not in bpy_mods]
    code = ("import sys; sys.modules['bpy'] = None\n"  # `import bpy` raises ImportError
            + "".join(f"import addon.{m}\n" for m in pure)
            + "print('ok')")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr[-2000:]


def test_each_bpy_half_names_its_pure_half():
    bpy_mods = _bpy_modules()
    for bpy_half, pure_half in HALVES.items():
        assert bpy_half in bpy_mods and pure_half not in bpy_mods, (bpy_half, pure_half)
        first_paragraph = ast.get_docstring(_tree(bpy_half)).split("\n\n")[0]
        assert f"addon/{pure_half}.py" in first_paragraph, (bpy_half, first_paragraph)
