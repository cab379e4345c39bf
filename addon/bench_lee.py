"""Measurements for the Lee 2018 V-groove model (numbers for the report; nothing here is asserted
except through tests/test_render_lee.py, which uses `furnace_means`).

- `furnace_means` / `render_furnace`: white-furnace sphere grids over alpha for Lee (F = 1),
  single scattering (Walter GGX, height-correlated Smith, F = 1; Cook-Torrance, Beckmann with
  V-cavities, F >= 0.9996 since its catalog entry has no F = 1 option) and Cycles' own
  multiple-scattering GGX closure (`microfacet_multi_ggx_aniso`).
- `shader_cost`: render time of the Lee shader against the Cook-Torrance shader at equal
  samples on the same grid (one run each).
- `tracer_vs_closed_form`: time for the analytic sampler (lee.sample) and the brute-force tracer
  (vgroove.trace) to reach the same standard error of the albedo; the deterministic closed-form
  quadrature (lee.albedo) timed beside them.
- `moments_accuracy`: the default moment rules (lee.MOMENT_NODES) against much finer ones.
`markdown(results)` formats any of these dicts as a Markdown table. Run them all with
`python -m addon.bench_lee` (from the repository root, the pinned environment).
"""
from __future__ import annotations

import math
import time

import numpy as np

FURNACE_ALPHAS = (0.25, 0.5, 0.75, 1.0)
GOLD = {"fresnel_type": "conductor"}  # catalog default n, k: gold
# Cook-Torrance offers only conductor/dielectric Fresnel: n = 0.001, k = 100 gives F >= 0.9996.
NEAR_ONE_CONDUCTOR = {"fresnel_type": "conductor", "n": (0.001,) * 3, "k": (100.0,) * 3}
MULTI_GGX = ('#include "stdcycles.h"\nshader multi_ggx(output closure color BSDF = 0) '
             '{{ BSDF = microfacet_multi_ggx_aniso(N, vector(0), {a:.9g}, {a:.9g}, color(1)); }}')


def furnace_rows():
    """(label, model id or None for raw OSL, values) of the furnace comparison."""
    return [
        ("Lee symmetric GGX", "lee_vgroove", {"fresnel_type": "none", "distribution": "ggx"}),
        ("Lee asymmetric GGX", "lee_vgroove", {"fresnel_type": "none", "distribution": "ggx",
                                               "groove": "asymmetric"}),
        ("Lee symmetric Beckmann", "lee_vgroove", {"fresnel_type": "none",
                                                   "distribution": "beckmann"}),
        ("Walter GGX (single)", "walter_reflection", {"fresnel_type": "none", "distribution": "ggx",
                                                      "sampler": "vndf"}),
        ("Cook-Torrance (single)", "cook_torrance", {"specular": 1.0, "sampler": "vcavity",
                                                     **NEAR_ONE_CONDUCTOR}),
        ("Cycles multi-GGX", None, {}),
    ]


def _factory(model_id, values, alpha, name):
    from . import harness

    if model_id is None:
        return lambda: harness.osl_material(MULTI_GGX.format(a=alpha), name)
    vals = {**values, "roughness": math.sqrt(alpha)}
    return lambda: harness.model_material(model_id, vals, name)


def render_furnace(alphas=FURNACE_ALPHAS, samples: int = 64, cell_px: int = 32, seed: int = 11):
    """Render the furnace grid (rows of furnace_rows(), columns alphas) in the white furnace.
    Returns (labels, layout, image, means) with means[label] = list of sphere means (pixels
    with mu >= 0.05, green channel) per alpha."""
    from . import grid, harness

    rows = furnace_rows()
    factories = [_factory(m, v, a, f"{label} a={a}") for label, m, v in rows for a in alphas]
    layout, image, _ = harness.render_specs(None, grid.WHITE, samples, seed=seed,
                                            cols=len(alphas), cell_px=cell_px,
                                            materials=factories)
    index, _, mu = layout.pixel_geometry()
    means = {}
    for r, (label, _, _) in enumerate(rows):
        means[label] = [float(image[(index == r * len(alphas) + c) & (mu >= 0.05)][:, 1].mean())
                        for c in range(len(alphas))]
    return [r[0] for r in rows], layout, image, means


def furnace_means(alphas=FURNACE_ALPHAS, samples: int = 64, cell_px: int = 32, seed: int = 11):
    return render_furnace(alphas, samples, cell_px, seed)[3]


def shader_cost(samples: int = 128, cell_px: int = 32, repeats: int = 2) -> dict:
    """Render time of the same 8-sphere grid (gold, roughness 0.05 .. 1) with the Lee shader
    (symmetric and asymmetric GGX) and the Cook-Torrance shader (specular 1, V-cavity sampler),
    white furnace, equal samples; best of `repeats`."""
    from . import grid, harness
    from .grid import SphereSpec

    rough = (0.05, 0.3, 0.5, 0.7, 0.85, 1.0, 0.2, 0.6)
    grids = {
        "cook_torrance": [SphereSpec("cook_torrance", {"specular": 1.0, "roughness": r, **GOLD})
                          for r in rough],
        "lee symmetric ggx": [SphereSpec("lee_vgroove", {"roughness": r, **GOLD}) for r in rough],
        "lee asymmetric ggx": [SphereSpec("lee_vgroove", {"roughness": r, "groove": "asymmetric",
                                                          **GOLD}) for r in rough],
        "lee symmetric beckmann": [SphereSpec("lee_vgroove", {"roughness": r,
                                                              "distribution": "beckmann", **GOLD})
                                   for r in rough],
    }
    out = {}
    for name, specs in grids.items():
        out[name] = min(harness.render_specs(specs, grid.WHITE, samples, seed=1, cell_px=cell_px)[2]
                        for _ in range(repeats))
    base = out["cook_torrance"]
    return {name: {"seconds": t, "ratio_to_cook_torrance": t / base} for name, t in out.items()}


def tracer_vs_closed_form(cases=(("ggx", 0.5, 60.0), ("ggx", 1.0, 0.0), ("beckmann", 1.0, 80.0)),
                          groove: str = "symmetric", n: int = 1 << 18, seed: int = 5) -> dict:
    """Per case: seconds per sample and albedo standard error (G channel, gold) of lee.sample and
    vgroove.trace, the time each needs for a target standard error of 1e-4, their ratio, and
    the time of the deterministic closed-form albedo (lee.albedo, n = 512)."""
    from .reference import lee
    from .reference import vgroove as vg
    from .reference.microfacet import Microfacet

    from .catalog import MODELS
    model = MODELS["lee_vgroove"]
    gold = vg.fresnel_fn("conductor", n=model.param("n").default, k=model.param("k").default)
    out = {}
    for dist, alpha, deg in cases:
        mf = Microfacet(dist, alpha)
        wi = np.array([math.sin(math.radians(deg)), 0.0, math.cos(math.radians(deg))])
        rng = np.random.default_rng(seed)
        t0 = time.perf_counter()
        m1, s1 = lee.sample_albedo(wi, mf, n, rng, gold, groove)
        t1 = time.perf_counter() - t0
        table = vg.SizeBiasedTable(mf) if groove == "asymmetric" else None
        t0 = time.perf_counter()
        m2, s2 = vg.albedo(wi, mf, n, rng, gold, groove, table=table)
        t2 = time.perf_counter() - t0
        t0 = time.perf_counter()
        q = lee.albedo(wi, mf, gold, groove)
        tq = time.perf_counter() - t0
        target = 1e-4
        need1 = t1 * (s1[1] / target) ** 2
        need2 = t2 * (s2[1] / target) ** 2
        out[f"{groove} {dist} a={alpha} {deg:g} deg"] = {
            "albedo_G": float(q[1]), "sampler_G": float(m1[1]), "tracer_G": float(m2[1]),
            "sampler_s_per_1e-4": need1, "tracer_s_per_1e-4": need2,
            "tracer_over_sampler": need2 / need1, "quadrature_s": tq}
    return out


def moments_accuracy(mus=(1.0, 0.5, 0.2, 0.05, 0.01),
                     alphas=(0.09, 1.0)) -> dict:
    """Max abs difference of (E, Vn, Vt) between the default rules of lee.moments and rules with
    about 8x the nodes (symmetric 384^2 tensor; asymmetric R3 with 8x the points), gold."""
    from .catalog import MODELS
    from .reference import lee
    from .reference import vgroove as vg
    from .reference.microfacet import Microfacet

    model = MODELS["lee_vgroove"]
    gold = lee.FresnelTable(vg.fresnel_fn("conductor", n=model.param("n").default,
                                          k=model.param("k").default))
    mus = np.asarray(mus)
    out = {}
    for groove in ("symmetric", "asymmetric"):
        for dist in ("ggx", "beckmann"):
            for a in alphas:
                mf = Microfacet(dist, a)
                kmax = lee.max_bounces(a, dist, groove)
                t0 = time.perf_counter()
                d = np.array(lee.moments(mus, mf, gold, groove, kmax))
                t = time.perf_counter() - t0
                nt, nphi, npart = lee.MOMENT_NODES[groove, dist]
                fine = (384, 384, 1) if groove == "symmetric" else (nt, nphi, 8 * npart)
                f = np.array(lee.moments(mus, mf, gold, groove, kmax, *fine))
                out[f"{groove} {dist} a={a}"] = {"max_abs_error": float(np.abs(d - f).max()),
                                                 "seconds_per_mu": t / len(mus)}
    return out


def markdown(results: dict) -> str:
    """A Markdown table of {row: {column: value}}."""
    cols = list(next(iter(results.values())).keys())
    lines = ["| case | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for name, row in results.items():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def furnace_markdown(alphas, means: dict) -> str:
    lines = ["| model | " + " | ".join(f"alpha {a:g}" for a in alphas) + " |",
             "|---" * (len(alphas) + 1) + "|"]
    for label, values in means.items():
        lines.append(f"| {label} | " + " | ".join(f"{v:.4f}" for v in values) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    what = set(sys.argv[1:]) or {"furnace", "cost", "tracer", "accuracy"}
    if "furnace" in what:
        print(furnace_markdown(FURNACE_ALPHAS, furnace_means()))
    if "cost" in what:
        print(markdown(shader_cost()))
    if "tracer" in what:
        print(markdown(tracer_vs_closed_form()))
    if "accuracy" in what:
        print(markdown(moments_accuracy()))
