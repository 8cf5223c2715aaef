"""Splits every data set shares: subject lists and validation hold-outs from the training side.

The protocol of each benchmark lives in its package (``ntu.splits``, ``msr_action3d.splits``,
``hdm05.splits``, ``casia_b.splits``); they build on these two functions. The test side of a
split is never touched here: validation always comes from training samples.
"""

from __future__ import annotations

import numpy as np


def subject_masks(
    subjects: np.ndarray, train_subjects, test_subjects, label: str = "split='custom'"
) -> tuple[np.ndarray, np.ndarray]:
    """Boolean masks of the samples of ``train_subjects`` and of ``test_subjects``.

    Both lists are required, non-empty, disjoint, and every listed subject must have samples;
    errors name the list (``label`` names the split in the messages).
    """
    absent = [
        name for name, value in (("train_subjects", train_subjects), ("test_subjects", test_subjects)) if value is None
    ]
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


def validation_split(
    train_idx: np.ndarray, subjects: np.ndarray, val_fraction: float = 0.2, seed: int = 0, by_subject: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Hold out part of the training samples for validation; the test set is never touched.

    Args:
        train_idx: sample indices of the training split (from :func:`split_indices`).
        subjects: per-sample subject IDs of the whole dataset (indexed by ``train_idx``).
        val_fraction: share of training subjects (``by_subject``) or training samples held out; 0 holds out
            nothing (the run then trains on every training sample and keeps its last checkpoint).
        seed: the same seed and inputs always give the same split.
        by_subject: hold out whole training subjects (at least 1, never all), so that no
            validation subject is seen in training; else a random share of training samples.

    Returns:
        ``(train_idx, val_idx)``: sorted, disjoint, together equal to the input ``train_idx``.
    """
    if not 0.0 <= val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in [0, 1), got {val_fraction}")
    train_idx = np.sort(np.asarray(train_idx, dtype=np.int64))
    if val_fraction == 0:
        return train_idx, train_idx[:0]
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
