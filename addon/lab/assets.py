"""`make assets`: the presets' asset library (addon/asset_library.py) written from presets/*.toml.

Two steps, each run by the Blender it needs (scripts/build_assets.py):

1. `render_previews`, on the pinned release: each preset on one sphere of the lab's grid
   (addon/lab/thumbnails.py), written as assets/previews/<id>.png. The presets panel shows
   these files; the library's assets carry the same pixels.
2. `write_library`, on Blender 4.2 (the oldest the manifest admits: it cannot read a file
   written by 5.x): one material per preset, made by the function Apply uses
   (`preset_ui.new_material`), marked as an asset with the preset's description, catalogue,
   tags and preview, written with its node group and OSL text into one compressed .blend,
   and the catalogs file beside it.
"""
from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from .. import asset_library, preset_ui
from ..presets import Preset, load_all
from . import images, thumbnails


def render_previews(out_dir=asset_library.PREVIEWS_DIR, presets: list[Preset] | None = None,
                    samples: int = 64, log=print) -> list[Path]:
    """Render the previews (PREVIEW_PX square, gradient world) into `out_dir`."""
    return thumbnails.render_thumbnails(out_dir, presets, size=asset_library.PREVIEW_PX,
                                        samples=samples, log=log)


def set_preview(idblock, path) -> None:
    """Give `idblock` the PNG at `path` as its preview, as stored (sRGB bytes; previews hold
    display values, row 0 at the bottom)."""
    rgb = images.read_image(path)
    h, w = rgb.shape[:2]
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = rgb[::-1, :, :3]
    preview = idblock.preview_ensure()
    preview.image_size = (w, h)
    preview.image_pixels_float.foreach_set(rgba.ravel())


def make_asset(preset: Preset, preview_dir=asset_library.PREVIEWS_DIR):
    """The preset's material, marked as an asset of the library."""
    material = preset_ui.new_material(preset)
    material.asset_mark()
    data = material.asset_data
    data.description = preset.description
    data.author = asset_library.AUTHOR
    data.license = asset_library.LICENSE
    data.copyright = f"Values: {preset.citation()}"[:256]
    data.catalog_id = asset_library.catalog_id(asset_library.catalog_path(preset))
    for tag in asset_library.tags(preset):
        data.tags.new(tag, skip_if_exists=True)
    set_preview(material, asset_library.preview_path(preset.id, preview_dir))
    return material


def write_library(directory=asset_library.ASSETS_DIR, presets: list[Preset] | None = None,
                  preview_dir=asset_library.PREVIEWS_DIR, log=print) -> Path:
    """Write the library's .blend and catalogs file into `directory`; returns the .blend."""
    presets = list(load_all().values()) if presets is None else list(presets)
    missing = [p.id for p in presets if not asset_library.preview_path(p.id, preview_dir).is_file()]
    if missing:
        raise FileNotFoundError(f"no preview for {missing} in {preview_dir}: render them first")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    materials = {make_asset(p, preview_dir) for p in presets}
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    blend = directory / asset_library.BLEND_NAME
    bpy.data.libraries.write(str(blend), materials, path_remap="NONE", fake_user=True,
                             compress=True)
    (directory / asset_library.CATALOGS_NAME).write_text(asset_library.catalogs_text(presets))
    log(f"[assets] wrote {blend} ({blend.stat().st_size / 1024:.0f} KB, {len(materials)} "
        f"materials, Blender {bpy.app.version_string})")
    return blend
