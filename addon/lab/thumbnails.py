"""Preset thumbnails: each preset rendered on one sphere of the lab's sphere grid.

Development tooling (`scripts/render_scene.py --thumbnails DIR`): the add-on only looks the
pictures up (`asset_library.preview_dirs`), it never renders them.
"""
from __future__ import annotations

from pathlib import Path

from ..presets import Preset, load_all
from . import grid, harness, images
from .grid import SphereSpec


def render_thumbnails(out_dir, presets: list[Preset] | None = None, size: int = 64,
                      samples: int = 32, env: str = "gradient", log=print) -> list[Path]:
    """Render each preset on one sphere (the harness's sphere grid, one render for all) and write
    `out_dir/<id>.png` (sRGB, size x size). Returns the written paths."""
    presets = list(load_all().values()) if presets is None else list(presets)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    specs = [SphereSpec(p.model_id, p.params, p.id) for p in presets]
    cols = min(len(specs), 8)
    log(f"[thumbnails] rendering {len(specs)} presets, {size} px, {samples} samples")
    layout, image, seconds = harness.render_specs(specs, grid.ENVIRONMENTS[env], samples,
                                                  seed=0, cols=cols, cell_px=size)
    log(f"[thumbnails] render {seconds:.1f} s")
    written = []
    for i, preset in enumerate(presets):
        row, col = divmod(i, cols)
        tile = image[row * size:(row + 1) * size, col * size:(col + 1) * size, :3]
        path = out_dir / f"{preset.id}.png"
        images.write_png(path, linear_to_srgb(tile))
        written.append(path)
        log(f"[thumbnails] wrote {path}")
    return written


def linear_to_srgb(linear):
    import numpy as np

    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
