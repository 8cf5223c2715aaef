"""NTU evaluation splits, custom subject splits and validation hold-outs."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from mocapkit.datasets.ntu.splits import (
    NTU60_XSUB_TRAIN_SUBJECTS,
    NTU120_XSUB_TRAIN_SUBJECTS,
    SPLITS,
    format_split_summary,
    split_indices,
    split_summary,
)
from mocapkit.datasets.splits import validation_split


@pytest.fixture(scope="module")
def grid():
    """One sample per (setup 1-32, camera 1-3, subject 1-106): 10,176 samples."""
    setups, cameras, subjects = np.meshgrid(np.arange(1, 33), np.arange(1, 4), np.arange(1, 107), indexing="ij")
    return SimpleNamespace(setups=setups.ravel(), cameras=cameras.ravel(), subjects=subjects.ravel())


def _check_partition(train, test, n):
    assert train.dtype == np.int64 and test.dtype == np.int64
    assert np.all(np.diff(train) > 0) and np.all(np.diff(test) > 0)
    assert not np.intersect1d(train, test).size
    assert train.max(initial=0) < n and test.max(initial=0) < n


def test_subject_lists():
    assert len(NTU60_XSUB_TRAIN_SUBJECTS) == 20 and len(set(NTU60_XSUB_TRAIN_SUBJECTS)) == 20
    assert len(NTU120_XSUB_TRAIN_SUBJECTS) == 53 and len(set(NTU120_XSUB_TRAIN_SUBJECTS)) == 53
    # pyskl uses the 53-subject list for NTU-60 too: restricted to subjects <= 40 it is the same split.
    assert tuple(s for s in NTU120_XSUB_TRAIN_SUBJECTS if s <= 40) == NTU60_XSUB_TRAIN_SUBJECTS
    assert max(NTU120_XSUB_TRAIN_SUBJECTS) == 103


def test_ntu60_xsub(grid):
    train, test = split_indices(grid, "ntu60_xsub")
    _check_partition(train, test, len(grid.subjects))
    assert set(grid.subjects[train]) == set(NTU60_XSUB_TRAIN_SUBJECTS)
    assert set(grid.subjects[test]).isdisjoint(NTU60_XSUB_TRAIN_SUBJECTS)
    assert {3, 6, 40, 41, 106} <= set(grid.subjects[test])
    assert grid.setups[np.concatenate([train, test])].max() == 17  # NTU-60 setups only
    assert len(train) + len(test) == 17 * 3 * 106


def test_ntu60_xview(grid):
    train, test = split_indices(grid, "ntu60_xview")
    _check_partition(train, test, len(grid.subjects))
    assert set(grid.cameras[train]) == {2, 3} and set(grid.cameras[test]) == {1}
    assert len(train) == 17 * 2 * 106 and len(test) == 17 * 106


def test_ntu120_xsub(grid):
    train, test = split_indices(grid, "ntu120_xsub")
    _check_partition(train, test, len(grid.subjects))
    assert set(grid.subjects[train]) == set(NTU120_XSUB_TRAIN_SUBJECTS)
    assert len(set(grid.subjects[test])) == 106 - 53
    assert len(train) + len(test) == len(grid.subjects)


def test_ntu120_xset(grid):
    train, test = split_indices(grid, "ntu120_xset")
    _check_partition(train, test, len(grid.subjects))
    assert set(grid.setups[train]) == set(range(2, 33, 2))
    assert set(grid.setups[test]) == set(range(1, 33, 2))


def test_plain_dict_and_missing_key():
    data = {"subjects": np.array([1, 3, 2, 1]), "cameras": np.array([1, 2, 3, 1])}
    train, test = split_indices(data, "custom", train_subjects=[1, 2], test_subjects=[3])
    assert train.tolist() == [0, 2, 3] and test.tolist() == [1]
    with pytest.raises(KeyError, match="'setups'"):
        split_indices(data, "ntu120_xset")


def test_unknown_split_lists_known_ones(grid):
    with pytest.raises(ValueError, match="unknown split 'xsub'") as info:
        split_indices(grid, "xsub")
    for name in SPLITS:
        assert name in str(info.value)


def test_custom_split(grid):
    train, test = split_indices(grid, "custom", train_subjects=[1, 2, 3], test_subjects=(10, 11))
    assert set(grid.subjects[train]) == {1, 2, 3} and set(grid.subjects[test]) == {10, 11}
    with pytest.raises(ValueError, match="missing: test_subjects"):
        split_indices(grid, "custom", train_subjects=[1])
    with pytest.raises(ValueError, match="missing: train_subjects, test_subjects"):
        split_indices(grid, "custom")
    with pytest.raises(ValueError, match=r"subjects \[2\] are in both"):
        split_indices(grid, "custom", train_subjects=[1, 2], test_subjects=[2, 3])
    with pytest.raises(ValueError, match=r"test_subjects lists subjects \[200\] that have no samples"):
        split_indices(grid, "custom", train_subjects=[1], test_subjects=[3, 200])
    with pytest.raises(ValueError, match="only used by split='custom'"):
        split_indices(grid, "ntu60_xsub", train_subjects=[1])


def test_validation_by_subject(grid):
    train, _ = split_indices(grid, "ntu60_xsub")
    tr, val = validation_split(train, grid.subjects, val_fraction=0.2, seed=0)
    assert np.array_equal(np.sort(np.concatenate([tr, val])), train)
    val_subjects, tr_subjects = set(grid.subjects[val]), set(grid.subjects[tr])
    assert val_subjects.isdisjoint(tr_subjects)
    assert len(val_subjects) == 4 and val_subjects <= set(NTU60_XSUB_TRAIN_SUBJECTS)
    again = validation_split(train, grid.subjects, val_fraction=0.2, seed=0)
    assert np.array_equal(again[0], tr) and np.array_equal(again[1], val)
    others = {frozenset(grid.subjects[validation_split(train, grid.subjects, seed=s)[1]]) for s in range(1, 6)}
    assert len(others | {frozenset(val_subjects)}) > 1  # the seed matters


def test_validation_by_subject_bounds():
    subjects = np.array([5, 5, 7, 7, 7, 9])
    tr, val = validation_split(np.arange(6), subjects, val_fraction=0.01)
    assert len(set(subjects[val])) == 1  # at least one subject
    tr, val = validation_split(np.arange(6), subjects, val_fraction=0.99)
    assert len(set(subjects[tr])) == 1  # never all of them
    with pytest.raises(ValueError, match="at least 2 training subjects"):
        validation_split(np.array([0, 1]), subjects)
    with pytest.raises(ValueError, match="val_fraction"):
        validation_split(np.arange(6), subjects, val_fraction=1.0)
    with pytest.raises(ValueError, match="val_fraction"):
        validation_split(np.arange(6), subjects, val_fraction=-0.1)
    for by_subject in (True, False):  # 0: no validation part, every training sample trains
        tr, val = validation_split(np.array([4, 0, 2]), subjects, val_fraction=0, by_subject=by_subject)
        assert tr.tolist() == [0, 2, 4] and val.size == 0


def test_validation_by_sample(grid):
    train, _ = split_indices(grid, "ntu120_xsub")
    tr, val = validation_split(train, grid.subjects, val_fraction=0.1, seed=3, by_subject=False)
    assert len(val) == round(0.1 * len(train))
    assert np.array_equal(np.union1d(tr, val), train) and not np.intersect1d(tr, val).size
    tr2, val2 = validation_split(train, grid.subjects, val_fraction=0.1, seed=3, by_subject=False)
    assert np.array_equal(val, val2)


def test_summary(grid):
    summary = split_summary(grid)
    assert summary["ntu60_xview"] == {"train": 17 * 2 * 106, "test": 17 * 106, "unused": 15 * 3 * 106}
    assert summary["ntu120_xset"]["unused"] == 0
    table = format_split_summary(summary)
    assert table.splitlines()[0] == "| split | train | test | unused |"
    assert f"| ntu60_xview | {17 * 2 * 106} | {17 * 106} |" in table
    custom = split_summary(grid, splits=["custom"], train_subjects=[1], test_subjects=[2])
    assert custom["custom"]["train"] == custom["custom"]["test"] == 32 * 3


def test_works_on_a_prepared_cache(tmp_path):
    from mocapkit.datasets.formats.ntu_skeleton import sequence_from_positions, write_skeleton
    from mocapkit.datasets.ntu.cache import NTUCache
    from mocapkit.datasets.ntu.prepare import prepare_ntu

    src = tmp_path / "src"
    src.mkdir()
    positions = np.zeros((1, 3, 25, 3)) + [0.0, 0.0, 3.0]
    names = ["S001C001P001R001A001", "S001C002P003R001A001", "S002C003P001R002A002", "S020C001P045R001A070"]
    for name in names:
        write_skeleton(src / f"{name}.skeleton", sequence_from_positions(name, positions))
    prepare_ntu(src, tmp_path / "cache", progress=False)
    cache = NTUCache(tmp_path / "cache")
    train, test = split_indices(cache, "ntu60_xview")
    assert cache.names[train].tolist() == names[1:3] and cache.names[test].tolist() == names[:1]
    train, test = split_indices(cache, "ntu120_xsub")
    assert cache.names[train].tolist() == [names[0], names[2], names[3]]
