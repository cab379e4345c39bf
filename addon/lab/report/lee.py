"""Section 5, the Lee 2018 V-groove model: the measurements of addon/lab/bench_lee.py at the
mode's settings (white furnace over alpha against single scattering and Cycles' multi-GGX,
render cost per sample against Cook-Torrance, closed form against the brute-force tracer, the
accuracy of the moment rules), the furnace picture and the page text."""
from __future__ import annotations

import time

import numpy as np

from .. import bench_lee
from .plotting import _plt


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    """The section's measurements and its furnace plot."""
    lee = lee_section(cfg, progress, notes)
    if lee.get("furnace"):
        plot_lee_furnace(lee["furnace"], out / "lee_furnace.png")
    return {"lee": lee}


# -- measurement -----------------------------------------------------------------------------
def lee_section(cfg, progress, notes) -> dict:
    """The measurements of addon/lab/bench_lee.py at the mode's settings. Each part that fails is
    reported in `notes` (and left out of the page) rather than losing the run."""
    out = {}
    for name, fn in (("furnace", furnace), ("cost", cost), ("tracer", tracer),
                     ("moments", moments)):
        start = time.perf_counter()
        try:
            out[name] = fn(cfg.lee, progress)
        except Exception as exc:  # noqa: BLE001 - report it rather than lose the page
            notes.append(f"Lee section, {name}: failed: {type(exc).__name__}: {exc}")
            progress(f"Lee {name} FAILED: {type(exc).__name__}: {exc}")
            continue
        out.setdefault("seconds", {})[name] = time.perf_counter() - start
    return out


def furnace(lc, progress) -> dict:
    progress(f"Lee furnace grid: {len(bench_lee.furnace_rows())} models x "
             f"{len(bench_lee.FURNACE_ALPHAS)} alphas, {lc.furnace_samples} samples")
    alphas = bench_lee.FURNACE_ALPHAS
    labels, layout, image, means = bench_lee.render_furnace(alphas, lc.furnace_samples,
                                                            lc.furnace_px)
    noise = bench_lee.furnace_noise(layout, image, labels, alphas)
    lee = means["Lee symmetric GGX"][-1]
    progress(f"Lee furnace at alpha {alphas[-1]:g}: Lee {lee:.4f}, Walter GGX "
             f"{means['Walter GGX (single)'][-1]:.4f}, Cook-Torrance "
             f"{means['Cook-Torrance (single)'][-1]:.4f}, Cycles multi-GGX "
             f"{means['Cycles multi-GGX'][-1]:.4f}")
    return {"alphas": list(alphas), "labels": labels, "means": means, "noise": noise,
            "samples": lc.furnace_samples, "cell_px": lc.furnace_px, "layout": layout,
            "image": image}


def cost(lc, progress) -> dict:
    res = bench_lee.shader_cost(lc.cost_samples, lc.cost_px, lc.cost_repeats,
                                progress=progress)
    progress("Lee shader cost per sample, x Cook-Torrance: " + ", ".join(
        f"{k} {v['ratio_to_cook_torrance']:.2f}" for k, v in res.items()
        if not k.startswith("_") and not k.startswith("Cook")))
    return res


def tracer(lc, progress) -> dict:
    res = bench_lee.tracer_vs_closed_form(lc.tracer_cases, n=lc.tracer_n, target=lc.target,
                                          quad_orders=lc.quad_orders, quad_ref=lc.quad_ref,
                                          progress=progress)
    progress("Lee tracer / closed form at equal albedo error: " + ", ".join(
        f"{k} x{v['tracer_over_closed_form']:.3g}" for k, v in res.items()))
    return res


def moments(lc, progress) -> dict:
    res = bench_lee.moments_accuracy(lc.moment_mus, lc.moment_alphas, lc.moment_grooves,
                                     lc.moment_distributions, progress=progress)
    worst = max(v["max_abs_error"] for v in res.values())
    progress(f"Lee moment rules: max abs error {worst:.2g}")
    return res


# -- plot ------------------------------------------------------------------------------------
def _draw_furnace_image(ax, layout, image, labels, alphas):
    """The furnace grid as rendered, linear, with dotted outlines of the spheres."""
    from matplotlib.patches import Circle

    ax.imshow(np.clip(np.nan_to_num(image[..., :3]), 0.0, 1.0), interpolation="nearest")
    ax.set_xticks([(c + 0.5) * layout.cell_px for c in range(len(alphas))])
    ax.set_xticklabels([f"alpha {a:g}" for a in alphas], fontsize=8)
    ax.set_yticks([(r + 0.5) * layout.cell_px for r in range(len(labels))])
    ax.set_yticklabels(labels, fontsize=8)
    ax.set_title("White furnace (L = 1), linear: a sphere keeping all energy vanishes",
                 fontsize=8)
    scale = max(layout.width, layout.height) / layout.ortho_scale
    for x, y in layout.centers():
        ax.add_patch(Circle((layout.width / 2 + x * scale - 0.5,
                             layout.height / 2 - y * scale - 0.5),
                            layout.radius * scale, fill=False, lw=0.6, ls=":",
                            color="tab:blue"))


def _draw_furnace_means(ax, labels, alphas, means, noise):
    """The sphere means (with their noise) against alpha, one curve per model."""
    for i, label in enumerate(labels):  # Lee rows coincide at 1: told apart by style
        lee = label.startswith("Lee")
        ax.errorbar(alphas, means[label], yerr=noise[label], marker="os^Dvp"[i % 6],
                    ms=6 - 1.5 * i if lee else 3, mfc="none" if lee else None, capsize=2,
                    lw=2.4 - 0.7 * i if lee else 1.2, ls="-" if not lee else "--",
                    label=label)
    ax.axhline(1.0, color="k", lw=0.6)
    ax.set_xlabel("alpha (= roughness^2)", fontsize=8)
    ax.set_ylabel("sphere mean (mu >= 0.05)", fontsize=8)
    ax.set_title("Energy kept: multiple vs single scattering", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, frameon=False)
    ax.grid(alpha=0.3)


def plot_lee_furnace(furnace, path, dpi=80):
    """The furnace grid as rendered (linear, 1 = white: a sphere that keeps all the energy
    vanishes, the loss reads as darkening; dotted outlines mark the spheres) beside the
    sphere means against alpha."""
    plt = _plt()
    fig, (ax_img, ax_plot) = plt.subplots(1, 2, figsize=(11, 4.6), dpi=dpi,
                                          gridspec_kw={"width_ratios": [1.15, 1]})
    _draw_furnace_image(ax_img, furnace["layout"], furnace["image"], furnace["labels"],
                        furnace["alphas"])
    _draw_furnace_means(ax_plot, furnace["labels"], furnace["alphas"], furnace["means"],
                        furnace["noise"])
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- page ------------------------------------------------------------------------------------
def page(cfg, rows, res) -> list:
    """Section 5's Markdown lines ([] when it was not run)."""
    lee = res.get("lee")
    if not lee:
        return []
    lc = cfg.lee
    L = ["## 5. Lee 2018 (V-grooves)\n",
         "Lee, Jarabo, Jeon, Gutierrez, Kim 2018: multiple mirror reflection inside V-grooves in "
         "closed form (`lee_vgroove`, `osl/lee_vgroove.osl`, numpy twin `addon/lab/reference/lee/`). "
         "Measured by `addon/lab/bench_lee.py` (`python -m addon.lab.bench_lee` runs it alone)"
         + (" at this mode's smaller settings, stated below." if cfg.mode != "full" else ".") + "\n"]
    if lee.get("furnace"):
        L += furnace_lines(lee["furnace"])
    if lee.get("cost"):
        L += cost_lines(lee["cost"])
    if lee.get("tracer"):
        L += tracer_lines(lc, lee["tracer"])
    if lee.get("moments"):
        L += moment_lines(lc, lee["moments"])
    return L


def furnace_lines(f) -> list:
    alphas, means, noise = f["alphas"], f["means"], f["noise"]
    last = {k: v[-1] for k, v in means.items()}
    return [
        "### White furnace\n",
        f"A uniform white environment (L = 1), one row of spheres per model, alpha = "
        f"{', '.join(f'{x:g}' for x in alphas)} (roughness = sqrt(alpha)), {f['samples']} "
        f"samples per pixel, {f['cell_px']} px cells. A sphere that keeps all the energy is 1 "
        "everywhere and vanishes against the background; single scattering darkens, most at "
        "the rim.\n",
        "![Lee white furnace](lee_furnace.png)\n",
        "Sphere mean (pixels with mu >= 0.05, green channel) ± its standard error (pixel "
        "spread / sqrt(pixels): an upper bound where the expected value varies over the "
        "sphere, as for single scattering). Lee with F = 1: every sample weighs exactly 1, "
        "so zero noise. Walter GGX: height-correlated Smith, F = 1. Cook-Torrance: Beckmann, "
        "V-cavities, F >= 0.9996 (conductor n = 0.001, k = 100: the model has no F = 1 "
        "option). Cycles multi-GGX: `microfacet_multi_ggx_aniso`, white albedo.\n",
        bench_lee.furnace_markdown(alphas, means, noise),
        "",
        f"At alpha = {alphas[-1]:g} Lee keeps {last['Lee symmetric GGX']:.4f} of the energy, "
        f"Cycles' multi-GGX {last['Cycles multi-GGX']:.4f}; single scattering loses "
        f"{1 - last['Walter GGX (single)']:.0%} (Walter GGX) and "
        f"{1 - last['Cook-Torrance (single)']:.0%} (Cook-Torrance).\n"]


def cost_lines(c) -> list:
    st = c["_setup"]
    lo, hi = st["samples"]
    L = ["### Render cost per sample: Lee shader against Cook-Torrance\n",
         f"Gold, white furnace, one row of {st['spheres_per_row']} spheres (roughness "
         f"{', '.join(f'{r:g}' for r in st['roughness'])}, {st['cell_px']} px cells) per "
         "shader, all rows in ONE scene (scene sync and OSL JIT done once before timing, "
         f"{st['setup_seconds']:.1f} s). Each row rendered alone through a render border at "
         f"{lo} and {hi} samples, rows interleaved, {st['repeats']} repeats: the time per "
         f"sample is (t({hi}) - t({lo})) / {hi - lo}, which cancels the per-render overhead. "
         "Each number is taken within a repeat (rows rendered moments apart share the "
         "machine's load) and the median over the repeats shown; for the ratio to "
         "Cook-Torrance also its range.\n",
         f"| shader | ms per sample (row) | x Cook-Torrance | range over repeats | "
         f"render at {hi} samples (s) |",
         "|---|---|---|---|---|"]
    for k, v in c.items():
        if k.startswith("_"):
            continue
        L.append(f"| {k} | {v['ms_per_sample']:.3g} | **{v['ratio_to_cook_torrance']:.2f}** | "
                 f"{v['ratio_min']:.2f} - {v['ratio_max']:.2f} | {v[f'seconds_at_{hi}']:.3g} |")
    L.append("")
    return L


def _secs(t):
    return f"{t:.3g} s" if t >= 0.01 else f"{t * 1000:.2g} ms"


def tracer_lines(lc, t) -> list:
    L = ["### Closed form against the brute-force tracer: time to the same albedo error\n",
         f"Directional albedo (green channel, gold, symmetric grooves) to an error of "
         f"{lc.target:g}. Closed form: the deterministic quadrature `lee.albedo` of order n "
         f"(n x n/2 groove normals); its error is the difference from order {lc.quad_ref} "
         f"(which itself moves by at most "
         f"{max(v['quad_ref_change'] for v in t.values()):.1g} from order {lc.quad_ref // 2}); "
         "the time is that of the first order from which every larger one is within the "
         f"target. Analytic sampler (`lee.sample`, what the shader does) and brute-force "
         f"tracer (`vgroove.trace`, rays bounced in explicit grooves): {lc.tracer_n:,} samples "
         "each, time scaled to a standard error equal to the target (t (s / target)^2). "
         "Last column: tracer mean - closed form, in the tracer's standard errors (a "
         "few units either way are chance).\n",
         "| case | albedo | closed form: order, time | analytic sampler | brute-force tracer | "
         "tracer / closed form | tracer / sampler | tracer - closed form (s.e.) |",
         "|---|---|---|---|---|---|---|---|"]
    for k, v in t.items():
        cf = (f"{v['closed_form_order']}, {_secs(v['closed_form_s'])}"
              if v["closed_form_order"] else "not reached")
        L.append(f"| {k} | {v['albedo_G']:.5f} | {cf} | {_secs(v['sampler_s'])} | "
                 f"{_secs(v['tracer_s'])} | **{v['tracer_over_closed_form']:.3g}** | "
                 f"{v['tracer_over_sampler']:.2f} | {v['tracer_z']:+.1f} |")
    L.append("")
    return L


def moment_lines(lc, m) -> list:
    L = ["### Accuracy of the moment rules\n",
         "The directional moments (E, Vn, Vt) that the reference image is built from "
         "(`lee.moments`, default rules `lee.MOMENT_NODES`) against rules with about 8x the "
         "nodes (symmetric: a 384 x 384 tensor rule; asymmetric: 8x the partner points), gold, "
         f"at mu = {', '.join(f'{x:g}' for x in lc.moment_mus)}.\n",
         "| grooves, distribution, alpha | max abs error of (E, Vn, Vt) | seconds per mu "
         "(default rule) |",
         "|---|---|---|"]
    for k, v in m.items():
        L.append(f"| {k} | {v['max_abs_error']:.2g} | {v['seconds_per_mu']:.3g} |")
    L.append("")
    return L
