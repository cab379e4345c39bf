"""Refresh the reference tables the repository carries (addon/lab/table_cache.py, SEED_PATH):
write every entry named in RECORD (written by a `make test` run with
MICROFACET_LAB_TABLE_RECORD=RECORD) into the archive, and nothing else.

    python scripts/seed_tables.py RECORD        (`make tables` runs it)
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from addon.lab import table_cache  # noqa: E402


def main(record: str) -> None:
    names = Path(record).read_text(encoding="utf-8").split()
    if not names:
        raise SystemExit(f"{record} names no table: was it written by a make test run?")
    size = table_cache.write_seed(names)
    print(f"{len(set(names))} tables in {table_cache.SEED_PATH} ({size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main(sys.argv[1])
