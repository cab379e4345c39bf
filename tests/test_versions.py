"""What must hold on every Blender version the manifest admits (4.2 LTS to 5.3).

`make test` runs the whole suite on the pinned release and this file, with test_package.py
(install the zip, build every node group, apply every preset from the installed copy),
test_cli.py and test_harness.py, in each compatibility environment (tests/compat/). Here: the
running Blender is one the manifest admits; every preset renders finite, non-negative and lit;
and one white-furnace sphere per model converges to the numpy reference within its noise, so
a version that changed a closure, the hash stream, the Script node's inputs or the harness's
scene (materials, world, point-cloud spheres) is caught, whatever the version.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import presets  # noqa: E402
from addon.catalog import MODELS  # noqa: E402
from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def test_running_blender_is_admitted_by_the_manifest():
    with open(ROOT / "blender_manifest.toml", "rb") as fh:
        minimum = tomllib.load(fh)["blender_version_min"]
    assert tuple(bpy.app.version) >= tuple(int(x) for x in minimum.split("."))


def test_every_preset_renders_finite_and_lit():
    """All presets on one grid under the gradient: no NaN, Inf or negative pixel, and every
    sphere brighter than a black one (catches a shader that compiled but returns nothing, as
    when an input no longer reaches it)."""
    chosen = list(presets.load_all().values())
    specs = [SphereSpec(p.model_id, p.params, p.id) for p in chosen]
    layout, image, _ = harness.render_specs(specs, grid.GRADIENT, 16, seed=3, cols=6, cell_px=24)
    rgb = image[..., :3]
    assert np.isfinite(rgb).all() and (rgb >= 0).all()
    index, _, mu = layout.pixel_geometry()
    for i, preset in enumerate(chosen):
        sphere = rgb[(index == i) & (mu > 0.05)]
        assert sphere.size and sphere.mean() > 0.02, f"{preset.id}: mean {sphere.mean():.4f}"


# One sphere per model at roughness 0.5 with its catalog defaults (gold, glass, ...).
FURNACE = [SphereSpec(model_id, {"roughness": 0.5}, f"{model_id} r=0.5") for model_id in MODELS]


def test_white_furnace_spheres_match_the_reference_within_noise():
    """Bias per band of incidence against the per-pixel noise (Sidak z over every band and
    channel, plus the reference's own accuracy), and the power to see 1% on each whole sphere.
    Catches a wrong weight, closure, Fresnel or masking on this version."""
    layout, image, _ = harness.render_specs(FURNACE, grid.WHITE, 256, seed=1, cell_px=40)
    reference = grid.reference_grid_image(layout, FURNACE, grid.WHITE)
    bands = grid.band_stats(layout, image, reference, sides=False)
    z_crit = grid.sidak_z(3 * len(bands))
    failures = [f"{FURNACE[b.sphere].label} mu in {b.band}: bias {b.bias}, stderr {b.stderr}"
                for b in bands if grid.inconsistent(b, z_crit)]
    failures += grid.relative_bias_failures(layout, image, reference, [s.label for s in FURNACE])
    assert not failures, f"Blender {bpy.app.version_string}, z_crit {z_crit:.2f}:\n" + \
        "\n".join(failures)


@pytest.mark.parametrize("use_openimageio", [True, False], ids=["openimageio", "blender"])
def test_png_reads_back_exactly(tmp_path, use_openimageio):
    """images.write_png then images.read_image: the values written come back, row 0 at the top,
    three channels, through the bundled OpenImageIO and through Blender's loader (the only reader
    where the 4.2 wheel has no OpenImageIO). Catches a flipped image, a colour transform or an
    extra alpha channel."""
    from addon.lab import images

    if use_openimageio and not images.has_openimageio():
        pytest.skip(f"this bpy ({bpy.app.version_string}) bundles no OpenImageIO")
    rgb = np.random.default_rng(5).random((6, 9, 3))
    images.write_png(tmp_path / "x.png", rgb)
    png = images.read_image(tmp_path / "x.png", use_openimageio)
    assert png.shape == (6, 9, 3)
    assert np.abs(png - np.round(rgb * 255) / 255).max() < 1e-6


def test_render_exr_reads_the_same_through_blender_and_openimageio(tmp_path):
    """The harness's render EXR (linear RGBA, float) read by Blender's loader equals what the
    bundled OpenImageIO reads, so 4.2 (Blender's loader only) sees the same numbers."""
    from addon.lab import images

    if not images.has_openimageio():
        pytest.skip(f"this bpy ({bpy.app.version_string}) bundles no OpenImageIO")
    path = tmp_path / "x.exr"
    harness.render_specs(FURNACE[:2], grid.GRADIENT, 2, seed=1, cols=2, cell_px=12, path=str(path))
    by_oiio = images.read_image(path, use_openimageio=True)
    by_blender = images.read_image(path, use_openimageio=False)
    assert by_oiio.shape == by_blender.shape == (12, 24, 4)
    assert by_oiio[..., :3].max() > 0.1 and np.array_equal(by_oiio, by_blender)
