"""Scene specialization (addon/specialize.py): the specialised render equals the unspecialised one
within noise; unused Microfacet Lab shaders are pruned and only used ones compiled; bounces follow
the documented rules; linked model switches are reported. The file-size and render-time gains
are measured and printed (run with -s to see them), not asserted.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import compat, nodes, presets, specialize  # noqa: E402

from addon.lab import grid, harness  # noqa: E402
from addon.catalog import MODELS  # noqa: E402

PRESETS = ("red_plastic", "gold_cook_torrance", "white_plastic", "copper_cook_torrance")
SAMPLES, CELL = 32, 40


def build(bounces=4):
    """Sphere grid of Cook-Torrance presets; the file also holds a pinned, unused Walter group
    and its text (a shader the user tried and pinned, then stopped using)."""
    scene = harness.new_scene()
    chosen = [presets.find(p) for p in PRESETS]
    mats = [harness.model_material(p.model_id, p.params, p.id) for p in chosen]
    layout = grid.GridLayout(rows=1, cols=len(mats), cell_px=CELL)
    harness.build_grid_scene(layout, mats, grid.GRADIENT, SAMPLES, seed=3, max_bounces=bounces)
    unused = nodes.ensure_group("walter_reflection")
    unused.use_fake_user = True
    return scene, layout


def within_noise(a, b, index):
    """Mean difference over sphere pixels against its standard error, per channel (pixels are
    independent samples, as in tests/test_render_reference.py)."""
    d = (a[..., :3] - b[..., :3])[index >= 0]
    mean = d.mean(0)
    stderr = d.std(0, ddof=1) / np.sqrt(len(d))
    return mean, stderr, np.abs(d).max()


def test_specialised_render_equals_unspecialised_and_is_smaller(tmp_path):
    scene, layout = build()
    full_blend = tmp_path / "full.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(full_blend), compress=False)
    image_full, t_full = harness.render(scene)

    start = time.perf_counter()
    report = specialize.specialize(scene)
    t_specialize = time.perf_counter() - start
    assert report.compiled == [] and report.up_to_date == ["cook_torrance"]
    assert report.removed_groups == ["Microfacet Lab: " + MODELS["walter_reflection"].label]
    assert report.removed_texts == ["MicrofacetLab_walter_reflection.osl"]
    assert "MicrofacetLab_cook_torrance.osl" in bpy.data.texts
    assert "Microfacet Lab: sphere" in bpy.data.node_groups  # not ours to remove
    assert report.lobes == {"diffuse", "glossy"} and not report.secondary_hits
    assert report.linked_enums == []
    c = scene.cycles
    assert (c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces,
            c.volume_bounces, c.transparent_max_bounces) == (1, 1, 1, 0, 0, 0)
    harness.check_compiled()
    spec_blend = tmp_path / "specialised.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(spec_blend), compress=False)
    image_spec, t_spec = harness.render(scene)

    index, _, _ = layout.pixel_geometry()
    mean, stderr, worst = within_noise(image_spec, image_full, index)
    assert np.isfinite(image_spec).all()
    assert (np.abs(mean) <= 4 * stderr + 1e-6).all(), (mean, stderr)
    # Background pixels see the world directly in both.
    assert np.allclose(image_spec[index < 0], image_full[index < 0], atol=1e-6)
    full, spec = full_blend.stat().st_size, spec_blend.stat().st_size
    print(f"\n[specialize] .blend {full} -> {spec} bytes ({full - spec} bytes, "
          f"{100 * (full - spec) / full:.1f}% smaller); render {t_full:.2f} s -> {t_spec:.2f} s "
          f"(one render each, 2-core machine: noisy); specialize itself {t_specialize:.2f} s; "
          f"mean diff {mean} +- {stderr}, max |diff| {worst:.2e}")
    assert spec < full


def test_bounce_rules_follow_the_materials():
    scene, _ = build()
    # A visible glass object: transmission stays, depth keeps the scene's values.
    glass = compat.new_node_material("glass")
    tree = glass.node_tree
    out = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    bsdf = tree.nodes.new("ShaderNodeBsdfGlass")
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    mesh = bpy.data.meshes.new("pane")
    mesh.materials.append(glass)
    obj = bpy.data.objects.new("pane", mesh)
    scene.collection.objects.link(obj)
    report = specialize.scan(scene)
    assert report.secondary_hits and "transmission" in report.lobes
    assert report.bounces_after == {"max_bounces": 4, "diffuse_bounces": 4, "glossy_bounces": 4,
                                    "transmission_bounces": 4, "volume_bounces": 0,
                                    "transparent_max_bounces": 0}
    # Only Walter materials (glossy only): no diffuse, no transmission.
    assert specialize.needed_bounces({"glossy"}, True, report.bounces_before) == {
        "max_bounces": 4, "diffuse_bounces": 0, "glossy_bounces": 4, "transmission_bounces": 0,
        "volume_bounces": 0, "transparent_max_bounces": 0}
    # A foreign OSL script counts as every lobe kind.
    script = tree.nodes.new("ShaderNodeScript")
    assert specialize.material_lobes(glass) == set(specialize.ALL)
    tree.nodes.remove(script)


def test_linked_model_switch_is_reported_and_outside_materials_are_kept():
    scene, _ = build()
    mat = bpy.data.materials[PRESETS[0]]
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup")
    value = mat.node_tree.nodes.new("ShaderNodeValue")
    mat.node_tree.links.new(value.outputs[0], node.inputs["Sampler"])
    # A library material (fake user, on no object) using the Walter model.
    library = harness.model_material("walter_reflection", {}, "library walter")
    library.use_fake_user = True
    report = specialize.specialize(scene)
    assert report.linked_enums == [f"{PRESETS[0]} / {node.name} / Sampler"]
    assert any("WARNING linked model switch" in line for line in report.lines())
    assert report.removed_groups == [] and report.removed_texts == []
    assert report.kept_groups == ["Microfacet Lab: " + MODELS["walter_reflection"].label]
    assert report.up_to_date == ["cook_torrance"]  # the library's model is not compiled


def test_stale_shader_is_recompiled_unused_one_is_not():
    scene, _ = build()
    ct = bpy.data.texts["MicrofacetLab_cook_torrance.osl"]
    ct.write("\n// edited by hand\n")  # stale: differs from the add-on's OSL
    group = bpy.data.node_groups["Microfacet Lab: " + MODELS["cook_torrance"].label]
    group.nodes[nodes.SCRIPT_NODE_NAME].bytecode = ""
    report = specialize.specialize(scene)
    assert report.compiled == ["cook_torrance"] and report.up_to_date == []
    assert "edited by hand" not in ct.as_string()
    harness.check_compiled()
