"""prepare_ntu -> cache folder -> NTUCache, on real samples plus synthetic and broken files."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.formats.ntu_skeleton import (
    SkeletonFormatError,
    parse_ntu_name,
    read_skeleton,
    select_main_bodies,
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.prepare import prepare_ntu
from tests.shared_data import NTU_SAMPLES as SAMPLES
from tests.shared_data import needs

needs_samples = needs(SAMPLES)

REAL = ["S001C001P001R001A011", "S001C003P008R002A058", "S003C001P015R001A034"]
THREE_BODY = "S005C002P002R002A050"
THREE_BODY_IDS = [72057594037900001, 72057594037900002, 72057594037900003]


def _synthetic(path: Path, bodies: int, frames: int, seed: int, body_ids=None) -> None:
    rng = np.random.default_rng(seed)
    scale = np.array([0.01, 0.3, 0.1][:bodies])[:, None, None, None]
    tall = np.array([0.3, 1.0, 0.3])  # taller than wide, as people are: spread denoising keeps them
    positions = rng.normal(size=(bodies, frames, 25, 3)) * scale * tall + [0.0, 0.5, 3.0]
    write_skeleton(path, sequence_from_positions(path.stem, positions, body_ids=body_ids))


def _tree(root: Path, real: bool = True) -> Path:
    """src/ with real samples (two levels deep) and synthetic files, one of them with 3 bodies."""
    src = root / "src"
    (src / "nested" / "deeper").mkdir(parents=True)
    if real and SAMPLES.is_dir():
        shutil.copy(SAMPLES / f"{REAL[0]}.skeleton", src)
        shutil.copy(SAMPLES / f"{REAL[1]}.skeleton", src / "nested")
        shutil.copy(SAMPLES / f"{REAL[2]}.skeleton", src / "nested" / "deeper")
    _synthetic(src / f"{THREE_BODY}.skeleton", 3, 40, seed=1, body_ids=THREE_BODY_IDS)
    _synthetic(src / "nested" / "S018C001P045R001A100.skeleton", 1, 25, seed=2)
    _synthetic(src / "nested" / "S002C003P004R002A001.skeleton", 2, 33, seed=3)
    (src / "README.txt").write_text("not a skeleton\n")
    return src


def _broken(path: Path) -> None:
    """A synthetic file cut in the middle of its second frame's joints (error on line 34)."""
    _synthetic(path, 1, 3, seed=4)
    path.write_text("\n".join(path.read_text().splitlines()[:33]) + "\n")


def _all_files(src: Path) -> dict[str, Path]:
    return {p.stem: p for p in src.rglob("*.skeleton")}


# --------------------------------------------------------------------------- contents


@needs_samples
def test_cache_matches_reader_and_body_selection(tmp_path):
    src = _tree(tmp_path)
    report = prepare_ntu(src, tmp_path / "cache", progress=False)
    cache = NTUCache(tmp_path / "cache")
    files = _all_files(src)
    assert report.files_found == len(files) == 6
    assert len(cache) == report.samples_written == 6
    assert list(cache.names) == sorted(files)
    for i, name in enumerate(cache.names):
        expected = select_main_bodies(read_skeleton(files[name])).positions
        got = cache.positions(i)
        assert got.dtype == np.float32 and got.shape == expected.shape == (2, cache.lengths[i], 25, 3)
        np.testing.assert_array_equal(got, expected)
        s = parse_ntu_name(name)
        assert (cache.labels[i], cache.subjects[i], cache.cameras[i], cache.setups[i], cache.replications[i]) == (
            s.action - 1,
            s.subject,
            s.camera,
            s.setup,
            s.replication,
        )
    # Samples are concatenated with no gaps.
    assert cache.offsets[0] == 0
    np.testing.assert_array_equal(cache.offsets[1:], np.cumsum(cache.lengths)[:-1])
    assert cache.all_positions.shape == (int(cache.lengths.sum()), 2, 25, 3)
    assert dict(zip(cache.names, cache.lengths))["S001C001P001R001A011"] == 82
    assert cache.num_classes == 120  # A100 is an NTU-120 action
    assert cache.class_names is None


def test_report_lists_dropped_bodies_and_meta(tmp_path):
    src = _tree(tmp_path, real=False)
    report = prepare_ntu(src, tmp_path / "cache", progress=False)
    assert [d["name"] for d in report.dropped_bodies] == [THREE_BODY]
    entry = report.dropped_bodies[0]
    assert [k["body_id"] for k in entry["kept"]] == THREE_BODY_IDS[1:]  # most motion first
    assert [k["rule"] for k in entry["kept"]] == ["most_motion", "most_motion"]
    assert [d["body_id"] for d in entry["dropped"]] == [THREE_BODY_IDS[0]]
    assert entry["dropped"][0]["rule"] == "less_motion" and "less motion" in entry["dropped"][0]["reason"]
    # every sample's decision is in the report, in cache order, the single-track ones too
    assert [b["name"] for b in report.bodies] == sorted(_all_files(src))
    single = next(b for b in report.bodies if b["tracks"] == 1)
    assert single["kept"][0]["rule"] == "only_candidate" and single["kept"][0]["reason"] == "the only track"
    on_disk = json.loads((tmp_path / "cache" / "report.json").read_text())
    assert on_disk["bodies"] == report.bodies
    assert (
        on_disk["bodies"][[b["name"] for b in report.bodies].index(THREE_BODY)]["dropped"][0]["body_id"]
        == THREE_BODY_IDS[0]
    )  # exact 64-bit ID
    assert on_disk["totals"]["tracks_dropped_less_motion"] == 1 and on_disk["totals"]["tracks_kept_most_motion"] == 4
    text = (tmp_path / "cache" / "report.txt").read_text()
    assert str(THREE_BODY_IDS[0]) in text and "[less_motion]" in text
    assert "Body selection (the 1 samples whose only track is body 0 are not listed); samples listed (2):" in text
    meta = json.loads((tmp_path / "cache" / "meta.json").read_text())
    assert meta["num_samples"] == 3 and meta["max_bodies"] == 2 and meta["frames_trimmed"] is False
    assert meta["source"] == str(src.resolve())
    assert meta["options"]["min_body_frames"] == 12
    assert meta["options"]["denoise_spread"] is True and meta["options"]["denoise_flicker"] is True


def test_class_names_and_max_bodies(tmp_path):
    src = _tree(tmp_path, real=False)
    (src / "classes.txt").write_text("\n".join(f"action {k}" for k in range(1, 121)) + "\n")
    prepare_ntu(src, tmp_path / "cache", max_bodies=3, progress=False)
    cache = NTUCache(tmp_path / "cache")
    assert cache.num_classes == 120 and cache.class_names[99] == "action 100"
    i = cache.index_of(THREE_BODY)
    assert cache.positions(i).shape == (3, 40, 25, 3) and cache.positions(i)[2].any()


def test_missing_list_excludes_samples(tmp_path):
    src = _tree(tmp_path, real=False)
    listing = tmp_path / "missing.txt"
    listing.write_text("The following samples have missing skeletons.\n\nS002C003P004R002A001\nS999C001P001R001A001\n")
    report = prepare_ntu(src, tmp_path / "cache", missing_list=listing, progress=False)
    cache = NTUCache(tmp_path / "cache")
    assert "S002C003P004R002A001" not in cache.names and len(cache) == 2
    assert [(s["name"], s["reason"]) for s in report.skipped] == [("S002C003P004R002A001", "missing_list")]
    assert "missing_list" in (tmp_path / "cache" / "report.txt").read_text()
    # A list of names works as well.
    report = prepare_ntu(src, tmp_path / "cache2", missing_list=["S018C001P045R001A100"], progress=False)
    assert report.samples_written == 2


@needs_samples
def test_official_missing_lists_keep_the_real_samples(tmp_path):
    src = _tree(tmp_path)
    report = prepare_ntu(
        src, tmp_path / "cache", progress=False, missing_list=SAMPLES / "NTU_RGBD120_samples_with_missing_skeletons.txt"
    )
    assert report.samples_written == 6 and not report.skipped


def test_same_cache_with_two_workers(tmp_path):
    src = _tree(tmp_path)
    prepare_ntu(src, tmp_path / "one", workers=1, progress=False)
    prepare_ntu(src, tmp_path / "two", workers=2, progress=False)
    a, b = NTUCache(tmp_path / "one"), NTUCache(tmp_path / "two")
    np.testing.assert_array_equal(np.asarray(a.all_positions), np.asarray(b.all_positions))
    for key in ("names", "offsets", "lengths", "labels", "subjects", "cameras", "setups", "replications"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))


# --------------------------------------------------------------------------- bad input


def test_stops_at_first_malformed_file(tmp_path):
    src = _tree(tmp_path, real=False)
    _broken(src / "nested" / "S003C001P001R001A001.skeleton")
    _broken(src / "S009C001P001R001A001.skeleton")  # later in name order
    with pytest.raises(SkeletonFormatError) as info:
        prepare_ntu(src, tmp_path / "cache", workers=2, progress=False)
    assert info.value.path == str(src / "nested" / "S003C001P001R001A001.skeleton")
    assert info.value.line == 34
    assert "S003C001P001R001A001.skeleton, line 34" in str(info.value)
    # No half-written cache is left looking finished.
    assert not (tmp_path / "cache" / "positions.npy").exists()
    with pytest.raises(FileNotFoundError, match="not a prepared NTU cache"):
        NTUCache(tmp_path / "cache")


@pytest.mark.parametrize("workers", [1, 2])
def test_skip_bad_reports_and_continues(tmp_path, workers):
    src = _tree(tmp_path, real=False)
    bad = src / "nested" / "S003C001P001R001A001.skeleton"
    _broken(bad)
    (src / "S001C001P001R001A001.skeleton").write_text("many\n")  # bad first line: 0 rows allocated
    (src / "walk_01.skeleton").write_text("1\n0\n")
    report = prepare_ntu(src, tmp_path / "cache", workers=workers, skip_bad=True, progress=False)
    reasons = {s["name"]: s["reason"] for s in report.skipped}
    assert reasons == {"S003C001P001R001A001": "malformed", "S001C001P001R001A001": "malformed", "walk_01": "bad_name"}
    message = next(s["message"] for s in report.skipped if s["name"] == "S003C001P001R001A001")
    assert f"{bad}, line 34" in message
    cache = NTUCache(tmp_path / "cache")
    assert len(cache) == 3 and report.samples_written == 3
    # The rows reserved for the broken file were given back: the array holds exactly the samples.
    assert cache.all_positions.shape[0] == int(cache.lengths.sum()) == report.total_frames
    i = cache.index_of(THREE_BODY)
    expected = select_main_bodies(read_skeleton(src / f"{THREE_BODY}.skeleton")).positions
    np.testing.assert_array_equal(cache.positions(i), expected)
    text = (tmp_path / "cache" / "report.txt").read_text()
    assert "[malformed]" in text and "line 34" in text and "[bad_name]" in text


def test_bad_name_without_skip_bad(tmp_path):
    src = _tree(tmp_path, real=False)
    (src / "walk_01.skeleton").write_text("1\n0\n")
    with pytest.raises(ValueError, match="walk_01.skeleton: file name is not an NTU sample name"):
        prepare_ntu(src, tmp_path / "cache", progress=False)


def test_duplicate_sample_name(tmp_path):
    src = _tree(tmp_path, real=False)
    shutil.copy(src / f"{THREE_BODY}.skeleton", src / "nested" / "deeper")
    with pytest.raises(ValueError, match=f"sample {THREE_BODY} already read from"):
        prepare_ntu(src, tmp_path / "cache", progress=False)


def test_empty_or_absent_source_folder(tmp_path):
    empty = tmp_path / "empty"
    (empty / "sub").mkdir(parents=True)
    (empty / "notes.txt").write_text("x")
    with pytest.raises(FileNotFoundError, match=f"no .skeleton files found under {empty}"):
        prepare_ntu(empty, tmp_path / "cache", progress=False)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        prepare_ntu(tmp_path / "nope", tmp_path / "cache", progress=False)


def test_frame_without_bodies_is_zero(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    positions = np.zeros((1, 10, 25, 3)) + [0.0, 0.0, 3.0]
    positions[0, :, :, 0] += np.linspace(0, 1, 10)[:, None]
    positions[0, 7:] = 0.0  # the body leaves: frames 7-9 have no body (kept, not trimmed)
    write_skeleton(src / "S001C001P001R001A001.skeleton", sequence_from_positions("S001C001P001R001A001", positions))
    (src / "S001C001P001R001A002.skeleton").write_text("2\n0\n0\n")  # no body at all
    report = prepare_ntu(src, tmp_path / "cache", progress=False)
    cache = NTUCache(tmp_path / "cache")
    assert list(cache.lengths) == [10, 2]
    assert cache.positions(0)[0, :7].any() and not cache.positions(0)[:, 7:].any()
    assert report.empty_samples == ["S001C001P001R001A002"]


# --------------------------------------------------------------------------- NTUCache


def test_cache_errors_and_pickling(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        NTUCache(tmp_path / "nope")
    with pytest.raises(FileNotFoundError, match="meta.json is missing"):
        NTUCache(tmp_path)
    src = _tree(tmp_path, real=False)
    prepare_ntu(src, tmp_path / "cache", progress=False)
    cache = NTUCache(tmp_path / "cache")
    first = cache.positions(0)
    clone = pickle.loads(pickle.dumps(cache))
    assert clone._positions is None  # memmap reopened lazily in the new process
    np.testing.assert_array_equal(clone.positions(0), first)
    first[:] = 1.0  # a copy, not a view of the read-only memmap
    assert not np.array_equal(cache.positions(0), first)
    with pytest.raises(IndexError):
        cache.positions(len(cache))
    with pytest.raises(KeyError, match="S999"):
        cache.index_of("S999C001P001R001A001")
