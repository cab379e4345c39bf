"""The world's bright spots as the shaders see them (bpy side of addon/world_spots.py).

`world_records(scene)` follows the world's active output through Mix and Add Shader nodes to
its Background nodes; a Background whose Color comes from an Environment Texture
(equirectangular image) hands over the image's bright spots, one whose Color comes from a Sky
Texture with a sun disc hands over the disc. A Mapping node between the texture and Generated
coordinates is followed when it only rotates (and scales uniformly). Anything else (a spot
painted with other nodes, a strength driven by a link) is not read: those worlds render
exactly, with more noise under their spots (docs/light-sampling.md).
"""
from __future__ import annotations

import math
import os

import numpy as np

from . import compat, world_spots

# Guiding weight of the Sky Texture's sun per unit of Sun Intensity and Background strength
# (about its irradiance at 45 degrees elevation; only its ratio to the scene's lamps matters).
SKY_SUN_POWER = 1000.0

# Spots found per image, by the image's identity and size (reading pixels costs a copy of
# the image: done once, not on every frame of an animation).
_IMAGE_CACHE: dict = {}


def _input(node, name):
    """A node's input socket by name, or None (a name lookup on `inputs` misses some sockets,
    e.g. the Sky Texture's Vector in 5.x, that iterating finds)."""
    return next((s for s in node.inputs if s.name == name), None)


def _source(socket):
    """The node linked into `socket`, or None (unlinked or a muted link)."""
    if socket is None or not socket.is_linked:
        return None
    link = socket.links[0]
    return None if getattr(link, "is_muted", False) else link.from_node


def _world_output(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"
               and getattr(n, "target", "ALL") in ("ALL", "CYCLES")]
    active = [n for n in outputs if n.is_active_output]
    return (active or outputs or [None])[0]


def _backgrounds(node, depth=0):
    """Background nodes feeding `node` through Mix and Add Shader nodes."""
    if node is None or depth > 16 or getattr(node, "mute", False):
        return
    if node.bl_idname == "ShaderNodeBackground":
        yield node
    elif node.bl_idname in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        for socket in node.inputs:
            if socket.type == "SHADER":
                yield from _backgrounds(_source(socket), depth + 1)


def _lookup_rotation(texture):
    """3x3 rotation taking a world direction to the direction `texture` looks up: identity for
    an unlinked Vector, a Mapping node's rotation when it is fed Generated coordinates and
    neither translates nor scales unevenly; None for anything else."""
    mapping = _source(_input(texture, "Vector"))
    if mapping is None:
        return np.eye(3)  # unlinked: the lookup direction is the world direction
    if mapping.bl_idname != "ShaderNodeMapping" or mapping.vector_type not in ("POINT", "VECTOR"):
        return None
    coords = _source(_input(mapping, "Vector"))
    link = _input(mapping, "Vector").links[0] if coords is not None else None
    if coords is None or coords.bl_idname != "ShaderNodeTexCoord" \
            or link.from_socket.name != "Generated":
        return None
    sockets = [_input(mapping, name) for name in ("Location", "Rotation", "Scale")]
    if any(s.is_linked for s in sockets):
        return None
    location, rotation, scale = (tuple(s.default_value) for s in sockets)
    if mapping.vector_type == "POINT" and any(x != 0.0 for x in location):
        return None
    if not (scale[0] > 0.0 and scale[0] == scale[1] == scale[2]):
        return None
    from mathutils import Euler
    return np.array(Euler(rotation, "XYZ").to_matrix())


def _file_path(image):
    """The file an image is read from, or None (packed, generated, edited in Blender)."""
    if image.source != "FILE" or image.packed_file is not None or image.is_dirty:
        return None
    import bpy

    return bpy.path.abspath(image.filepath, library=image.library)


def _image_key(image):
    """What identifies an image's pixels, read without loading them (Image.size loads the image
    into Blender's memory: a file's size and time stand for it)."""
    path = _file_path(image)
    try:
        stamp = None if path is None else (os.stat(path).st_mtime_ns, os.stat(path).st_size)
    except OSError:
        stamp = None
    content = stamp if stamp is not None else tuple(image.size)
    return (getattr(image, "session_uid", None), image.name_full, image.filepath_raw, content,
            image.source)


BANDS = 64  # the sun search reads an HDRI in this many bands of rows (one at a time)


def _band_rows(height: int) -> int:
    return max(8, -(-height // BANDS))


def _srgb_to_linear(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _band_luminance(pixels, srgb: bool):
    """Luminance of (rows, W, >=3) pixels, float32 (the sun search needs no more)."""
    rgb = pixels[..., :3]
    if srgb:
        rgb = _srgb_to_linear(rgb)
    return world_spots.luminance(rgb.astype(np.float32, copy=False))


def _is_srgb(image, as_stored: bool) -> bool:
    """Whether values are sRGB-encoded: in the file whenever the image's colour space is sRGB
    (`as_stored`); in Blender's copy only for 8-bit images (it makes float ones linear). Other
    colour spaces are read as linear: the spots only guide where rays go."""
    srgb = image.colorspace_settings.name.lower().startswith("srgb")
    return srgb and (as_stored or not image.is_float)


def _open_file(image):
    """(OpenImageIO module, reader) of an image's file by the OpenImageIO inside Blender, or
    None (no OpenImageIO, a packed, generated, edited or missing image)."""
    path = _file_path(image)
    if path is None:
        return None
    compat.expose_bundled_modules()
    try:
        import OpenImageIO as oiio
    except ImportError:
        return None
    reader = oiio.ImageInput.open(path)
    return None if reader is None else (oiio, reader)


def _file_bands(image):
    """(height, width, bands) of an image read from its file by the OpenImageIO inside Blender,
    one band of rows at a time (rows counted from the bottom, as Blender stores them); None where
    that cannot be done (_open_file)."""
    opened = _open_file(image)
    if opened is None:
        return None
    oiio, reader = opened
    path = _file_path(image)
    spec = reader.spec()
    if spec.nchannels < 3 or spec.width * spec.height == 0 or spec.depth > 1:
        reader.close()
        return None
    height, width, srgb = spec.height, spec.width, _is_srgb(image, as_stored=True)

    def bands():
        try:
            step = _band_rows(height)
            for top in range(0, height, step):
                end = min(top + step, height)
                pixels = reader.read_scanlines(0, 0, top, end, 0, 0, 3, oiio.FLOAT)
                if pixels is None or len(pixels) != end - top:
                    raise RuntimeError(f"OpenImageIO could not read {path}: {oiio.geterror()}")
                yield height - end, _band_luminance(np.asarray(pixels)[::-1], srgb)
        finally:
            reader.close()
    return height, width, bands()


def _pixel_bands(image):
    """(height, width, bands) of an image's pixels as Blender holds them (one float32 copy)."""
    width, height = image.size
    channels = image.channels
    if width * height == 0 or channels < 3:
        return None
    flat = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(flat)
    pixels = flat.reshape(height, width, channels)
    srgb = _is_srgb(image, as_stored=False)
    step = _band_rows(height)
    return height, width, ((row, _band_luminance(pixels[row:row + step], srgb))
                           for row in range(0, height, step))


def image_spots(image) -> list:
    """world_spots.band_spots of an image, cached; [] when it cannot be read. An image file is
    read in bands by OpenImageIO, so Blender does not load it; else its pixels are copied once."""
    key = _image_key(image)
    if key not in _IMAGE_CACHE:
        had_data = image.has_data
        spots = []
        try:
            found = _file_bands(image) or _pixel_bands(image)
            if found is not None:
                spots = world_spots.band_spots(found[2], found[0], found[1])
        except (RuntimeError, ValueError, MemoryError, OSError):
            spots = []
        if not had_data and image.has_data:
            image.buffers_free()  # do not keep a second copy of an image only Cycles needs
        _IMAGE_CACHE[key] = spots
    return _IMAGE_CACHE[key]


def _file_box(image, box):
    """(rows, columns, 3) of a box (world_spots.texel_box) read from the image's file by the
    OpenImageIO inside Blender, rows from the bottom; None where that cannot be done."""
    opened = _open_file(image)
    if opened is None:
        return None
    oiio, reader = opened
    try:
        spec = reader.spec()
        col0, row0, cols, rows = box
        top = spec.height - row0 - rows  # the file's rows run from the top
        pixels = reader.read_scanlines(0, 0, top, top + rows, 0, 0, 3, oiio.FLOAT)
    finally:
        reader.close()
    if pixels is None or len(pixels) != rows:
        return None
    rgb = np.asarray(pixels)[::-1][:, (col0 + np.arange(cols)) % spec.width]
    return _srgb_to_linear(rgb) if _is_srgb(image, as_stored=True) else rgb


def _pixel_box(image, box, pixels):
    """_file_box from Blender's copy of the pixels, (H, W, channels), copied once per image."""
    col0, row0, cols, rows = box
    rgb = pixels[row0:row0 + rows, (col0 + np.arange(cols)) % pixels.shape[1], :3]
    return _srgb_to_linear(rgb) if _is_srgb(image, as_stored=False) else rgb


def _blender_pixels(image) -> np.ndarray:
    width, height = image.size
    flat = np.empty(width * height * image.channels, dtype=np.float32)
    image.pixels.foreach_get(flat)
    return flat.reshape(height, width, image.channels)


def image_texels(image) -> list:
    """Per spot of image_spots(image): (box, (rows, columns, 3) linear RGB, width, height) of
    the pixels a lookup in its cone reads (world_spots.texel_box), or None; cached."""
    key = ("texels", _image_key(image))
    if key not in _IMAGE_CACHE:
        found, had_data, pixels = [], image.has_data, None
        try:
            width, height = _image_size(image)
            for axis, half, _ in image_spots(image):
                box = world_spots.texel_box(axis, half, height, width)
                rgb = None if box is None else _file_box(image, box)
                if box is not None and rgb is None:
                    pixels = _blender_pixels(image) if pixels is None else pixels
                    rgb = _pixel_box(image, box, pixels)
                found.append(None if rgb is None else (box, rgb, width, height))
        except (RuntimeError, ValueError, MemoryError, OSError):
            found = [None] * len(image_spots(image))
        if not had_data and image.has_data:
            image.buffers_free()
        _IMAGE_CACHE[key] = found
    return _IMAGE_CACHE[key]


def _image_size(image):
    """(width, height) of an image: its file's header where it has one (Image.size loads it)."""
    opened = _open_file(image)
    if opened is None:
        return tuple(image.size)
    spec = opened[1].spec()
    opened[1].close()
    return spec.width, spec.height


def _texture_spots(texture):
    """Spots (axis, half-angle, power) of an Environment or Sky Texture, in its lookup space,
    and per spot its texels' (box, RGB, width, height) (image_texels) or None."""
    if texture.bl_idname == "ShaderNodeTexEnvironment":
        if texture.image is None or texture.projection != "EQUIRECTANGULAR":
            return [], []
        return image_spots(texture.image), image_texels(texture.image)
    if texture.bl_idname == "ShaderNodeTexSky":
        if texture.sky_type not in compat.SKY_TYPES_WITH_SUN_DISC or not texture.sun_disc:
            return [], []
        half = 0.5 * float(texture.sun_size)
        axis = world_spots.sky_sun_direction(texture.sun_elevation, texture.sun_rotation)
        return [(axis, half, SKY_SUN_POWER * float(texture.sun_intensity))], [None]
    return [], []


def _background_records(background) -> list:
    strength = _input(background, "Strength")
    texture = _source(_input(background, "Color"))
    if strength is None or strength.is_linked or texture is None:
        return []
    rotation = _lookup_rotation(texture)
    if rotation is None:
        return []
    scale = float(strength.default_value)
    if not math.isfinite(scale) or scale <= 0.0:
        return []
    spots, found = _texture_spots(texture)
    # Cubic and Smart lookups are predicted as Linear: a prediction off changes only the noise.
    linear = getattr(texture, "interpolation", "Linear") != "Closest"
    texels = [None if f is None else world_spots.box_texels(f[0], f[1], f[2], f[3], linear,
                                                            rotation, scale) for f in found]
    return world_spots.spot_records(spots, rotation, scale, texels)


def world_records(scene) -> list:
    """LampRecords of the bright spots of the world `scene` renders, brightest first."""
    tree = compat.node_tree_of(scene.world)
    if tree is None:
        return []
    output = _world_output(tree)
    if output is None:
        return []
    records = []
    for background in _backgrounds(_source(_input(output, "Surface"))):
        records += _background_records(background)
    return sorted(records, key=lambda r: -r.power)
