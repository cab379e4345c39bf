"""Section "specialization": what `addon.specialize` gains on the look-dev scene of `make demo`
(Suzanne on a floor under a sky, a sun and an area lamp): render time and peak memory with and
without it, side by side in one run.

The file is set up as an artist's would be: every Microfacet Lab node group is in it (added
from the menu once, kept by a fake user), Blender's default bounces. Specialization then
compiles only the models the scene renders, removes the unused groups and their texts, and sets
the bounces of lobe kinds no material has to 0 (docs: addon/specialize.py). The lamp table is
specialized in both cases (only the scene's lamps are compiled in, addon/handover.py), so it is
not part of the difference. The two variants alternate, `repeats` times each, so that drift of
the machine falls on both.
"""
from __future__ import annotations

import re
import time

import numpy as np

from ...catalog import MODELS

# (label, preset): a material without transmission (where specialization can zero a kind of
# bounce) and one with it.
CASES = (("gold (Walter GGX)", "gold"), ("rough glass (Walter GGX)", "rough_glass"))
# Cycles' render statistics read "Mem: 66M | Sample 4/16" (some versions add "Peak: ...").
_PEAK = re.compile(r"(?:Mem|Peak)[: ]+([0-9.]+)\s*([KMG])", re.I)
_UNIT = {"K": 1.0 / 1024.0, "M": 1.0, "G": 1024.0}


def _peak_mib(stats: list) -> float:
    """The largest memory Cycles reported in its render statistics, MiB (nan if none)."""
    peaks = [float(m.group(1)) * _UNIT[m.group(2).upper()] for s in stats
             for m in _PEAK.finditer(s)]
    return max(peaks) if peaks else float("nan")


def _render(case_preset, specialized: bool, samples: int, size: tuple):
    import bpy

    from ... import nodes, presets, specialize
    from .. import harness, lookdev

    p = presets.find(case_preset)
    scene = lookdev.build_view(lambda: harness.model_material(p.model_id, p.params, p.id), *size)
    for model in MODELS.values():  # every group in the file, as after using the Add menu
        nodes.ensure_group(model.id).use_fake_user = True
    scene.cycles.samples = samples
    report = specialize.specialize(scene) if specialized else None
    stats = []

    def collect(*args):
        stats.extend(a for a in args if isinstance(a, str))

    bpy.app.handlers.render_stats.append(collect)
    try:
        start = time.perf_counter()
        harness.render(scene)
        seconds = time.perf_counter() - start
    finally:
        bpy.app.handlers.render_stats.remove(collect)
    return {"seconds": seconds, "peak_mib": _peak_mib(stats),
            "groups": sum(1 for g in bpy.data.node_groups if g.name.startswith("Microfacet Lab")),
            "report": report.lines() if report else None}


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    samples, size, repeats = {"full": (64, (240, 180), 3), "quick": (16, (160, 120), 2)}.get(
        cfg.mode, (4, (48, 36), 1))
    results = []
    for label, preset in CASES[:1] if cfg.mode == "smoke" else CASES:  # smoke: one compile
        runs = {False: [], True: []}
        for _ in range(repeats):
            for specialized in (False, True):
                runs[specialized].append(_render(preset, specialized, samples, size))
        entry = {"case": label, "samples": samples, "size": size, "repeats": repeats}
        for specialized, key in ((False, "plain"), (True, "specialized")):
            r = runs[specialized]
            entry[key] = {"seconds": [x["seconds"] for x in r],
                          "peak_mib": [x["peak_mib"] for x in r], "groups": r[-1]["groups"]}
        entry["report"] = runs[True][-1]["report"]
        results.append(entry)
        progress(f"specialization: {label}: {np.median(entry['plain']['seconds']):.2f} s -> "
                 f"{np.median(entry['specialized']['seconds']):.2f} s")
    return {"specialization": results}


def page(cfg, rows, res) -> list:
    data = res.get("specialization")
    if not data:
        return []
    lines = ["## Scene specialization on the look-dev scene", "",
             "Render time (median of the repeats, wall clock of the render call, scene sync and "
             "OSL JIT included) and Cycles' peak memory, without and with `addon.specialize`, "
             "alternating in one run. The file holds every Microfacet Lab node group, as after "
             "using the Add menu once; Blender's default bounces.", "",
             "| material | samples, size | time without | time with | ratio | peak MiB without "
             "| peak MiB with | groups without / with |", "|---|---|---|---|---|---|---|---|"]
    for e in data:
        t0, t1 = np.median(e["plain"]["seconds"]), np.median(e["specialized"]["seconds"])
        m0, m1 = np.nanmax(e["plain"]["peak_mib"]), np.nanmax(e["specialized"]["peak_mib"])
        lines.append(f"| {e['case']} | {e['samples']}, {e['size'][0]}x{e['size'][1]} | "
                     f"{t0:.2f} s | {t1:.2f} s | {t1 / t0:.2f} | {m0:.1f} | {m1:.1f} | "
                     f"{e['plain']['groups']} / {e['specialized']['groups']} |")
    lines += ["", "What specialization changed (last run of each material):", ""]
    for e in data:
        lines.append(f"- {e['case']}: " + "; ".join(e["report"] or []))
    return lines + [""]
