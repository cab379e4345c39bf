"""The extension package: manifest validation, zip contents, and an install into a fresh bpy.

The zip is built once (module fixture) by scripts/build_package.py, which runs the extension tool
bundled in the bpy wheel. It must hold exactly the Python modules the add-on imports at run time
(found by following the imports of the entry point, including those inside functions), plus osl/,
presets/, assets/ (the presets' asset library), README and LICENSE: no verification lab (addon/lab/), no tests, scripts or docs. The
install test runs Blender's own "Install from Disk" operator in a separate process with a
throw-away user resource directory, then registers, builds every model's node group and applies
every preset from the INSTALLED copy (bl_ext.user_default.microfacet_lab), and adds its asset
library to the Asset Browser, so a file missing from the zip shows up as an import, OSL compile,
preset or asset failure. The zip's size is printed (the note and README quote it).
"""
from __future__ import annotations

import ast
import importlib.util
import shutil
import zipfile
from pathlib import Path

import pytest

from addon.catalog import MODELS
from bpy_helpers import run_bpy_script

pytestmark = pytest.mark.compat

ROOT = Path(__file__).resolve().parent.parent
EXT_ID = "microfacet_lab"
MODULE = f"bl_ext.user_default.{EXT_ID}"


def _load_build_package():
    spec = importlib.util.spec_from_file_location("build_package", ROOT / "scripts" / "build_package.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


build_package = _load_build_package()


@pytest.fixture(scope="module")
def package(tmp_path_factory) -> Path:
    return build_package.build(ROOT, tmp_path_factory.mktemp("dist"))


def test_manifest_validates():
    output = build_package.validate(ROOT)
    assert "Success" in output, output
    data = build_package.manifest(ROOT)
    assert data["id"] == EXT_ID and data["type"] == "add-on"
    assert "permissions" not in data
    assert len(data["tagline"]) < 64


def test_validator_checks_tags(tmp_path):
    """The tags really are checked against Blender's list (the standalone tool checks none)."""
    text = (ROOT / "blender_manifest.toml").read_text()
    assert '"Material"' in text
    shutil.copy(ROOT / "__init__.py", tmp_path)
    (tmp_path / "blender_manifest.toml").write_text(text)
    build_package.validate(tmp_path)  # the copy alone validates ...
    (tmp_path / "blender_manifest.toml").write_text(text.replace('"Material"', '"No Such Tag"', 1))
    with pytest.raises(build_package.BuildError, match="No Such Tag"):  # ... a bad tag does not
        build_package.validate(tmp_path)


def runtime_modules(entry: Path = ROOT / "__init__.py") -> set[str]:
    """Repository paths of the modules the add-on imports at run time: the relative imports of
    the entry point, followed through every module (imports inside functions count too)."""
    seen, todo = set(), [entry.resolve()]
    while todo:
        path = todo.pop()
        rel = path.relative_to(ROOT).as_posix()
        if rel in seen:
            continue
        seen.add(rel)
        package = path.parent
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.level == 0:
                continue
            base = package
            for _ in range(node.level - 1):
                base = base.parent
            stem = base.joinpath(*node.module.split(".")) if node.module else base
            targets = [stem] if node.module else []
            targets += [stem / alias.name for alias in node.names]
            for target in targets:
                for candidate in (target.with_suffix(".py"), target / "__init__.py"):
                    if candidate.is_file():
                        todo.append(candidate.resolve())
    return seen


def test_runtime_modules_are_the_addon_without_the_lab():
    """What the closure finds: the add-on's modules, never a lab module (addon/lab/ may import
    the add-on; the add-on never imports the lab). Would catch a lab import slipped into the
    add-on, even one inside a function."""
    mods = runtime_modules()
    assert {"__init__.py", "addon/__init__.py", "addon/ui.py", "addon/nodes.py",
            "addon/preset_ui.py", "addon/presets.py", "addon/catalog.py", "addon/shaders.py",
            "addon/specialize.py", "addon/compat.py"} <= mods, mods
    assert not [m for m in mods if m.startswith("addon/lab/")], mods
    # The closure follows function-level imports (preset_ui imports specialize inside execute).
    assert "addon/specialize.py" in mods


# The data files the add-on reads at run time.
ADDON_DATA = {"addon/fallback_fit.json"}


def test_zip_contents(package):
    assert package.name == f"{EXT_ID}-{build_package.manifest(ROOT)['version']}.zip"
    with zipfile.ZipFile(package) as zf:
        names = set(zf.namelist())
    files = {n for n in names if not n.endswith("/")}
    # Python: exactly the modules the add-on imports at run time.
    assert {n for n in files if n.endswith(".py")} == runtime_modules()
    assert not [n for n in names if n.startswith(("addon/lab", "tests/", "scripts/", "docs/"))]
    for model in MODELS.values():
        assert f"osl/{model.shader}.osl" in files
    for sub in ("osl", "presets", "assets"):
        shipped = {p.relative_to(ROOT).as_posix() for p in (ROOT / sub).rglob("*")
                   if p.is_file() and not any(part.startswith(".") for part in p.parts)}
        assert shipped <= files, shipped - files
    allowed_top = {"__init__.py", "blender_manifest.toml", "addon", "osl", "presets", "assets",
                   "README.md", "LICENSE"}
    for name in files:
        top = name.split("/")[0]
        assert top in allowed_top, f"unexpected file in package: {name}"
        assert "__pycache__" not in name and not name.endswith((".pyc", ".pyo")), name
        assert not any(part.startswith(".") for part in name.split("/")), name
        if top == "addon":
            assert name.endswith(".py") or name in ADDON_DATA, f"unexpected under addon/: {name}"
    assert {"README.md", "LICENSE"} <= files
    assert ADDON_DATA <= files
    with zipfile.ZipFile(package) as zf:
        sizes = {}
        for info in zf.infolist():
            top = info.filename.split("/")[0]
            sizes[top] = sizes.get(top, 0) + info.compress_size
    print(f"\n[package] zip {package.stat().st_size / 1024:.0f} KB; compressed by folder (KB): "
          + ", ".join(f"{k} {v / 1024:.0f}" for k, v in sorted(sizes.items())))


def test_license_is_the_gpl3_the_manifest_declares():
    assert build_package.manifest(ROOT)["license"] == ["SPDX:GPL-3.0-or-later"]
    text = " ".join((ROOT / "LICENSE").read_text().split())
    assert text.startswith("GNU GENERAL PUBLIC LICENSE")
    assert "Version 3, 29 June 2007" in text and "END OF TERMS AND CONDITIONS" in text
    assert "or (at your option) any later version" in text
    assert len(text) > 30000  # the full text, not a notice


INSTALL_SCRIPT = '''
import os, sys
zip_path = sys.argv[1]
import bpy
if hasattr(bpy.utils, "expose_bundled_modules"):  # 4.4+ (the add-on does this via its compat)
    bpy.utils.expose_bundled_modules()

scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.shading_system = True

out = {"user_resources": bpy.utils.resource_path("USER")}
repo = next(r for r in bpy.context.preferences.extensions.repos if r.module == "user_default")
out["repo_dir"] = repo.directory
out["op"] = sorted(bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True))
out["enabled"] = "bl_ext.user_default.microfacet_lab" in bpy.context.preferences.addons

import importlib
ext = importlib.import_module("bl_ext.user_default.microfacet_lab")
out["ext_file"] = ext.__file__
out["operator_registered"] = hasattr(bpy.types, "NODE_OT_microfacet_lab_add")
out["operator_in_ops"] = "microfacet_lab_add" in dir(bpy.ops.node)
out["menu_registered"] = hasattr(bpy.types, "NODE_MT_microfacet_lab")

catalog = importlib.import_module(ext.__name__ + ".addon.catalog")
nodes = importlib.import_module(ext.__name__ + ".addon.nodes")
shaders = importlib.import_module(ext.__name__ + ".addon.shaders")
out["osl_dir"] = str(shaders.OSL_DIR)
groups = {}
for model_id in catalog.MODELS:
    group = nodes.ensure_group(model_id)
    script = group.nodes[nodes.SCRIPT_NODE_NAME]
    groups[model_id] = {
        "name": group.name,
        "bytecode_len": len(script.bytecode),
        "outputs": [s.name for s in script.outputs],
        "inputs": len(script.inputs),
    }
out["groups"] = groups
out["models"] = list(catalog.MODELS)

# Every preset, applied by the installed operator to its own object (what an artist does).
presets = importlib.import_module(ext.__name__ + ".addon.presets")
applied = {}
for preset_id in sorted(presets.load_all()):
    mesh = bpy.data.meshes.new(preset_id)
    obj = bpy.data.objects.new(preset_id, mesh)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    result = bpy.ops.material.microfacet_lab_apply_preset(preset=preset_id)
    mat = obj.active_material
    applied[preset_id] = {"result": sorted(result), "material": mat.name if mat else None,
                          "key": mat.get("microfacet_lab_preset") if mat else None}
out["presets_dir"] = str(presets.PRESETS_DIR)
out["applied"] = applied

# The asset library, added to the Asset Browser by the installed operator.
out["library_op"] = sorted(bpy.ops.preferences.microfacet_lab_add_asset_library())
libraries = [(lib.name, lib.path, lib.import_method)
             for lib in bpy.context.preferences.filepaths.asset_libraries]
out["libraries"] = libraries
blend = os.path.join(libraries[-1][1], "Microfacet Lab presets.blend")
with bpy.data.libraries.load(blend, link=True, assets_only=True) as (src, dst):
    dst.materials = list(src.materials)
out["assets"] = sorted(m.get("microfacet_lab_preset") for m in dst.materials
                       if m.asset_data is not None and m.preview is not None)
report(out)
'''


def test_install_in_fresh_blender(package, tmp_path):
    user = tmp_path / "user_resources"
    user.mkdir()
    out = run_bpy_script(INSTALL_SCRIPT, tmp_path, str(package),
                         env={"BLENDER_USER_RESOURCES": str(user)})
    log = out.pop("_log")
    assert Path(out["user_resources"]).resolve() == user.resolve(), log
    assert Path(out["repo_dir"]).resolve().is_relative_to(user.resolve()), log
    assert out["op"] == ["FINISHED"], log
    assert out["enabled"], log
    installed = Path(out["repo_dir"]) / EXT_ID
    # The add-on that runs is the installed copy, not the repository.
    assert Path(out["ext_file"]).resolve() == (installed / "__init__.py").resolve(), log
    assert Path(out["osl_dir"]).resolve() == (installed / "osl").resolve(), log
    assert out["operator_registered"] and out["operator_in_ops"] and out["menu_registered"], log
    assert out["models"] == list(MODELS), log
    for model_id, group in out["groups"].items():
        assert group["bytecode_len"] > 0, f"{model_id}: no bytecode\n{log}"
        assert "BSDF" in group["outputs"], f"{model_id}: outputs {group['outputs']}\n{log}"
        assert group["inputs"] == len(MODELS[model_id].params), f"{model_id}\n{log}"
    assert Path(out["presets_dir"]).resolve() == (installed / "presets").resolve(), log
    shipped = sorted(p.stem for p in (ROOT / "presets").glob("*.toml"))
    assert sorted(out["applied"]) == shipped, log
    for preset_id, applied in out["applied"].items():
        assert applied["result"] == ["FINISHED"], f"{preset_id}: {applied}\n{log}"
        assert applied["key"] == preset_id and applied["material"], f"{preset_id}: {applied}"
    assert out["library_op"] == ["FINISHED"], log
    name, path, method = out["libraries"][-1]
    assert name == "Microfacet Lab" and Path(path).resolve() == (installed / "assets").resolve(), log
    # Dropped presets are appended (5.3 makes a new library Pack: linked, read-only data).
    assert method in ("APPEND_REUSE", "APPEND"), log
    assert out["assets"] == shipped, log


def test_build_script_cli(tmp_path):
    """`make package` entry point: prints the zip path, exit 0; non-zero with a message on failure."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_package.py"),
                           "--output-dir", str(tmp_path)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip().splitlines()[-1]).is_file()
    bad = tmp_path / "bad"
    bad.mkdir()
    shutil.copy(ROOT / "__init__.py", bad)
    (bad / "blender_manifest.toml").write_text(
        (ROOT / "blender_manifest.toml").read_text().replace('version = "0.1.0"', 'version = "x"', 1))
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_package.py"),
                           "--source-dir", str(bad), "--output-dir", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert "build_package: error:" in proc.stderr and "version" in proc.stderr, proc.stderr
