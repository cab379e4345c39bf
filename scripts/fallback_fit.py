"""Fit the correction lobe of Lee's native branch to the numpy reference and write it to
addon/fallback_fit.json (addon/lab/fallback_fit.py). Run with `make fallback-fit` after changing
Lee's reference or the native branch; tests/test_fallback_fit.py says when it is due."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from addon.lab import fallback_fit  # noqa: E402


def main() -> None:
    data = fallback_fit.run()
    fallback_fit.write(data)
    for pid, entry in data["presets"].items():
        print(f"{pid}: worst {entry['before']['worst']:.1%} -> {entry['after']['worst']:.1%}, "
              f"mean {entry['before']['mean']:.2%} -> {entry['after']['mean']:.2%}")


if __name__ == "__main__":
    main()
