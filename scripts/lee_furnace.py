"""White-furnace comparison of multiple against single scattering (the seed's figs. 21-22).

Renders, headless in Cycles OSL, a sphere grid in a white environment (L = 1): rows Lee 2018
V-grooves (symmetric GGX, asymmetric GGX, symmetric Beckmann; F = 1), Walter GGX single
scattering (height-correlated Smith, F = 1), Cook-Torrance single scattering (Beckmann,
V-cavities; F >= 0.9996) and Cycles' multiple-scattering GGX (`microfacet_multi_ggx_aniso`);
columns alpha = 0.25, 0.5, 0.75, 1. A sphere that keeps all the energy is uniformly 1.
Writes out/lee_furnace.png (the grid and the sphere means against alpha) and prints the table.

    python scripts/lee_furnace.py [--samples 64] [--cell 64] [--out out]
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from addon.lab import bench_lee  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--cell", type=int, default=64, help="pixels per sphere cell")
    parser.add_argument("--out", default=str(ROOT / "out"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    alphas = bench_lee.FURNACE_ALPHAS
    labels, layout, image, means = bench_lee.render_furnace(alphas, args.samples, args.cell)
    print(bench_lee.furnace_markdown(alphas, means))
    path = out / "lee_furnace.png"
    save_picture(path, labels, alphas, layout, image, means)
    print(f"wrote {path}")


def save_picture(path, labels, alphas, layout, image, means):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_img, ax_plot) = plt.subplots(1, 2, figsize=(13, 6.2), dpi=110,
                                          gridspec_kw={"width_ratios": [1.1, 1]})
    # Linear values shown as they are (1 = white): energy loss reads as darkening.
    ax_img.imshow(np.clip(image[..., :3], 0.0, 1.0), interpolation="nearest")
    ax_img.set_xticks([(c + 0.5) * layout.cell_px for c in range(len(alphas))])
    ax_img.set_xticklabels([f"alpha {a:g}" for a in alphas])
    ax_img.set_yticks([(r + 0.5) * layout.cell_px for r in range(len(labels))])
    ax_img.set_yticklabels(labels)
    ax_img.set_title("White furnace (L = 1), linear: an invisible sphere keeps all energy")
    from matplotlib.patches import Circle
    scale = max(layout.width, layout.height) / layout.ortho_scale  # pixels per world unit
    for x, y in layout.centers():
        ax_img.add_patch(Circle((layout.width / 2 + x * scale - 0.5, layout.height / 2 - y * scale - 0.5),
                                layout.radius * scale, fill=False, lw=0.6, ls=":", color="tab:blue"))
    for label in labels:
        ax_plot.plot(alphas, means[label], marker="o", label=label)
    ax_plot.axhline(1.0, color="k", lw=0.6)
    ax_plot.set_xlabel("alpha (= roughness^2)")
    ax_plot.set_ylabel("sphere mean (mu >= 0.05)")
    ax_plot.set_title("Energy kept: multiple vs single scattering")
    ax_plot.legend(fontsize=8)
    ax_plot.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
