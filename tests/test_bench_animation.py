"""`make bench-animation` (addon/lab/bench_animation.py) runs, on a tiny scene: two frames with
and without the lamps' hand-over, and the HDRI sun search on a small image. Its figures are
timings and are not asserted; what is: the search finds the synthetic sun where it was put and
allocates less than the image, both runs render every frame, and the hand-over ran once per
frame in the first run and never after frame 1 in the second. Would catch a bench that rots
(an API it uses changes) or a search that reads the image wrongly (rows flipped, a colour
space ignored: each was seen while it was written)."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import world_lights  # noqa: E402
from addon.lab import bench_animation  # noqa: E402


def test_bench_runs_and_finds_the_sun(tmp_path):
    # Gold (Walter GGX), not the bench's rough Lee: the same hand-over and OSL, and less JIT
    # per frame (each of the four renders: 5.1 s with Lee, 2.1 s with gold, measured).
    result = bench_animation.run(frames=2, width=16, height=9, samples=1, hdri_widths=(2048,),
                                 typical=None, log=lambda *_: None, preset="gold")
    file_search, packed_search = result["spot_search"]
    assert file_search["route"] == "file" and packed_search["route"] == "packed"
    assert file_search["spots"] == packed_search["spots"] == 1
    assert file_search["share"] < 1.0
    assert len(result["live"]["frames"]) == len(result["static"]["frames"]) == 2
    assert len(result["live"]["handover"]) == 2 and len(result["static"]["handover"]) == 1
    assert len(result["live"]["withdraw"]) == len(result["static"]["withdraw"]) == 1

    # The sun is found where write_hdri put it, from the file and from Blender's pixels.
    image = bpy.data.images.load(str(bench_animation.write_hdri(tmp_path / "sky.exr", 2048)))
    sun = np.asarray(bench_animation.SUN_DIRECTION) / np.linalg.norm(bench_animation.SUN_DIRECTION)
    texels = []
    for packed in (False, True):
        if packed:
            image.pack()
        world_lights._IMAGE_CACHE.clear()
        (axis, half, power), = world_lights.image_spots(image)
        assert float(np.dot(axis, sun)) > np.cos(np.radians(1.0)), (packed, axis)
        (found,) = world_lights.image_texels(image)
        texels.append(found)
    # The spot's pixels for the shaders' prediction, read alike from the file and from Blender's
    # copy (the same box, the same linear values: rows counted from the bottom both ways; the
    # copy's values pass through Blender's colour management, 2e-5 apart as measured, where a
    # flipped row or an sRGB decoding would be far apart).
    (box, rgb, width, height), (box_p, rgb_p, width_p, height_p) = texels
    assert box == box_p and (width, height) == (width_p, height_p) == (2048, 1024)
    assert rgb.max() == pytest.approx(4.0e4, rel=1e-4) and np.allclose(rgb, rgb_p, rtol=1e-4)
