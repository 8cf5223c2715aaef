"""Prepared caches check themselves on opening: damaged files fail naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.cache_files import CacheIntegrityError
from mocapkit.datasets.casia_b.cache import GEICache, write_gei_cache
from mocapkit.datasets.formats.ntu_skeleton import (
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.prepare import prepare_ntu


@pytest.fixture
def ntu_cache(tmp_path) -> Path:
    src = tmp_path / "src"
    src.mkdir()
    rng = np.random.default_rng(0)
    for k, frames in enumerate((12, 20, 9, 15)):
        positions = rng.normal(size=(1, frames, 25, 3)) * 0.1 + [0.0, 0.5, 3.0]
        name = f"S001C001P001R001A{k + 1:03d}"
        write_skeleton(src / f"{name}.skeleton", sequence_from_positions(name, positions))
    out = tmp_path / "cache"
    prepare_ntu(src, out, progress=False)
    return out


def test_meta_records_integrity(ntu_cache):
    meta = json.loads((ntu_cache / "meta.json").read_text())
    record = meta["integrity"]
    assert record["num_samples"] == 4
    assert record["array"]["shape"][0] == 56 and record["array"]["nan_rows"] == 0
    assert len(record["index"]["sha256"]) == 64
    cache = NTUCache(ntu_cache)
    assert len(cache) == 4 and cache.positions(1).shape == (2, 20, 25, 3)
    cache.verify()


def test_positions_that_lost_rows(ntu_cache):
    path = ntu_cache / "positions.npy"
    np.save(path, np.load(path)[:28])  # still a valid .npy, half the rows
    with pytest.raises(CacheIntegrityError, match=r"positions.npy: shape \[28, 2, 25, 3\], meta.json recorded"):
        NTUCache(ntu_cache)


def test_positions_that_lost_rows_without_integrity_record(ntu_cache):
    meta = json.loads((ntu_cache / "meta.json").read_text())
    del meta["integrity"]  # a cache written before the record existed
    (ntu_cache / "meta.json").write_text(json.dumps(meta))
    NTUCache(ntu_cache)  # still opens when intact
    path = ntu_cache / "positions.npy"
    np.save(path, np.load(path)[:28])
    with pytest.raises(CacheIntegrityError, match=r"positions.npy: .*samples point outside its 28 rows"):
        NTUCache(ntu_cache)


def test_truncated_positions_bytes(ntu_cache):
    path = ntu_cache / "positions.npy"
    path.write_bytes(path.read_bytes()[:-1000])
    with pytest.raises(CacheIntegrityError, match=r"positions.npy: the file is \d+ bytes but its header announces"):
        NTUCache(ntu_cache)


def test_truncated_index(ntu_cache):
    path = ntu_cache / "index.npz"
    path.write_bytes(path.read_bytes()[:300])
    with pytest.raises(CacheIntegrityError, match=r"index.npz: the file is 300 bytes"):
        NTUCache(ntu_cache)
    meta = json.loads((ntu_cache / "meta.json").read_text())
    del meta["integrity"]
    (ntu_cache / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CacheIntegrityError, match=r"index.npz: unreadable"):
        NTUCache(ntu_cache)


def test_index_changed_after_writing(ntu_cache):
    path = ntu_cache / "index.npz"
    with np.load(path) as index:
        arrays = dict(index)
    arrays["labels"] = arrays["labels"][::-1].copy()
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(CacheIntegrityError, match=r"index.npz: (its SHA-256 checksum differs|the file is)"):
        NTUCache(ntu_cache)


@pytest.mark.parametrize("content", ["{not json", "[1, 2]", "\xff\xfe"])
def test_bad_meta_json_names_the_file(ntu_cache, content):
    (ntu_cache / "meta.json").write_bytes(content.encode("latin-1"))
    with pytest.raises(CacheIntegrityError, match=r"meta.json: "):
        NTUCache(ntu_cache)


def test_nan_rows_are_reported(ntu_cache):
    positions = np.load(ntu_cache / "positions.npy", mmap_mode="r+")
    positions[13, 0, 4, 1] = np.nan  # sample 1 (rows 12..31), frame 1
    positions.flush()
    del positions
    cache = NTUCache(ntu_cache)
    np.testing.assert_array_equal(cache.nan_rows(), [13])
    with pytest.raises(CacheIntegrityError, match=r"positions.npy: 1 rows hold NaN \(first: 13\)"):
        cache.verify()
    with pytest.raises(CacheIntegrityError, match=r"sample S001C001P001R001A002 holds NaN \(row 13, frame 1"):
        cache.positions(1)
    cache.positions(0)  # other samples stay readable


def _gei_cache(out: Path) -> Path:
    geis = np.random.default_rng(0).random((6, 8, 5))
    index = {
        "names": [f"001/nm-01/{v:03d}" for v in range(6)],
        "subjects": np.ones(6),
        "conditions": np.zeros(6),
        "sequences": np.ones(6),
        "views": np.arange(6) * 18,
        "cycles": np.zeros(6),
        "frames": np.full(6, 30),
    }
    return write_gei_cache(out, geis, index, {"per": "sequence"})


def test_gei_cache_checks(tmp_path):
    out = _gei_cache(tmp_path / "gei")
    cache = GEICache(out)
    assert len(cache) == 6 and cache.gei(2).shape == (8, 5)
    np.save(out / "geis.npy", np.load(out / "geis.npy")[:3])
    with pytest.raises(CacheIntegrityError, match=r"geis.npy: shape \[3, 8, 5\]"):
        GEICache(out)
    meta = json.loads((out / "meta.json").read_text())
    del meta["integrity"]
    (out / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CacheIntegrityError, match=r"geis.npy: 3 GEIs for 6 index entries"):
        GEICache(out)


def test_errors_are_picklable():
    import pickle

    err = pickle.loads(pickle.dumps(CacheIntegrityError("x/index.npz", "truncated")))
    assert str(err) == "x/index.npz: truncated; prepare the cache again" and err.path == "x/index.npz"
