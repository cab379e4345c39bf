"""Write the presets' asset library into assets/ (addon/lab/assets.py); `make assets` runs both
steps, each with the Blender it needs:

    python scripts/build_assets.py previews [--samples N]   # pinned release: assets/previews/*.png
    python scripts/build_assets.py library                  # Blender 4.2: the .blend and catalogs

Prints what it wrote; exits non-zero with a message on failure.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from addon.lab import assets  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("step", choices=["previews", "library"])
    parser.add_argument("--samples", type=int, default=64, help="previews: samples per pixel")
    args = parser.parse_args(argv)
    try:
        if args.step == "previews":
            assets.render_previews(samples=args.samples)
        else:
            assets.write_library()
    except (OSError, RuntimeError) as error:
        print(f"build_assets: error: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
