"""Render presets on a sphere grid from the command line, inside Blender or under pip bpy.

    blender --background --python scripts/render_scene.py -- --preset gold --preset chrome --out x.png
    python scripts/render_scene.py --preset gold --out x.png          # pip bpy (bpy==5.0.1)

Arguments after `--` are read when there is one (Blender's own arguments come before it).
One sphere per preset (the harness's exact point-cloud spheres under an orthographic camera, in a
smooth gradient or white-furnace environment); `--all` renders every preset. The output format
follows the extension: .png (8-bit sRGB) or .exr (32-bit linear). `--specialize` runs
addon/specialize.py on the scene before rendering; `--save-blend` writes the .blend (after
specialization, when asked); `--thumbnails DIR` writes one PNG per preset for the gallery.
Progress goes to stdout, prefixed with [render_scene].
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def script_args(argv: list[str]) -> list[str]:
    """The arguments meant for this script: those after `--` when present, else argv[1:]."""
    return argv[argv.index("--") + 1:] if "--" in argv else argv[1:]


def log(message: str) -> None:
    print(f"[render_scene] {message}", flush=True)


def parse(args: list[str]):
    parser = argparse.ArgumentParser(prog="render_scene.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", action="append", default=[],
                        help="preset id (repeat, or comma-separated); see --list")
    parser.add_argument("--all", action="store_true", help="every preset")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    parser.add_argument("--out", default="out/render_scene.png", help=".png or .exr")
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--size", type=int, default=64, help="pixels per sphere")
    parser.add_argument("--cols", type=int, default=4)
    parser.add_argument("--env", choices=("gradient", "white"), default="gradient")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--bounces", type=int, default=4, help="light-path bounces before --specialize")
    parser.add_argument("--specialize", action="store_true",
                        help="compile only the shaders used, prune the rest, set bounces to what the materials need")
    parser.add_argument("--save-blend", default=None, help="also save the scene as this .blend")
    parser.add_argument("--thumbnails", default=None, metavar="DIR",
                        help="write DIR/<preset>.png for the gallery instead of one grid")
    return parser.parse_args(args)


def main(argv: list[str] | None = None) -> int:
    args = parse(script_args(sys.argv if argv is None else argv))
    from addon import presets

    available, errors = presets.scan()
    for error in errors:
        log(f"skipping malformed preset: {error}")
    if args.list:
        for p in available.values():
            print(f"{p.id:22} {p.model_id:18} {p.label}  [{p.citation()[:60]}]")
        return 0
    ids = list(available) if args.all else [i.strip() for a in args.preset for i in a.split(",") if i.strip()]
    if not ids:
        log("no preset given (use --preset ID or --all; --list shows them)")
        return 2
    try:
        chosen = [presets.find(i) for i in ids]
    except presets.PresetError as error:
        log(f"error: {error}")
        return 2

    start = time.perf_counter()
    log(f"importing bpy ({len(chosen)} preset(s): {', '.join(p.id for p in chosen)})")
    import bpy  # noqa: F401  (inside Blender this is the running Blender)

    from addon.lab import grid, harness, thumbnails

    if args.thumbnails:
        thumbnails.render_thumbnails(args.thumbnails, chosen, size=args.size, samples=args.samples,
                                  env=args.env, log=log)
        log(f"done in {time.perf_counter() - start:.1f} s")
        return 0

    layout = grid.GridLayout(rows=-(-len(chosen) // args.cols), cols=min(args.cols, len(chosen)),
                             cell_px=args.size)
    scene = harness.new_scene()
    materials = []
    for p in chosen:
        log(f"material {p.id}: {p.label} ({p.model_id})")
        materials.append(harness.model_material(p.model_id, p.params, f"Microfacet Lab {p.label}"))
    harness.build_grid_scene(layout, materials, grid.ENVIRONMENTS[args.env], args.samples,
                             seed=args.seed, max_bounces=args.bounces)
    if args.specialize:
        from addon import specialize

        report = specialize.specialize(scene)
        for line in report.lines():
            log(f"specialize: {line}")
    if args.save_blend:
        path = Path(args.save_blend).resolve()
        path.parent.mkdir(parents=True, exist_ok=True)
        bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)
        log(f"saved {path} ({path.stat().st_size} bytes)")

    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    settings = scene.render.image_settings
    if out.suffix.lower() == ".png":
        settings.file_format, settings.color_mode, settings.color_depth = "PNG", "RGB", "8"
    else:
        settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    scene.render.filepath = str(out)
    log(f"rendering {layout.width}x{layout.height} px, {args.samples} samples ...")
    render_start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    log(f"render {time.perf_counter() - render_start:.1f} s")
    if not out.is_file():
        log(f"error: no image written to {out}")
        return 1
    log(f"wrote {out} in {time.perf_counter() - start:.1f} s total")
    return 0


if __name__ == "__main__":
    code = main()
    if code:
        sys.exit(code)
