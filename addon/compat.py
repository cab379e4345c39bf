"""Differences between the Blender versions the extension supports (4.2 LTS to 5.3), in one place.

Every other module calls these functions instead of testing `bpy.app.version`. Each difference
is detected by the feature itself where Blender offers a way to ask, and by version otherwise;
the comment says which Blender changed what. Measured with the pip `bpy` wheels 4.2.23, 4.5.15,
5.0.1 and 5.3.0.
"""
from __future__ import annotations

import bpy

# Blender 5.0: shader node groups take Menu sockets, and the Menu Switch node works in shader
# trees (4.x offers neither: enums stay integer sockets there).
MENU_SOCKETS = bpy.app.version >= (5, 0, 0)

# Blender 5.0 (Cycles commit "Add polarized fresnel function for conductors", August 2025):
# conductor_bsdf evaluates the exact conductor Fresnel; 4.x uses a fast approximation that
# rendered a Walter gold sphere up to 0.4% too bright in a white furnace (z = 20, 4.2.23), so
# there the light-sampled split gives a conductor no native part (docs/light-sampling.md).
EXACT_CONDUCTOR_FRESNEL = bpy.app.version >= (5, 0, 0)

# Blender 5.3: Cycles inverts the IOR of its refraction and dielectric closures on back faces
# itself (its own Glass and Refraction nodes stopped doing it; 4.2.23, 4.5.15, 5.0.1, 5.1.2 and
# 5.2.3 leave it to the shader): refraction(N, 1/1.5) on a back face bent rays as 1.5 does in
# 5.3.0 and as 1/1.5 before. By version: the OSL library's version cannot tell (5.2.3 ships OSL
# 1.15.3 and does not invert, 5.3.0 1.15.6 does). osl/cycles.h, refraction_toward.
CYCLES_INVERTS_BACKFACE_IOR = bpy.app.version >= (5, 3, 0)
# Blender 4.3 added the Metallic BSDF node (Cycles' conductor of complex IOR n + ik); before it
# the nearest native metal is the Principled BSDF's (addon/fallback.py).
METALLIC_BSDF = hasattr(bpy.types, "ShaderNodeBsdfMetallic")
# Cycles' own anisotropic closures on a surface without a tangent (dPdu 0, as on point-cloud
# spheres): black in 4.2 (Principled) and 5.0 (Metallic), a round-axis frame in 5.3 as our
# shaders build (measured; 5.1 and 5.2 not). Before it the native branch drops the anisotropy.
NATIVE_ANISOTROPY = bpy.app.version >= (5, 3, 0)
# An Attribute node of type Object reads the object's custom property on the lab's point-cloud
# spheres from 4.5 (4.5.15, 5.0.1, 5.3.0); 4.2.23 rendered them as if every value were unset
# (measured; 4.3 and 4.4 not). Only the lab's per-object stress grid relies on it.
OBJECT_ATTRIBUTES_ON_POINT_CLOUDS = bpy.app.version >= (4, 5, 0)


def expose_bundled_modules() -> None:
    """Put the wheel's own oslquery and OpenImageIO on sys.path (Blender 4.4+; inside a Blender
    executable, and in older wheels, there is nothing to expose). Never install the PyPI
    OpenImageIO beside bpy: a second OpenImageIO breaks oslquery (docs/cycles-osl.md)."""
    if hasattr(bpy.utils, "expose_bundled_modules"):
        bpy.utils.expose_bundled_modules()


def new_node_material(name: str):
    """A material with a node tree (before 5.0 a new material has none until use_nodes)."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    return material


def new_node_world(name: str):
    """A world with a node tree (before 5.0 a new world has none until use_nodes)."""
    world = bpy.data.worlds.new(name)
    if world.node_tree is None:
        world.use_nodes = True
    return world


def node_tree_of(idblock):
    """The node tree a material or world renders with, or None (before 5.0 a tree can exist
    with use_nodes off, and then it is not used; 5.0 deprecates use_nodes: always on)."""
    if idblock is None or idblock.node_tree is None:
        return None
    return idblock.node_tree if getattr(idblock, "use_nodes", True) else None


# Sky Texture types that draw a sun disc (5.0 split Nishita into single and multiple scattering).
SKY_TYPES_WITH_SUN_DISC = frozenset({"NISHITA", "SINGLE_SCATTERING", "MULTIPLE_SCATTERING"})


def set_modifier_input(modifier, identifier: str, value) -> None:
    """Set a Geometry Nodes modifier's group input (5.3 moved them from ID properties on the
    modifier to `modifier.properties.inputs.<identifier>.value`)."""
    properties = getattr(modifier, "properties", None)
    inputs = getattr(properties, "inputs", None)
    if inputs is not None and hasattr(inputs, identifier):
        getattr(inputs, identifier).value = value
    else:
        modifier[identifier] = value


def modifier_input_values(modifier) -> list:
    """The values of a Geometry Nodes modifier's group inputs (see set_modifier_input)."""
    properties = getattr(modifier, "properties", None)
    inputs = getattr(properties, "inputs", None)
    if inputs is not None:
        group = modifier.node_group
        items = group.interface.items_tree if group is not None else ()
        return [getattr(inputs, item.identifier).value for item in items
                if getattr(item, "in_out", None) == "INPUT" and hasattr(inputs, item.identifier)
                and hasattr(getattr(inputs, item.identifier), "value")]
    return [modifier[key] for key in modifier.keys()]


def append_on_import(library) -> str:
    """Make an asset library append what is dragged from it (editable local data the add-on can
    hand lamps to), reusing earlier appends where Blender offers it: Append (Reuse Data), the
    4.2-5.0 default; 5.3 makes new libraries Pack (linked, read-only data packed into the file)
    by default and takes only Link, Append or Pack. Returns the method set."""
    for method in ("APPEND_REUSE", "APPEND"):
        try:
            library.import_method = method
            return method
        except TypeError:
            continue
    return library.import_method
