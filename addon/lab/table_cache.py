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

Besides moment tables (`tables`), a caller may keep plain arrays (`arrays`): the numpy
reference images of the lamp tests (Lee's sun term is 3e6 evaluations) and the glass traces of
the back-face tests. Such a caller names the lab files its arrays are computed from beyond the
reference (`sources`), and they join the key.
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


@functools.lru_cache(maxsize=None)
def sources_digest(sources: tuple) -> str:
    """Hash of the named files' source (a folder: its .py files)."""
    h = hashlib.sha256()
    paths = [p for s in map(Path, sources)
             for p in (sorted(s.rglob("*.py")) if s.is_dir() else [s])]
    for path in paths:
        h.update(os.path.relpath(path, _ADDON).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _plain(inputs):
    """`inputs` with every array replaced by its dtype, shape and hash (an array's repr elides
    the middle of a large one)."""
    if isinstance(inputs, np.ndarray):
        return ("ndarray", inputs.dtype.str, inputs.shape,
                hashlib.sha256(np.ascontiguousarray(inputs).tobytes()).hexdigest())
    if isinstance(inputs, (list, tuple)):
        return type(inputs)(_plain(x) for x in inputs)
    return inputs


def key(name: str, inputs, sources: tuple = ()) -> str:
    parts = [name, repr(_plain(inputs)), np.__version__, code_digest()]
    if sources:
        parts.append(sources_digest(tuple(str(s) for s in sources)))
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def _save(path: Path, arrays: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    with os.fdopen(fd, "wb") as out:
        np.savez(out, **arrays)
    os.replace(tmp, path)  # another process computing the same entry writes the same bytes


# An entry is an npz mapping; these turn a computed result into one and back (`prefix`: the
# entry's name in the seed archive).
def _from_tables(tables) -> dict:
    arrays = {"count": np.array(len(tables))}
    for i, table in enumerate(tables):
        if table is not None:
            arrays.update({f"{i}_{f}": getattr(table, f) for f in _FIELDS})
    return arrays


def _tables_from(data, prefix: str = "") -> list:
    """The tables of one entry from an npz mapping (its arrays' names after `prefix`)."""
    return [MomentTable(*(data[f"{prefix}{i}_{f}"] for f in _FIELDS))
            if f"{prefix}{i}_x" in data else None for i in range(int(data[prefix + "count"]))]


def _from_arrays(arrays) -> dict:
    return {"count": np.array(len(arrays)),
            **{f"a{i}": np.asarray(a) for i, a in enumerate(arrays)}}


def _arrays_from(data, prefix: str = "") -> list:
    return [data[f"{prefix}a{i}"] for i in range(int(data[prefix + "count"]))]


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
    return _cached(name, key(name, inputs), compute, _from_tables, _tables_from)


def arrays(name: str, inputs, compute, sources: tuple = ()) -> list:
    """compute() -> a list of numpy arrays, cached like `tables`; `sources`: the files (or
    folders) besides the reference that the arrays are computed from."""
    return _cached(name, key(name, inputs, sources), compute, _from_arrays, _arrays_from)


def _cached(name: str, digest: str, compute, encode, decode) -> list:
    if not enabled():
        return list(compute())
    stem = f"{name}-{digest}"
    _record(stem + ".npz")
    path = directory() / f"{stem}.npz"
    if path.exists():
        try:
            with np.load(path, allow_pickle=False) as data:
                return decode(data)
        except (OSError, ValueError, KeyError):
            pass  # a damaged entry: compute it again
    if _seed() is not None and f"{stem}/count" in _seed():
        return decode(_seed(), stem + "/")
    result = list(compute())
    _save(path, encode(result))
    return result


def _record(filename: str) -> None:
    """Append the entry's name to $MICROFACET_LAB_TABLE_RECORD, if set (`make tables`)."""
    log = os.environ.get("MICROFACET_LAB_TABLE_RECORD")
    if log:
        with open(log, "a", encoding="utf-8") as out:
            out.write(filename + "\n")
