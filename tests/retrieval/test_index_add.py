"""Plain DTW (every joint, root-centred) and ``mocapkit index --add``: appending files to an index answers as an
index built from scratch on the union, and every refusal names both sides."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli import main as cli
from mocapkit.motion.container import Motion
from mocapkit.retrieval import MotionIndex, RetrievalIndexError, SkeletonInputError, build_index
from mocapkit.retrieval.dtw import PlainDTWRetrieval, root_centred_joints
from mocapkit.retrieval.index import VERSION, add_to_index
from mocapkit.train.registry import build_method, method_names
from tests.shared_data import synthetic_hdm05_folder


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """3 classes × 2 actors × 2 takes, HDM05 layout, 120 fps."""
    return synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", "hopBothLegs1hops", "squat1Reps"), clips_per_actor=2, max_frames=160
    )


def _split(folder: Path, tmp_path: Path) -> tuple[Path, Path, Path]:
    """``(first, second, union)`` folders: actor bd, actor mm, and the folder holding both (the same files)."""
    union = tmp_path / "union"
    first, second = union / "first", union / "second"
    shutil.copytree(folder / "bd", first / "bd")
    shutil.copytree(folder / "mm", second / "mm")
    return first, second, union


def _ranking(index: MotionIndex, query: Path) -> list[tuple[str, float]]:
    """(file name, distance) of every indexed file, nearest first."""
    hits = index.search([str(query)], k=0)[0]["results"]
    return [(Path(h["path"]).name, h["distance"]) for h in hits]


# ------------------------------------------------------------------------------------------ plain DTW
def test_plain_dtw_is_root_centred_every_joint_and_not_turned():
    rng = np.random.default_rng(0)
    positions = rng.normal(size=(60, 4, 3)) + np.array([5.0, 1.0, -3.0])
    motion = Motion(positions, ["root", "a", "b", "c"], 60.0, parents=(-1, 0, 1, 1), name="m")
    seq = root_centred_joints(motion, fps=30.0)
    assert seq.shape == (30, 4, 3)
    assert np.allclose(seq[:, 0], 0.0)
    np.testing.assert_allclose(seq[0], positions[0] - positions[0, 0], atol=1e-5)
    # turning the body turns the features (no heading normalisation): plain DTW tells the two apart
    turned = positions.copy()
    turned[..., [0, 2]] = turned[..., [2, 0]] * np.array([1.0, -1.0])
    other = Motion(turned, ["root", "a", "b", "c"], 60.0, parents=(-1, 0, 1, 1), name="turned")
    method = PlainDTWRetrieval(parallel=False).fit([motion])
    # itself: 0 up to the float32 frame costs' rounding (retrieval/frames.py)
    assert method.distances([motion])[0, 0] == pytest.approx(0.0, abs=1e-3)
    assert method.distances([other])[0, 0] > 0.1
    # another skeleton is refused, naming the file and both joint counts
    three = Motion(positions[:, :3], ["root", "a", "b"], 60.0, parents=(-1, 0, 1), name="three.bvh")
    with pytest.raises(SkeletonInputError, match=r"three.bvh: 3 joints, the database clips have 4"):
        method.distances([three])


def test_plain_dtw_fills_gaps():
    positions = np.tile(np.linspace(0, 1, 40)[:, None, None], (1, 3, 3))
    positions[:, 0] = 0.0
    positions[10:20, 2] = np.nan
    motion = Motion(positions, ["root", "a", "b"], 30.0, parents=(-1, 0, 1), name="gappy")
    seq = root_centred_joints(motion, fps=30.0)
    assert np.isfinite(seq).all()
    np.testing.assert_allclose(seq[15, 2], positions[15, 1], atol=1e-6)  # the line interpolated across the gap


# ------------------------------------------------------------------------------------------ add
@pytest.mark.parametrize(
    "method", ["dtw_plain", "dtw_positions", "dtw_mutual_proximity", "dtw_world_frame", "dtw_takes"]
)
def test_an_appended_index_ranks_as_one_built_on_the_union(folder, tmp_path, method):
    first, second, union = _split(folder, tmp_path)
    build_index(first, tmp_path / "grown", method=method, quiet=True)
    _, report = add_to_index(tmp_path / "grown", second, quiet=True)
    assert len(report["added"]) == 6 and not report["duplicates"]
    grown = MotionIndex.load(tmp_path / "grown")  # what was written
    scratch = build_index(union, method=method, quiet=True)
    assert len(grown.files) == len(scratch.files) == 12
    for query in (min((second / "mm").glob("*squat*.amc")), min((first / "bd").glob("*walk*.amc"))):
        a, b = _ranking(grown, query), _ranking(scratch, query)
        assert [name for name, _ in a] == [name for name, _ in b]
        np.testing.assert_allclose([d for _, d in a], [d for _, d in b], rtol=1e-6)  # float32 frame costs


def test_a_dtw_index_keeps_its_frames_on_disk_memory_mapped(folder, tmp_path):
    """Each feature's frames are their own .npy file, opened memory-mapped; the loaded index ranks as the one built,
    and --add appends to the files in place (the same files, their first frames untouched; no other feature's file
    left behind)."""
    first, second, _ = _split(folder, tmp_path)
    built = build_index(first, tmp_path / "idx", method="dtw_mutual_proximity", quiet=True)
    files = sorted(p.name for p in (tmp_path / "idx").glob("*.npy"))
    assert files == ["database_positions_frames.npy", "database_relational_frames.npy"]
    loaded = MotionIndex.load(tmp_path / "idx")
    assert all(isinstance(store.data, np.memmap) for store in loaded.method.database_.values())
    query = min((second / "mm").glob("*squat*.amc"))
    assert _ranking(loaded, query) == _ranking(built, query)
    np.save(tmp_path / "idx" / "database_world_velocity_frames.npy", np.zeros((2, 3)))  # a stale file
    frames_file = tmp_path / "idx" / "database_positions_frames.npy"
    inode, before = frames_file.stat().st_ino, frames_file.read_bytes()
    del loaded  # (its read-only map of the file)
    grown, _ = add_to_index(tmp_path / "idx", second, quiet=True)
    assert sorted(p.name for p in (tmp_path / "idx").glob("*.npy")) == files
    header = 128  # numpy's .npy header for these arrays
    assert frames_file.stat().st_ino == inode and frames_file.read_bytes()[header : len(before)] == before[header:]
    assert _ranking(grown, query) == _ranking(MotionIndex.load(tmp_path / "idx"), query)
    assert len(MotionIndex.load(tmp_path / "idx").method.database_["positions"]) == 12
    (tmp_path / "idx" / "database_positions_frames.npy").write_bytes(b"not an array")  # damaged: named
    with pytest.raises(RetrievalIndexError, match=r"database_positions_frames\.npy: cannot be read"):
        MotionIndex.load(tmp_path / "idx")


def test_adding_beyond_the_reference_clips_keeps_them(folder, tmp_path):
    """Past ``n_reference`` clips the reference clips and scales stay; the new clips get their own statistics."""
    first, second, _ = _split(folder, tmp_path)
    index = build_index(first, tmp_path / "idx", method="dtw_mutual_proximity", overrides=["n_reference=4"], quiet=True)
    scales, reference = index.method.scales_.copy(), index.method.reference_.copy()
    grown, _ = add_to_index(tmp_path / "idx", second, quiet=True)
    assert np.array_equal(grown.method.reference_, reference) and np.array_equal(grown.method.scales_, scales)
    # the distances to the reference clips are kept only while every clip is one (they would not be read again)
    assert grown.method.reference_distances_ is None and not any(
        key.startswith("reference_distances") for key in grown.method._state()
    )
    assert len(grown.method.database_mean_) == 12 and np.isfinite(grown.method.database_std_).all()
    query = min((second / "mm").glob("*hop*.amc"))
    top = _ranking(grown, query)[0][0]
    assert "hopBothLegs1hops" in top and "_bd_" in top  # the other actor's hop, not itself (left out)


def test_add_skips_duplicates_reports_bad_files_and_refuses_others(folder, tmp_path, capsys):
    first, second, _ = _split(folder, tmp_path)
    out = tmp_path / "idx"
    build_index(first, out, method="dtw_positions", quiet=True)
    # files already indexed: skipped with a message, nothing written
    _, report = add_to_index(out, first, quiet=True)
    assert len(report["duplicates"]) == 6 and not report["added"]
    # a bad file: refused naming it, or skipped and reported with --skip-bad
    bad = second / "mm" / "HDM_mm_broken_001_120.amc"
    bad.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot not numbers\n")
    with pytest.raises(RetrievalIndexError, match="HDM_mm_broken_001_120.amc"):
        add_to_index(out, second, quiet=True)
    assert len(MotionIndex.load(out).files) == 6  # nothing appended
    capsys.readouterr()
    assert cli(["index", str(second), "--out", str(out), "--add", "--skip-bad"]) == 0
    captured = capsys.readouterr()
    assert "added 6 files" in captured.out and "skipped 1" in captured.out
    assert "HDM_mm_broken_001_120.amc" in captured.err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["n_files"] == 12 and manifest["skipped"][0]["path"].endswith("HDM_mm_broken_001_120.amc")
    # another method or other parameters: refused naming both
    with pytest.raises(RetrievalIndexError, match="--method dtw_positions.*--method dtw_relational"):
        add_to_index(out, second, method="dtw_relational", quiet=True)
    with pytest.raises(RetrievalIndexError, match=r"window: index None, asked 0.1"):
        add_to_index(out, second, overrides=["window=0.1"], quiet=True)
    # an index of another format version: refused naming both versions
    manifest["version"] = 3
    (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RetrievalIndexError, match=rf"version 3, expected 'mocapkit-retrieval-index' version {VERSION}"):
        add_to_index(out, second, quiet=True)


@pytest.mark.parametrize("name", [n for n in method_names("retrieval") if n != "embedding"])
def test_every_method_appends_or_refuses(name, folder):
    """A method appends (the database grows; a query identical to an added clip finds it first) or raises
    NotImplementedError, which ``index --add`` turns into a refusal naming the index."""
    from mocapkit.datasets import read_motion

    fast = {
        "dtw_mutual_proximity": ["n_reference=4"],
        "dtw_world_frame": ["n_reference=4"],
        "tsr_stpm": ["n_atoms=16", "n_nonzero=2", "ksvd_iter=2"],
        "tsr_stpm_thesis": ["n_atoms=16", "n_nonzero=4", "ksvd_iter=2"],
    }.get(name, [] if name.startswith("dtw") else ["n_words=8", "n_features=20", "n_neighbors=2"])
    if name == "udfs":
        fast = [*fast, "views=[gpf]"]
    files = sorted(folder.rglob("*.amc"))
    motions = [read_motion(f) for f in files]
    method = build_method("retrieval", name, fast).fit(motions[:8])
    try:
        method.add(motions[8:])
    except NotImplementedError:
        return
    assert method.n_database_ == len(motions)
    d = method.distances(motions[9:10])
    assert d.shape == (1, len(motions)) and int(np.argmin(d[0])) == 9


# ------------------------------------------------------------------------------------------ workers
def test_index_workers_read_the_files_as_one_process_does(folder, tmp_path):
    """--workers N reads and normalises the files in N processes: the same files, in the same order, the same
    ranking; a bad file is still named, or skipped and reported with --skip-bad."""
    one = build_index(folder, method="dtw_positions", quiet=True)
    two = build_index(folder, method="dtw_positions", quiet=True, workers=2)
    assert one.files == two.files
    query = min(folder.glob("*/*squat*.amc"))
    assert _ranking(one, query) == _ranking(two, query)
    broken = tmp_path / "broken"
    shutil.copytree(folder, broken)
    (broken / "bd" / "HDM_bd_broken_001_120.amc").write_text("1\nroot 0 0\n")
    with pytest.raises(RetrievalIndexError, match="HDM_bd_broken_001_120.amc"):
        build_index(broken, method="dtw_positions", quiet=True, workers=2)
    skipping = build_index(broken, method="dtw_positions", quiet=True, workers=2, skip_bad=True)
    assert len(skipping.files) == len(one.files) and skipping.skipped[0]["path"].endswith("broken_001_120.amc")
    with pytest.raises(RetrievalIndexError, match="--workers 0"):
        build_index(folder, method="dtw_positions", quiet=True, workers=0)


def test_plain_dtw_names_the_file_of_another_skeleton_when_files_are_read_apart(folder, tmp_path):
    """Files normalised one at a time (the workers) are checked for one skeleton when the index is fitted, and the
    odd one out is named."""
    from mocapkit.datasets import read_motion, write_motion

    mixed = tmp_path / "mixed"
    shutil.copytree(folder / "bd", mixed / "bd")
    motion = read_motion(min((folder / "mm").glob("*.amc")))
    fewer = Motion(motion.positions[:, :5], motion.joint_names[:5], motion.fps, parents=motion.parents[:5], name="few")
    write_motion(mixed / "few.c3d", fewer)
    with pytest.raises(RetrievalIndexError, match=r"few\.c3d: clip \d+: 5 joints"):
        build_index(mixed, method="dtw_plain", quiet=True, workers=2)


def test_a_library_built_in_parts_with_its_frames_on_disk_ranks_as_one_built_in_memory(folder, tmp_path):
    """``store_frames`` then ``add`` (how bench_retrieval builds 10^6 clips): the frames go to .npy files that grow
    in place, and the search (prefiltered, mutual proximity past ``n_reference``) ranks as the same fit and add in
    memory; an index saved into that folder keeps the files as they are."""
    from mocapkit.datasets import read_motion

    motions = [read_motion(p) for p in sorted(folder.glob("*/*.amc"))]
    overrides = ["prefilter=5", "n_reference=4"]
    on_disk = build_method("retrieval", "dtw_large", overrides).fit(motions[:6]).store_frames(tmp_path / "parts")
    in_memory = build_method("retrieval", "dtw_large", overrides).fit(motions[:6])
    for part in (motions[6:9], motions[9:]):
        on_disk.add(part)
        in_memory.add(part)
    assert all(isinstance(store.data, np.memmap) for store in on_disk.database_.values())
    assert sorted(p.name for p in (tmp_path / "parts").iterdir()) == [
        "database_positions_frames.npy",
        "database_relational_frames.npy",
        "database_speeds_frames.npy",
    ]
    a, b = on_disk.search(motions, 4), in_memory.search(motions, 4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_allclose(a[1], b[1])
    inode = (tmp_path / "parts" / "database_positions_frames.npy").stat().st_ino
    MotionIndex("dtw_large", on_disk, [{"path": str(i)} for i in range(12)], [], []).save(tmp_path / "parts")
    assert (tmp_path / "parts" / "database_positions_frames.npy").stat().st_ino == inode
    loaded = MotionIndex.load(tmp_path / "parts").method
    np.testing.assert_array_equal(loaded.search(motions, 4)[0], a[0])


def test_a_large_library_is_indexed_in_parts_with_every_file(folder, tmp_path, monkeypatch):
    """Past ``PART_FILES`` files a DTW index is fitted on a part spread over the library and the other parts are
    added, their frames appended to the output folder's files: every file is indexed once, and a method with
    nothing to learn ranks as when built in one go."""
    from mocapkit.retrieval import index as index_module

    whole = build_index(folder, method="dtw_plain", quiet=True)
    monkeypatch.setattr(index_module, "PART_FILES", 5)
    parts = build_index(folder, tmp_path / "idx", method="dtw_plain", quiet=True)
    assert sorted(parts.paths) == sorted(whole.paths) and len(set(parts.paths)) == 12
    assert isinstance(parts.method.database_["positions"].data, np.memmap)
    query = min((folder / "mm").glob("*squat*.amc"))
    assert _ranking(MotionIndex.load(tmp_path / "idx"), query) == _ranking(whole, query)
    large = build_index(folder, tmp_path / "large", method="dtw_large", overrides=["n_reference=4"], quiet=True)
    assert len(large.files) == 12 and len(large.method.database_mean_) == 12
    assert [r["path"] for r in large.search([str(query)], k=1)[0]["results"]] != [str(query.resolve())]
