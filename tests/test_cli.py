"""scripts/render_scene.py: the command-line flow under pip bpy, in fresh processes (tiny
renders). The Blender-executable form (`blender --background --python ... -- args`) differs only in
where the arguments start, which `script_args` handles and the `--` run below exercises.
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "render_scene.py"


def load_script():
    spec = importlib.util.spec_from_file_location("render_scene_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(*args, cwd):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([sys.executable, str(SCRIPT), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)
    return proc, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"


def test_arguments_after_double_dash():
    module = load_script()
    assert module.script_args(["blender", "--background", "--python", "x.py", "--", "--preset", "gold"]) \
        == ["--preset", "gold"]
    assert module.script_args(["x.py", "--preset", "gold"]) == ["--preset", "gold"]
    args = module.parse(["--preset", "gold,chrome", "--specialize"])
    assert args.preset == ["gold,chrome"] and args.specialize


def test_unknown_preset_is_a_clear_error_without_rendering(tmp_path):
    proc, log = run("--preset", "unobtainium", cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "no preset 'unobtainium'" in proc.stdout, log


@pytest.mark.render
def test_pip_bpy_renders_presets_to_png(tmp_path):
    import numpy as np

    out = tmp_path / "grid.png"
    proc, log = run("--preset", "gold,red_plastic", "--out", str(out), "--samples", "4",
                    "--size", "24", cwd=tmp_path)
    assert proc.returncode == 0, log
    assert "[render_scene] rendering 48x24 px" in proc.stdout and "[render_scene] wrote" in proc.stdout, log
    pytest.importorskip("bpy")
    from addon import compat

    pixels = np.round(compat.read_image(out) * 255).astype(np.uint8)
    assert pixels.shape == (24, 48, 3)
    gold, plastic = pixels[12, 12].astype(int), pixels[12, 36].astype(int)
    assert gold[0] > gold[2] and plastic[0] > plastic[1] + 40, (gold, plastic)
    assert np.ptp(pixels) > 50


@pytest.mark.render
def test_double_dash_specialize_exr_and_blend(tmp_path):
    out, blend = tmp_path / "x.exr", tmp_path / "x.blend"
    proc, log = run("--", "--preset", "chrome", "--out", str(out), "--samples", "2", "--size", "16",
                    "--specialize", "--save-blend", str(blend), cwd=tmp_path)
    assert proc.returncode == 0, log
    assert "already up to date: ['walter_reflection']" in proc.stdout, log
    assert "transmission_bounces 4 -> 0" in proc.stdout, log
    assert out.stat().st_size > 0 and blend.stat().st_size > 0
