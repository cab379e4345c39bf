"""The presets' asset library (assets/, written by `make assets`: addon/lab/assets.py), read by
every supported Blender (it is written by 4.2, the oldest).

- The library holds one material per preset and nothing else: the preset's description,
  catalogue (listed in the catalogs file), tags, preview (the shipped PNG's pixels) and
  parameter values. Would catch a preset added, removed or edited without `make assets`.
- A preset dropped from the library (Blender appends the material, reusing what an earlier drop
  appended) becomes the material Apply makes: after the add-on's depsgraph handler
  (addon/adopt.py) the same group datablock, node for node the same tree and inputs, and the
  same pixels at a fixed seed. Would catch a dropped material that keeps its appended group
  (renamed ".001", so the lamps' hand-over never reaches it, or with 4.2's integer sockets on
  5.x), or an adoption that loses a value.

The shaders' OSL inside the library is not compared with osl/: the add-on rebuilds a dropped
preset's group from its own source, so a library written before a shader edit renders the
current shader.
"""
from __future__ import annotations

import numpy as np
import pytest

from addon import asset_library
from addon.presets import load_all

pytestmark = pytest.mark.compat

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import adopt, nodes, preset_ui  # noqa: E402
from addon.lab import grid, harness, images  # noqa: E402

BLEND = asset_library.ASSETS_DIR / asset_library.BLEND_NAME
PRESETS = load_all()


def _linked_library():
    with bpy.data.libraries.load(str(BLEND), link=True, assets_only=True) as (src, dst):
        dst.materials = list(src.materials)
    return {m.get(preset_ui.MATERIAL_KEY): m for m in dst.materials}


def test_library_holds_one_asset_per_preset():
    harness.new_scene()
    library = _linked_library()
    assert sorted(library) == sorted(PRESETS)
    catalog_ids = {line.split(":")[0] for line in
                   (asset_library.ASSETS_DIR / asset_library.CATALOGS_NAME).read_text().splitlines()
                   if line and not line.startswith(("#", "VERSION"))}
    for preset_id, material in library.items():
        preset = PRESETS[preset_id]
        data = material.asset_data
        assert data.description == preset.description, preset_id
        assert data.catalog_id == asset_library.catalog_id(asset_library.catalog_path(preset))
        assert data.catalog_id in catalog_ids, preset_id
        assert [t.name for t in data.tags] == asset_library.tags(preset)
        preview = material.preview
        w, h = preview.image_size
        assert (w, h) == (asset_library.PREVIEW_PX,) * 2, preset_id
        pixels = np.empty(w * h * 4, dtype=np.float32)
        preview.image_pixels_float.foreach_get(pixels)
        shipped = images.read_image(asset_library.preview_path(preset_id))
        assert np.abs(pixels.reshape(h, w, 4)[::-1, :, :3] - shipped).max() < 1.5 / 255, preset_id
        node = preset_ui.lab_node(material)
        assert node is not None and nodes.model_of(node.node_tree) == preset.model, preset_id
        values = nodes.read_inputs(node, preset.model)
        expected = preset.resolved()
        for key, value in expected.items():
            assert values[key] == pytest.approx(value, rel=1e-6, abs=1e-6), (preset_id, key)


def test_make_assets_writes_a_library_blender_reads_back(tmp_path):
    """The writer `make assets` runs (here on two presets, with the shipped previews): a .blend
    whose materials are assets with previews, and the catalogs file beside it."""
    from addon.lab import assets

    chosen = [PRESETS["gold"], PRESETS["rough_glass_heitz"]]
    blend = assets.write_library(tmp_path, chosen, log=lambda *_: None)
    harness.new_scene()
    with bpy.data.libraries.load(str(blend), link=True, assets_only=True) as (src, dst):
        dst.materials = list(src.materials)
    assert sorted(m.get(preset_ui.MATERIAL_KEY) for m in dst.materials) == ["gold", "rough_glass_heitz"]
    assert all(m.asset_data is not None and tuple(m.preview.image_size) == (128, 128)
               for m in dst.materials)
    text = (tmp_path / asset_library.CATALOGS_NAME).read_text()
    assert "Metals" in text and "Multiple scattering/Glass" in text


def test_the_panel_shows_the_assets_previews():
    """The presets panel's gallery loads each preset's shipped PNG (whose pixels the asset
    carries, checked above). Headless Blender gives previews no icon id, so their pixels are
    compared instead."""
    harness.new_scene()
    preset_ui.register()
    try:
        preset_ui.refresh(force=True)
        for preset_id in PRESETS:
            preview = preset_ui.preview(preset_id)
            assert preview is not None, preset_id
            w, h = preview.image_size
            assert (w, h) == (asset_library.PREVIEW_PX,) * 2, preset_id
            pixels = np.empty(w * h * 4, dtype=np.float32)
            preview.image_pixels_float.foreach_get(pixels)
            shipped = images.read_image(asset_library.preview_path(preset_id))
            assert np.abs(pixels.reshape(h, w, 4)[::-1, :, :3] - shipped).max() < 1.5 / 255
    finally:
        preset_ui.unregister()


def _drop(preset_id):
    """What dropping the asset does: append the material (the library's import method,
    Append (Reuse Data)), then the depsgraph update that follows."""
    name = asset_library_name(preset_id)
    before = set(bpy.data.materials)
    result = bpy.ops.wm.append(filepath=f"{BLEND}/Material/{name}", directory=f"{BLEND}/Material/",
                               filename=name, do_reuse_local_id=True)
    assert result == {"FINISHED"}
    material = next(iter(set(bpy.data.materials) - before))
    bpy.context.view_layer.update()  # the add-on's depsgraph_update_post handler adopts here
    return material


def asset_library_name(preset_id):
    return preset_ui.NAME_PREFIX + PRESETS[preset_id].label


def _applied(preset_id):
    mesh = bpy.data.meshes.new("apply " + preset_id)
    obj = bpy.data.objects.new("apply " + preset_id, mesh)
    material, action = preset_ui.apply_preset(obj, PRESETS[preset_id])
    assert action == "created"
    bpy.data.objects.remove(obj)
    return material


def _tree(material):
    def value(s):
        v = getattr(s, "default_value", None)
        return tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v

    tree = material.node_tree
    return (sorted((n.name, n.bl_idname, getattr(getattr(n, "node_tree", None), "name", None),
                    tuple(value(s) for s in n.inputs))
                   for n in tree.nodes),
            sorted((l.from_node.name, l.from_socket.name, l.to_node.name, l.to_socket.name)
                   for l in tree.links),
            material.get(preset_ui.MATERIAL_KEY))


@pytest.mark.render
def test_a_dropped_preset_is_the_applied_material():
    dropped_ids = ("rough_gold_lee", "gold", "silver")  # silver reuses gold's adopted group
    adopt.register()
    try:
        dropped, applied = {}, {}

        def drop(preset_id):
            def make():
                dropped[preset_id] = _drop(preset_id)
                return dropped[preset_id]
            return make

        def apply(preset_id):
            def make():
                applied[preset_id] = _applied(preset_id)
                return applied[preset_id]
            return make

        _, image_dropped, _ = harness.render_specs(
            [None] * 3, grid.GRADIENT, 4, seed=3, cols=3, cell_px=24,
            materials=[drop(p) for p in dropped_ids])
        assert adopt.appended_groups() == []
        groups = sorted(g.name for g in bpy.data.node_groups if nodes.model_of(g) is not None)
        assert groups == sorted({nodes.group_name(PRESETS[p].model) for p in dropped_ids})
        texts = sorted(t.name for t in bpy.data.texts)
        assert not [t for t in texts if not t.endswith(".osl")], texts  # no "... .osl.001"
        dropped_trees = {p: _tree(m) for p, m in dropped.items()}

        _, image_applied, _ = harness.render_specs(
            [None] * 3, grid.GRADIENT, 4, seed=3, cols=3, cell_px=24,
            materials=[apply(p) for p in dropped_ids])
        for preset_id in dropped_ids:
            a, d = _tree(applied[preset_id]), dropped_trees[preset_id]
            assert a == d, preset_id
        assert np.array_equal(image_dropped, image_applied)
        assert image_dropped[..., :3].mean() > 0.02
    finally:
        adopt.unregister()
