"""The "comparisons" section's lobes, pictures and costs (the seed's figures 21 and 23), beside the
albedo tables of multiple_scattering.py:

- lobe slices: f |cos_o| in the plane of incidence at 60 degrees, gold, for Lee's symmetric and
  asymmetric grooves (their closed-form evaluation), Heitz 2016 (the walk's stochastic
  evaluation, mean of many walks with its standard error) and single-scattering Walter
  (height-correlated GGX, closed form); the ratio of the back-scattered value (wo = wi) to the
  mirror direction's says how retro-reflective each surface is;
- rendered spheres: a row per model (gold under the gradient world, roughness 0.3, 0.6, 1), all
  rendered in this run with the same scene, light and samples;
- cost per sample: each row rendered at two sample counts, the difference of the render times
  over the difference of the samples (so scene set-up and shader compilation drop out), as a
  ratio to single-scattering Walter in the same run.
"""
from __future__ import annotations

import numpy as np

from ..grid import SphereSpec
from ..reference import make_bsdf

THETA_I = 60.0
LOBE_ROUGHNESS = (0.5, 1.0)
RENDER_ROUGHNESS = (0.3, 0.6, 1.0)
GOLD = {"fresnel_type": "conductor"}
# (label, catalog model, values): the seed's figure 23 set, on GGX slopes, gold.
VIEW_MODELS = (
    ("Lee symmetric", "lee_vgroove", {**GOLD, "groove": "symmetric"}),
    ("Lee asymmetric", "lee_vgroove", {**GOLD, "groove": "asymmetric"}),
    ("Heitz 2016", "heitz2016", {**GOLD}),
    ("Walter single (GGX)", "walter_reflection",
     {**GOLD, "masking": "height_correlated", "estimator": "stochastic"}),
)


def _in_plane(theta_deg):
    t = np.radians(np.asarray(theta_deg, dtype=float))
    return np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=-1)


def lobe_slices(walks: int, step: float, rng) -> dict:
    """f |cos_o| over theta_o in [-85, 85] degrees (negative: the mirror side, wo.x < 0; +60 is
    wo = wi) for each model and roughness, RGB, with standard errors (0 for closed forms)."""

    thetas = np.arange(-85.0, 85.0 + 1e-9, step)
    wo = _in_plane(thetas)
    wi = np.broadcast_to(_in_plane(THETA_I), wo.shape)
    slices = []
    for r in LOBE_ROUGHNESS:
        for label, model_id, values in VIEW_MODELS:
            bsdf = make_bsdf(model_id, {**values, "roughness": r})
            if model_id == "heitz2016":
                f, se = bsdf.walk.eval_mean(wi, wo, walks, rng, bsdf.max_order)
            else:
                f = np.asarray(bsdf.eval(wi, wo)) * np.abs(wo[:, 2:3])
                se = np.zeros_like(f)
            slices.append({"model": label, "roughness": r, "f_cos": f.tolist(),
                           "stderr": se.tolist()})
    return {"theta_i": THETA_I, "theta_o": thetas.tolist(), "walks": walks, "slices": slices}


def retro_ratio(theta_o, f_cos) -> float:
    """f at wo = wi over f at the mirror direction (RGB mean; cosines cancel, same theta)."""
    th = np.asarray(theta_o)
    f = np.asarray(f_cos).mean(axis=1)
    back = f[np.argmin(np.abs(th - THETA_I))]
    mirror = f[np.argmin(np.abs(th + THETA_I))]
    return float(back / mirror) if mirror > 0 else float("nan")


def _row_specs(model_id, values, label):
    return [SphereSpec(model_id, {**values, "roughness": r}, f"{label} r={r}")
            for r in RENDER_ROUGHNESS]


def rendered_rows(samples: int, cell_px: int, progress, repeats: int = 1) -> dict:
    """Each model's row under the gradient world at `samples` (the picture) and at samples / 4,
    timed `repeats` times in turn; cost per sample from the median difference. Returns images
    (not for results.json) and costs."""
    from .. import grid, harness

    rows, costs = [], []
    low = max(samples // 4, 1)
    for label, model_id, values in VIEW_MODELS:
        specs = _row_specs(model_id, values, label)
        # The render calls' own wall times (scene building excluded); their difference drops
        # what does not scale with the samples (sync, shader compilation).
        diffs = []
        for rep in range(repeats):
            _, _, t_low = harness.render_specs(specs, grid.GRADIENT, low, seed=11 + rep,
                                               cols=len(specs), cell_px=cell_px)
            layout, image, t_high = harness.render_specs(specs, grid.GRADIENT, samples,
                                                         seed=12, cols=len(specs),
                                                         cell_px=cell_px)
            diffs.append(t_high - t_low)
        per_sample = max(float(np.median(diffs)), 0.0) / (samples - low)
        rows.append(image[..., :3])
        costs.append({"model": label, "seconds_per_sample": per_sample,
                      "pixels": int(layout.width * layout.height)})
        progress(f"comparisons: rendered {label} ({per_sample * 1e3:.2f} ms per sample)")
    base = next(c["seconds_per_sample"] for c in costs if c["model"].startswith("Walter"))
    for c in costs:
        c["ratio_to_walter"] = c["seconds_per_sample"] / base if base > 0 else float("nan")
    return {"images": rows, "costs": costs, "samples": samples, "low_samples": low,
            "cell_px": cell_px, "repeats": repeats}


def plot_lobes(data, path):
    from .plotting import _plt

    plt = _plt()
    fig, axes = plt.subplots(1, len(LOBE_ROUGHNESS), figsize=(4.2 * len(LOBE_ROUGHNESS), 3.2),
                             squeeze=False)
    th = np.asarray(data["theta_o"])
    for j, r in enumerate(LOBE_ROUGHNESS):
        ax = axes[0, j]
        for s in data["slices"]:
            if s["roughness"] == r:
                ax.plot(th, np.asarray(s["f_cos"]).mean(axis=1), label=s["model"])
        ax.axvline(-THETA_I, color="0.8", lw=0.8)
        ax.axvline(THETA_I, color="0.8", lw=0.8, ls="--")
        ax.set_title(f"gold, roughness {r:g}, incidence {THETA_I:g} deg", fontsize=8)
        ax.set_xlabel("theta_o in the plane (deg; -60 mirror, +60 back toward the light)",
                      fontsize=7)
        ax.set_ylabel("f cos (RGB mean)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_spheres(data, path):
    from .plotting import _plt

    plt = _plt()
    n = len(data["images"])
    fig, axes = plt.subplots(n, 1, figsize=(1.6 * len(RENDER_ROUGHNESS), 1.7 * n), squeeze=False)
    for i, (img, cost) in enumerate(zip(data["images"], data["costs"])):
        ax = axes[i, 0]
        srgb = np.clip(img, 0.0, 1.0) ** (1 / 2.2)
        ax.imshow(srgb, origin="upper", interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_ylabel(cost["model"], fontsize=7)
    axes[0, 0].set_title("gold under the gradient world; roughness "
                         + ", ".join(f"{r:g}" for r in RENDER_ROUGHNESS), fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def page_lines(lobes, renders) -> list:
    lines = ["### Lobe slices (gold, incidence 60 degrees, plane of incidence)", "",
             f"Heitz 2016 by its stochastic evaluation ({lobes['walks']:,} walks per direction); "
             "Lee and Walter by their closed forms. Figure: `lobe_slices.png`. "
             "Back / mirror: f at wo = wi over f at the mirror direction.", "",
             "| roughness | model | back / mirror | f cos at the mirror | f cos back |",
             "|---|---|---|---|---|"]
    th = lobes["theta_o"]
    for s in lobes["slices"]:
        f = np.asarray(s["f_cos"]).mean(axis=1)
        lines.append(f"| {s['roughness']:g} | {s['model']} | {retro_ratio(th, s['f_cos']):.3f} | "
                     f"{f[np.argmin(np.abs(np.asarray(th) + THETA_I))]:.4f} | "
                     f"{f[np.argmin(np.abs(np.asarray(th) - THETA_I))]:.4f} |")
    lines += ["", "### Rendered side by side, and the cost per sample", "",
              f"Rows of {len(RENDER_ROUGHNESS)} spheres ({renders['cell_px']} px cells), each "
              f"rendered at {renders['low_samples']} and {renders['samples']} samples in this run "
              f"({renders.get('repeats', 1)} times in turn); cost per sample = the median "
              "difference of the render times over the difference of the samples. Figure: `comparison_spheres.png`.", "",
              "| model | ms per sample (row) | against Walter |", "|---|---|---|"]
    for c in renders["costs"]:
        lines.append(f"| {c['model']} | {c['seconds_per_sample'] * 1e3:.2f} | "
                     f"x{c['ratio_to_walter']:.2f} |")
    return lines + [""]
