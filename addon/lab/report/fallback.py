"""Section "fallback": every preset's native branch (what renders without OSL: addon/fallback.py)
against the exact model it stands in for, and what the branch costs where OSL runs.

- Albedo over incidence: both rendered under the white furnace; per band of mu = n.wi the
  relative error of the fallback's mean against the exact model's, with the noise of that
  difference (the scatter of the per-pixel differences of the two renders over sqrt(n)).
- The look: both under the gradient world and under a 4-degree sun over a dim world, the
  relative error of each sphere's mean, and rows of pictures (exact, fallback,
  4 x |difference|) for each.
- Cost with OSL on: the presets' grid, and each model's presets alone, rendered with and without
  the branch, alternating; the wall clock of the render call (scene sync and OSL JIT included).
- The fitted corrections (fallback.FITTED, addon/lab/fallback_fit.py): the numpy albedo and
  lobe errors of the branch with and without them, as `make fallback-fit` stored them
  (tests/test_fallback_fit.py holds them to the reference).
"""
from __future__ import annotations


import numpy as np

from ... import fallback, presets
from .. import grid
from . import scenes
from .plotting import to_display


def _settings(mode):
    # samples, cell pixels, cost repeats
    return {"full": (256, 48, 3), "quick": (64, 32, 2)}.get(mode, (8, 16, 1))


def _render(materials, env, samples, cell, seed, osl, cols, light_sampling=True, lamps=None):
    from .. import harness

    layout, image, seconds = harness.render_specs(None, env, samples, seed=seed, cols=cols,
                                                  cell_px=cell, materials=materials, osl=osl,
                                                  light_sampling=light_sampling, lamps=lamps)
    return layout, image[..., :3], seconds


def _band_errors(layout, fallback_image, exact_image):
    """Per sphere: [(band, relative error (3,), its standard error (3,))]."""
    out = {}
    for s in grid.band_stats(layout, fallback_image, exact_image, sides=False):
        ref = np.maximum(np.abs(s.reference), 1e-6)
        out.setdefault(s.sphere, []).append((s.band, s.bias / ref, s.stderr / ref))
    return out


def _sphere_means(layout, image):
    index, _, _ = layout.pixel_geometry()
    return np.array([image[index == i].mean(axis=0) for i in range(layout.count)])


def _sphere_noise(layout, difference):
    """The standard error of each sphere's mean difference, per channel: the scatter of its
    pixels' differences over sqrt(n) (the pixels are independent renders of two seeds; the
    scatter also holds the model's error varying over the sphere, so this is an upper bound)."""
    index, _, _ = layout.pixel_geometry()
    return np.array([difference[index == i].std(axis=0) / np.sqrt(max((index == i).sum(), 1))
                     for i in range(layout.count)])


def smoke_presets(mode) -> list:
    """The presets the section renders: all of them, or in the smoke run each model's first
    (every grid's OSL compile is per material: the smoke run's section took 37 of its 115 s)."""
    chosen = [presets.load_all()[k] for k in sorted(presets.load_all())]
    if mode == "smoke":
        firsts = {}
        for p in chosen:
            firsts.setdefault(p.model_id, p)
        chosen = list(firsts.values())
    return chosen


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    from ..fallback_scenes import preset_material
    from ..images import write_png

    samples, cell, repeats = _settings(cfg.mode)
    chosen = smoke_presets(cfg.mode)
    cols = min(7, len(chosen))  # a full last row: the layout counts its empty cells as spheres
    made = [preset_material(p) for p in chosen]
    entries = [{"preset": p.id, "model": p.model_id, "native": fallback.NATIVE[p.model_id]}
               for p in chosen]
    images = {}
    envs = (("white", grid.WHITE, None), ("gradient", grid.GRADIENT, None),
            ("sun", scenes.env_for("sun"), scenes.add_sun))
    for env_key, env, lamps in envs:
        # The albedo with the world's light sampling off: Cycles' rough glass closures are
        # biased bright under it (GGX and Multiscatter GGX glass alike, +15% at grazing
        # incidence, roughness 0.6), which is Cycles', not the branch's; the look keeps it on.
        ls = env_key != "white"
        layout, exact, _ = _render(made, env, samples, cell, 1, True, cols, ls, lamps)
        _, approx, _ = _render(made, env, samples, cell, 2, False, cols, ls, lamps)
        images[env_key] = (exact, approx)
        if env_key == "white":
            for i, bands in _band_errors(layout, approx, exact).items():
                entries[i]["albedo"] = [{"mu": list(b), "error": e.tolist(), "noise": n.tolist()}
                                        for b, e, n in bands]
        else:
            e, a = _sphere_means(layout, exact), _sphere_means(layout, approx)
            noise = _sphere_noise(layout, approx - exact)
            for i, entry in enumerate(entries):
                entry[env_key] = ((a[i] - e[i]) / np.maximum(e[i], 1e-6)).tolist()
                entry[env_key + "_noise"] = (noise[i] / np.maximum(e[i], 1e-6)).tolist()
        progress(f"fallback: {env_key} rendered ({samples} samples)")
    write_png(out / "fallback.png", np.concatenate(
        [to_display(image) for key in ("gradient", "sun")
         for image in (images[key][0], images[key][1],
                       4.0 * np.abs(images[key][1] - images[key][0]))], axis=0))

    cost = _cost(chosen, made, samples, cell, repeats, cols, cfg.mode == "smoke")
    ratios = ", ".join(f"{m} {_ratio(c):.3f}" for m, c in cost["models"].items())
    progress(f"fallback: OSL-on cost with / without the branch: all {_ratio(cost):.3f}; {ratios}")
    return {"fallback": {"presets": entries, "cost": cost, "samples": samples, "cell_px": cell}}


def _cost(chosen, made, samples, cell, repeats, cols, smoke=False) -> dict:
    """Render-call seconds with and without the branch, alternating: the presets' whole grid,
    then each model's presets alone (scene sync and OSL JIT included, as an artist pays them).
    The smoke run times one model alone, the one with the fewest presets (its figures are noise
    at 8 samples; the per-model JITs would double its time)."""
    from ..fallback_scenes import without_branch

    def timed(mats):
        seconds = {True: [], False: []}
        for _ in range(repeats):
            for branch in (True, False):
                grid_mats = mats if branch else [without_branch(m) for m in mats]
                seconds[branch].append(_render(grid_mats, grid.GRADIENT, samples, cell, 3, True,
                                               cols)[2])
        return {"with": seconds[True], "without": seconds[False], "spheres": len(mats)}

    cost = timed(made)
    cost["samples"] = samples
    cost["models"] = {}
    model_ids = list(dict.fromkeys(p.model_id for p in chosen))
    if smoke:
        model_ids = [min(model_ids, key=[p.model_id for p in chosen].count)]
    for model_id in model_ids:
        cost["models"][model_id] = timed([m for p, m in zip(chosen, made)
                                          if p.model_id == model_id])
    return cost


def _ratio(cost) -> float:
    return float(np.median(cost["with"]) / np.median(cost["without"]))


def _worst(entry):
    errors = np.array([b["error"] for b in entry.get("albedo", [])])
    if errors.size == 0:
        return float("nan"), float("nan")
    return float(np.abs(errors).max()), float(np.abs(errors).mean())


def page(cfg, rows, res) -> list:
    data = res.get("fallback")
    if not data:
        return []
    cost = data["cost"]
    lines = ["## Without OSL: the native branch against the exact model", "",
             f"Every preset rendered exact (OSL) and as its native branch (OSL off), "
             f"{data['samples']} samples, spheres of {data['cell_px']} px. Albedo: the white "
             "furnace with the world's light sampling off, the relative error of the branch per "
             "band of mu = n.wi (worst and mean over bands and channels; noise: the standard "
             "error of that difference, largest band). Look: the gradient world with its light "
             "sampling on, as artists render, and a 4-degree sun lamp over a dim world, the "
             "relative error of the sphere's mean per channel (noise: its standard error, "
             "largest channel; a small sun's highlight on a sharp lobe is a few pixels, so a "
             "near-mirror's look under the sun is mostly noise). Cycles' own rough glass closures render too bright under a sampled "
             "world (in the white furnace, roughness 0.6: +15% at grazing incidence, +3.6% "
             "facing, where the same closures with the world's light sampling off are within "
             "0.1% of their model): that bias is in the look of every glass preset whose "
             "branch or exact shader uses them.", "",
             "| preset | model | native branch | albedo error worst | mean | noise | "
             "look, gradient (R, G, B) | look, sun (R, G, B) |",
             "|---|---|---|---|---|---|---|---|"]
    for e in data["presets"]:
        worst, mean = _worst(e)
        noise = max((max(b["noise"]) for b in e.get("albedo", [])), default=float("nan"))
        looks = [", ".join(f"{100 * v:+.1f}%" for v in e.get(key, []))
                 + f" (noise {100 * max(e.get(key + '_noise', [np.nan])):.1f}%)"
                 for key in ("gradient", "sun")]
        lines.append(f"| {e['preset']} | {e['model']} | {e['native']} | {100 * worst:.1f}% | "
                     f"{100 * mean:.1f}% | {100 * noise:.1f}% | {looks[0]} | {looks[1]} |")
    lines += ["", "![exact, native branch, 4 x difference: the gradient, then the sun]"
              "(fallback.png)", "",
              f"Cost where OSL runs: the render call (scene sync, OSL JIT and {cost['samples']} "
              f"samples) with and without the branch, medians of {len(cost['with'])} alternating "
              "runs, for the presets' whole grid and for each model's presets alone. Where OSL "
              "runs the branch's closures are weighted 0 and dropped; what the branch can cost "
              "is its nodes' sync and their evaluation in the shader.", "",
              "| presets | spheres | with the branch (s) | without (s) | ratio |",
              "|---|---|---|---|---|"]
    for name, c in [("all", cost)] + list(cost.get("models", {}).items()):
        lines.append(f"| {name} | {c['spheres']} | {np.median(c['with']):.2f} | "
                     f"{np.median(c['without']):.2f} | {_ratio(c):.3f} |")
    return lines + [""] + fit_lines()


def fit_lines() -> list:
    """The numpy errors of the native branches without and with their fitted corrections."""
    fit = fallback.fit()
    lines = ["### The fitted corrections and the presets' errors (numpy)", "",
             "Lee's, Cook-Torrance's and Heitz 2016's metals add a single-scattering Glossy "
             "lobe; Heitz 2016's glass and Walter's Separable masking scale the native closure. "
             "Each is a polynomial in roughness, Facing and F0 fitted to the reference "
             "(`make fallback-fit`). Albedo: "
             "relative error over the training grid (roughness "
             f"{fit['training']['roughness'][0]}-{fit['training']['roughness'][-1]}, "
             f"{len(fit['training']['mu'])} incidences; Fresnel: the presets' metals, "
             "dielectrics, and F = 1 where the model has it) or the preset's "
             "incidences; lobe: the angle between the mean directions of the reflected (for "
             "glass: reflected and transmitted) light (plain -> fitted). The presets' figures "
             "are what the panel and the operators tell the artist.",
             "", "| variant or preset | albedo worst, plain -> fitted | mean | "
             "lobe mean (deg) | lobe worst (deg) |", "|---|---|---|---|---|"]
    def pair(e, name, stat, fmt):
        plain = e.get(name + "_plain")
        return (fmt(plain[stat]) + " -> " if plain else "") + fmt(e[name][stat])

    def pct(v):
        return f"{100 * v:.1f}%"

    def deg(v):
        return f"{v:.1f}"

    for name, e in list(fit["variants"].items()) + list(fit["presets"].items()):
        lines.append(f"| {name} | {pair(e, 'albedo', 'worst', pct)} | "
                     f"{pair(e, 'albedo', 'mean', pct)} | {pair(e, 'lobe', 'mean', deg)} | "
                     f"{pair(e, 'lobe', 'worst', deg)} |")
    return lines + [""]
