"""The harness itself: geometry, environment and the compile guard, checked without any model.

A perfect mirror (Cycles' own `reflection` closure) in the gradient environment must show
L(reflect(wi, n)) at every pixel: this pins the camera mapping, the exact spheres, the pixel
filter and the world's direction convention, independently of every microfacet formula.
"""
import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import compat, nodes, shader_nodes, shaders  # noqa: E402

from addon.lab import grid, harness  # noqa: E402
from addon.catalog import MODELS, ENUM  # noqa: E402

MIRROR = '#include "stdcycles.h"\nshader mirror(output closure color BSDF = 0) { BSDF = reflection(N); }'


def test_mirror_sphere_sees_the_analytic_environment():
    makers = [lambda: harness.osl_material(MIRROR, "mirror")] * 2
    # One sample: it lands on the pixel centre (measured: later samples of a pixel sometimes land
    # further away than the 0.01 px filter suggests, a zero-mean spread, ~1e-7 on average).
    layout, image, _ = harness.render_specs(None, grid.GRADIENT, 1, cols=2, cell_px=64,
                                            materials=makers)
    index, normal, mu = layout.pixel_geometry()
    wo = 2 * mu[..., None] * normal - grid.VIEW
    expected = grid.GRADIENT.radiance(wo)
    # mu > 0.05 as everywhere: at the rim the reflected direction turns by ~1/mu per pixel, so
    # the 0.01 px filter footprint alone moves the value there.
    sel = (index >= 0) & (mu > 0.05)
    err = np.abs(image[sel][:, 0] - expected[sel])
    assert sel.sum() > 4000
    assert err.max() < 2e-5, err.max()  # measured 2.4e-6: float precision


def test_seeds_rendered_in_one_scene_are_the_separate_renders():
    """harness.render_seeds (persistent data, the shaders compiled once) gives each seed's
    pixels exactly as a render of its own would: it would catch a seed that does not reach the
    render, or state left over from the previous one."""
    specs = [grid.SphereSpec("walter_reflection", {"roughness": r}, f"r={r}") for r in (0.3, 0.8)]
    kwargs = {"cols": 2, "cell_px": 16}
    _, together = harness.render_seeds(specs, grid.GRADIENT, 4, (1, 2), **kwargs)
    alone = [harness.render_specs(specs, grid.GRADIENT, 4, seed=s, **kwargs)[1] for s in (1, 2)]
    assert not np.array_equal(together[0], together[1])
    for a, b in zip(together, alone):
        assert np.array_equal(a, b)


# Emits 1 where trace() toward the next row (-y, rising 0.02) hits something, else 0.5.
SEES_NEXT_ROW = ('#include "stdcycles.h"\nshader seen(output closure color BSDF = 0) {\n'
                 '    vector next_row = normalize(vector(0, -1, 0.02));\n'
                 '    BSDF = (trace(P, next_row) ? 1.0 : 0.5) * emission();\n}')


def test_a_row_rendered_alone_is_out_of_the_other_rows_trace():
    """OSL's trace() sees the grid's spheres though they are invisible to every secondary ray (1 in
    the full grid where the ray meets the next row); harness.render_row_alone takes the other rows
    out of its way (all 0.5). It would catch the report rendering a row with the others in the way
    of the shaders' view of a lamp: the light-sampled rows under the point and area lamps then found
    the lamp only by rare, heavy delta hits (relative RMSE 0.2-0.3 at 1024 samples)."""
    layout = grid.GridLayout(3, 1, cell_px=16)
    harness.new_scene()
    mats = [harness.osl_material(SEES_NEXT_ROW, f"sees next row {i}") for i in range(3)]
    scene = harness.build_grid_scene(layout, mats, grid.GRADIENT, 1)
    index, _, mu = layout.pixel_geometry()
    row0 = (index == 0) & (mu > 0.2)
    full, _ = harness.render(scene)
    harness.render_row_alone(scene, layout, 0)
    alone, _ = harness.render(scene)
    assert row0.sum() > 100
    assert np.mean(full[row0][:, 0] == 1.0) > 0.5  # 68%: the rest pass over the next sphere
    assert np.all(alone[row0][:, 0] == 0.5)
    assert np.all(alone[index == 1] == 0.0)  # outside the border: not rendered


def test_values_read_per_object_render_as_the_same_values_in_value_nodes():
    """harness.attribute_model_material (the stress grid under the sun) gives the pixels of
    harness.linked_model_material for the same values: it would catch an attribute that does
    not reach the shader (read as 0) and pass a stress grid that tested nothing."""
    if not compat.OBJECT_ATTRIBUTES_ON_POINT_CLOUDS:
        with pytest.raises(RuntimeError, match="does not pass object attributes"):
            harness.attribute_model_material("walter_reflection", {}, ["roughness"], "a")
        return
    values = {"roughness": 0.4, "n": (0.2, 0.9, 1.4), "k": (3.0, 2.4, 1.9)}
    enums = {"fresnel_type": "conductor"}
    images = []
    for per_object in (False, True):
        harness.new_scene()
        if per_object:
            mat = harness.attribute_model_material("walter_reflection", enums, list(values), "a")
        else:
            mat = harness.linked_model_material("walter_reflection", {**enums, **values}, "v")
        layout = grid.GridLayout(1, 1, cell_px=32)
        scene = harness.build_grid_scene(layout, [mat], grid.GRADIENT, 4, 3)
        if per_object:
            harness.set_object_values(scene.objects[harness.sphere_name(0)], values)
        images.append(harness.render(scene)[0])
    index, _, _ = layout.pixel_geometry()
    a, b = (im[index == 0][:, :3] for im in images)
    assert a.mean() > 0.05
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6)


def test_compile_guard_fails_loudly_on_a_broken_shader(monkeypatch):
    harness.new_scene()
    model = MODELS["walter_reflection"]
    monkeypatch.setattr(shaders, "shader_source", lambda m, lamps=(): "shader broken( { syntax error")
    tree = bpy.data.node_groups.new("guard", "ShaderNodeTree")
    script = tree.nodes.new("ShaderNodeScript")
    with pytest.raises(shader_nodes.ShaderCompileError, match="no bytecode or no sockets"):
        shader_nodes.compile_script_node(script, model)
    # The scene-level guard sees the empty node too, before any render.
    with pytest.raises(RuntimeError, match="no bytecode or no sockets"):
        harness.check_compiled()


@pytest.mark.parametrize("model_id", list(MODELS))
def test_node_group_sockets_follow_the_catalog(model_id):
    harness.new_scene()
    model = MODELS[model_id]
    group = nodes.ensure_group(model_id)
    inputs = [s for s in group.interface.items_tree if s.in_out == "INPUT"]
    assert [s.name for s in inputs] == [p.label for p in model.params]
    for socket, param in zip(inputs, model.params):
        if param.kind == ENUM and compat.MENU_SOCKETS:  # a menu of the items' labels
            assert socket.socket_type == "NodeSocketMenu"
            assert socket.default_value == param.item_label(param.default)
        elif param.kind == ENUM:
            assert socket.default_value == param.index(param.default)
            assert (socket.min_value, socket.max_value) == (0, len(param.items) - 1)
        elif param.kind == "float":
            assert socket.default_value == pytest.approx(param.default)
            assert (socket.min_value, socket.max_value) == pytest.approx((param.min, param.max))
    assert harness.uncompiled_script_nodes() == []
