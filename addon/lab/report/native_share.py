"""Section "light sampling": the share of each model's directional albedo that the light-sampled
split hands to Cycles' native GGX closure (its Fresnel included; addon/lab/reference/split.py), per roughness and
incidence, with Monte Carlo standard errors; numpy only."""
from __future__ import annotations

import numpy as np

from ..reference import make_bsdf
from ..reference import split

ROUGHNESS = (0.2, 0.5, 0.8)
THETAS = (0.0, 45.0, 70.0, 85.0)
# (label, model, values): the presets' kinds of surface the split serves.
CASES = (
    ("Walter GGX gold, height-correlated", "walter_reflection", {"fresnel_type": "conductor"}),
    ("Walter GGX gold, separable", "walter_reflection",
     {"fresnel_type": "conductor", "masking": "separable"}),
    ("Walter GGX dielectric 1.5", "walter_reflection", {"fresnel_type": "dielectric", "ior": 1.5}),
    ("Walter GGX glass 1.5 (of R + T)", "walter_glass", {}),
    ("Walter Beckmann gold (not split)", "walter_reflection",
     {"fresnel_type": "conductor", "distribution": "beckmann"}),
    ("Cook-Torrance (not split)", "cook_torrance", {}),
    ("Lee V-grooves (not split)", "lee_vgroove", {}),
)


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    n = 1 << (14 if cfg.mode != "full" else 17)
    table = []
    for label, model_id, values in CASES:
        for r in ROUGHNESS:
            values_r = {**values, "roughness": r}
            try:
                bsdf = make_bsdf(model_id, values_r)
            except Exception:  # noqa: BLE001 - a model without a numpy BSDF in make_bsdf
                bsdf = None
            if bsdf is None or not split.supports_split(bsdf):
                table.append({"case": label, "roughness": r, "share": None})
                continue
            t = np.radians(THETAS)
            wi = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1)
            share, err = split.albedo_share(bsdf, wi, n=n, seed=cfg.seed)
            table.append({"case": label, "roughness": r, "share": share.tolist(),
                          "stderr": err.tolist()})
        progress(f"native share: {label}")
    return {"native_share": {"thetas": THETAS, "samples": n, "table": table}}


def page(cfg, rows, res) -> list:
    data = res.get("native_share")
    if not data:
        return []
    head = " | ".join(f"{t:g} deg" for t in data["thetas"])
    lines = ["## Light sampling: the share Cycles light-samples", "",
             "Share of the directional albedo carried by Cycles' native GGX closure in the "
             "Native + Residual estimator (`c E_n / E`, E_n the native closure's albedo, Fresnel included; addon/lab/reference/split.py, "
             f"{data['samples']:,} Monte Carlo samples per entry; the largest standard error is "
             "given per row). Per channel R/G/B where they differ. The residual carries the "
             "rest, its direction aimed partly at the lamps the add-on hands over; models that "
             "are not split carry everything in it (docs/light-sampling.md).", "",
             f"| model | roughness | {head} | s.e. |", "|---|---|" + "---|" * len(data["thetas"]) + "---|"]
    for row in data["table"]:
        if row["share"] is None:
            cells = ["0 (all residual)"] * len(data["thetas"]) + ["-"]
        else:
            cells = [_fmt(s) for s in row["share"]] + [f"{np.max(row['stderr']):.1e}"]
        lines.append(f"| {row['case']} | {row['roughness']:g} | " + " | ".join(cells) + " |")
    return lines + [""]


def _fmt(rgb) -> str:
    rgb = np.asarray(rgb)
    if np.ptp(rgb) < 5e-4:
        return f"{rgb.mean():.3f}"
    return "/".join(f"{v:.3f}" for v in rgb)
