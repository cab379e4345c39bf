"""Section 2, the samplers: Walter D cos against visible normals (Smith) against V-cavity
visible normals in numpy (variance and maximum of the sample weight against incidence and
roughness), and a firefly picture of rough spheres at 4 samples; plots and page text."""
from __future__ import annotations

import math

import numpy as np

from .. import grid, stability
from ..reference import make_bsdf
from ..reference.quadrature import moments_at
from ...catalog import MODELS
from .config import MU_MIN_RMSE
from .plotting import _plt, to_display
from .references import ReferenceTables, relative_rmse

FIREFLY_ROWS = (  # (label, model, values): F = 1 reflection, and rough glass (issue 3)
    ("Walter GGX reflection, F = 1", "walter_reflection",
     {"distribution": "ggx", "fresnel_type": "none", "roughness": 0.6}),
    ("Walter GGX glass, IOR 1.5", "walter_glass",
     {"distribution": "ggx", "ior": 1.5, "roughness": 0.6}),
)
FIREFLY_SAMPLERS = ("dcos", "vndf")


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    """The section's measurements and plots."""
    study = sampler_study(cfg, progress)
    plot_sampler_study(study, cfg, out / "sampler_weights.png")
    ff = fireflies(cfg, progress, out)
    plot_fireflies(ff, out / "fireflies.png")
    return {"study": study, "ff": ff}


# -- measurement -----------------------------------------------------------------------------
def _study_values(model, sampler, roughness):
    ids = {p.id for p in model.params}
    v = {"roughness": roughness, "sampler": sampler}
    if "fresnel_type" in ids and "none" in model.param("fresnel_type").items:
        v["fresnel_type"] = "none"
    elif "fresnel_type" in ids:  # a nearly perfect conductor: F ~ 1
        v.update(fresnel_type="conductor", n=(1.0, 1.0, 1.0), k=(100.0,) * 3)
    if "specular" in ids:
        v["specular"] = 1.0
    return v


def weight_stats(bsdf, thetas, n_samples, rng) -> dict:
    """Variance, maximum and mean of the sample weight (mean over RGB) per incidence angle."""
    var, mx, mean = [], [], []
    for th in thetas:
        t = math.radians(th)
        wi = np.array([math.sin(t), 0.0, math.cos(t)])
        u = rng.random((n_samples, stability.U_DIMS))
        _, w, _ = stability._sample(bsdf, np.broadcast_to(wi, (len(u), 3)), u)
        w = np.asarray(w, float).mean(-1)
        var.append(float(w.var()))
        mx.append(float(w.max()))
        mean.append(float(w.mean()))
    return {"variance": var, "max": mx, "mean": mean}


def sampler_study(cfg, progress) -> dict:
    """Per model with a sampler switch: variance and maximum of the sample weight (F ~ 1)
    against incidence angle, per sampler and roughness."""

    rng = np.random.default_rng(cfg.seed + 11)
    out = {}
    for model_id, model in MODELS.items():
        if not any(p.id == "sampler" for p in model.params):
            continue
        try:
            make_bsdf(model_id, {})
        except Exception:  # noqa: BLE001
            continue
        res = {}
        for sampler in model.param("sampler").items:
            for r in cfg.study_roughness:
                bsdf = make_bsdf(model_id, _study_values(model, sampler, r))
                res[(sampler, r)] = weight_stats(bsdf, cfg.study_thetas, cfg.study_samples, rng)
        out[model_id] = res
        progress(f"sampler study: {model.label} done")
    return out


def fireflies(cfg, progress, out_dir) -> dict:
    """Rough spheres (roughness 0.6; reflection with F = 1, and glass) at 4 samples with D cos
    and with visible normals, beside the reference: the rim is the grazing view."""
    from .. import harness

    specs = [grid.SphereSpec(model, {**values, "sampler": s}, f"{label}, {s}")
             for label, model, values in FIREFLY_ROWS for s in FIREFLY_SAMPLERS]
    layout, image, _ = harness.render_specs(specs, grid.GRADIENT, 4, seed=5,
                                            cols=len(FIREFLY_SAMPLERS), cell_px=cfg.fireflies_px)
    tables = ReferenceTables(cfg.moment_order, cfg.walk_moments)
    ref = grid.reference_image(layout, [tables.get(s) for s in specs], grid.GRADIENT, moments_at)
    index, _, mu = layout.pixel_geometry()
    stats = {}
    for i, s in enumerate(specs):
        sel = index == i
        rim = sel & (mu < 0.3)
        stats[s.label] = {"max": float(image[..., :3][sel].max()),
                          "rmse": relative_rmse(image, ref, sel & (mu > MU_MIN_RMSE)),
                          "rim_rmse": relative_rmse(image, ref, rim)}
    progress("fireflies rendered")
    return {"layout": layout, "image": image, "reference": ref, "stats": stats}


# -- plots -----------------------------------------------------------------------------------
def plot_sampler_study(study, cfg, path, dpi=70):
    plt = _plt()
    models = list(study)
    if not models:
        return
    fig, axes = plt.subplots(len(models), 2, figsize=(9.5, 2.9 * len(models)), dpi=dpi,
                             squeeze=False)
    colors = {"dcos": "tab:red", "vndf": "tab:blue", "vcavity": "tab:green"}
    styles = ["-", "--", "-.", ":"]
    for i, model_id in enumerate(models):
        for (sampler, r), d in study[model_id].items():
            ls = styles[list(cfg.study_roughness).index(r) % 4]
            for j, key in enumerate(("variance", "max")):
                axes[i][j].semilogy(cfg.study_thetas, np.maximum(d[key], 1e-8), ls,
                                    color=colors.get(sampler, "k"), lw=1.2,
                                    label=f"{sampler} r={r}")
        axes[i][0].set_ylabel(f"{MODELS[model_id].label}\nvariance of weight", fontsize=8)
        axes[i][0].set_ylim(bottom=1e-8)
        axes[i][1].set_ylabel(f"max weight ({cfg.study_samples} samples)", fontsize=8)
        for ax in axes[i]:
            ax.tick_params(labelsize=7)
            ax.grid(True, which="both", lw=0.3, alpha=0.5)
    for ax in axes[-1]:
        ax.set_xlabel("incidence angle (deg)", fontsize=8)
    axes[0][1].legend(fontsize=6.5, ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_fireflies(ff, path, dpi=90):
    """One row per FIREFLY_ROWS entry: D cos, visible normals, the numpy reference."""
    plt = _plt()
    layout, image, ref = ff["layout"], ff["image"], ff["reference"]
    c = layout.cell_px
    titles = ("D cos (Walter), 4 spp", "visible normals, 4 spp", "numpy reference")
    fig, axes = plt.subplots(len(FIREFLY_ROWS), 3, figsize=(7.2, 2.5 * len(FIREFLY_ROWS)),
                             dpi=dpi, squeeze=False)
    for r, (label, _, _) in enumerate(FIREFLY_ROWS):
        rows = slice(r * c, (r + 1) * c)
        panels = (image[rows, :c], image[rows, c:2 * c], ref[rows, :c])
        for j, (ax, img) in enumerate(zip(axes[r], panels)):
            ax.imshow(to_display(img), interpolation="nearest")
            ax.set_title(f"{label}\n{titles[j]}" if j == 0 else titles[j], fontsize=8)
            ax.axis("off")
    fig.suptitle("Roughness 0.6, gradient environment", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- page ------------------------------------------------------------------------------------
def page(cfg, rows, res) -> list:
    """Section 2's Markdown lines ([] when it was not run)."""
    return _study_lines(cfg, res.get("study")) + _firefly_lines(res.get("ff"))


def _study_lines(cfg, study) -> list:
    if not study:
        return []
    L = ["## 2. The samplers: D cos against visible normals against V-cavity visible normals\n",
         f"numpy, F ~ 1 (Fresnel 'none' or a k = 100 conductor; Cook-Torrance with specular 1), "
         f"{cfg.study_samples} samples per point: variance and maximum of the sample weight "
         "f cos / pdf against incidence angle, per roughness.\n",
         "![sample weights](sampler_weights.png)\n"]
    thetas = list(cfg.study_thetas)
    pick = [th for th in (0.0, 60.0, 80.0, 89.0, 89.5, 89.9) if th in thetas] or thetas[:3]
    L.append("| model | sampler | roughness | "
             + " | ".join(f"var / max at {th:g} deg" for th in pick) + " |")
    L.append("|---|---|---|" + "---|" * len(pick))
    for model_id, res in study.items():
        for (sampler, r), d in res.items():
            cells = [f"{d['variance'][thetas.index(th)]:.3g} / {d['max'][thetas.index(th)]:.3g}"
                     for th in pick]
            L.append(f"| {MODELS[model_id].label} | {sampler} | {r} | " + " | ".join(cells) + " |")
    L.append("")
    return L


def _firefly_lines(ff) -> list:
    if not ff:
        return []
    L = ["Fireflies: rough spheres (reflection and glass) at 4 samples per pixel (the rim is "
         "the grazing view):\n",
         "![fireflies](fireflies.png)\n",
         "| sphere, sampler | max pixel | relative RMSE (mu > 0.05) | relative RMSE at the rim (mu < 0.3) |",
         "|---|---|---|---|"]
    for k, s in ff["stats"].items():
        L.append(f"| {k} | {s['max']:.3g} | {s['rmse']:.3f} | {s['rim_rmse']:.3f} |")
    L.append("")
    return L
