"""The presets as a Blender asset library (no bpy here; the bpy half is asset_browser.py).

The extension ships `assets/`: one .blend holding one material per preset, marked as an asset
with the preset's description, catalogued by kind, with its rendered preview; the catalogs file
Blender reads beside it; and the previews as PNGs, which the presets panel shows too. The lab
writes them all from presets/*.toml (`make assets`: addon/lab/assets.py).

Blender 4.2 to 5.3 give an add-on no way to declare an asset library of its own (5.3's
"asset-library" extensions are a separate package type, for remote libraries), so the add-on
registers `assets/` as a user asset library when the artist asks for it (asset_browser.py).
The .blend is written by the oldest Blender the manifest admits: Blender 4.2 cannot read files
written by 5.x, and every later version reads 4.2's.
"""
from __future__ import annotations

import uuid
from pathlib import Path

from .presets import Preset

ASSETS_DIR = Path(__file__).resolve().parent.parent / "assets"
BLEND_NAME = "Microfacet Lab presets.blend"
PREVIEWS_DIR = ASSETS_DIR / "previews"
CATALOGS_NAME = "blender_assets.cats.txt"  # Blender's own file name for an asset library's catalogs
LIBRARY_NAME = "Microfacet Lab"
PREVIEW_PX = 128  # preview images, square: sharp in the Asset Browser, small in the zip
AUTHOR = "Microfacet Lab"
LICENSE = "GPL-3.0-or-later"

# A preset's `category` -> its catalog, in the order the Asset Browser lists them.
CATALOGS = {"metal": "Metals", "plastic": "Plastics", "coating": "Coatings", "glass": "Glass"}
OTHER = "Other"
# Models that simulate light bouncing more than once between microfacets: their presets sit in
# a catalog of their own, so the multiple-scattering looks are found side by side.
MULTIPLE_SCATTERING = {"lee_vgroove": "Multiple scattering", "heitz2016": "Multiple scattering"}

_NAMESPACE = uuid.UUID("6f1d2b1e-58a4-4c7e-9a57-1ab0a1c9f3d2")  # fixed: catalog ids stay stable


def catalog_path(preset: Preset) -> str:
    """The catalog a preset's material is filed under, e.g. "Metals" or
    "Multiple scattering/Metals"."""
    kind = CATALOGS.get(preset.category, OTHER)
    group = MULTIPLE_SCATTERING.get(preset.model_id)
    return f"{group}/{kind}" if group else kind


def catalog_id(path: str) -> str:
    """A catalog's UUID, derived from its path (the same in every build of the library)."""
    return str(uuid.uuid5(_NAMESPACE, path))


def catalog_paths(presets) -> list[str]:
    """Every catalog the presets need, parents first."""
    paths = set()
    for preset in presets:
        parts = catalog_path(preset).split("/")
        paths.update("/".join(parts[:i]) for i in range(1, len(parts) + 1))
    return sorted(paths)


def catalogs_text(presets) -> str:
    """The catalogs file (Blender's format: `UUID:catalog/path:simple name` lines)."""
    lines = ["# Written by make assets (addon/lab/assets.py) from presets/*.toml.",
             "VERSION 1", ""]
    for path in catalog_paths(presets):
        lines.append(f"{catalog_id(path)}:{path}:{path.replace('/', '-')}")
    return "\n".join(lines) + "\n"


def tags(preset: Preset) -> list[str]:
    """Asset tags: the model's name and the preset's kind (searchable in the Asset Browser)."""
    return [preset.model.label, CATALOGS.get(preset.category, OTHER)]


def preview_path(preset_id: str, folder: Path = PREVIEWS_DIR) -> Path:
    return Path(folder) / f"{preset_id}.png"


def preview_dirs() -> list[Path]:
    """Where the presets panel looks for <preset id>.png: the shipped previews, then those of
    `scripts/render_scene.py --thumbnails out/presets` in a clone."""
    return [PREVIEWS_DIR, ASSETS_DIR.parent / "out" / "presets"]
