"""Section 4, stability on stiff and extreme inputs: runs the numpy sweep and the OSL stress
grid of addon/lab/stability.py (which does the work) and writes their page text."""
from __future__ import annotations

from .. import stability
from ...catalog import MODELS
from .scenes import add_sun


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    """The numpy sweep, then (unless in smoke mode) the OSL stress grid per environment."""
    progress("numpy stability sweep")
    sweep = stability.numpy_sweep(albedo_samples=cfg.albedo_samples, stride=cfg.sweep_stride,
                                  progress=progress, combo_seconds=cfg.combo_seconds,
                                  model_seconds=cfg.model_seconds)
    tot = sweep["_total"]
    progress(f"numpy sweep: {tot.cases:,} cases, NaN {tot.nan}, Inf {tot.inf}, negative "
             f"{tot.negative}, energy {tot.energy}")
    stress = []
    if cfg.stress != "none":
        for env_key in ("gradient", "sun"):
            progress(f"OSL stress grid under {env_key}")
            s = stability.osl_stress_grid(env_key, quick=cfg.stress == "quick",
                                          sun=add_sun if env_key == "sun" else None)
            progress(f"OSL stress grid {env_key}: {s.spheres} spheres, NaN {s.nan}, Inf "
                     f"{s.inf}, negative {s.negative}")
            stress.append(s)
    else:
        notes.append("smoke mode: the OSL stress grid is not rendered.")
    return {"sweep": sweep, "stress": stress}


def page(cfg, rows, res) -> list:
    """Section 4's Markdown lines ([] when it was not run)."""
    return sweep_lines(cfg, res.get("sweep")) + stress_lines(res.get("stress") or [])


def sweep_lines(cfg, sweep) -> list:
    if not sweep:
        return []
    tot = sweep["_total"]
    L = ["## 4. Stability on stiff and extreme inputs\n",
         f"numpy sweep (`addon/lab/stability.py`): {tot.cases:,} cases ({tot.eval_cases:,} evaluations "
         f"f and f cos, {tot.sample_cases:,} samples) and {tot.albedo_tests:,} Monte Carlo albedo "
         f"tests ({cfg.albedo_samples} samples each, energy violation when the albedo exceeds 1 "
         f"by more than {sweep['_z_crit']:.2f} standard errors) over {tot.combos:,} parameter "
         "combinations: roughness 0, 1e-9, around the alpha = 1e-7 delta threshold, 1e-3 .. 1, "
         "beyond 1 and NaN (clamped by the catalog), eta in {1, 1 +- 1e-6, 0.1, 10, 100, 0, NaN}, "
         "conductor n, k extremes, every enum; incidence up to 90 deg - 1e-6 and 90; wo = wi, "
         "wo ~ wi, the mirror, wo.h -> 0, grazing wo, both hemispheres; uniforms at 0 and "
         "1 - 2^-53.\n",
         "| model | combinations | cases | NaN | Inf | negative | non-unit wo | energy violations | exceptions | max albedo | time (s) |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    sweep_notes = []
    for k, rec in sweep.items():
        if k.startswith("_"):
            continue
        L.append(_sweep_row(k, rec))
        extra = _sweep_note(cfg, rec)
        if extra:
            sweep_notes.append(f"{MODELS[k].label}:{extra}")
    L.append(f"| **all** | {tot.combos} | {tot.cases:,} | **{tot.nan}** | **{tot.inf}** | "
             f"**{tot.negative}** | {tot.non_unit} | **{tot.energy}** | **{tot.errors}** | "
             f"{tot.max_albedo:.4f} | {tot.seconds:.1f} |")
    L.append("")
    L += [f"- {n}" for n in sweep_notes]
    L.append("")
    if tot.examples:
        L += ["First offending inputs:\n", "```"] + list(tot.examples[:20]) + ["```\n"]
    return L


def _sweep_row(k, rec) -> str:
    """A model's row of the sweep table."""
    if rec.skipped:
        return f"| {MODELS[k].label} | skipped: {rec.skipped} | | | | | | | | | |"
    return (f"| {MODELS[k].label} | {rec.combos} | {rec.cases:,} | {rec.nan} | {rec.inf} | "
            f"{rec.negative} | {rec.non_unit} | {rec.energy} | {rec.errors} | {rec.max_albedo:.4f} | "
            f"{rec.seconds:.1f} |")


def _sweep_note(cfg, rec) -> str:
    """What a model's row does not say: unsupported eval, timeouts, a spent budget ('' if none)."""
    if rec.skipped:
        return ""
    return ((f" eval not implemented for {rec.unsupported} combinations (sampled "
             "only)." if rec.unsupported else "")
            + (f" {rec.timeouts} combinations slower than the per-combination limit "
               f"of {cfg.combo_seconds:g} s (listed below)." if rec.timeouts else "")
            + (f" Time budget ({cfg.model_seconds:g} s) spent: {rec.budget_stop} "
               "combinations not run." if rec.budget_stop else ""))


def stress_lines(stress) -> list:
    if not stress:
        return []
    L = ["OSL stress grid: the same kinds of extremes through the shaders, values fed by linked "
         "Value nodes (bypassing the sockets' ranges); every sphere's rim is a grazing view.\n",
         "| environment | spheres | sphere pixels | NaN pixels | Inf pixels | negative pixels | render (s) |",
         "|---|---|---|---|---|---|---|"]
    for s in stress:
        L.append(f"| {s.env} | {s.spheres} | {s.pixels:,} | **{s.nan}** | **{s.inf}** | "
                 f"**{s.negative}** | {s.seconds:.1f} |")
    skipped = {m: w for s in stress for m, w in s.skipped.items()}
    for m, w in skipped.items():
        L.append(f"\n{MODELS[m].label}: not in the stress grid ({w}).")
    bad = [b for s in stress for b in s.bad]
    for b in bad[:20]:
        L.append(f"\n- bad sphere: {b[0]} {stability.describe(b[1])}: NaN {b[2]}, Inf {b[3]}, "
                 f"negative {b[4]}")
    L.append("")
    return L
