"""Section 1, error against render time: every row (model variant x sampler, and Cycles'
native closure) rendered on a sphere grid per environment at each sample count, its relative
RMSE against the numpy reference against the wall clock of the render; the time to TARGET,
its ratio to the native closure, the plots and the page text."""
from __future__ import annotations

import math
import time

import numpy as np

from . import optix
from .config import (AREA_LAMP, CONE_LIGHTS, HDRI_SIZE, LAMP_ENVS, MU_MIN_RMSE, POINT_LAMP,
                     SPOT_STRENGTH, SUN_ANGLE_DEG, SUN_DIRECTION, SUN_STRENGTH, SUN_WORLD, TARGET)
from .plotting import SAMPLER_STYLE, _plt, to_display
from .references import reference_image, relative_rmse
from .rows import (RATIO_TO, SELF_REFERENCE_FACTOR, eval_is_fast, self_referenced, specs_for,
                   twin)
from .lights import cone_radiance
from .scenes import build_env_scene, calibrate_sun


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    """The section's measurements and plots (and the OptiX comparison where bpy has one)."""
    sun_cal = calibrate_sun(progress) if set(CONE_LIGHTS) & set(cfg.envs) else None
    conv = convergence(cfg, rows, tables, progress, sun_cal)
    table = time_table(conv, rows)
    plot_convergence(conv, rows, out / "rmse_vs_time.png")
    plot_grids(conv, rows, out / "grids.png")
    gpu = optix.compare_if_available(cfg, rows, tables, progress, notes)
    return {"conv": conv, "table": table, "sun_cal": sun_cal, "gpu": gpu}


# -- measurement -----------------------------------------------------------------------------
def rows_per_env(cfg, rows) -> dict:
    """The rows run under each environment: under a lamp only those held to a render of
    themselves or whose numpy eval is fast enough for the lamp quadrature of every pixel."""
    if cfg.mode == "smoke":  # the study's code runs the same for either estimator's row
        rows = [r for r in rows if not _has_light_sampled_twin(r, rows)]
    fast = {None: True}  # a self-referenced row needs no numpy term
    for row in rows:
        model_id, values = twin(row, LAMP_ENVS[0])
        if model_id not in fast:
            fast[model_id] = eval_is_fast(model_id, values)
    return {e: [r for r in rows if e not in LAMP_ENVS or fast[twin(r, e)[0]]] for e in cfg.envs}


def _has_light_sampled_twin(row, rows) -> bool:
    """A row of the Stochastic estimator beside the same sampler's Native + Residual row."""
    return any(r.variant == row.variant and r.sampler == f"{row.sampler} + native"
               for r in rows)


def convergence(cfg, rows, tables, progress, sun_cal=None) -> dict:
    out = {"envs": {}, "setup_seconds": {}, "sun_quadrature_error": {}, "left_out": {}}
    env_rows = rows_per_env(cfg, rows)
    for e, rs in env_rows.items():
        left = [r.key for r in rows if r not in rs]
        if left:
            out["left_out"][e] = left
    count = [0, sum(len(rs) for rs in env_rows.values()) * len(cfg.samples)]  # done, total
    for env_key in cfg.envs:
        measure_env(cfg, env_key, env_rows[env_key], tables, progress, sun_cal, out, count)
    return out


def measure_env(cfg, env_key, rows, tables, progress, sun_cal, out, count):
    """One environment: its scene (set up once), the reference, every row's curve into `out`."""
    from .. import harness

    progress(f"{env_key}: building the scene ({len(rows)} rows x {len(cfg.roughness)} spheres)")
    t0 = time.perf_counter()
    scene, layout = build_env_scene(rows, cfg, env_key, sun_cal=sun_cal)
    harness.render(scene)  # sync + OSL JIT, once
    out["setup_seconds"][env_key] = time.perf_counter() - t0
    progress(f"{env_key}: scene sync and OSL JIT {out['setup_seconds'][env_key]:.1f} s; "
             f"reference images")
    specs = [s for row in rows for s in specs_for(row, cfg.roughness, env_key)]
    sun = cone_radiance(env_key, sun_cal) if env_key in CONE_LIGHTS else None
    reference, sun_err = reference_image(layout, specs, env_key, tables, sun, cfg.sun_nodes)
    out["sun_quadrature_error"][env_key] = sun_err
    series, finals = render_rows(cfg, env_key, rows, scene, layout, reference, progress, count)
    out["envs"][env_key] = {"series": series, "image": finals, "reference": reference,
                            "layout": layout}


def render_rows(cfg, env_key, rows, scene, layout, reference, progress, count):
    """Each row alone (a render border, the other rows hidden) at every sample count: ({row
    key: [(samples, seconds, relative RMSE)]}, the grid at the largest count)."""
    from .. import harness

    index, _, mu = layout.pixel_geometry()
    series = {}
    finals = np.zeros((layout.height, layout.width, 3))
    for r, row in enumerate(rows):
        harness.render_row_alone(scene, layout, r)
        sel = (index >= r * layout.cols) & (index < (r + 1) * layout.cols) & (mu > MU_MIN_RMSE)
        band = slice(r * layout.cell_px, (r + 1) * layout.cell_px)
        if self_referenced(row, env_key):
            reference[band] = _self_reference(cfg, scene, r, progress, env_key, row)[band, :, :3]
        pts = []
        for k, spp in enumerate(cfg.samples):
            count[0] += 1
            progress(f"{env_key}: {row.key}, {spp} samples", count[0], count[1])
            scene.cycles.samples = spp
            scene.cycles.seed = cfg.seed + 1000 * k + r + 1
            image, seconds = harness.render(scene)
            pts.append((spp, seconds, relative_rmse(image, reference, sel)))
        finals[band] = image[band, :, :3]
        series[row.key] = pts
    return series, finals


def _self_reference(cfg, scene, r, progress, env_key, row):
    """A row's reference rendered by itself at SELF_REFERENCE_FACTOR times the largest count."""
    from .. import harness

    spp = SELF_REFERENCE_FACTOR * max(cfg.samples)
    progress(f"{env_key}: {row.key}, its own reference at {spp} samples")
    scene.cycles.samples = spp
    scene.cycles.seed = cfg.seed + 7919 * (r + 1)
    image, _ = harness.render(scene)
    return image


def time_to_target(points, target=TARGET):
    """(seconds, how): interpolated on the log-log curve where it crosses `target`; beyond the
    last point extrapolated with the 1/sqrt(t) slope ('extrapolated'), or 'floor' when the last
    points stop falling (a bias); 'first' when the first point is already below."""
    t = np.array([p[1] for p in points], float)
    e = np.array([p[2] for p in points], float)
    below = np.nonzero(e <= target)[0]
    if len(below):
        k = int(below[0])
        if k == 0:
            return float(t[0]), "first"
        x0, x1 = np.log(e[k - 1]), np.log(e[k])
        y0, y1 = np.log(max(t[k - 1], 1e-6)), np.log(max(t[k], 1e-6))
        f = (np.log(target) - x0) / (x1 - x0) if x1 != x0 else 1.0
        return float(np.exp(y0 + f * (y1 - y0))), "interpolated"
    if len(e) >= 3 and e[-1] > 0.8 * e[-3]:
        return float("inf"), "floor"
    return float(t[-1] * (e[-1] / target) ** 2), "extrapolated"


def time_table(conv, rows) -> list:
    """Per env and row: time to TARGET and its ratio to the native closure of the variant (or of
    the variant RATIO_TO names)."""
    table = []
    for env_key, data in conv["envs"].items():
        env_rows = [row for row in rows if row.key in data["series"]]
        times = {row.key: time_to_target(data["series"][row.key]) for row in env_rows}
        native = {row.variant: times[row.key][0] for row in env_rows if row.sampler == "native"}
        for row in env_rows:
            t, how = times[row.key]
            nat = native.get(RATIO_TO.get(row.variant, row.variant))
            ratio = t / nat if nat and math.isfinite(t) and math.isfinite(nat) else None
            last = data["series"][row.key][-1]
            table.append({"env": env_key, "row": row.key, "variant": row.variant,
                          "sampler": row.sampler, "seconds": t, "how": how, "ratio": ratio,
                          "final_rmse": last[2], "final_samples": last[0]})
    return table


# -- plots -----------------------------------------------------------------------------------
ENV_TITLES = {"white": "white furnace", "gradient": "smooth gradient",
              **{k: {"lamp": f"sun lamp {a:g} deg", "world": f"world spot {a:g} deg, no lamp",
                     "image": f"HDRI spot {a:g} deg (image), no lamp"}[kind]
                 + " over dim world" for k, (kind, a) in CONE_LIGHTS.items()},
              "point": f"point lamp r {POINT_LAMP['radius']:g} at {POINT_LAMP['height'] - 1:g} "
                       "over dim world",
              "area": "area lamp {:g} x {:g} over dim world".format(*AREA_LAMP["size"])}


def _plot_env_curves(ax, series, rows, colors):
    """One environment's panel: a curve per row, the 1/sqrt(t) slope and the target."""
    for row in rows:
        if row.key not in series:
            continue
        pts = np.array(series[row.key], float)
        native = row.sampler == "native"
        ax.loglog(np.maximum(pts[:, 1], 1e-4), pts[:, 2], SAMPLER_STYLE.get(row.sampler, "-"),
                  color="k" if native and False else colors[row.variant],
                  lw=2.6 if native else 1.2, marker="o" if native else ".", ms=3,
                  label=f"{row.variant} / {row.sampler}")
    t = np.array([p[1] for pts in series.values() for p in pts])
    e = np.array([p[2] for pts in series.values() for p in pts])
    t0, e0 = np.median(t), np.median(e) * 2.5
    tt = np.array([t.min(), t.max()]) if t.min() > 0 else np.array([1e-3, t.max()])
    ax.loglog(tt, e0 * np.sqrt(t0 / tt), color="0.4", lw=1, ls="-.", label="slope 1/sqrt(t)")
    ax.axhline(TARGET, color="0.6", lw=0.8)


PANEL_COLUMNS = 4  # environments per row of panels (eight in one row were too wide to read)


def plot_convergence(conv, rows, path, dpi=72):
    plt = _plt()
    envs = list(conv["envs"])
    ncols = min(PANEL_COLUMNS, len(envs))
    nrows = -(-len(envs) // ncols)
    legend = 4.0  # inches kept free for the legend on the right
    width = 4.3 * ncols + legend
    fig, axes = plt.subplots(nrows, ncols, figsize=(width, 4.2 * nrows), dpi=dpi,
                             squeeze=False)
    variants = list(dict.fromkeys(r.variant for r in rows))
    colors = {v: plt.cm.tab10(i % 10) for i, v in enumerate(variants)}
    for ax in axes.flat[len(envs):]:
        ax.set_visible(False)
    for ax, env_key in zip(axes.flat, envs):
        _plot_env_curves(ax, conv["envs"][env_key]["series"], rows, colors)
        ax.set_title(ENV_TITLES.get(env_key, env_key), fontsize=9)
        ax.set_xlabel("render time per row (s)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    for line in axes:
        line[0].set_ylabel("relative RMSE vs numpy reference", fontsize=8)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=6.5, frameon=False)
    fig.tight_layout(rect=(0, 0, 1 - legend / width, 1))
    fig.savefig(path)
    plt.close(fig)


def plot_grids(conv, rows, path, dpi=70):
    plt = _plt()
    envs = list(conv["envs"])
    fig, axes = plt.subplots(1, 2 * len(envs), figsize=(2.1 * 2 * len(envs), 0.33 * len(rows) + 1),
                             dpi=dpi, squeeze=False)
    for i, env_key in enumerate(envs):
        d = conv["envs"][env_key]
        for j, (title, img) in enumerate((("render", d["image"]), ("reference", d["reference"]))):
            ax = axes[0][2 * i + j]
            ax.imshow(to_display(img), interpolation="nearest")
            ax.set_title(f"{env_key}: {title}", fontsize=7)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- page ------------------------------------------------------------------------------------
def page(cfg, rows, res) -> list:
    """Section 1's Markdown lines ([] when it was not run)."""
    conv, table, sun_cal = res.get("conv"), res.get("table"), res.get("sun_cal")
    if not conv:
        return []
    by = {(t["env"], t["row"]): t for t in table}
    envs = list(conv["envs"])
    L = _intro_lines(cfg, conv) + _sun_lines(cfg, conv, sun_cal)
    L.append("![relative RMSE against render time](rmse_vs_time.png)\n")
    rows = [r for r in rows if any((e, r.key) in by for e in envs)]  # the smoke run's subset
    L += _time_lines(rows, envs, by) + _final_rmse_lines(cfg, rows, envs, by)
    for e, left in conv.get("left_out", {}).items():
        L.append(f"Not run under {e}: {', '.join(left)} (numpy eval too slow for the sun-disk "
                 "quadrature of every pixel).\n")
    L.append(f"Renders at {cfg.samples[-1]} samples and references: ![grids](grids.png)\n")
    return L


def _intro_lines(cfg, conv) -> list:
    return ["## 1. Error against render time\n",
            f"Each model variant x sampler (and Cycles' native closure for the same BSDF) is one "
            f"row of {len(cfg.roughness)} spheres, roughness {', '.join(map(str, cfg.roughness))}, "
            f"{cfg.cell_px} px cells, rendered at {', '.join(map(str, cfg.samples))} samples per "
            "pixel. Error: relative RMSE = RMS over the row's sphere pixels (mu > 0.05) and RGB of "
            "render - reference, over the mean reference. Time: wall clock of the render call for "
            "that row alone (render border, persistent data: the one-off scene sync and OSL JIT "
            "per environment, " + ", ".join(f"{k} {v:.1f} s" for k, v in conv["setup_seconds"].items())
            + ", are not included). Lee's V-grooves and Heitz 2016 are timed against Cycles' "
            "multiscatter GGX gold (`conductor_bsdf` \"multi_ggx\"), a different model with no "
            "numpy twin: its error is measured against its own render at "
            f"{SELF_REFERENCE_FACTOR} times the largest sample count "
            f"({SELF_REFERENCE_FACTOR * max(cfg.samples)}), Lee's against Lee's numpy "
            "reference. Under the lamps Heitz 2016's rows are held to renders of themselves "
            "too (its numpy evaluation is a walk, too noisy for a per-pixel lamp quadrature): "
            "their error there is noise alone, which is what the time to 1% measures; the "
            "render tests hold the model to numpy.\n"]


def _sun_lines(cfg, conv, sun_cal) -> list:
    if not sun_cal:
        return []
    return [f"Sun: {SUN_ANGLE_DEG:g} degree disk, strength {SUN_STRENGTH:g}, direction "
            f"{SUN_DIRECTION}, over a uniform world of {SUN_WORLD}. Its radiance as Cycles "
            f"renders it, read off a mirror sphere at one sample: {sun_cal['radiance']:.3f} "
            f"(spread {sun_cal['spread']:.2g} over {sun_cal['pixels_inside']} pixels; "
            f"strength / (2 pi (1 - cos(angle/2))) = {sun_cal['formula']:.3f}). The reference is "
            f"{SUN_WORLD} E(mu) plus the radiance times a product Gauss rule of f |wo.n| over "
            f"the sun's cone ({cfg.sun_nodes[0]} x {cfg.sun_nodes[1]} nodes; the half-order rule "
            f"differs by at most {max(conv['sun_quadrature_error'].values(), default=0):.2g} "
            "absolute). Delta-lobe shaders find the sun only by chance; native closures sample "
            "it.\n",
            "Further cone lights, the same reference with their own radiance and angle: "
            + "; ".join(f"`{k}`: " + (f"a sun lamp of {a:g} degrees, strength {SUN_STRENGTH:g}, "
                                      "radiance scaled by the 4-degree calibration"
                                      if kind == "lamp" else
                                      f"no lamp, a {a:g}-degree spot painted into the world "
                                      f"(irradiance {SPOT_STRENGTH:g} at normal incidence), lit "
                                      "by Cycles' world importance sampling, not read by the "
                                      "add-on" if kind == "world" else
                                      f"the same spot drawn in the pixels of a "
                                      f"{HDRI_SIZE[0]} x {HDRI_SIZE[1]} equirectangular image "
                                      "(Closest), which the add-on finds and hands over; its "
                                      "reference integrates the pixel cells")
                        for k, (kind, a) in CONE_LIGHTS.items() if k != "sun" and k in cfg.envs)
            + ". Under the 0.5-degree sun the quick report's 256 samples are a low-sample "
            "count for any estimator that finds the sun by chance: its RMSE there is "
            "extrapolated from points before the rare hits are drawn (the low-spp trap).\n"]


def _fmt_t(t, how):
    if how == "floor" or not math.isfinite(t):
        return "not reached (error stops falling)"
    s = f"{t:.3g} s" if t >= 0.01 else f"{t * 1000:.2g} ms"
    return {"extrapolated": f"~{s} (extrapolated)", "first": f"<= {s} (1st point)"}.get(how, s)


def _time_lines(rows, envs, by) -> list:
    """The time-to-target table: per row and environment the time and the ratio to native."""
    L = [f"Time to {TARGET:.0%} relative RMSE (interpolated on the log-log curve; beyond the "
         "last point extrapolated along 1/sqrt(t)) and its ratio to the native closure for the "
         "same BSDF measured in the same run:\n",
         "| model variant / sampler | " + " | ".join(f"{e}: time | {e}: x native" for e in envs) + " |",
         "|---|" + "---|---|" * len(envs)]
    for row in rows:
        cells = []
        for e in envs:
            t = by.get((e, row.key))
            if t is None:
                cells += ["not run", "-"]
                continue
            cells.append(_fmt_t(t["seconds"], t["how"]))
            cells.append("-" if row.sampler == "native" else
                         (f"{t['ratio']:.2g}" if t["ratio"] is not None else "n/a"))
        L.append(f"| {row.key} | " + " | ".join(cells) + " |")
    L.append("")
    L.append("'not reached (error stops falling)': the error levels off above the target over the "
             "last points, i.e. a bias against the reference (or, under the sun, noise too heavy "
             "to fall yet); the RMSE at the largest sample count is below. Ratios > 1: slower "
             "than the native closure.\n")
    return L


def _final_rmse_lines(cfg, rows, envs, by) -> list:
    L = [f"Relative RMSE at {cfg.samples[-1]} samples:\n",
         "| model variant / sampler | " + " | ".join(envs) + " |",
         "|---|" + "---|" * len(envs)]
    for row in rows:
        L.append(f"| {row.key} | " + " | ".join(f"{by[(e, row.key)]['final_rmse']:.4f}"
                                               if (e, row.key) in by else "not run" for e in envs) + " |")
    L.append("")
    return L
