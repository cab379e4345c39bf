"""Render presets on a sphere grid from the command line, inside Blender or under pip bpy.

    blender --background --python scripts/render_scene.py -- --preset gold --preset chrome --out x.png
    python scripts/render_scene.py --preset gold --out x.png          # pip bpy (bpy==5.0.1)

Arguments after `--` are read when there is one (Blender's own arguments come before it).
One sphere per preset (the harness's exact point-cloud spheres under an orthographic camera, in a
smooth gradient or white-furnace environment); `--all` renders every preset. The output format
follows the extension: .png (8-bit sRGB), .jpg or .jpeg (JPEG, sRGB, quality 95) or .exr (32-bit
float, linear); any other extension is refused. `--specialize` runs addon/specialize.py on the
scene before rendering; `--save-blend` writes the .blend (after specialization, when asked);
`--thumbnails DIR` writes one PNG per preset for the gallery.

Every argument is checked before bpy is imported: a number out of range (see --help), an unknown
output extension or an unknown preset is an error naming the value, with exit status 2 and nothing
written. Progress goes to stdout, prefixed with [render_scene].
"""
from __future__ import annotations

import argparse
import difflib
import re
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


# The accepted range of each numeric option, inclusive (checked before bpy is imported). Blender
# itself allows more samples (16777216) but renders at most 65536 px a side and at least 4
# (resolution_x/y), up to 1024 bounces and seeds up to 2^31 - 1 (Cycles' own limits, the same in
# 4.2 to 5.3).
RANGES = {
    "samples": (1, 65536),
    "size": (4, 4096),
    "cols": (1, 64),
    "bounces": (0, 1024),
    "seed": (0, 2**31 - 1),
}
MAX_IMAGE_PX = 65536  # Blender's largest resolution_x / resolution_y
# Output extension -> what is written (image_settings: file format, colour mode, depth).
FORMATS = {
    ".png": "8-bit PNG, sRGB",
    ".jpg": "JPEG, sRGB, quality 95",
    ".jpeg": "JPEG, sRGB, quality 95",
    ".exr": "OpenEXR, 32-bit float, linear",
}
JPEG_QUALITY = 95
THUMBNAIL_COLS = 8  # addon/lab/thumbnails.py lays the thumbnails out 8 to a row
_WHOLE = re.compile(r"[+-]?[0-9]+")


def _range_text(name: str) -> str:
    low, high = RANGES[name]
    return f"give a whole number from {low} to {high}"


def check_number(name: str, text: str) -> tuple[int | None, str | None]:
    """(value, None) for a whole number in RANGES[name], else (None, the error message)."""
    low, high = RANGES[name]
    if not _WHOLE.fullmatch(text.strip()):
        return None, f"--{name} {text} is not a whole number: {_range_text(name)}"
    value = int(text)
    if not low <= value <= high:
        return None, f"--{name} {text} is out of range: {_range_text(name)}"
    return value, None


def check_out(out: str) -> str | None:
    """None when --out names a supported format, else the error message."""
    suffix = Path(out).suffix.lower()
    if suffix in FORMATS:
        return None
    accepted = ", ".join(FORMATS)
    if not suffix:
        return f"--out {out} has no extension: the extension picks the format; accepted: {accepted}"
    return f"--out {out}: unsupported extension {Path(out).suffix!r}; accepted: {accepted}"


def parse(args: list[str]):
    """The parsed arguments, numbers as ints; a bad value exits with status 2 (argparse's way:
    usage and `render_scene.py: error: ...` on stderr) before anything is imported or written."""
    parser = argparse.ArgumentParser(prog="render_scene.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", action="append", default=[],
                        help="preset id (repeat, or comma-separated); see --list")
    parser.add_argument("--all", action="store_true", help="every preset")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    parser.add_argument("--out", default="out/render_scene.png",
                        help="the image; its extension picks the format: .png (8-bit, sRGB), "
                             ".jpg or .jpeg (JPEG, sRGB, quality 95), .exr (32-bit float, linear); "
                             "any other is refused")

    def number(name, default, text):
        low, high = RANGES[name]
        parser.add_argument(f"--{name}", default=str(default), metavar="N",
                            help=f"{text} ({low} to {high}; default {default})")

    number("samples", 64, "samples per pixel")
    number("size", 64, "pixels per sphere")
    number("cols", 4, "spheres per row (--thumbnails puts 8 to a row)")
    parser.add_argument("--env", choices=("gradient", "white"), default="gradient")
    number("seed", 0, "Cycles seed")
    number("bounces", 4, "light-path bounces before --specialize")
    parser.add_argument("--specialize", action="store_true",
                        help="compile only the shaders used, prune the rest, set bounces to what the materials need")
    parser.add_argument("--save-blend", default=None, help="also save the scene as this .blend")
    parser.add_argument("--thumbnails", default=None, metavar="DIR",
                        help="write DIR/<preset>.png for the gallery instead of one grid "
                             "(--size, --samples and --env apply)")
    parsed = parser.parse_args(args)
    for name in RANGES:
        value, error = check_number(name, getattr(parsed, name))
        if error:
            parser.error(error)
        setattr(parsed, name, value)
    error = check_out(parsed.out)
    if error:
        parser.error(error)
    return parsed


def unknown_preset(preset_id: str, known: list[str]) -> str:
    close = difflib.get_close_matches(preset_id, known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"no preset {preset_id!r}{hint}; --list shows the presets"


def image_px(count: int, cols: int, size: int) -> tuple[int, int]:
    """(width, height) in pixels of `count` spheres at most `cols` to a row."""
    return min(cols, count) * size, -(-count // cols) * size


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
    known = sorted(p.stem for p in presets.PRESETS_DIR.glob("*.toml"))
    for i in ids:
        if i not in known:
            log(f"error: {unknown_preset(i, known)}")
            return 2
    try:
        chosen = [presets.find(i) for i in ids]
    except presets.PresetError as error:
        log(f"error: {error}")
        return 2
    width, height = image_px(len(chosen), THUMBNAIL_COLS if args.thumbnails else args.cols, args.size)
    if max(width, height) > MAX_IMAGE_PX:
        log(f"error: {len(chosen)} spheres of --size {args.size} make a {width}x{height} px image; "
            f"Blender renders at most {MAX_IMAGE_PX} px a side: give a smaller --size"
            + ("" if args.thumbnails else " or a --cols that balances rows and columns"))
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
    from addon import handover

    handover.hand_over(scene)  # the lamps' table, as the add-on's render_pre handler does
    if args.save_blend:
        path = Path(args.save_blend).resolve()
        path.parent.mkdir(parents=True, exist_ok=True)
        bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)
        log(f"saved {path} ({path.stat().st_size} bytes)")

    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    set_image_format(scene.render.image_settings, out.suffix.lower())
    scene.render.filepath = str(out)
    log(f"rendering {layout.width}x{layout.height} px, {args.samples} samples "
        f"({FORMATS[out.suffix.lower()]}) ...")
    render_start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    log(f"render {time.perf_counter() - render_start:.1f} s")
    if not out.is_file():
        log(f"error: no image written to {out}")
        return 1
    log(f"wrote {out} in {time.perf_counter() - start:.1f} s total")
    return 0


def set_image_format(settings, suffix: str) -> None:
    """Image settings for FORMATS[suffix]. The same assignments work in 4.2 to 5.3 (5.0 added
    image_settings.media_type; a factory scene's is IMAGE, under which these formats are listed).
    PNG and JPEG go through the scene's view transform (the harness sets Standard: sRGB); EXR
    stores the linear render."""
    if suffix == ".png":
        settings.file_format, settings.color_mode, settings.color_depth = "PNG", "RGB", "8"
    elif suffix in (".jpg", ".jpeg"):
        settings.file_format, settings.color_mode = "JPEG", "RGB"
        settings.quality = JPEG_QUALITY
    elif suffix == ".exr":
        settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    else:  # check_out refused it already
        raise ValueError(f"unsupported extension {suffix!r}")


if __name__ == "__main__":
    code = main()
    if code:
        sys.exit(code)
