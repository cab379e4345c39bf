"""The page: the header and the sections' Markdown lines, in order, and how to regenerate it."""
from __future__ import annotations

from pathlib import Path

REGENERATE = [
    "## How to regenerate\n",
    "`make report` (full, over an hour on 2 cores), `make report QUICK=1` (about 5 "
    "minutes: fewer samples, smaller grids, a subset of the sweep), "
    "`python scripts/report.py --smoke` (seconds; used by the tests). Output: `report/` "
    "(this page, PNGs, `results.json`); the full run also refreshes the README figures in "
    "`docs/figures/`."]


def write_page(path, header, parts) -> None:
    """Write `header` (lines), then each part (a section's lines), then REGENERATE to `path`."""
    lines = list(header)
    for part in parts:
        lines += part
    lines += REGENERATE
    Path(path).write_text("\n".join(lines) + "\n")
