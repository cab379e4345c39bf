"""scripts/render_scene.py: the command-line flow under pip bpy, in fresh processes (tiny
renders). The Blender-executable form (`blender --background --python ... -- args`) differs only in
where the arguments start, which `script_args` handles and the `--` run below exercises.
"""
from __future__ import annotations

import importlib.util
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.compat

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "render_scene.py"


def load_script():
    spec = importlib.util.spec_from_file_location("render_scene_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(*args, cwd):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([sys.executable, str(SCRIPT), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)
    return proc, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"


def written(tmp_path):
    return sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))


def test_numbers_are_parsed_as_ints_with_defaults():
    module = load_script()
    args = module.parse([])
    assert (args.samples, args.size, args.cols, args.bounces, args.seed) == (64, 64, 4, 4, 0)
    args = module.parse(["--samples", "1", "--size", "4", "--cols", "64", "--bounces", "0",
                         "--seed", str(2**31 - 1), "--out", "x.JPEG"])
    assert (args.samples, args.size, args.cols, args.bounces, args.seed) == (1, 4, 64, 0, 2**31 - 1)
    assert all(type(getattr(args, n)) is int for n in ("samples", "size", "cols", "bounces", "seed"))


# (option, value, the range the message names); out of range or not a whole number.
RANGE = {"--samples": (1, 65536), "--size": (4, 4096), "--cols": (1, 64), "--bounces": (0, 1024),
         "--seed": (0, 2**31 - 1)}
BAD_NUMBERS = [("--samples", "-5"), ("--samples", "0"), ("--samples", "65537"), ("--size", "3"),
               ("--size", "0"), ("--size", "-64"), ("--size", "4097"), ("--cols", "0"),
               ("--cols", "-1"), ("--cols", "65"), ("--bounces", "-1"), ("--bounces", "1025"),
               ("--seed", "-1"), ("--seed", str(2**31))]
NOT_WHOLE = [("--samples", "1.5"), ("--size", "abc"), ("--cols", "2e3"), ("--seed", "0x10"),
             ("--bounces", "")]


@pytest.mark.parametrize("thumbnails", [False, True], ids=["grid", "thumbnails"])
@pytest.mark.parametrize("option,value", BAD_NUMBERS + NOT_WHOLE)
def test_bad_number_is_refused_before_anything_is_written(tmp_path, option, value, thumbnails):
    extra = ["--thumbnails", str(tmp_path / "thumbs")] if thumbnails else []
    proc, log = run("--preset", "gold", "--out", str(tmp_path / "sub" / "x.png"),
                    "--save-blend", str(tmp_path / "blend" / "x.blend"), *extra, option, value,
                    cwd=tmp_path)
    assert proc.returncode == 2, log
    low, high = RANGE[option]
    problem = "is out of range" if (option, value) in BAD_NUMBERS else "is not a whole number"
    assert f"error: {option} {value} {problem}: give a whole number from {low} to {high}" in proc.stderr, log
    assert "importing bpy" not in proc.stdout, log
    assert written(tmp_path) == []


@pytest.mark.parametrize("thumbnails", [False, True], ids=["grid", "thumbnails"])
@pytest.mark.parametrize("name", ["x.gif", "x.tif", "x.jpgg", "x.png.bak", "x.webp"])
def test_unsupported_extension_is_refused(tmp_path, name, thumbnails):
    extra = ["--thumbnails", str(tmp_path / "thumbs")] if thumbnails else []
    out = tmp_path / "sub" / name
    proc, log = run("--preset", "gold", "--out", str(out), *extra, cwd=tmp_path)
    assert proc.returncode == 2, log
    assert f"unsupported extension {out.suffix!r}; accepted: .png, .jpg, .jpeg, .exr" in proc.stderr, log
    assert written(tmp_path) == []


def test_missing_extension_is_refused(tmp_path):
    proc, log = run("--preset", "gold", "--out", str(tmp_path / "picture"), cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "has no extension" in proc.stderr and ".png, .jpg, .jpeg, .exr" in proc.stderr, log
    assert written(tmp_path) == []


def test_unknown_preset_suggests_the_closest(tmp_path):
    proc, log = run("--preset", "gold,goldd", "--out", str(tmp_path / "sub" / "x.png"), cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "error: no preset 'goldd' (did you mean 'gold'?); --list shows the presets" in proc.stdout, log
    assert ".toml" not in proc.stdout and "(file)" not in proc.stdout, log
    proc, log = run("--preset", "zzzzzz", cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "error: no preset 'zzzzzz'; --list shows the presets" in proc.stdout, log
    assert written(tmp_path) == []


def test_image_larger_than_blender_renders_is_refused(tmp_path):
    proc, log = run("--all", "--size", "4096", "--cols", "1", "--out", str(tmp_path / "x.png"),
                    cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "px image; Blender renders at most 65536 px a side" in proc.stdout, log
    assert written(tmp_path) == []


CHECK_WITHOUT_BPY = """
import runpy, sys
sys.argv = [sys.argv[1], *sys.argv[2:]]
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
    code = 0
except SystemExit as exit:
    code = exit.code
print("bpy imported:", "bpy" in sys.modules, "exit:", code)
"""


@pytest.mark.parametrize("args", [["--samples", "0"], ["--seed", "-3"], ["--out", "x.gif"],
                                  ["--preset", "goldd"], ["--all", "--size", "4096", "--cols", "1"]],
                         ids=["samples", "seed", "extension", "preset", "too-large"])
def test_argument_errors_are_found_before_bpy_is_imported(tmp_path, args):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([sys.executable, "-c", CHECK_WITHOUT_BPY, str(SCRIPT), "--preset", "gold", *args],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert "bpy imported: False exit: 2" in proc.stdout, (proc.stdout, proc.stderr)
    assert written(tmp_path) == []


def png_header(data: bytes) -> tuple[int, int]:
    """(bit depth, colour type) from the IHDR chunk (colour type 2: RGB)."""
    assert data[12:16] == b"IHDR"
    return data[24], data[25]


def jpeg_luma_dc_quantizer(data: bytes) -> int:
    """The first entry of the luminance quantization table: libjpeg's standard table scaled by
    quality, 16 -> 2 at quality 95 (3 at Blender's default 90)."""
    i = 2
    while i < len(data):
        assert data[i] == 0xFF, i
        marker, length = data[i + 1], struct.unpack(">H", data[i + 2:i + 4])[0]
        segment = data[i + 4:i + 2 + length]
        j = 0
        while marker == 0xDB and j < len(segment):
            precision, table = segment[j] >> 4, segment[j] & 15
            if table == 0:
                return struct.unpack(">H", segment[j + 1:j + 3])[0] if precision else segment[j + 1]
            j += 1 + 64 * (2 if precision else 1)
        i += 2 + length
    raise AssertionError("no luminance quantization table")


def exr_channels(data: bytes) -> dict[str, int]:
    """Channel name -> pixel type (0 UINT, 1 HALF, 2 FLOAT) from the header's chlist."""
    start = data.index(b"channels\0chlist\0") + len(b"channels\0chlist\0") + 4
    channels = {}
    while data[start] != 0:
        end = data.index(b"\0", start)
        channels[data[start:end].decode()] = struct.unpack("<i", data[end + 1:end + 5])[0]
        start = end + 1 + 16
    return channels


MAGIC = {".png": b"\x89PNG", ".jpg": b"\xff\xd8\xff", ".jpeg": b"\xff\xd8\xff", ".exr": b"v/1\x01"}


def check_format(path: Path) -> None:
    """The file is of the format its extension names (README: 8-bit PNG, JPEG quality 95,
    32-bit float EXR)."""
    data = path.read_bytes()
    suffix = path.suffix.lower()
    assert data.startswith(MAGIC[suffix]), (path, data[:8])
    if suffix == ".png":
        assert png_header(data) == (8, 2)
    elif suffix == ".exr":
        channels = exr_channels(data)
        assert {"R", "G", "B"} <= set(channels) and set(channels.values()) == {2}, channels
    else:
        assert jpeg_luma_dc_quantizer(data) == 2


# x.jpeg and X.JPG differ from x.jpg only in how the add-on reads the name (the same Python on
# every Blender): the pinned release alone runs them.
@pytest.mark.render
@pytest.mark.parametrize("name", ["x.png", "x.jpg", "x.exr"] + [
    pytest.param(name, marks=pytest.mark.release_only) for name in ("x.jpeg", "X.JPG")])
def test_format_follows_the_extension(tmp_path, name):
    out = tmp_path / "sub" / name
    proc, log = run("--preset", "gold", "--out", str(out), "--samples", "2", "--size", "8", cwd=tmp_path)
    assert proc.returncode == 0, log
    assert written(tmp_path) == ["sub", f"sub/{name}"], log
    check_format(out)


@pytest.mark.render
def test_png_and_jpeg_are_srgb_of_the_linear_exr(tmp_path):
    import numpy as np

    paths = {ext: tmp_path / f"x.{ext}" for ext in ("exr", "png", "jpg")}
    for path in paths.values():
        proc, log = run("--preset", "gold,red_plastic", "--out", str(path), "--samples", "4",
                        "--size", "16", cwd=tmp_path)
        assert proc.returncode == 0, log
    pytest.importorskip("bpy")
    from addon.lab import images

    # [..., :3]: without OpenImageIO (the 4.2 wheel) Blender's loader reads an RGB file as RGBA
    image = {ext: images.read_image(path)[..., :3] for ext, path in paths.items()}
    linear = np.clip(image["exr"], 0.0, 1.0)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    # measured: PNG within 1.7/255 (Blender's dither), JPEG 6/255 on average (chroma subsampling
    # at the spheres' edges); storing the linear values would be 61/255 off on average
    assert np.abs(image["png"] - srgb).max() < 3 / 255
    assert np.abs(image["jpg"] - srgb).mean() < 12 / 255
    assert np.abs(image["jpg"] - linear).mean() > 40 / 255


def test_arguments_after_double_dash():
    module = load_script()
    assert module.script_args(["blender", "--background", "--python", "x.py", "--", "--preset", "gold"]) \
        == ["--preset", "gold"]
    assert module.script_args(["x.py", "--preset", "gold"]) == ["--preset", "gold"]
    args = module.parse(["--preset", "gold,chrome", "--specialize"])
    assert args.preset == ["gold,chrome"] and args.specialize


def test_unknown_preset_is_a_clear_error_without_rendering(tmp_path):
    proc, log = run("--preset", "unobtainium", cwd=tmp_path)
    assert proc.returncode == 2, log
    assert "no preset 'unobtainium'" in proc.stdout, log


@pytest.mark.render
def test_pip_bpy_renders_presets_to_png(tmp_path):
    import numpy as np

    out = tmp_path / "grid.png"
    proc, log = run("--preset", "gold,red_plastic", "--out", str(out), "--samples", "4",
                    "--size", "24", cwd=tmp_path)
    assert proc.returncode == 0, log
    assert "[render_scene] rendering 48x24 px" in proc.stdout and "[render_scene] wrote" in proc.stdout, log
    pytest.importorskip("bpy")
    from addon.lab import images

    pixels = np.round(images.read_image(out) * 255).astype(np.uint8)
    assert pixels.shape == (24, 48, 3)
    gold, plastic = pixels[12, 12].astype(int), pixels[12, 36].astype(int)
    assert gold[0] > gold[2] and plastic[0] > plastic[1] + 40, (gold, plastic)
    assert np.ptp(pixels) > 50


@pytest.mark.render
def test_double_dash_specialize_exr_and_blend(tmp_path):
    out, blend = tmp_path / "x.exr", tmp_path / "x.blend"
    proc, log = run("--", "--preset", "chrome", "--out", str(out), "--samples", "2", "--size", "16",
                    "--specialize", "--save-blend", str(blend), cwd=tmp_path)
    assert proc.returncode == 0, log
    assert "already up to date: ['walter_reflection']" in proc.stdout, log
    assert "transmission_bounces 4 -> 0" in proc.stdout, log
    assert out.stat().st_size > 0 and blend.stat().st_size > 0
