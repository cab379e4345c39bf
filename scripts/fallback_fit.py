"""Fit the native branches' corrections (addon/fallback.py, FITTED) to the numpy reference and
write them to addon/fallback_fit.json (addon/lab/fallback_fit.py). Run with `make fallback-fit`
after changing a fitted model's reference or the native branch; tests/test_fallback_fit.py says
when it is due."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from addon.lab import fallback_fit  # noqa: E402


def main() -> None:
    data = fallback_fit.run()
    fallback_fit.write(data)
    for pid, entry in data["presets"].items():
        print(f"{pid}: albedo worst {entry['albedo']['worst']:.1%}, mean "
              f"{entry['albedo']['mean']:.2%}; lobe mean {entry['lobe']['mean']:.1f} deg")


if __name__ == "__main__":
    main()
