"""The reference tables kept on disk between runs (addon/lab/table_cache.py): read back bit for
bit, keyed by their inputs, never used when switched off, recomputed when damaged. What this
catches: a cache that hands one model's table to another, or a reference that drifts from what
its code computes."""
import numpy as np
import pytest

from addon.lab import table_cache
from addon.lab.reference.quadrature import MomentTable


@pytest.fixture()
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("MICROFACET_LAB_CACHE", str(tmp_path))
    monkeypatch.delenv("MICROFACET_LAB_TABLE_CACHE", raising=False)
    monkeypatch.delenv("MICROFACET_LAB_TABLE_RECORD", raising=False)
    monkeypatch.setattr(table_cache, "SEED_PATH", tmp_path / "seed.npz")
    table_cache._seed.cache_clear()
    yield tmp_path / "tables"
    table_cache._seed.cache_clear()


def _table(seed):
    rng = np.random.default_rng(seed)
    return MomentTable(np.sort(rng.normal(size=5)), *(rng.normal(size=(5, 3)) for _ in range(3)))


def _counting(result):
    calls = []

    def compute():
        calls.append(1)
        return result
    return compute, calls


def _same(a, b):
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in table_cache._FIELDS)


def test_tables_read_back_bit_for_bit(cache_dir):
    tables = [_table(1), None, _table(2)]
    compute, calls = _counting(tables)
    first = table_cache.tables("t", ("a", 1), compute)
    again = table_cache.tables("t", ("a", 1), compute)
    assert len(calls) == 1 and len(list(cache_dir.iterdir())) == 1
    assert again[1] is None and _same(again[0], tables[0]) and _same(again[2], tables[2])
    assert first[0] is tables[0]


def test_other_inputs_or_names_compute_their_own(cache_dir):
    compute, calls = _counting([_table(3)])
    table_cache.tables("t", ("a", 1), compute)
    table_cache.tables("t", ("a", 2), compute)
    table_cache.tables("u", ("a", 1), compute)
    assert len(calls) == 3


def test_switched_off_it_computes_and_writes_nothing(cache_dir, monkeypatch):
    monkeypatch.setenv("MICROFACET_LAB_TABLE_CACHE", "0")
    compute, calls = _counting([_table(4)])
    table_cache.tables("t", 1, compute)
    table_cache.tables("t", 1, compute)
    assert len(calls) == 2 and not cache_dir.exists()


def test_a_damaged_entry_is_computed_again(cache_dir):
    compute, calls = _counting([_table(5)])
    table_cache.tables("t", 1, compute)
    (entry,) = cache_dir.iterdir()
    entry.write_bytes(b"not an npz")
    again = table_cache.tables("t", 1, compute)
    assert len(calls) == 2 and _same(again[0], _table(5))


def test_the_key_follows_the_code():
    assert len(table_cache.code_digest()) == 64
    assert table_cache.key("t", 1) != table_cache.key("t", 2)


def test_the_digest_covers_the_reference_sources(tmp_path, monkeypatch):
    """A change in any file a table is computed from changes the key (so the table is computed
    again); the catalog and the reference are among them."""
    names = {p.name for p in table_cache._SOURCES}
    assert {"catalog.py", "table_cache.py"} <= names
    assert any(d.name == "reference" for d in table_cache._SOURCE_DIRS)
    source = tmp_path / "reference" / "model.py"
    source.parent.mkdir()
    source.write_text("ALPHA = 1\n")
    monkeypatch.setattr(table_cache, "_SOURCES", ())
    monkeypatch.setattr(table_cache, "_SOURCE_DIRS", (source.parent,))
    table_cache.code_digest.cache_clear()
    before = table_cache.key("t", 1)
    source.write_text("ALPHA = 2\n")
    table_cache.code_digest.cache_clear()
    after = table_cache.key("t", 1)
    table_cache.code_digest.cache_clear()
    assert before != after


def test_a_fresh_machine_reads_the_repository_seed_and_records_what_it_read(cache_dir, tmp_path,
                                                                           monkeypatch):
    """What `make tables` writes and a fresh clone reads: an entry found in the seed archive is
    read from it bit for bit (not computed, not copied into the cache); a key the seed lacks
    (other inputs, or changed code) is computed; every entry read is recorded when asked."""
    record = tmp_path / "record.txt"
    monkeypatch.setenv("MICROFACET_LAB_TABLE_RECORD", str(record))
    compute, calls = _counting([_table(5), None])
    table_cache.tables("t", ("a", 1), compute)
    table_cache.write_seed(record.read_text().split())
    for entry in cache_dir.iterdir():
        entry.unlink()
    table_cache._seed.cache_clear()
    again = table_cache.tables("t", ("a", 1), compute)
    assert len(calls) == 1 and _same(again[0], _table(5)) and again[1] is None
    assert not list(cache_dir.iterdir())
    table_cache.tables("t", ("a", 2), compute)
    assert len(calls) == 2
    name = f"t-{table_cache.key('t', ('a', 1))}.npz"
    assert record.read_text().split() == [name, name, f"t-{table_cache.key('t', ('a', 2))}.npz"]


def test_arrays_read_back_bit_for_bit_keyed_by_their_content_and_sources(cache_dir, tmp_path):
    """Plain arrays (the lamp tests' reference images, the glass traces): read back bit for bit;
    an input array is keyed by its content, also where its repr elides it; a change in a source
    file the caller names is a new key."""
    result = [np.arange(6.0).reshape(2, 3), np.array([1e-300, np.pi])]
    compute, calls = _counting(result)
    big = np.zeros(5000)
    first = table_cache.arrays("a", ("x", big), compute)
    again = table_cache.arrays("a", ("x", big.copy()), compute)
    assert len(calls) == 1 and all(np.array_equal(a, b) and a.dtype == b.dtype
                                   for a, b in zip(again, result))
    assert first[0] is result[0]
    changed = big.copy()
    changed[2500] = 1.0  # repr(big) == repr(changed)
    table_cache.arrays("a", ("x", changed), compute)
    assert len(calls) == 2
    source = tmp_path / "lab.py"
    source.write_text("A = 1\n")
    before = table_cache.key("a", 1, (source,))
    source.write_text("A = 2\n")
    table_cache.sources_digest.cache_clear()
    assert table_cache.key("a", 1, (source,)) != before != table_cache.key("a", 1)


def test_the_seed_holds_only_table_entries():
    """addon/lab/table_seed.npz (make tables): arrays named <name>-<key>/<array>, nothing else."""
    import re
    assert table_cache.SEED_PATH.exists(), "make tables writes it; the repository carries it"
    with np.load(table_cache.SEED_PATH, allow_pickle=False) as data:
        names = data.files
    pattern = re.compile(r"^[a-z0-9_]+-[0-9a-f]{32}/(count|\d+_(x|E|Vn|Vt_over_sin)|a\d+)$")
    assert names and not [n for n in names if not pattern.match(n)]
