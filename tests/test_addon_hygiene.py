"""register()/unregister() of the extension's entry point, repeated, in a fresh bpy process.

The repository root is imported as a package (its __init__.py uses `from . import addon`) under a
fixed name via importlib, so this works whatever the clone's directory is called.
"""
from __future__ import annotations

from pathlib import Path

from bpy_helpers import run_bpy_script

ROOT = Path(__file__).resolve().parent.parent
CYCLES = 10

HYGIENE_SCRIPT = '''
import importlib.util, sys
root, cycles = sys.argv[1], int(sys.argv[2])
import bpy

spec = importlib.util.spec_from_file_location(
    "microfacet_lab_under_test", root + "/__init__.py", submodule_search_locations=[root])
pkg = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = pkg
spec.loader.exec_module(pkg)

MENU = "NODE_MT_category_shader_shader"
menu = getattr(bpy.types, MENU, None)

def state():
    ui = sys.modules.get(spec.name + ".addon.ui")
    draw = getattr(ui, "draw_add_menu", None)
    funcs = menu._dyn_ui_initialize() if menu is not None else []
    return {
        "operator": hasattr(bpy.types, "NODE_OT_microfacet_lab_add"),
        "op_callable": "microfacet_lab_add" in dir(bpy.ops.node),
        "menu": hasattr(bpy.types, "NODE_MT_microfacet_lab"),
        "draw_count": sum(f is draw for f in funcs) if draw is not None else 0,
    }

out = {"menu_exists": menu is not None, "before": state(), "registered": [], "unregistered": []}
for i in range(cycles):
    pkg.register()
    out["registered"].append(state())
    pkg.unregister()
    out["unregistered"].append(state())
out["ui_module"] = sys.modules[spec.name + ".addon.ui"].__file__
report(out)
'''


def test_register_unregister_cycles(tmp_path):
    out = run_bpy_script(HYGIENE_SCRIPT, tmp_path, str(ROOT), str(CYCLES))
    log = out.pop("_log")
    assert out["menu_exists"], f"Add > Shader menu class not found in this Blender\n{log}"
    assert Path(out["ui_module"]).resolve() == (ROOT / "addon" / "ui.py").resolve()
    off = {"operator": False, "op_callable": False, "menu": False, "draw_count": 0}
    on = {"operator": True, "op_callable": True, "menu": True, "draw_count": 1}
    assert out["before"] == off, log
    assert len(out["registered"]) == len(out["unregistered"]) == CYCLES
    for i, (registered, unregistered) in enumerate(zip(out["registered"], out["unregistered"])):
        assert registered == on, f"cycle {i}, registered: {registered}\n{log}"
        assert unregistered == off, f"cycle {i}, after unregister: {unregistered}\n{log}"
