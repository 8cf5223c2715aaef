"""Evaluation splits: NTU X-Sub / X-View / X-Set, custom subject splits, and validation hold-outs.

Every function works on plain per-sample arrays, so other datasets can reuse
them. ``data`` is anything with ``subjects`` / ``cameras`` / ``setups`` arrays
(one entry per sample, 1-based IDs as in the NTU names): an
:class:`~mocapkit.datasets.ntu_cache.NTUCache`, a ``dict`` or any object with
those attributes. Only the arrays a split needs must be present.

Protocol facts (field-anchors §1.1):

* NTU-60 uses setups S001–S017 only; the ``ntu60_*`` splits ignore samples from
  later setups, so they can be computed on an NTU-120 cache too.
* ``ntu60_xsub``: the 20 training subjects in :data:`NTU60_XSUB_TRAIN_SUBJECTS`, every other subject is test.
* ``ntu60_xview``: cameras 2 and 3 train, camera 1 test.
* ``ntu120_xsub``: the 53 training subjects in :data:`NTU120_XSUB_TRAIN_SUBJECTS`, every other subject is test.
* ``ntu120_xset``: even setup IDs train, odd setup IDs test.
* ``custom``: explicit ``train_subjects`` and ``test_subjects``; samples of other subjects are unused.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

NTU60_XSUB_TRAIN_SUBJECTS: tuple[int, ...] = (
    1, 2, 4, 5, 8, 9, 13, 14, 15, 16, 17, 18, 19, 25, 27, 28, 31, 34, 35, 38,
)
NTU120_XSUB_TRAIN_SUBJECTS: tuple[int, ...] = (
    1, 2, 4, 5, 8, 9, 13, 14, 15, 16, 17, 18, 19, 25, 27, 28, 31, 34, 35, 38,
    45, 46, 47, 49, 50, 52, 53, 54, 55, 56, 57, 58, 59, 70, 74, 78, 80, 81, 82, 83,
    84, 85, 86, 89, 91, 92, 93, 94, 95, 97, 98, 100, 103,
)
NTU_XVIEW_TRAIN_CAMERAS: tuple[int, ...] = (2, 3)
NTU_XVIEW_TEST_CAMERAS: tuple[int, ...] = (1,)
#: Last setup of NTU-60 (NTU-120 adds S018–S032).
NTU60_MAX_SETUP = 17

SPLITS = ("ntu60_xsub", "ntu60_xview", "ntu120_xsub", "ntu120_xset", "custom")


def split_indices(data, split: str, train_subjects: Iterable[int] | None = None,
                  test_subjects: Iterable[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)`` of one protocol, sorted int64 arrays.

    Args:
        data: an object or mapping with per-sample ``subjects`` / ``cameras`` / ``setups`` arrays.
        split: one of :data:`SPLITS`.
        train_subjects, test_subjects: for ``split="custom"`` only (both required, disjoint,
            and every listed subject must have samples).

    Raises:
        ValueError: unknown split (lists the known ones); bad custom subject lists.
        KeyError: ``data`` lacks an array the split needs (names it).
    """
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; known splits: {', '.join(SPLITS)}")
    if split != "custom" and (train_subjects is not None or test_subjects is not None):
        raise ValueError(f"train_subjects / test_subjects are only used by split='custom', not {split!r}")

    if split == "ntu60_xsub":
        in_ntu60 = _array(data, "setups") <= NTU60_MAX_SETUP
        is_train = np.isin(_array(data, "subjects"), NTU60_XSUB_TRAIN_SUBJECTS)
        train, test = in_ntu60 & is_train, in_ntu60 & ~is_train
    elif split == "ntu60_xview":
        in_ntu60 = _array(data, "setups") <= NTU60_MAX_SETUP
        cameras = _array(data, "cameras")
        train = in_ntu60 & np.isin(cameras, NTU_XVIEW_TRAIN_CAMERAS)
        test = in_ntu60 & np.isin(cameras, NTU_XVIEW_TEST_CAMERAS)
    elif split == "ntu120_xsub":
        train = np.isin(_array(data, "subjects"), NTU120_XSUB_TRAIN_SUBJECTS)
        test = ~train
    elif split == "ntu120_xset":
        train = _array(data, "setups") % 2 == 0
        test = ~train
    else:
        train, test = subject_masks(_array(data, "subjects"), train_subjects, test_subjects)
    return np.flatnonzero(train), np.flatnonzero(test)


def subject_masks(subjects: np.ndarray, train_subjects, test_subjects,
                  label: str = "split='custom'") -> tuple[np.ndarray, np.ndarray]:
    """Boolean masks of the samples of ``train_subjects`` and of ``test_subjects``.

    Both lists are required, non-empty, disjoint, and every listed subject must have samples;
    errors name the list (``label`` names the split in the messages).
    """
    absent = [name for name, value in (("train_subjects", train_subjects), ("test_subjects", test_subjects))
              if value is None]
    if absent:
        raise ValueError(f"{label} needs both subject lists; missing: {', '.join(absent)}")
    train_set = {int(s) for s in train_subjects}
    test_set = {int(s) for s in test_subjects}
    for name, chosen in (("train_subjects", train_set), ("test_subjects", test_set)):
        if not chosen:
            raise ValueError(f"{label}: {name} is empty")
    overlap = sorted(train_set & test_set)
    if overlap:
        raise ValueError(f"{label}: subjects {overlap} are in both train_subjects and test_subjects")
    present = set(np.unique(subjects).tolist())
    for name, chosen in (("train_subjects", train_set), ("test_subjects", test_set)):
        without = sorted(chosen - present)
        if without:
            raise ValueError(f"{label}: {name} lists subjects {without} that have no samples")
    return np.isin(subjects, sorted(train_set)), np.isin(subjects, sorted(test_set))


def validation_split(train_idx: np.ndarray, subjects: np.ndarray, val_fraction: float = 0.2, seed: int = 0,
                     by_subject: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Hold out part of the training samples for validation; the test set is never touched.

    Args:
        train_idx: sample indices of the training split (from :func:`split_indices`).
        subjects: per-sample subject IDs of the whole dataset (indexed by ``train_idx``).
        val_fraction: share of training subjects (``by_subject``) or training samples held out.
        seed: the same seed and inputs always give the same split.
        by_subject: hold out whole training subjects (at least 1, never all), so that no
            validation subject is seen in training; else a random share of training samples.

    Returns:
        ``(train_idx, val_idx)``: sorted, disjoint, together equal to the input ``train_idx``.
    """
    if not 0.0 < val_fraction < 1.0:
        raise ValueError(f"val_fraction must be between 0 and 1 (exclusive), got {val_fraction}")
    train_idx = np.sort(np.asarray(train_idx, dtype=np.int64))
    subjects = np.asarray(subjects)
    if len(train_idx) and (train_idx.min() < 0 or train_idx.max() >= len(subjects)):
        raise IndexError(f"train_idx holds indices outside 0..{len(subjects) - 1} (the length of subjects)")
    rng = np.random.default_rng(seed)
    if by_subject:
        pool = np.unique(subjects[train_idx])  # sorted, so the draw only depends on the seed
        if len(pool) < 2:
            raise ValueError(f"by-subject validation needs at least 2 training subjects, got {pool.tolist()}")
        n_val = min(max(int(round(val_fraction * len(pool))), 1), len(pool) - 1)
        val_subjects = rng.choice(pool, size=n_val, replace=False)
        is_val = np.isin(subjects[train_idx], val_subjects)
    else:
        if len(train_idx) < 2:
            raise ValueError(f"validation split needs at least 2 training samples, got {len(train_idx)}")
        n_val = min(max(int(round(val_fraction * len(train_idx))), 1), len(train_idx) - 1)
        is_val = np.zeros(len(train_idx), dtype=bool)
        is_val[rng.choice(len(train_idx), size=n_val, replace=False)] = True
    return train_idx[~is_val], train_idx[is_val]


def split_summary(data, splits: Iterable[str] = ("ntu60_xsub", "ntu60_xview", "ntu120_xsub", "ntu120_xset"),
                  **custom) -> dict[str, dict[str, int]]:
    """Sample counts per split: ``{split: {"train": n, "test": n, "unused": n}}``.

    ``unused`` counts samples in neither part (e.g. NTU-120-only setups under an
    ``ntu60_*`` split). ``custom`` keyword arguments (``train_subjects``,
    ``test_subjects``) are passed on for ``"custom"``.
    """
    total = len(_array(data, "subjects"))
    summary = {}
    for split in splits:
        kwargs = custom if split == "custom" else {}
        train, test = split_indices(data, split, **kwargs)
        summary[split] = {"train": len(train), "test": len(test), "unused": total - len(train) - len(test)}
    return summary


def format_split_summary(summary: Mapping[str, Mapping[str, int]]) -> str:
    """:func:`split_summary` as a markdown table, for reports."""
    lines = ["| split | train | test | unused |", "|---|---:|---:|---:|"]
    lines += [f"| {name} | {c['train']} | {c['test']} | {c['unused']} |" for name, c in summary.items()]
    return "\n".join(lines)


def _array(data, key: str) -> np.ndarray:
    """``data.key`` or ``data[key]`` as a 1-D integer array; KeyError naming ``key`` if absent."""
    if isinstance(data, Mapping):
        value = data.get(key)
    else:
        value = getattr(data, key, None)
    if value is None:
        raise KeyError(f"{type(data).__name__} has no per-sample {key!r} array, which this split needs")
    value = np.asarray(value)
    if value.ndim != 1:
        raise ValueError(f"per-sample {key!r} must be 1-D, got shape {value.shape}")
    return value.astype(np.int64, copy=False)
