"""Section "lookdev": samples and time for equal noise against Cycles' closest native closure on
the look-dev scene (addon/lab/lookdev.py: Suzanne on a floor under the sky, Blender's defaults),
per preset and light: one lamp beside the sky (a 1-degree sun, the area lamp, a point lamp in
the area lamp's place), the sky alone, or an HDRI of the sky with a 1-degree sun in its pixels
(no lamp: the add-on hands the sun over as for F12).

- Noise: each material renders at the same sample count with two seeds; the per-pixel variance
  is (a - b)^2 / 2, averaged over Suzanne's pixels and the channels (a mask rendered with
  Suzanne emitting 1 and nothing else lit). Variance falls as 1 / samples, so the samples for
  equal noise are var_ours / var_native.
- Cost per sample: the render call at the full sample count less one at 1 sample (scene sync
  and OSL JIT cancel), over the samples in between. Time for equal noise: the samples ratio
  times the cost ratio.
- The lamps are handed over as for F12 (harness.render). A low sample count flatters an
  estimator whose rare heavy samples have not happened yet: its variance is a lower bound
  there (docs/light-sampling-proofs.md, "rare heavy samples").
"""
from __future__ import annotations

import numpy as np

from ... import presets
from ...catalog import MODELS

# (preset, Cycles' closest native material: lookdev.native_material's kind)
PAIRS = (("gold", "metallic"), ("gold_cook_torrance", "metallic_beckmann"),
         ("nickel", "metallic_beckmann"), ("rough_gold_lee", "metallic_multiscatter"),
         ("rough_aluminium_lee", "metallic_multiscatter"),
         ("rough_gold_heitz", "metallic_multiscatter"), ("rough_glass_heitz", "glass_multiscatter"))
LIGHTS = ("sun", "area", "point", "hdri", "sky")
SUN_ANGLE_DEG = 1.0
MASK_SAMPLES = 16


def _settings(mode):
    """(samples, (width, height), pairs, lights) of a mode."""
    if mode == "full":
        return 64, (240, 180), PAIRS, LIGHTS
    if mode == "quick":
        return 16, (160, 120), PAIRS, LIGHTS
    return 4, (64, 48), PAIRS[:1], LIGHTS[:1]


def _lamps(light):
    from .. import lookdev

    return {"sun": lambda scene: lookdev.add_sun(scene, SUN_ANGLE_DEG), "area": lookdev.add_area,
            "point": lookdev.add_point, "hdri": lookdev.add_hdri_sky,
            "sky": lambda scene: None}[light]


def _render(make, size, samples, seed, light):
    from .. import harness, lookdev

    scene = lookdev.build_view(make, *size, seed=seed, lamps=_lamps(light))
    scene.cycles.samples = samples
    harness.check_compiled()
    image, seconds = harness.render(scene)
    return np.asarray(image)[..., :3], seconds


def suzanne_mask(size) -> np.ndarray:
    """True on the pixels that see Suzanne alone: Suzanne emits 1, the sky is off, no lamps."""
    from .. import harness, lookdev

    def make():
        material, tree, output = harness.new_material("mask")
        emission = tree.nodes.new("ShaderNodeEmission")
        tree.links.new(emission.outputs[0], output.inputs["Surface"])
        return material

    scene = lookdev.build_view(make, *size, lamps=lambda s: None)
    for node in scene.world.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Strength"].default_value = 0.0
    scene.cycles.samples = MASK_SAMPLES
    image, _ = harness.render(scene)
    return np.asarray(image)[..., :3].min(axis=-1) > 0.999


def measure(make, size, samples, light, mask) -> dict:
    """Noise (variance per sample count) and cost per sample of one material under one light."""
    a, t0 = _render(make, size, samples, 0, light)
    b, t1 = _render(make, size, samples, 1, light)
    _, t_one = _render(make, size, 1, 2, light)
    variance = 0.5 * (a - b) ** 2
    extra = 0.5 * (t0 + t1) - t_one  # not positive where the samples cost less than the noise
    return {"variance": float(variance[mask].mean()), "mean": float(0.5 * (a + b)[mask].mean()),
            "per_sample": extra / (samples - 1) if extra > 0 and samples > 1 else float("nan"),
            "finite": bool(np.isfinite(a).all() and np.isfinite(b).all())}


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    from .. import harness, lookdev

    samples, size, pairs, lights = _settings(cfg.mode)
    mask = suzanne_mask(size)
    entries = []
    for preset_id, kind in pairs:
        preset = presets.load_all()[preset_id]
        values = MODELS[preset.model_id].resolve(preset.params)
        ours = (lambda: harness.model_material(preset.model_id, values, preset_id))
        native = (lambda: lookdev.native_material(kind, values))
        for light in lights:
            m_ours = measure(ours, size, samples, light, mask)
            m_native = measure(native, size, samples, light, mask)
            ratio = m_ours["variance"] / max(m_native["variance"], 1e-30)
            cost = m_ours["per_sample"] / m_native["per_sample"]
            entries.append({"preset": preset_id, "model": preset.model_id, "native": kind,
                            "light": light, "ours": m_ours, "native_measure": m_native,
                            "samples_ratio": ratio, "cost_ratio": cost,
                            "time_ratio": ratio * cost})
            progress(f"lookdev: {preset_id} vs {kind} under {light}: x{ratio:.2f} samples, "
                     f"x{ratio * cost:.2f} time for equal noise")
    return {"lookdev": {"samples": samples, "size": list(size), "mask_pixels": int(mask.sum()),
                        "sun_angle_deg": SUN_ANGLE_DEG, "entries": entries}}


def _cell(e) -> str:
    time = f"x{e['time_ratio']:.1f}" if np.isfinite(e["time_ratio"]) else "time -"
    return f"x{e['samples_ratio']:.1f} ({time})"


def page(cfg, rows, res) -> list:
    data = res.get("lookdev")
    if not data:
        return []
    lights = list(dict.fromkeys(e["light"] for e in data["entries"]))
    names = {"sun": f"{data['sun_angle_deg']:g}-degree sun", "area": "area lamp",
             "point": "point lamp", "hdri": "HDRI with a 1-degree sun", "sky": "sky only"}
    lines = ["## Look-dev: samples for equal noise against Cycles' closest closure", "",
             f"Suzanne on a floor under the sky ({data['size'][0]} x {data['size'][1]} px, "
             f"{data['samples']} samples, Blender's defaults), one light beside the sky. Each "
             "cell: the samples ours needs for the noise of Cycles' closure (the ratio of the "
             "per-pixel variances over Suzanne's "
             f"{data['mask_pixels']} pixels, from two seeds each), and in brackets the time "
             "(that ratio times the ratio of the cost per sample; - where the samples cost less "
             "than the timer's noise).", "",
             "| preset | against | " + " | ".join(names[k] for k in lights) + " |",
             "|---|---|" + "---|" * len(lights)]
    by_pair = {}
    for e in data["entries"]:
        by_pair.setdefault((e["preset"], e["native"]), {})[e["light"]] = e
    for (preset_id, kind), cells in by_pair.items():
        row = [_cell(cells[k]) if k in cells else "-" for k in lights]
        lines.append(f"| {preset_id} | {kind} | " + " | ".join(row) + " |")
    return lines + [""]
