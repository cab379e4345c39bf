"""Validate the extension manifest and build dist/microfacet_lab-<version>.zip.

Runs the extension tool that ships inside the bpy wheel (`bl_pkg/cli/blender_ext.py`, the same
code as `blender --command extension`) with this Python, as a subprocess: `validate`, then
`build`. Tags are checked against Blender's own list (`_bpy_internal/extensions/tags.py`, which is
what `blender --command extension` passes as --valid-tags; run standalone, the tool checks no
tags at all).

    python scripts/build_package.py [--source-dir DIR] [--output-dir DIR]

Prints the path of the zip; exits non-zero with a message on failure.
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = "blender_manifest.toml"


class BuildError(RuntimeError):
    pass


def scripts_dir() -> Path:
    """Blender's scripts/ directory: inside the pip bpy wheel, else asked of bpy itself."""
    spec = importlib.util.find_spec("bpy")
    if spec is not None and spec.submodule_search_locations:
        for location in spec.submodule_search_locations:
            found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
            if found:
                return found[-1].parents[3]
    try:
        import bpy  # inside a Blender executable
        return Path(bpy.utils.system_resource("SCRIPTS"))
    except Exception as error:  # noqa: BLE001
        raise BuildError(f"cannot locate Blender's scripts directory (is bpy installed?): {error}")


def tool_path() -> Path:
    path = scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not path.is_file():
        raise BuildError(f"Blender extension tool not found at {path}")
    return path


def valid_tags_path() -> Path:
    path = scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    if not path.is_file():
        raise BuildError(f"Blender's list of valid tags not found at {path}")
    return path


def manifest(source_dir: Path = ROOT) -> dict:
    path = source_dir / MANIFEST
    if not path.is_file():
        raise BuildError(f"no {MANIFEST} in {source_dir}")
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def zip_name(source_dir: Path = ROOT) -> str:
    data = manifest(source_dir)
    return f"{data['id']}-{data['version']}.zip"


def _run_tool(*args: str) -> str:
    cmd = [sys.executable, str(tool_path()), *args, "--valid-tags", str(valid_tags_path())]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    output = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0:
        raise BuildError(f"`blender_ext {args[0]}` failed (exit {proc.returncode}):\n{output}")
    return output


def validate(source_dir: Path = ROOT) -> str:
    """Validate the manifest; returns the tool's output, raises BuildError on failure."""
    return _run_tool("validate", str(source_dir))


def build(source_dir: Path = ROOT, output_dir: Path | None = None) -> Path:
    """Validate, then build the zip into output_dir (default <source_dir>/dist); its path."""
    source_dir = Path(source_dir).resolve()
    output_dir = Path(output_dir).resolve() if output_dir else source_dir / "dist"
    validate(source_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    out = output_dir / zip_name(source_dir)
    if out.exists():
        out.unlink()
    _run_tool("build", "--source-dir", str(source_dir), "--output-filepath", str(out))
    if not out.is_file():
        raise BuildError(f"the build reported success but wrote no {out}")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source-dir", type=Path, default=ROOT)
    parser.add_argument("--output-dir", type=Path, default=None,
                        help="where to write the zip (default: <source-dir>/dist)")
    args = parser.parse_args(argv)
    try:
        out = build(args.source_dir, args.output_dir)
    except BuildError as error:
        print(f"build_package: error: {error}", file=sys.stderr)
        return 1
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
