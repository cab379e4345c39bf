"""Portability (the render-farm case): a .blend made with the add-on renders the same in a fresh
bpy process that never imports the add-on, because the OSL bytecode travels in the file with the
INTERNAL Script nodes; with OSL off (a GPU render farm) the node groups' native branches, saved
in the file too, render the same way.

Measured: the fresh process reproduces the image exactly with the same seed (max |diff| 0 on
this machine; docs/cycles-osl.md notes ~3e-7 between thread counts), so the test asserts agreement
within noise (per-pixel statistics) and a tight bound on the largest pixel difference.
"""
from __future__ import annotations

import numpy as np
import pytest

from bpy_helpers import run_bpy_script

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import presets  # noqa: E402

from addon.lab import grid, harness  # noqa: E402

PRESETS = ("gold", "red_plastic", "aluminium_brushed")

CHILD = '''
import sys
blend, exr, osl = sys.argv[1], sys.argv[2], sys.argv[3] == "osl"
import bpy
scene = open_blend(blend)
scene.cycles.shading_system = osl
scripts = [(g.name, n.mode, len(n.bytecode), n.script.name if n.script else None)
           for g in bpy.data.node_groups if g.bl_idname == "ShaderNodeTree"
           for n in g.nodes if n.bl_idname == "ShaderNodeScript"]
scene.render.filepath = exr
bpy.ops.render.render(write_still=True)
foreign = sorted(m for m in sys.modules if m == "addon" or m.startswith("addon.")
                 or "microfacet" in m.lower())
path_has_repo = any(p and __import__("os").path.isfile(__import__("os").path.join(p, "addon", "catalog.py"))
                    for p in sys.path)
report({"scripts": scripts, "foreign_modules": foreign, "repo_importable": path_has_repo,
        "engine": scene.render.engine, "osl": scene.cycles.shading_system})
'''


@pytest.mark.parametrize("osl", [True, False], ids=["osl", "no_osl"])
def test_saved_material_renders_identically_without_the_addon(tmp_path, osl):
    """With OSL the shaders run from the bytecode in the file; without it (a GPU farm) the
    groups' native branches render, also saved in the file (addon/fallback.py)."""
    from addon.lab import images

    specs = [grid.SphereSpec(presets.find(p).model_id, presets.find(p).params, p) for p in PRESETS]
    layout, image, _ = harness.render_specs(specs, grid.GRADIENT, 16, seed=7, cols=3, cell_px=32,
                                            osl=osl)
    blend = tmp_path / "farm.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), compress=False)

    farm = tmp_path / "farm"
    farm.mkdir()
    exr = farm / "farm.exr"
    out = run_bpy_script(CHILD, farm, str(blend), str(exr), "osl" if osl else "no_osl")
    log = out.pop("_log")
    assert out["foreign_modules"] == [] and not out["repo_importable"], log
    assert out["engine"] == "CYCLES" and out["osl"] == osl, log
    assert len(out["scripts"]) == 2 and all(mode == "INTERNAL" and size > 1000
                                            for _, mode, size, _ in out["scripts"]), out["scripts"]

    farm_image = images.read_image(exr)
    assert farm_image.shape == image.shape
    index, _, _ = layout.pixel_geometry()
    d = (farm_image[..., :3] - image[..., :3])[index >= 0]
    mean, stderr = d.mean(0), d.std(0, ddof=1) / np.sqrt(len(d))
    print(f"\n[portability] max |diff| {np.abs(d).max():.2e}, mean {mean} +- {stderr}")
    assert (np.abs(mean) <= 4 * stderr + 1e-6).all(), (mean, stderr)
    assert np.abs(d).max() < 1e-4
    # The spheres are not black: the shaders (or the native branches) really ran there.
    for i in range(len(PRESETS)):
        assert farm_image[index == i][:, :3].mean() > 0.05


ANIMATION_CHILD = '''
import sys
blend, out_dir = sys.argv[1], sys.argv[2]
import bpy
scene = open_blend(blend)
for frame in (1, 2):
    scene.frame_set(frame)
    scene.render.filepath = f"{out_dir}/frame{frame}.exr"
    bpy.ops.render.render(write_still=True)
foreign = sorted(m for m in sys.modules if m == "addon" or m.startswith("addon.")
                 or "microfacet" in m.lower())
report({"foreign_modules": foreign})
'''


@pytest.mark.release_only  # the saved file's portability is the tests above, on every version
def test_animation_renders_on_a_farm_without_the_addon(tmp_path):
    """A render farm: the frames of an animation whose sun turns, rendered by a fresh process
    without the add-on. The add-on hands each frame's lamps to the shaders before it renders;
    the farm has only the table of the frame rendered last before saving (frame 2). So frame 2
    must be the same image, and frame 1 the same image within its noise (the shaders are exact
    with any table: it only guides where rays go). Would catch a frame that needs the add-on to
    render, or a table that biases a frame it was not made for."""
    import mathutils

    from addon.lab import images

    specs = [grid.SphereSpec(presets.find(p).model_id, presets.find(p).params, p) for p in PRESETS]
    layout, _, _ = harness.render_specs(specs, grid.GRADIENT, 16, seed=5, cols=3, cell_px=32)
    scene = bpy.context.scene
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.5  # soft: a stale table leaves no rare, heavy hits
    scene.collection.objects.link(sun)
    for frame, toward in ((1, (0.3, -0.4, 0.87)), (2, (-0.5, 0.2, 0.84))):
        sun.rotation_euler = mathutils.Vector(toward).to_track_quat("Z", "Y").to_euler()
        sun.keyframe_insert("rotation_euler", frame=frame)
    ours = {}
    for frame in (1, 2):
        scene.frame_set(frame)
        ours[frame] = harness.render(scene)[0]
    blend = tmp_path / "animation.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), compress=False)

    farm = tmp_path / "farm"
    farm.mkdir()
    out = run_bpy_script(ANIMATION_CHILD, farm, str(blend), str(farm))
    assert out["foreign_modules"] == [], out["_log"]
    index, _, _ = layout.pixel_geometry()
    for frame in (1, 2):
        theirs = images.read_image(farm / f"frame{frame}.exr")
        d = (theirs[..., :3] - ours[frame][..., :3])[index >= 0]
        mean, stderr = d.mean(0), d.std(0, ddof=1) / np.sqrt(len(d))
        print(f"\n[farm] frame {frame}: max |diff| {np.abs(d).max():.2e}, mean {mean} +- {stderr}")
        assert (np.abs(mean) <= 4 * stderr + 1e-6).all(), (frame, mean, stderr)
        if frame == 2:  # the saved table is this frame's: the same samples
            assert np.abs(d).max() < 1e-4
        else:  # another table: other samples, so the noise differs (the test sees it does)
            assert np.abs(d).max() > 1e-3
        assert theirs[index >= 0][:, :3].mean() > 0.05
