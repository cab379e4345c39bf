"""Section 3, the cost of the reference: time and accuracy of the gradient reference image of
one grid (one row per model variant with a quadrature reference: not the Monte Carlo walk)
against the quadrature order; page text."""
from __future__ import annotations

import time

import numpy as np

from .. import grid
from ..reference import make_bsdf
from ..reference.quadrature import moments_at
from .references import ReferenceTables
from .rows import specs_for


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    """The section's measurements."""
    return {"refcost": reference_cost(cfg, rows, progress)}


def reference_cost(cfg, rows, progress) -> list:
    """Time and accuracy of the gradient reference image of one grid (one row per model
    variant) against the quadrature order, relative to order `ref_high_order`."""


    seen, specs = set(), []
    for row in rows:
        # A walk's tables (Heitz 2016) are Monte Carlo: no quadrature order to study.
        if row.model_id and getattr(make_bsdf(row.model_id, row.values), "stochastic_eval", False):
            continue
        if row.model_id and row.variant not in seen:
            seen.add(row.variant)
            specs += specs_for(row, cfg.roughness)
    layout = grid.GridLayout(-(-len(specs) // len(cfg.roughness)), len(cfg.roughness),
                             cell_px=cfg.ref_cell_px)
    index, _, mu = layout.pixel_geometry()
    sel = index >= 0
    results = []
    images = {}
    for order in tuple(cfg.ref_orders) + (cfg.ref_high_order,):
        progress(f"reference cost: quadrature order {order}")
        start = time.perf_counter()
        tables = ReferenceTables(order)
        img = grid.reference_image(layout, [tables.get(s) for s in specs], grid.GRADIENT,
                                   moments_at)
        images[order] = (img, time.perf_counter() - start)
    high, _ = images[cfg.ref_high_order]
    for order, (img, seconds) in images.items():
        d = np.abs(img - high)[sel]
        results.append({"order": order, "seconds": seconds, "max_abs": float(d.max()),
                        "rel_rmse": float(np.sqrt(np.mean(d * d)) / np.mean(high[sel])),
                        "spheres": len(specs)})
    return results


def page(cfg, rows, res) -> list:
    """Section 3's Markdown lines ([] when it was not run)."""
    refcost = res.get("refcost")
    if not refcost:
        return []
    hi = refcost[-1]
    L = ["## 3. Cost of the reference\n",
         f"The gradient reference image of {hi['spheres']} spheres ({cfg.ref_cell_px} px cells): "
         f"moment tables (48 incidences each) by quadrature of order N, against order "
         f"{hi['order']}.\n",
         "| order N | time (s) | max abs difference | relative RMS difference |",
         "|---|---|---|---|"]
    for r in refcost:
        L.append(f"| {r['order']} | {r['seconds']:.2f} | {r['max_abs']:.2g} | {r['rel_rmse']:.2g} |")
    L.append("")
    return L
