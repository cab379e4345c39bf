"""Measurements for the Lee 2018 V-groove model (numbers for the report, `make report`'s section
"Lee 2018 (V-grooves)"; nothing here is asserted except through tests/test_render_lee.py, which
uses `furnace_means`, and the report's smoke test).

- `furnace_means` / `render_furnace`: white-furnace sphere grids over alpha for Lee (F = 1),
  single scattering (Walter GGX, height-correlated Smith, F = 1; Cook-Torrance, Beckmann with
  V-cavities, F >= 0.9996 since its catalog entry has no F = 1 option) and Cycles' own
  multiple-scattering GGX closure (`microfacet_multi_ggx_aniso`); `furnace_noise` gives each
  sphere mean's standard error.
- `shader_cost`: render time per sample of the Lee shader against the Cook-Torrance shader:
  one scene holding every shader's row, each row rendered alone through a render border at two
  sample counts, rows interleaved, the slope taken (scene sync, OSL JIT and the per-render
  overhead cancel); ratio to Cook-Torrance per repeat.
- `tracer_vs_closed_form`: time for the closed-form quadrature (lee.albedo), the analytic
  sampler (lee.sample) and the brute-force tracer (vgroove.trace) to reach the same albedo error.
- `moments_accuracy`: the default moment rules (lee.MOMENT_NODES) against much finer ones.
- `max_bounces_agreement`: Max Bounces read by the twins: the albedo from LeeBRDF.eval
  (quadrature at normal incidence), from the sampler (Monte Carlo, standard error) and from
  lee.albedo (closed form), gold, per Max Bounces (docs/lee-asymmetric-grooves.md sec. 4).
`markdown(results)` formats any of these dicts as a Markdown table. Run them all with
`python -m addon.lab.bench_lee` (from the repository root, the pinned environment).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..catalog import MODELS
from .reference import lee, make_bsdf, vgroove as vg
from .reference.microfacet import Microfacet

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


def furnace_noise(layout, image, labels, alphas) -> dict:
    """Standard error of each sphere mean of `render_furnace` (pixels with mu >= 0.05, green):
    the pixels' standard deviation / sqrt(count). An upper bound where the expected value
    varies over the sphere (single scattering loses more at the rim); exactly 0 for Lee with
    F = 1, whose every sample weighs 1."""
    index, _, mu = layout.pixel_geometry()
    out = {}
    for r, label in enumerate(labels):
        out[label] = []
        for c in range(len(alphas)):
            v = image[(index == r * len(alphas) + c) & (mu >= 0.05)][:, 1]
            out[label].append(float(v.std(ddof=1) / math.sqrt(len(v))))
    return out


COST_ROUGHNESS = (0.05, 0.2, 0.3, 0.5, 0.6, 0.7, 0.85, 1.0)


def cost_rows():
    """(label, model id, values) of the shader-cost grid, gold; Cook-Torrance first (the base)."""
    return [
        ("Cook-Torrance (V-cavity sampler)", "cook_torrance", {"specular": 1.0, **GOLD}),
        ("Lee symmetric GGX", "lee_vgroove", {**GOLD}),
        ("Lee asymmetric GGX", "lee_vgroove", {"groove": "asymmetric", **GOLD}),
        ("Lee symmetric Beckmann", "lee_vgroove", {"distribution": "beckmann", **GOLD}),
    ]


def shader_cost(samples=(16, 144), cell_px: int = 32, repeats: int = 3,
                roughness=COST_ROUGHNESS, progress=None) -> dict:
    """Render time per sample of the Lee shader against the Cook-Torrance shader (gold, white
    furnace, one row of spheres per shader, roughness `roughness`), measured side by side:
    ONE scene holds every row (persistent data; scene sync and OSL JIT are done once before
    timing); each row is rendered alone (harness.render_row_alone) at the two sample counts
    `samples`, rows interleaved (order reversed on odd repeats). Seconds per sample of a row =
    the slope (t(hi) - t(lo)) / (hi - lo), which cancels the per-render overhead (EXR
    write/read). Everything is taken per repeat (rows rendered moments apart, so a change in
    the machine's load hits them alike) and summarised by the median over the repeats; the
    ratio to Cook-Torrance also by its minimum and maximum."""
    from . import grid, harness

    rows = cost_rows()
    lo, hi = samples
    layout = grid.GridLayout(len(rows), len(roughness), cell_px=cell_px)
    scene = harness.new_scene()
    mats = [harness.model_material(m, {**v, "roughness": r}, f"{label} r={r}")
            for label, m, v in rows for r in roughness]
    harness.build_grid_scene(layout, mats, grid.WHITE, lo, 1)
    scene.render.use_persistent_data = True
    t0 = time.perf_counter()
    harness.render(scene)  # sync + OSL JIT, once
    setup = time.perf_counter() - t0
    times = {label: {lo: [], hi: []} for label, _, _ in rows}
    n_total, done = repeats * len(rows) * 2, 0
    for rep in range(repeats):
        order = list(enumerate(rows))
        if rep % 2:
            order.reverse()
        for r, (label, _, _) in order:
            harness.render_row_alone(scene, layout, r)
            for spp in (lo, hi):
                done += 1
                if progress:
                    progress(f"Lee shader cost: {label}, {spp} samples", done, n_total)
                scene.cycles.samples = spp
                scene.cycles.seed = 1 + rep
                times[label][spp].append(harness.render(scene)[1])
    base = rows[0][0]

    def slope(label, rep):
        t = times[label]
        return (t[hi][rep] - t[lo][rep]) / (hi - lo)

    out = {}
    for label, _, _ in rows:
        slopes = [slope(label, k) for k in range(repeats)]
        per_rep = [slope(label, k) / slope(base, k) for k in range(repeats)]
        med = float(np.median(slopes))
        out[label] = {"ms_per_sample": 1e3 * med,
                      "ratio_to_cook_torrance": float(np.median(per_rep)),
                      "ratio_min": min(per_rep), "ratio_max": max(per_rep),
                      f"seconds_at_{hi}": float(np.median(times[label][hi])),
                      "overhead_s": float(np.median(times[label][lo])) - lo * med}
    out["_setup"] = {"setup_seconds": setup, "samples": list(samples), "repeats": repeats,
                     "spheres_per_row": len(roughness), "cell_px": cell_px,
                     "roughness": list(roughness)}
    return out


TRACER_CASES = (("ggx", 0.5, 60.0), ("ggx", 1.0, 0.0), ("beckmann", 1.0, 80.0))


def _best_time(fn, repeat_below: float = 0.5):
    """(result, seconds) of fn(); run a second time and the faster kept when under
    `repeat_below` seconds (short timings are noisy)."""
    t0 = time.perf_counter()
    res = fn()
    t = time.perf_counter() - t0
    if t < repeat_below:
        t0 = time.perf_counter()
        res = fn()
        t = min(t, time.perf_counter() - t0)
    return res, t


def tracer_vs_closed_form(cases=TRACER_CASES, groove: str = "symmetric", n: int = 1 << 18,
                          seed: int = 5, target: float = 1e-4,
                          quad_orders=(32, 64, 128, 256, 512), quad_ref: int = 1024,
                          progress=None) -> dict:
    """Time to the same albedo error (G channel, gold), per case (distribution, alpha,
    incidence in degrees):
    - closed form: the deterministic quadrature lee.albedo at orders `quad_orders`; its error
      is |A(order) - A(quad_ref)|; time to `target` = the time of the first order from which
      every larger one is within it;
    - analytic sampler (lee.sample) and brute-force tracer (vgroove.trace): n samples each,
      standard error s in t seconds; time to `target` = t (s / target)^2.
    Also the agreement of the tracer's mean with the reference quadrature, in standard errors."""

    model = MODELS["lee_vgroove"]
    gold = vg.fresnel_fn("conductor", n=model.param("n").default, k=model.param("k").default)
    out = {}
    for i, (dist, alpha, deg) in enumerate(cases):
        if progress:
            progress(f"Lee closed form vs tracer: {dist} alpha {alpha} at {deg:g} deg", i + 1,
                     len(cases))
        mf = Microfacet(dist, alpha)
        wi = np.array([math.sin(math.radians(deg)), 0.0, math.cos(math.radians(deg))])
        ref = lee.albedo(wi, mf, gold, groove, n=quad_ref)[1]
        half = lee.albedo(wi, mf, gold, groove, n=quad_ref // 2)[1]
        quad = []
        for order in quad_orders:
            q, tq = _best_time(lambda: lee.albedo(wi, mf, gold, groove, n=order))
            quad.append((order, tq, abs(float(q[1]) - float(ref))))
        ok = [k for k in range(len(quad)) if all(e <= target for _, _, e in quad[k:])]
        q_order, q_time = (quad[ok[0]][0], quad[ok[0]][1]) if ok else (None, float("inf"))
        rng = np.random.default_rng(seed)
        t0 = time.perf_counter()
        m1, s1 = lee.sample_albedo(wi, mf, n, rng, gold, groove)
        t1 = time.perf_counter() - t0
        table = vg.SizeBiasedTable(mf) if groove == "asymmetric" else None
        t0 = time.perf_counter()
        m2, s2 = vg.albedo(wi, mf, n, rng, gold, groove, table=table)
        t2 = time.perf_counter() - t0
        need_sampler = t1 * (s1[1] / target) ** 2
        need_tracer = t2 * (s2[1] / target) ** 2
        out[f"{groove} {dist} a={alpha} {deg:g} deg"] = {
            "albedo_G": float(ref), "quad_ref_change": abs(float(ref) - float(half)),
            "closed_form_order": q_order, "closed_form_s": q_time,
            "sampler_s": need_sampler, "tracer_s": need_tracer,
            "tracer_over_closed_form": need_tracer / q_time,
            "tracer_over_sampler": need_tracer / need_sampler,
            "tracer_G": float(m2[1]), "tracer_z": (float(m2[1]) - float(ref)) / float(s2[1]),
            "quadrature": [{"order": o, "seconds": t, "error": e} for o, t, e in quad]}
    return out


def moments_accuracy(mus=(1.0, 0.5, 0.2, 0.05, 0.01), alphas=(0.09, 1.0),
                     grooves=("symmetric", "asymmetric"), distributions=("ggx", "beckmann"),
                     progress=None) -> dict:
    """Max abs difference of (E, Vn, Vt) between the default rules of lee.moments and rules with
    about 8x the nodes (symmetric 384^2 tensor; asymmetric R3 with 8x the points), gold."""

    model = MODELS["lee_vgroove"]
    gold = lee.FresnelTable(vg.fresnel_fn("conductor", n=model.param("n").default,
                                          k=model.param("k").default))
    mus = np.asarray(mus)
    out = {}
    todo = [(g, d, a) for g in grooves for d in distributions for a in alphas]
    for i, (groove, dist, a) in enumerate(todo):
        if progress:
            progress(f"Lee moment rules: {groove} {dist} alpha {a}", i + 1, len(todo))
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


def max_bounces_agreement(alpha: float = 1.0, max_bounces=(1, 2, 5, 0),
                          grooves=("symmetric", "asymmetric"), n: int = 200000, seed: int = 7,
                          progress=None) -> dict:
    """Green-channel albedo at normal incidence, GGX `alpha`, catalog gold, per groove and Max
    Bounces: `eval` = 2 pi integral of LeeBRDF.eval cos sin over theta_o (200 panels of 64
    Gauss-Legendre nodes; the lobe is isotropic at normal incidence), `sampler` = mean weight of
    `n` LeeBRDF.sample draws with its standard error, `closed_form` = lee.albedo(kmax = Max
    Bounces). All three read Max Bounces as the number of bounces that get their Fresnel
    factor (later ones F = 1)."""

    x, w = np.polynomial.legendre.leggauss(64)
    edges = np.linspace(0.0, 0.5 * math.pi, 201)
    half = 0.5 * np.diff(edges)[:, None]
    theta = (0.5 * (edges[:-1] + edges[1:])[:, None] + half * x).ravel()
    weight = (half * w).ravel() * 2.0 * math.pi * np.cos(theta) * np.sin(theta)
    wo = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=-1)
    wi = np.array([0.0, 0.0, 1.0])
    out = {}
    for groove in grooves:
        for mb in max_bounces:
            if progress:
                progress(f"Lee Max Bounces {mb}: {groove}")
            b = make_bsdf("lee_vgroove", {"roughness": math.sqrt(alpha), "groove": groove,
                                          "fresnel_type": "conductor", "max_bounces": float(mb)})
            e = float(weight @ b.eval(wi, wo)[:, 1])
            rng = np.random.default_rng(seed)
            _, wt, _ = b.sample(wi, rng.random((n, 3 if groove == "symmetric" else 6)))
            q = lee.albedo(wi, b.mf, b.fresnel, groove, n=512 if groove == "symmetric" else 128,
                           kmax=b.kmax, n_partner=64)
            out[f"{groove} max_bounces={mb}"] = {
                "kmax": b.kmax, "eval_terms": b.kterms, "eval_G": e,
                "sampler_G": float(wt[:, 1].mean()),
                "sampler_se_G": float(wt[:, 1].std() / math.sqrt(n)),
                "closed_form_G": float(q[1])}
    return out


def markdown(results: dict) -> str:
    """A Markdown table of {row: {column: value}}; rows whose key starts with '_' (settings)
    and columns holding lists or dicts are left out."""
    rows = {k: v for k, v in results.items() if not str(k).startswith("_")}
    cols = [c for c, v in next(iter(rows.values())).items() if not isinstance(v, (list, dict))]
    lines = ["| case | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for name, row in rows.items():
        cells = []
        for c in cols:
            v = row[c]
            cells.append("-" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def furnace_markdown(alphas, means: dict, noise: dict | None = None) -> str:
    """The furnace table; with `noise` (furnace_noise) each mean carries its standard error."""
    lines = ["| model | " + " | ".join(f"alpha {a:g}" for a in alphas) + " |",
             "|---" * (len(alphas) + 1) + "|"]
    for label, values in means.items():
        cells = [f"{v:.4f}" + (f" ± {noise[label][i]:.1g}" if noise else "")
                 for i, v in enumerate(values)]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    def _progress(message, i=None, n=None):
        print(f"[bench_lee] {f'({i}/{n}) ' if i is not None else ''}{message}", file=sys.stderr,
              flush=True)

    what = set(sys.argv[1:]) or {"furnace", "cost", "tracer", "accuracy", "max_bounces"}
    if "furnace" in what:
        labels, layout, image, means = render_furnace()
        print(furnace_markdown(FURNACE_ALPHAS, means,
                               furnace_noise(layout, image, labels, FURNACE_ALPHAS)))
    if "cost" in what:
        print(markdown(shader_cost(progress=_progress)))
    if "tracer" in what:
        print(markdown(tracer_vs_closed_form(progress=_progress)))
    if "accuracy" in what:
        print(markdown(moments_accuracy(progress=_progress)))
    if "max_bounces" in what:
        print(markdown(max_bounces_agreement(progress=_progress)))
