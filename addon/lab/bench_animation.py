"""What the add-on costs an animation (`make bench-animation`; scripts/bench_animation.py).

The look-dev scene (addon/lab/lookdev.py: Suzanne on a floor) with a Microfacet Lab preset,
under an HDRI world (a synthetic equirectangular EXR with a sun, written here: no outside
assets), a sun lamp that turns and an area lamp that moves over the frames. The animation is
rendered twice in one process, side by side:

- "hand-over": the add-on as it ships, its render_pre handler handing the lamps of each frame
  to the shaders (addon/handover.py);
- "static": the same frames with the handler removed after the first frame, so the shaders keep
  frame 1's lamp table (they stay exact, only noisier where the lamps moved).

The difference of the two totals is what the hand-over costs (its own Python, the OSL
recompiles and Cycles' shader rebuilds they cause), given per frame and as a share of a frame.
The HDRI's bright-spot search is measured on its own: time and the memory it allocates
(tracemalloc sees numpy's buffers) against the image's own size (width x height x 4 floats).
"""
from __future__ import annotations

import math
import tempfile
import time
import tracemalloc
from pathlib import Path

import bpy
import numpy as np

from .. import handover, preset_ui, world_lights
from ..presets import find
from . import lookdev

SUN_DIRECTION = (0.3, -0.5, 0.81)  # the HDRI's sun (toward it, world space)


def write_hdri(path, width: int) -> Path:
    """An equirectangular sky (blue zenith, bright horizon) with a 0.53-degree sun of about
    10^5 times the sky's radiance, as a float EXR of width x width/2 pixels."""
    height = width // 2
    rows = (np.arange(height) + 0.5) / height  # v, row 0 at the bottom (Blender's order)
    cols = (np.arange(width) + 0.5) / width
    z = np.cos(math.pi * (1.0 - rows))[:, None]
    phi = math.pi - 2.0 * math.pi * cols[None, :]
    st = np.sqrt(1.0 - z * z)
    d = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), z), -1)
    sun = np.asarray(SUN_DIRECTION) / np.linalg.norm(SUN_DIRECTION)
    in_sun = d @ sun >= math.cos(math.radians(0.265))
    sky = np.where(z > 0, 0.3 + 0.5 * (1 - z), 0.2)
    image = bpy.data.images.new("bench hdri", width, height, alpha=True, float_buffer=True)
    rgba = np.empty((height, width, 4), dtype=np.float32)
    rgba[..., 0] = sky * 0.8
    rgba[..., 1] = sky * 0.9
    rgba[..., 2] = sky * 1.2
    rgba[..., 3] = 1.0
    rgba[in_sun, :3] = 4.0e4
    del d, in_sun
    image.pixels.foreach_set(rgba.ravel())
    del rgba
    image.filepath_raw = str(path)
    image.file_format = "OPEN_EXR"
    image.save()
    bpy.data.images.remove(image)
    return Path(path)


def set_hdri_world(scene, path):
    world = bpy.data.worlds.new("bench HDRI")
    world.use_nodes = True
    tree = world.node_tree
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = bpy.data.images.load(str(path))
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    tree.links.new(texture.outputs["Color"], background.inputs["Color"])
    scene.world = world
    return texture.image


def animate_lamps(scene, frames: int):
    """The sun turns 60 degrees in azimuth, the area lamp slides 3 m, from frame 1 to `frames`."""
    sun, area = bpy.data.objects["Sun"], bpy.data.objects["Area"]
    scene.frame_start, scene.frame_end = 1, frames
    for frame, turn, slide in ((1, 0.0, 0.0), (frames, math.radians(60.0), 3.0)):
        sun.rotation_euler[2] = turn
        sun.keyframe_insert("rotation_euler", index=2, frame=frame)
        area.location[0] = 2.5 - slide
        area.keyframe_insert("location", index=0, frame=frame)


def _rss_peak_reset():
    """Reset the process's peak resident memory (Linux); its current size in bytes, or None."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return _status("VmRSS")
    except OSError:
        return None


def _status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))


def spot_search(image) -> dict:
    """The HDRI bright-spot search alone, uncached: seconds, the peak memory it allocates in
    Python and numpy (tracemalloc), and the process's peak resident growth (which also counts
    an image Blender loads, and OpenImageIO's buffers), against the image's own (RGBA float)."""
    world_lights._IMAGE_CACHE.clear()
    image.buffers_free()
    rss = _rss_peak_reset()
    tracemalloc.start()
    start = time.perf_counter()
    spots = world_lights.image_spots(image)
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    grew = None if rss is None else _status("VmHWM") - rss
    own = image.size[0] * image.size[1] * 4 * 4
    return {"size": tuple(image.size), "seconds": seconds, "peak_mb": peak / 2**20,
            "image_mb": own / 2**20, "share": peak / own, "spots": len(spots),
            "rss_mb": None if grew is None else grew / 2**20,
            "route": "packed" if image.packed_file is not None else "file"}


class _FrameClock:
    """render_pre / render_post handlers timing each frame, and hand_over's own time: before a
    frame (handover) and when the job is done and the lamps' prediction is withdrawn
    (withdraw)."""

    def __init__(self):
        self.frames, self.handover, self.withdraw = [], [], []
        self._start = None
        self._real_hand_over = handover.hand_over

    def _timed_hand_over(self, *args, **kwargs):
        start = time.perf_counter()
        try:
            return self._real_hand_over(*args, **kwargs)
        finally:
            seconds = time.perf_counter() - start
            (self.handover if kwargs.get("predict", True) else self.withdraw).append(seconds)

    def pre(self, *_):
        self._start = time.perf_counter()

    def post(self, *_):
        self.frames.append(time.perf_counter() - self._start)

    def __enter__(self):
        bpy.app.handlers.render_pre.insert(0, self.pre)
        bpy.app.handlers.render_post.append(self.post)
        handover.hand_over = self._timed_hand_over
        return self

    def __exit__(self, *exc):
        handover.hand_over = self._real_hand_over
        bpy.app.handlers.render_pre.remove(self.pre)
        bpy.app.handlers.render_post.remove(self.post)


def render_animation(scene, out_dir, static: bool) -> dict:
    scene.render.filepath = str(Path(out_dir) / ("static_" if static else "live_"))
    scene.render.image_settings.file_format = "PNG"
    handler = handover._on_render_pre

    def drop_after_first(*_):
        if handler in bpy.app.handlers.render_pre:
            bpy.app.handlers.render_pre.remove(handler)

    if static:
        bpy.app.handlers.render_post.append(drop_after_first)
    try:
        with _FrameClock() as clock:
            start = time.perf_counter()
            bpy.ops.render.render(animation=True)
            total = time.perf_counter() - start
    finally:
        if drop_after_first in bpy.app.handlers.render_post:
            bpy.app.handlers.render_post.remove(drop_after_first)
        handover.register()
    return {"total": total, "frames": clock.frames, "handover": clock.handover,
            "withdraw": clock.withdraw}


def typical_frame(hdri, preset: str, width: int = 1280, height: int = 720,
                  samples: int = 32) -> float:
    """Seconds to render one frame of the same scene at a production-like size, for scale."""
    scene = lookdev.build_view(lambda: preset_ui.new_material(find(preset)), width, height)
    set_hdri_world(scene, hdri)
    scene.cycles.samples = samples
    scene.render.filepath = str(Path(hdri).parent / "typical.png")
    scene.render.image_settings.file_format = "PNG"
    handover.hand_over(scene)
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - start


def run(frames: int = 100, width: int = 96, height: int = 54, samples: int = 4,
        preset: str = "rough_gold_lee", hdri_widths=(4096, 8192), typical=(1280, 720, 32),
        log=print) -> dict:
    """The benchmark; returns its figures (scripts/bench_animation.py prints them)."""
    out = {"frames": frames, "size": (width, height), "samples": samples, "preset": preset}
    with tempfile.TemporaryDirectory() as tmp:
        spots = []
        for hdri_width in hdri_widths:
            scene = lookdev.build_view(lambda: preset_ui.new_material(find(preset)), width, height)
            image = set_hdri_world(scene, write_hdri(Path(tmp) / f"sky{hdri_width}.exr", hdri_width))
            spots.append(spot_search(image))
            image.pack()  # a packed image has no file to read in bands: Blender's pixels are copied
            spots.append(spot_search(image))
            for s in spots[-2:]:
                log(f"[animation] HDRI {s['size']} ({s['route']}): {s['spots']} spot(s), "
                    f"{s['seconds']:.2f} s, numpy peak {s['peak_mb']:.0f} MB = {s['share']:.2f} x "
                    f"the image, resident peak +{s['rss_mb']:.0f} MB")
        out["spot_search"] = spots
        # The animation under the smaller HDRI (its spots are cached after the first frame).
        scene = lookdev.build_view(lambda: preset_ui.new_material(find(preset)), width, height)
        set_hdri_world(scene, Path(tmp) / f"sky{hdri_widths[0]}.exr")
        scene.cycles.samples = samples
        animate_lamps(scene, frames)
        handover.register()
        runs = {}
        for static in (False, True):
            runs["static" if static else "live"] = render_animation(scene, tmp, static)
            log(f"[animation] {'static' if static else 'hand-over'}: "
                f"{runs['static' if static else 'live']['total']:.1f} s for {frames} frames")
        out.update(runs)
        if typical:
            out["typical"] = (*typical, typical_frame(Path(tmp) / f"sky{hdri_widths[0]}.exr",
                                                      preset, *typical))
            log(f"[animation] one {typical[0]}x{typical[1]} frame at {typical[2]} spp: "
                f"{out['typical'][3]:.1f} s")
    live, static = out["live"], out["static"]
    out["overhead_per_frame"] = (live["total"] - static["total"]) / frames
    out["handover_per_frame"] = float(np.mean(live["handover"]))
    out["frame"] = static["total"] / frames
    out["overhead_share"] = out["overhead_per_frame"] / out["frame"]
    if typical:
        out["typical_share"] = out["overhead_per_frame"] / out["typical"][3]
    return out
