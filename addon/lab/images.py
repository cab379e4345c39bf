"""Image files for the lab and the tests (the add-on itself reads and writes none): an image
read as float64 pixels, an 8-bit PNG written as given, renders written as one multilayer EXR.
The pip bpy 4.2 wheel bundles no OpenImageIO, so reading falls back to Blender's own loader
there; the other version facts are in addon/compat.py."""
from __future__ import annotations

import bpy
import numpy as np

from ..compat import expose_bundled_modules


def has_openimageio() -> bool:
    """Whether the bundled OpenImageIO can be imported (the pip bpy 4.2 wheel ships none)."""
    expose_bundled_modules()
    try:
        import OpenImageIO  # noqa: F401  (only whether it imports)
    except ImportError:
        return False
    return True


def read_image(path, use_openimageio: bool | None = None):
    """An image file as float64 (H, W, C), row 0 at the top, values as stored (EXR: linear).
    The bundled OpenImageIO reads it where there is one, else Blender's image loader."""
    if use_openimageio is None:
        use_openimageio = has_openimageio()
    if use_openimageio:
        import OpenImageIO as oiio

        pixels = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)
        if pixels is None or pixels.size == 0:
            raise RuntimeError(f"could not read {path}: {oiio.geterror()}")
        return np.asarray(pixels, dtype=np.float64)
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = image.size
        if w == 0 or h == 0:
            raise RuntimeError(f"could not read {path}")
        if not image.is_float:  # an 8-bit file: keep its stored values, as OpenImageIO does
            image.colorspace_settings.is_data = True
        # Blender holds every image as RGBA; the file's own channels follow from its depth.
        in_file = image.depth // (32 if image.is_float else 8)
        flat = np.empty(w * h * image.channels, dtype=np.float32)
        image.pixels.foreach_get(flat)
        pixels = flat.reshape(h, w, image.channels)[::-1, :, :in_file]
        return pixels.astype(np.float64)
    finally:
        bpy.data.images.remove(image)


def write_png(path, rgb) -> None:
    """Write an (H, W, 3) array in [0, 1] (row 0 at the top) as an 8-bit PNG, stored as given
    (no colour transform), with Blender's own image writer (every version has it)."""
    data = np.round(np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0) * 255.0) / 255.0
    h, w = data.shape[:2]
    image = bpy.data.images.new("Microfacet Lab PNG", w, h, alpha=False, float_buffer=False)
    try:
        image.colorspace_settings.is_data = True
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[..., :3] = data[::-1, :, :3]
        image.pixels.foreach_set(rgba.ravel())
        image.filepath_raw = str(path)
        image.file_format = "PNG"
        image.save()
    finally:
        bpy.data.images.remove(image)


def set_multilayer_exr(image_settings) -> None:
    """Write every pass to one multilayer OpenEXR: a media type from Blender 5.0, a file format
    before."""
    if "media_type" in image_settings.bl_rna.properties:
        image_settings.media_type = "MULTI_LAYER_IMAGE"  # its one format: OPEN_EXR_MULTILAYER
    image_settings.file_format = "OPEN_EXR_MULTILAYER"
