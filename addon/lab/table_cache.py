"""Reference moment tables kept on disk between runs.

The sphere-grid references are deterministic but slow: quadrature tables of glass take seconds
each, the Monte Carlo tables of Heitz 2016 over a minute. Every test run and report computed
them afresh. Here a list of tables is stored once, in
`$MICROFACET_LAB_CACHE/tables` (default ~/.cache/microfacet-lab, beside the environments),
under a key that hashes the caller's name and inputs, numpy's version and the source of what
a table is computed from: the catalog (addon/catalog.py), the numpy reference
(addon/lab/reference/) and this file. Any change there computes them again; an old entry is
never read, only left behind. A table read back equals the one
computed bit for bit (npz, no pickle). Set MICROFACET_LAB_TABLE_CACHE=0 to compute everything
afresh (a cold run) without touching the cache.

The repository carries the entries `make test` reads, in one archive (addon/lab/
table_seed.npz, refreshed by `make tables`), so a fresh clone on a fresh machine reads them
instead of spending minutes of Monte Carlo and quadrature on them. They are looked up under the
same key, after the user's cache: an entry whose code or inputs changed is simply not found
there and is computed (and cached) as before, so a stale seed costs time, never a wrong table.
`make tables` runs `make test` with MICROFACET_LAB_TABLE_RECORD naming a file that collects
every entry's name, then writes those entries into the archive (write_seed).
"""
from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from .reference.quadrature import MomentTable

_ADDON = Path(__file__).resolve().parent.parent
# What a table is computed from (the callers pass everything else in their inputs).
_SOURCES = (_ADDON / "catalog.py", _ADDON / "lab" / "table_cache.py")
_SOURCE_DIRS = (_ADDON / "lab" / "reference",)
_FIELDS = ("x", "E", "Vn", "Vt_over_sin")
SEED_PATH = Path(__file__).resolve().parent / "table_seed.npz"


def enabled() -> bool:
    return os.environ.get("MICROFACET_LAB_TABLE_CACHE", "1") != "0"


def directory() -> Path:
    root = os.environ.get("MICROFACET_LAB_CACHE") or Path.home() / ".cache" / "microfacet-lab"
    return Path(root) / "tables"


@functools.lru_cache(maxsize=None)
def code_digest() -> str:
    """Hash of the catalog's, the reference's and this module's source."""
    h = hashlib.sha256()
    paths = list(_SOURCES) + [p for d in _SOURCE_DIRS for p in d.rglob("*.py")]
    for path in sorted(paths):
        h.update(os.path.relpath(path, _ADDON).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def key(name: str, inputs) -> str:
    text = "\n".join((name, repr(inputs), np.__version__, code_digest()))
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _save(path: Path, tables) -> None:
    arrays = {"count": np.array(len(tables))}
    for i, table in enumerate(tables):
        if table is not None:
            arrays.update({f"{i}_{f}": getattr(table, f) for f in _FIELDS})
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    with os.fdopen(fd, "wb") as out:
        np.savez(out, **arrays)
    os.replace(tmp, path)  # another process computing the same tables writes the same bytes


def _load(path: Path) -> list:
    with np.load(path, allow_pickle=False) as data:
        return _tables_from(data)


def _tables_from(data, prefix: str = "") -> list:
    """The tables of one entry from an npz mapping (its arrays' names after `prefix`)."""
    return [MomentTable(*(data[f"{prefix}{i}_{f}"] for f in _FIELDS))
            if f"{prefix}{i}_x" in data else None for i in range(int(data[prefix + "count"]))]


@functools.lru_cache(maxsize=None)
def _seed():
    """The repository's archive of entries (arrays named "<entry>/<array>"), or None."""
    return np.load(SEED_PATH, allow_pickle=False) if SEED_PATH.exists() else None


def write_seed(entries, path: Path | None = None) -> int:
    """Write the named entries (file names as recorded) into the seed archive, each from the
    user's cache or else the current seed; returns the archive's size in bytes."""
    arrays = {}
    for entry in sorted(set(entries)):
        stem = entry.removesuffix(".npz")
        source = directory() / entry
        if source.exists():
            with np.load(source, allow_pickle=False) as data:
                arrays.update({f"{stem}/{k}": data[k] for k in data.files})
        elif _seed() is not None and f"{stem}/count" in _seed():
            arrays.update({k: _seed()[k] for k in _seed().files if k.startswith(stem + "/")})
        else:
            raise FileNotFoundError(f"{entry} is in neither the cache nor the seed")
    path = path or SEED_PATH
    np.savez_compressed(path, **arrays)
    return path.stat().st_size


def tables(name: str, inputs, compute) -> list:
    """compute() -> a list of MomentTable (or None), read from the cache (or the repository's
    seed) when it holds this name and these inputs for this code, else computed and stored."""
    if not enabled():
        return list(compute())
    stem = f"{name}-{key(name, inputs)}"
    _record(stem + ".npz")
    path = directory() / f"{stem}.npz"
    if path.exists():
        try:
            return _load(path)
        except (OSError, ValueError, KeyError):
            pass  # a damaged entry: compute it again
    if _seed() is not None and f"{stem}/count" in _seed():
        return _tables_from(_seed(), stem + "/")
    result = list(compute())
    _save(path, result)
    return result


def _record(filename: str) -> None:
    """Append the entry's name to $MICROFACET_LAB_TABLE_RECORD, if set (`make tables`)."""
    log = os.environ.get("MICROFACET_LAB_TABLE_RECORD")
    if log:
        with open(log, "a", encoding="utf-8") as out:
            out.write(filename + "\n")
