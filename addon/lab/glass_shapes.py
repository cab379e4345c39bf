"""The ball and the bowl of addon/lab/glass_trace.py, built and rendered in Cycles.

A smooth UV sphere (256 x 128 segments) of radius 1 at the origin, or its lower half, under the
grid's orthographic camera and environment, with world light sampling off (Cycles' rough glass
returns more than 1 in a white furnace with it on; harness.add_world) and every ray type seeing
the object, so light enters, bounces inside and leaves as in a real scene.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from . import harness
from .glass_trace import layout
from .grid import GridLayout

SEGMENTS, RINGS = 256, 128


def uv_sphere(segments: int = SEGMENTS, rings: int = RINGS):
    """Vertices and faces of a unit UV sphere (a pole at each end, `rings` - 1 rings of
    `segments` vertices, quads between rings, triangle fans at the poles), wound outward.
    bmesh.ops.create_uvsphere builds the same tessellation but takes 1.7 s at 256 x 128."""
    polar = np.pi * np.arange(1, rings) / rings
    azimuth = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(polar), np.cos(azimuth)),
                     np.outer(np.sin(polar), np.sin(azimuth)),
                     np.repeat(np.cos(polar)[:, None], segments, axis=1)], axis=-1)
    verts = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    top, bottom = 0, len(verts) - 1
    index = 1 + np.arange((rings - 1) * segments).reshape(rings - 1, segments)
    after = np.roll(index, -1, axis=1)  # the next vertex of the same ring
    faces = [(top, index[0, j], after[0, j]) for j in range(segments)]
    faces += [(index[k, j], index[k + 1, j], after[k + 1, j], after[k, j])
              for k in range(rings - 2) for j in range(segments)]
    faces += [(index[-1, j], bottom, after[-1, j]) for j in range(segments)]
    return verts, faces


def add_shape(scene, shape: str, material):
    verts, faces = uv_sphere()
    if shape == "bowl":  # the lower half, the equator ring included
        keep = verts[:, 2] <= 1e-6
        renumber = np.cumsum(keep) - 1
        faces = [tuple(renumber[list(f)]) for f in faces if keep[list(f)].all()]
        verts = verts[keep]
    mesh = bpy.data.meshes.new(shape)
    mesh.from_pydata(verts.tolist(), [], [tuple(int(i) for i in f) for f in faces])
    mesh.validate()
    mesh.shade_smooth()
    mesh.materials.append(material)
    obj = bpy.data.objects.new(shape, mesh)
    scene.collection.objects.link(obj)
    return obj


def add_plane(scene, name: str, x: float, tilt: float, back_facing: bool, material):
    """A 1.8 x 1.8 square centred at (x, 0, 0), its normal tilted by `tilt` radians from +z
    (toward the camera) about the x axis, or away from the camera with `back_facing` (the
    same square wound the other way). Invisible to secondary rays: what it reflects or
    refracts sees the world, as a sphere of the grid does."""
    c, s = math.cos(tilt), math.sin(tilt)
    corners = [(x + px, py * c, py * s) for px, py in ((-0.9, -0.9), (0.9, -0.9), (0.9, 0.9),
                                                        (-0.9, 0.9))]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(corners, [], [(3, 2, 1, 0) if back_facing else (0, 1, 2, 3)])
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    for ray in ("diffuse", "glossy", "transmission", "shadow", "volume_scatter"):
        setattr(obj, f"visible_{ray}", False)
    scene.collection.objects.link(obj)
    return obj


def glass_node_material(roughness: float, ior: float):
    """Cycles' own Glass BSDF (GGX): the same BSDF as walter_glass with height-correlated
    masking, handled on back faces by Blender itself."""
    material, tree, output = harness.new_material(f"Cycles glass {roughness} {ior}")
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.distribution = "GGX"
    glass.inputs["Roughness"].default_value = roughness
    glass.inputs["IOR"].default_value = ior
    tree.links.new(glass.outputs["BSDF"], output.inputs["Surface"])
    return material


def render_shape(shape: str, make_material, env, size_px: int, samples: int, seeds,
                 max_bounces: int = 64) -> list:
    """Render the shape with the material `make_material()` builds (called after the scene is
    reset) at each of `seeds`, its OSL compiled once; returns the images (size_px, size_px, 4)."""
    view = layout(size_px)
    scene = harness.new_scene()
    harness.configure_render(scene, view, samples, seeds[0], max_bounces)
    harness.add_world(scene, env, light_sampling=False)
    harness.add_camera(scene, view)
    add_shape(scene, shape, make_material())
    harness.check_compiled()
    return harness.render_each_seed(scene, seeds)


def render_plane_pair(make_front, make_back, tilt: float, env, samples: int, seed: int):
    """Two planes at the same tilt in one render, the left facing the camera with the material
    `make_front()` builds, the right facing away with `make_back()`'s. Returns the
    pixels of each (n, 3): the middle of each square, away from its edges."""
    view = GridLayout(rows=1, cols=2, cell_px=48)
    scene = harness.new_scene()
    harness.configure_render(scene, view, samples, seed, max_bounces=8)
    harness.add_world(scene, env, light_sampling=False)
    harness.add_camera(scene, view)
    add_plane(scene, "front", -1.1, tilt, False, make_front())
    add_plane(scene, "back", 1.1, tilt, True, make_back())
    harness.check_compiled()
    image, _ = harness.render(scene)
    h, w = image.shape[:2]
    rows = slice(h // 2 - 8, h // 2 + 8)  # inside the squares up to a 60-degree tilt
    return (image[rows, 12:36, :3].reshape(-1, 3), image[rows, w - 36:w - 12, :3].reshape(-1, 3))
