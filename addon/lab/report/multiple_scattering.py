"""Section "comparisons": the seed's section 5 comparisons of multiple-scattering models, in numpy
(albedo over incidence and roughness; the seed's figures 21, 22 and 23):

- fig. 21: Lee's V-grooves, symmetric against asymmetric walls, at the same roughness;
- fig. 22: Lee against single-scattering Cook-Torrance (Beckmann, V-cavity) as roughness grows:
  the energy in the white furnace (F = 1), where single scattering darkens;
- fig. 23: Lee against Heitz et al. 2016 (the random walk on the Smith microsurface) and
  Walter's single scattering (height-correlated GGX), in the white furnace and for gold.

Albedos: Lee by its deterministic quadrature (lee.albedo, converged to 1e-5), Heitz 2016 by
its random walk (heitz2016, Monte Carlo with standard errors), single scattering by its
sampler's weights (Monte Carlo). Lobe slices, rendered spheres and the cost per sample:
comparison_views.py.
"""
from __future__ import annotations

import numpy as np

from ...catalog import MODELS
from . import comparison_views
from ..reference import lee
from ..reference.bsdf import MicrofacetBRDF
from ..reference.heitz2016 import HeitzConductor
from ..reference.microfacet import Microfacet

ROUGHNESS = (0.2, 0.5, 0.8, 1.0)
MODELS_SHOWN = ("Lee symmetric", "Lee asymmetric", "Heitz 2016", "Walter single (GGX)",
                "Cook-Torrance single (Beckmann, V-cavity)")


def _gold():
    p = MODELS["walter_reflection"]
    return p.param("n").default, p.param("k").default


def _albedo(model: str, roughness: float, fresnel: str, theta_deg: float, walks: int, rng):
    """(albedo RGB, standard error RGB) of one model at one incidence."""
    n, k = _gold() if fresnel == "conductor" else ((1.0,) * 3, (0.0,) * 3)
    alpha = roughness * roughness
    t = np.radians(theta_deg)
    wi = np.array([np.sin(t), 0.0, np.cos(t)])
    zero = np.zeros(3)
    if model.startswith("Lee"):
        groove = "asymmetric" if "asym" in model else "symmetric"
        quad = {"n": 128, "n_partner": 64} if groove == "asymmetric" else {}
        E = lee.albedo(wi, Microfacet("ggx", alpha), lee.fresnel_fn(fresnel, 1.5, n, k),
                       groove, **quad)
        return np.asarray(E).reshape(-1, 3)[0], zero
    if model == "Heitz 2016":
        a = HeitzConductor(Microfacet("ggx", alpha), fresnel, n=n, k=k).albedo(wi, walks, rng)
        return np.asarray(a.E).reshape(3), np.asarray(a.E_se).reshape(3)
    dist, masking = ("beckmann", "vcavity") if model.startswith("Cook") else ("ggx",
                                                                            "height_correlated")
    bsdf = MicrofacetBRDF(Microfacet(dist, alpha), masking, "vcavity" if masking == "vcavity"
                          else "vndf", fresnel, n=n, k=k)
    _, w, _ = bsdf.sample(np.broadcast_to(wi, (walks, 3)), rng.random((walks, 3)))
    return w.mean(axis=0), w.std(axis=0) / np.sqrt(walks)


def compute(cfg, rows, tables, progress, notes, out) -> dict:
    full = cfg.mode == "full"
    thetas = (0, 15, 30, 45, 60, 70, 80, 85) if full else (0, 30, 60, 80)
    walks = 1 << (17 if full else 13)
    roughness = ROUGHNESS if cfg.mode != "smoke" else (0.5,)
    rng = np.random.default_rng(cfg.seed)
    data = []
    for fresnel in ("none", "conductor"):
        for r in roughness:
            for model in MODELS_SHOWN:
                E = [_albedo(model, r, fresnel, t, walks, rng) for t in thetas]
                data.append({"fresnel": fresnel, "roughness": r, "model": model,
                             "albedo": [e[0].tolist() for e in E],
                             "stderr": [e[1].tolist() for e in E]})
            progress(f"comparisons: F {fresnel}, roughness {r}")
    result = {"thetas": thetas, "walks": walks, "curves": data}
    _plot(result, out / "multiple_scattering.png")
    # Lobes, rendered spheres and cost per sample (comparison_views.py).
    lobe_walks = 1 << (15 if full else 11)
    result["lobes"] = comparison_views.lobe_slices(lobe_walks, 5.0 if full else 10.0, rng)
    comparison_views.plot_lobes(result["lobes"], out / "lobe_slices.png")
    progress("comparisons: lobe slices")
    samples = {"full": 1024, "quick": 256}.get(cfg.mode, 16)
    renders = comparison_views.rendered_rows(samples, 96 if full else 64, progress,
                                            repeats=1 if cfg.mode == "smoke" else 3)
    comparison_views.plot_spheres(renders, out / "comparison_spheres.png")
    result["renders"] = {k: v for k, v in renders.items() if k != "images"}
    return {"comparisons": result}


def _plot(result, path):
    from .plotting import _plt

    plt = _plt()
    fresnels = ("none", "conductor")
    rough = sorted({c["roughness"] for c in result["curves"]})
    fig, axes = plt.subplots(len(fresnels), len(rough), figsize=(3.2 * len(rough), 5.6),
                             squeeze=False, sharex=True)
    styles = dict(zip(MODELS_SHOWN, ("-", "--", "-.", ":", (0, (1, 3)))))
    for i, f in enumerate(fresnels):
        for j, r in enumerate(rough):
            ax = axes[i, j]
            for c in result["curves"]:
                if c["fresnel"] == f and c["roughness"] == r:
                    y = np.asarray(c["albedo"]).mean(axis=1)  # channel mean for gold
                    ax.plot(result["thetas"], y, linestyle=styles[c["model"]], label=c["model"])
            ax.set_title(f"{'white furnace (F = 1)' if f == 'none' else 'gold'}, roughness {r:g}",
                         fontsize=8)
            ax.set_xlabel("incidence (deg)", fontsize=8)
            ax.set_ylabel("albedo" + (" (RGB mean)" if f == "conductor" else ""), fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def page(cfg, rows, res) -> list:
    data = res.get("comparisons")
    if not data:
        return []
    th = data["thetas"]
    lines = ["## Multiple-scattering models compared (the seed's figures 21-23)", "",
             "Directional albedo over incidence (GGX slopes for Lee, Heitz 2016 and Walter; "
             "Beckmann for Cook-Torrance), in the white furnace (F = 1: the energy a model "
             "keeps) and for gold (RGB mean). Lee: deterministic quadrature; Heitz 2016 and the "
             f"single-scattering models: {data['walks']:,} Monte Carlo samples per entry (the "
             "largest standard error is given per row). Figure: `multiple_scattering.png`.", "",
             "| Fresnel | roughness | model | " + " | ".join(f"{t:g} deg" for t in th)
             + " | s.e. |", "|---|---|---|" + "---|" * len(th) + "---|"]
    for c in data["curves"]:
        vals = " | ".join(f"{np.mean(e):.4f}" for e in c["albedo"])
        se = ("quadrature, < 1e-5" if c["model"].startswith("Lee")
              else f"{np.max(c['stderr']):.1e}")
        lines.append(f"| {'F = 1' if c['fresnel'] == 'none' else 'gold'} | {c['roughness']:g} | "
                     f"{c['model']} | {vals} | {se} |")
    lines.append("")
    if data.get("lobes") and data.get("renders"):
        lines += comparison_views.page_lines(data["lobes"], data["renders"])
    return lines
