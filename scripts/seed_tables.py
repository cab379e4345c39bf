"""Refresh the reference tables the repository carries (addon/lab/table_cache.py, SEED_DIR):
copy every entry named in RECORD (written by a `make test` run with
MICROFACET_LAB_TABLE_RECORD=RECORD) from the user's cache, and remove the seed's other entries.

    python scripts/seed_tables.py RECORD        (`make tables` runs it)
"""
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from addon.lab import table_cache  # noqa: E402


def main(record: str) -> None:
    names = sorted(set(Path(record).read_text(encoding="utf-8").split()))
    if not names:
        raise SystemExit(f"{record} names no table: was it written by a make test run?")
    seed = table_cache.SEED_DIR
    seed.mkdir(exist_ok=True)
    for name in names:
        source = table_cache.directory() / name
        if not (seed / name).exists():
            if not source.exists():
                raise SystemExit(f"{name} is in neither the cache nor the seed")
            shutil.copyfile(source, seed / name)
    for old in seed.glob("*.npz"):
        if old.name not in names:
            old.unlink()
    size = sum(p.stat().st_size for p in seed.glob("*.npz"))
    print(f"{len(names)} tables in {seed} ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main(sys.argv[1])
