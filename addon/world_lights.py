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


def _image_key(image):
    return (getattr(image, "session_uid", None), image.name_full, image.filepath_raw,
            tuple(image.size), image.source)


def _image_luminance(image):
    """(H, W) linear luminance of a loaded image, or None."""
    width, height = image.size
    channels = image.channels
    if width * height == 0 or channels < 3:
        return None
    flat = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(flat)
    rgb = flat.reshape(height, width, channels)[..., :3].astype(np.float64)
    if not image.is_float and image.colorspace_settings.name.lower().startswith("srgb"):
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return world_spots.luminance(rgb)


def image_spots(image) -> list:
    """world_spots.image_spots of an image, cached; [] when it cannot be read."""
    key = _image_key(image)
    if key not in _IMAGE_CACHE:
        had_data = image.has_data
        try:
            lum = _image_luminance(image)
        except (RuntimeError, ValueError, MemoryError):
            lum = None
        if not had_data:
            image.buffers_free()  # do not keep a second copy of an image only Cycles needs
        _IMAGE_CACHE[key] = [] if lum is None else world_spots.image_spots(lum)
    return _IMAGE_CACHE[key]


def _texture_spots(texture):
    """Spots (axis, half-angle, power) of an Environment or Sky Texture, in its lookup space."""
    if texture.bl_idname == "ShaderNodeTexEnvironment":
        if texture.image is None or texture.projection != "EQUIRECTANGULAR":
            return []
        return image_spots(texture.image)
    if texture.bl_idname == "ShaderNodeTexSky":
        if texture.sky_type not in compat.SKY_TYPES_WITH_SUN_DISC or not texture.sun_disc:
            return []
        half = 0.5 * float(texture.sun_size)
        axis = world_spots.sky_sun_direction(texture.sun_elevation, texture.sun_rotation)
        return [(axis, half, SKY_SUN_POWER * float(texture.sun_intensity))]
    return []


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
    return world_spots.spot_records(_texture_spots(texture), rotation, scale)


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
