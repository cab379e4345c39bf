"""`run`: the sections in order, then the page, results.json and the README figures."""
from __future__ import annotations

import json
import math
import shutil
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from . import (convergence, fallback, lee, lookdev_noise, multiple_scattering, native_share,
               reference_cost, samplers, specialization, stability_section)
from .config import SECTIONS, Progress, config
from .machine import header_lines, machine_info
from .page import write_page
from .references import ReferenceTables
from .rows import build_rows

# (name in --sections, module): each module's compute() measures and plots, page() writes.
SECTION_MODULES = (("convergence", convergence), ("share", native_share), ("samplers", samplers),
                   ("refcost", reference_cost), ("stability", stability_section), ("lee", lee),
                   ("specialization", specialization), ("comparisons", multiple_scattering),
                   ("fallback", fallback), ("lookdev", lookdev_noise))
README_FIGURES = ("rmse_vs_time.png", "sampler_weights.png", "fireflies.png", "fallback.png")


def run(mode: str = "full", out_dir="report", figures_dir=None, progress=None,
        sections=SECTIONS, rows=(), envs=()) -> dict:
    """`rows`: words, of which a convergence row's variant must contain one (all rows if
    empty); `envs`: the environments run (the mode's if empty)."""
    words = tuple(rows)
    progress = progress or Progress()
    cfg = config(mode)
    unknown = set(envs) - set(cfg.envs)
    if unknown:
        raise ValueError(f"unknown environments {sorted(unknown)}: {mode} runs {cfg.envs}")
    if envs:
        cfg = replace(cfg, envs=tuple(e for e in cfg.envs if e in envs))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    info = machine_info()
    progress(f"mode {mode}: {info['cpu']}, {info['cores']} cores, Blender {info.get('blender')}, "
             f"numpy {info['numpy']}, Python {info['python']}")
    notes = []
    rows = [r for r in build_rows(notes) if not words or any(w in r.variant for w in words)]
    for n in notes:
        progress(n)
    tables = ReferenceTables(cfg.moment_order, cfg.walk_moments)
    res = {}
    for name, module in SECTION_MODULES:
        if name in sections:
            res.update(module.compute(cfg, rows, tables, progress, notes, out))
    total = time.perf_counter() - start
    write_page(out / "report.md", header_lines(cfg, info, notes, res.get("gpu"), total),
               [module.page(cfg, rows, res) for _, module in SECTION_MODULES])
    results = results_json(mode, info, notes, total, res)
    (out / "results.json").write_text(json.dumps(_jsonable(results), indent=1))
    if figures_dir:
        copy_figures(out, Path(figures_dir))
    progress(f"wrote {out / 'report.md'} ({total:.0f} s)")
    return results


def results_json(mode, info, notes, total, res) -> dict:
    """What results.json holds (before `_jsonable`): the numbers of every section, no images."""
    conv, study, ff = res.get("conv"), res.get("study"), res.get("ff")
    sweep, stress, lee_res = res.get("sweep"), res.get("stress") or [], res.get("lee")
    return {"mode": mode, "machine": info, "notes": notes, "seconds": total,
            "time_to_target": res.get("table"), "sun_calibration": res.get("sun_cal"),
            "native_share": res.get("native_share"), "specialization": res.get("specialization"),
            "comparisons": res.get("comparisons"), "fallback": res.get("fallback"),
            "lookdev": res.get("lookdev"),
            "reference_cost": res.get("refcost"), "gpu": res.get("gpu"),
            "convergence": {e: d["series"] for e, d in conv["envs"].items()} if conv else None,
            "sampler_study": {m: {f"{s} r={r}": v for (s, r), v in by_sampler.items()}
                              for m, by_sampler in (study or {}).items()},
            "fireflies": ff["stats"] if ff else None,
            "stability": {k: v for k, v in (sweep or {}).items()},
            "osl_stress": [{k: v for k, v in asdict(s).items() if k not in ("image", "layout")}
                           for s in stress],
            "lee": ({k: ({kk: vv for kk, vv in v.items() if kk not in ("image", "layout")}
                         if k == "furnace" else v) for k, v in lee_res.items()}
                    if lee_res else None)}


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return None
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else str(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if hasattr(obj, "__dataclass_fields__"):
        return _jsonable({k: v for k, v in asdict(obj).items() if k not in ("image", "layout")})
    return obj


def copy_figures(out: Path, fig_dir: Path) -> None:
    """Copy the README figures that this run drew into `fig_dir` (docs/figures on a full run)."""
    fig_dir.mkdir(parents=True, exist_ok=True)
    for name in README_FIGURES:
        if (out / name).exists():
            shutil.copy(out / name, fig_dir / name)
