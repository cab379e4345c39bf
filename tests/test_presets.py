"""Presets: the shipped files validate against the catalog and are physically sane; malformed
files fail with the file and the field named; the Apply operator creates, updates and swaps
materials and leaves the scene untouched on error; thumbnails render; the panel and operators
register and unregister cleanly.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addon import presets
from addon.catalog import MODELS
from addon.presets import PresetError
from bpy_helpers import run_bpy_script

pytestmark = pytest.mark.compat

ROOT = Path(__file__).resolve().parent.parent
ALL = presets.load_all()


def f0(n, k):
    """Normal-incidence reflectance of a conductor n + ik."""
    return ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2)


# --- the shipped presets -----------------------------------------------------------------------

def test_at_least_twelve_presets_over_every_catalog_model_kind():
    assert len(ALL) >= 12
    assert {p.model_id for p in ALL.values()} == set(MODELS)  # every model has presets
    categories = {p.category for p in ALL.values()}
    assert {"metal", "plastic", "coating"} <= categories


@pytest.mark.parametrize("preset_id", sorted(ALL))
def test_every_preset_cites_its_optical_constants(preset_id):
    p = ALL[preset_id]
    assert p.citation().strip()
    assert p.label and p.description
    if {"n", "k"} & set(p.params):
        assert p.params["fresnel_type"] == "conductor"
        assert p.source["wavelengths_nm"] == [650, 550, 450]
    if "ior" in p.params:  # glass has no Fresnel switch: it is a dielectric by model
        assert p.params.get("fresnel_type", "dielectric") == "dielectric"
        assert 1.0 < p.params["ior"] < 3.0
    # Validated values pass through the catalog's clamp unchanged.
    resolved = p.resolved()
    for pid, value in p.params.items():
        assert resolved[pid] == value


def test_metals_have_the_colour_of_their_measured_ior():
    refl = {pid: [f0(n, k) for n, k in zip(p.params["n"], p.params["k"])]
            for pid, p in ALL.items() if "n" in p.params}
    r, g, b = refl["gold"]
    assert r > g > b and r > 0.9 and b < 0.45  # yellow
    r, g, b = refl["copper"]
    assert r > g > b and r > 0.9 and g < 0.7  # orange-red
    assert min(refl["silver"]) > 0.9  # white, the most reflective
    assert 0.85 < min(refl["aluminium_brushed"])
    assert 0.5 < min(refl["chrome"]) < max(refl["chrome"]) < 0.7  # grey, darker
    assert max(refl["chrome"]) - min(refl["chrome"]) < 0.05


# --- malformed presets -------------------------------------------------------------------------

GOOD = '''
model = "walter_reflection"
label = "Test"
description = "A test preset."
[source]
citation = "nowhere"
wavelengths_nm = [650, 550, 450]
[params]
roughness = 0.3
fresnel_type = "conductor"
n = [0.2, 0.4, 1.4]
'''

BAD = {
    "unknown model": (GOOD.replace('"walter_reflection"', '"lee_multibounce"'), "model", "unknown model"),
    "unknown parameter": (GOOD + "rougness = 0.3\n", "params.rougness", "unknown parameter"),
    "wrong type": (GOOD.replace("roughness = 0.3", 'roughness = "0.3"'), "params.roughness", "expected a number"),
    "bool as number": (GOOD.replace("roughness = 0.3", "roughness = true"), "params.roughness", "expected a number"),
    "out of range": (GOOD.replace("roughness = 0.3", "roughness = 1.5"), "params.roughness", "out of range"),
    "negative channel": (GOOD.replace("[0.2, 0.4, 1.4]", "[0.2, -0.4, 1.4]"), "params.n[1]", "out of range"),
    "colour length": (GOOD.replace("[0.2, 0.4, 1.4]", "[0.2, 0.4]"), "params.n", "list of 3"),
    "unknown enum item": (GOOD.replace('"conductor"', '"metal"'), "params.fresnel_type", "unknown item"),
    "enum as int": (GOOD.replace('"conductor"', "0"), "params.fresnel_type", "a string"),
    "missing citation": (GOOD.replace('citation = "nowhere"', ""), "source.citation", "missing"),
    "missing wavelengths": (GOOD.replace("wavelengths_nm = [650, 550, 450]", ""),
                            "source.wavelengths_nm", "wavelengths"),
    "unknown top-level key": ("colour = 1\n" + GOOD, "colour", "unknown key"),
    "missing params": (GOOD.split("[params]")[0], "params", "missing"),
    "toml syntax": (GOOD + "roughness =\n", "(toml syntax)", ""),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_preset_names_file_and_field(case, tmp_path):
    text, field_name, words = BAD[case]
    path = tmp_path / "broken_preset.toml"
    path.write_text(text)
    with pytest.raises(PresetError) as info:
        presets.load_preset(path)
    assert info.value.field == field_name
    message = str(info.value)
    assert message.startswith("broken_preset.toml: " + field_name), message
    assert words in message


def test_the_good_template_loads_and_scan_isolates_bad_files(tmp_path):
    (tmp_path / "ok.toml").write_text(GOOD)
    (tmp_path / "bad.toml").write_text(BAD["out of range"][0])
    found, errors = presets.scan(tmp_path)
    assert list(found) == ["ok"] and found["ok"].params["roughness"] == 0.3
    assert [e.path.name for e in errors] == ["bad.toml"]
    with pytest.raises(PresetError, match="bad.toml: params.roughness"):
        presets.load_all(tmp_path)
    with pytest.raises(PresetError, match="no preset 'nope'"):
        presets.find("nope", tmp_path)


# --- bpy: operator, thumbnails -----------------------------------------------------------------

@pytest.fixture()
def ui():
    bpy = pytest.importorskip("bpy")
    from addon import preset_ui
    from addon.lab import harness

    harness.new_scene()
    preset_ui.register()
    mesh = bpy.data.meshes.new("ball")
    obj = bpy.data.objects.new("ball", mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    yield bpy, preset_ui, obj
    preset_ui.unregister()


def lab_inputs(material):
    from addon import preset_ui

    node = preset_ui.lab_node(material)
    return node, {s.name: (tuple(s.default_value) if hasattr(s.default_value, "__len__")
                           and not isinstance(s.default_value, str) else s.default_value)  # menus: str
                  for s in node.inputs}


def expected_inputs(preset):
    from addon import compat  # bpy: menus (item labels) on 5.0+, integer codes before

    model = preset.model
    out = {}
    for p in model.params:
        v = preset.resolved()[p.id]
        if p.kind == "color":  # N, K on vector sockets (RGB), colours on colour sockets (RGBA)
            out[p.label] = tuple(v) if p.socket == "VECTOR" else (*v, 1.0)
        elif p.kind == "enum":
            out[p.label] = p.item_label(v) if compat.MENU_SOCKETS else p.index(v)
        else:
            out[p.label] = v
    return out


def snapshot(bpy):
    """Everything the Apply operator could change."""
    def value(s):
        v = getattr(s, "default_value", None)
        return tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v

    state = {"materials": sorted(m.name for m in bpy.data.materials),
             "groups": sorted(g.name for g in bpy.data.node_groups),
             "texts": sorted(t.name for t in bpy.data.texts),
             "slots": [(o.name, [s.material.name if s.material else None for s in o.material_slots])
                       for o in bpy.data.objects]}
    for m in bpy.data.materials:
        if m.node_tree:
            state["mat " + m.name] = (
                sorted((n.name, n.bl_idname, getattr(getattr(n, "node_tree", None), "name", None),
                        tuple(value(s) for s in n.inputs)) for n in m.node_tree.nodes),
                sorted((l.from_node.name, l.from_socket.name, l.to_node.name, l.to_socket.name)
                       for l in m.node_tree.links))
    return state


def approx_equal(a, b):
    return a.keys() == b.keys() and all(pytest.approx(b[k], rel=1e-6, abs=1e-6) == a[k] for k in a)


@pytest.mark.render
def test_apply_creates_updates_and_swaps(ui):
    bpy, preset_ui, obj = ui
    op = bpy.ops.material.microfacet_lab_apply_preset
    assert op.poll()
    assert op(preset="gold") == {"FINISHED"}
    material = obj.active_material
    assert material.name == "Microfacet Lab Gold (polished)" and material["microfacet_lab_preset"] == "gold"
    node, values = lab_inputs(material)
    assert node.node_tree.name == "Microfacet Lab: " + MODELS["walter_reflection"].label
    assert approx_equal(values, expected_inputs(ALL["gold"]))

    assert op(preset="silver") == {"FINISHED"}  # same model: inputs change, same material
    assert obj.active_material == material and len(bpy.data.materials) == 1
    assert material.name == "Microfacet Lab Silver (polished)"
    assert approx_equal(lab_inputs(material)[1], expected_inputs(ALL["silver"]))

    assert op(preset="red_plastic") == {"FINISHED"}  # other model: the group is swapped
    node, values = lab_inputs(material)
    assert obj.active_material == material and len(bpy.data.materials) == 1
    assert node.node_tree.name == "Microfacet Lab: " + MODELS["cook_torrance"].label
    assert approx_equal(values, expected_inputs(ALL["red_plastic"]))
    assert len([n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]) == 1

    # A material that is not Microfacet Lab's is left alone: a new one takes the slot.
    other = bpy.data.materials.new("user material")
    obj.active_material = other
    assert op(preset="chrome") == {"FINISHED"}
    assert obj.active_material != other and other.name in bpy.data.materials
    assert approx_equal(lab_inputs(obj.active_material)[1], expected_inputs(ALL["chrome"]))

    # Redo panel: an enum property with every preset, on a REGISTER | UNDO operator.
    cls = preset_ui.MATERIAL_OT_microfacet_lab_apply_preset
    assert {"REGISTER", "UNDO"} <= cls.bl_options
    items = [i[0] for i in preset_ui.preset_items(None, bpy.context)]
    assert items == sorted(ALL)


@pytest.mark.render
@pytest.mark.parametrize("case", ["unknown model", "out of range", "unknown enum item", "toml syntax"])
def test_malformed_preset_leaves_the_scene_untouched(ui, tmp_path, case):
    bpy, preset_ui, obj = ui
    op = bpy.ops.material.microfacet_lab_apply_preset
    assert op(preset="copper") == {"FINISHED"}
    before = snapshot(bpy)
    path = tmp_path / "broken_preset.toml"
    path.write_text(BAD[case][0])
    with pytest.raises(RuntimeError, match=r"broken_preset\.toml: " + BAD[case][1].replace("[", r"\[").replace("(", r"\(").replace(")", r"\)")):
        op(filepath=str(path))
    assert snapshot(bpy) == before


@pytest.mark.render
def test_thumbnail_renders_tiny(tmp_path):
    pytest.importorskip("bpy")
    from addon.lab import images
    from addon.lab import thumbnails

    written = thumbnails.render_thumbnails(tmp_path, [ALL["gold"], ALL["red_plastic"]], size=24,
                                        samples=4, log=lambda *_: None)
    assert [p.name for p in written] == ["gold.png", "red_plastic.png"]
    pixels = np.round(images.read_image(written[0]) * 255).astype(int)
    assert pixels.shape == (24, 24, 3)
    centre = pixels[12, 12].astype(int)
    assert centre[0] > centre[2] + 20  # gold: more red than blue
    red = np.round(images.read_image(written[1]) * 255).astype(int)[12, 12]
    assert red[0] > red[1] + 40


# --- hygiene of the panel and operators --------------------------------------------------------

HYGIENE = '''
import importlib.util, sys
root, cycles = sys.argv[1], int(sys.argv[2])
import bpy
spec = importlib.util.spec_from_file_location(
    "microfacet_lab_under_test", root + "/__init__.py", submodule_search_locations=[root])
pkg = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = pkg
spec.loader.exec_module(pkg)

def state():
    mod = sys.modules.get(spec.name + ".addon.preset_ui")
    return {
        "apply": hasattr(bpy.types, "MATERIAL_OT_microfacet_lab_apply_preset"),
        "apply_op": "microfacet_lab_apply_preset" in dir(bpy.ops.material),
        "specialize": hasattr(bpy.types, "SCENE_OT_microfacet_lab_specialize"),
        "panel": hasattr(bpy.types, "MATERIAL_PT_microfacet_lab_presets"),
        "wm_prop": "microfacet_lab_preset" in bpy.types.WindowManager.bl_rna.properties,
        "previews": mod is not None and mod._previews is not None,
    }

out = {"before": state(), "on": [], "off": []}
for i in range(cycles):
    pkg.register()
    mod = sys.modules[spec.name + ".addon.preset_ui"]
    mod.preset_items(None, bpy.context)  # what drawing the panel does
    out["on"].append(state())
    out["items"] = len(mod.preset_items(None, bpy.context))
    pkg.unregister()
    out["off"].append(state())
report(out)
'''


def test_panel_and_operators_register_unregister_ten_times(tmp_path):
    out = run_bpy_script(HYGIENE, tmp_path, str(ROOT), "10")
    log = out.pop("_log")
    off = {"apply": False, "apply_op": False, "specialize": False, "panel": False,
           "wm_prop": False, "previews": False}
    assert out["before"] == off, log
    assert out["items"] == len(ALL)
    for i, (on, after) in enumerate(zip(out["on"], out["off"])):
        assert {k: v for k, v in on.items() if k != "previews"} == \
            {"apply": True, "apply_op": True, "specialize": True, "panel": True, "wm_prop": True}, (i, on, log)
        assert after == off, (i, after, log)
