"""`make demo`: the sphere gallery, rendered headless with Cycles OSL, no outside assets.

Models x roughness under two environments (a white furnace and a smooth gradient), including
Lee 2018 rows made from the shipped presets (their roughness swept). Glass is
rendered as a single interface, as the reference computes it: the refracted ray meets the
world directly (spheres are invisible to secondary rays). Writes
out/gallery.png and one EXR per environment, and prints each sphere's error against the numpy
reference and the render times. Then the look-dev render (addon/lab/lookdev.py): Suzanne on a
floor under a sky, a sun and an area lamp, every model beside Cycles' closest native material
at equal time, in out/lookdev.png.
"""
import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from addon import presets  # noqa: E402

from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

ROUGHNESS = (0.05, 0.25, 0.5, 0.75, 1.0)
COPPER = {"n": (0.271, 0.677, 1.316), "k": (3.609, 2.625, 2.292)}  # Johnson & Christy 1972
ROWS = [
    ("Cook-Torrance plastic", "cook_torrance",
     {"base_color": (0.8, 0.1, 0.05), "specular": 0.3, "fresnel_type": "dielectric", "ior": 1.5}),
    ("Cook-Torrance gold", "cook_torrance", {"specular": 1.0, "fresnel_type": "conductor"}),
    ("Walter GGX gold", "walter_reflection", {"distribution": "ggx", "fresnel_type": "conductor"}),
    ("Walter Beckmann copper", "walter_reflection",
     {"distribution": "beckmann", "fresnel_type": "conductor", **COPPER}),
    ("Walter GGX, F = 1", "walter_reflection", {"distribution": "ggx", "fresnel_type": "none"}),
    ("Walter glass, IOR 1.5", "walter_glass", {"distribution": "ggx", "ior": 1.5}),
]


def preset_row(preset_id: str, label: str):
    """A gallery row from a preset's values (the roughness is swept)."""
    preset = presets.find(preset_id)
    values = {k: v for k, v in preset.params.items() if k != "roughness"}
    return (label, preset.model_id, values)


# Lee 2018 multiple scattering in V-grooves, from the shipped presets.
ROWS += [preset_row("rough_gold_lee", "Lee gold (symmetric)"),
         preset_row("rough_aluminium_lee", "Lee aluminium (asymmetric)"),
         preset_row("rough_glass_lee", "Lee glass surface (Beckmann)")]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--samples", type=int, default=128)
    parser.add_argument("--cell", type=int, default=64, help="pixels per sphere cell")
    parser.add_argument("--out", default=str(ROOT / "out"))
    parser.add_argument("--lookdev-seconds", type=float, default=5.0,
                        help="wall time of each look-dev render (0 leaves the look-dev out)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    specs = [SphereSpec(model, {**values, "roughness": r}, f"{label} r={r}")
             for label, model, values in ROWS for r in ROUGHNESS]
    panels = {}
    total = time.perf_counter()
    for env_key in ("white", "gradient"):
        env = grid.ENVIRONMENTS[env_key]
        print(f"[demo] rendering {len(specs)} spheres under '{env.name}', "
              f"{args.samples} samples ...", flush=True)
        layout, image, seconds = harness.render_specs(
            specs, env, args.samples, seed=0, cols=len(ROUGHNESS), cell_px=args.cell,
            path=str(out / f"gallery_{env_key}.exr"))
        print(f"[demo]   render {seconds:.1f} s; computing the numpy reference ...", flush=True)
        start = time.perf_counter()
        reference = grid.reference_grid_image(layout, specs, env)
        print(f"[demo]   reference {time.perf_counter() - start:.1f} s", flush=True)
        stats = grid.band_stats(layout, image, reference, bands=((0.05, 1.0001),), sides=False)
        print(f"[demo]   {'sphere':<34} {'rel. bias (G)':>13} {'rel. noise':>10}")
        for s in stats:
            rel = s.bias[1] / s.reference[1]
            noise = s.stderr[1] / s.reference[1]
            print(f"[demo]   {specs[s.sphere].label:<34} {rel:+13.4%} {noise:10.4%}")
        panels[env_key] = (layout, image, reference, seconds)
    save_gallery(out / "gallery.png", specs, panels)
    print(f"[demo] wrote {out / 'gallery.png'}", flush=True)
    if args.lookdev_seconds > 0:
        from addon.lab import lookdev

        print(f"[demo] look-dev: Suzanne under a sky, a sun and an area lamp, "
              f"{args.lookdev_seconds:g} s per image ...", flush=True)
        lookdev.render_gallery(out / "lookdev.png", args.lookdev_seconds)
        print(f"[demo] wrote {out / 'lookdev.png'}")
    print(f"[demo] done in {time.perf_counter() - total:.0f} s total")


def to_display(image):
    """Linear to sRGB-ish display values (gamma 2.2), clipped."""
    return np.clip(image[..., :3], 0.0, 1.0) ** (1.0 / 2.2)


def save_gallery(path, specs, panels):
    """Renders under each environment, then render minus reference for the last one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(panels) + 1
    fig, axes = plt.subplots(1, n, figsize=(3.3 * n + 3.2, 0.55 * len(ROWS) + 1.8), dpi=110)
    for ax, (env_key, (layout, image, reference, seconds)) in zip(axes, panels.items()):
        ax.imshow(to_display(image), interpolation="nearest")
        ax.set_title(f"{grid.ENVIRONMENTS[env_key].name} ({seconds:.0f} s render)")
        _label_axes(ax, layout, ylabels=ax is axes[0])
    layout, image, reference, _ = panels[env_key]
    diff = (image[..., :3] - reference).mean(-1)
    diff[~(layout.pixel_geometry()[0] >= 0)] = 0.0
    limit = 0.05
    im = axes[-1].imshow(diff, cmap="RdBu_r", vmin=-limit, vmax=limit, interpolation="nearest")
    axes[-1].set_title(f"render - numpy reference ({grid.ENVIRONMENTS[env_key].name})")
    _label_axes(axes[-1], layout, ylabels=False)
    fig.colorbar(im, ax=axes[-1], fraction=0.046, pad=0.04, label="per-pixel noise, mean ~ 0")
    fig.suptitle("Microfacet Lab: OSL shaders in Cycles (Roughness as in Cycles, alpha = r^2)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _label_axes(ax, layout, ylabels):
    ax.set_xticks([(c + 0.5) * layout.cell_px for c in range(layout.cols)])
    ax.set_xticklabels([f"{r:g}" for r in ROUGHNESS])
    ax.set_xlabel("Roughness")
    ax.set_yticks([(r + 0.5) * layout.cell_px for r in range(layout.rows)])
    ax.set_yticklabels([label for label, _, _ in ROWS] if ylabels else [])


if __name__ == "__main__":
    main()
