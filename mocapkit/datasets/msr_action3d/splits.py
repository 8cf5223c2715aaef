"""MSR Action3D evaluation protocols.

Protocols (Li, Zhang & Liu 2010; Wang et al. 2012):

* ``cross_subject``: subjects 1, 3, 5, 7, 9 train, 2, 4, 6, 8, 10 test (configurable);
* ``random_half``: a seeded random half of each action's sequences trains, the rest
  tests (the thesis's split for its 93.33 %; not comparable with cross-subject);
* ``subset``: ``AS1`` / ``AS2`` / ``AS3``, the 8-action subsets of Li et al. 2010
  (:data:`ACTION_SUBSETS`), combined with either split.
"""

from __future__ import annotations

import numpy as np

from mocapkit.datasets.msr_action3d.dataset import ACTION_NAMES, ACTION_SUBSETS
from mocapkit.datasets.splits import subject_masks

#: Cross-subject protocol (Li et al. 2010; Wang et al. CVPR'12): odd subjects train, even subjects test.
CROSS_SUBJECT_TRAIN: tuple[int, ...] = (1, 3, 5, 7, 9)
CROSS_SUBJECT_TEST: tuple[int, ...] = (2, 4, 6, 8, 10)

MSR_SPLITS = ("cross_subject", "random_half")


def msr_split_indices(
    data,
    split: str = "cross_subject",
    subset: str | None = None,
    train_subjects=None,
    test_subjects=None,
    seed: int = 0,
    train_fraction: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)`` of an MSR Action3D protocol (sorted int64).

    Args:
        data: an :class:`MSRAction3D` or anything with per-sample ``actions`` and ``subjects`` arrays.
        split: ``"cross_subject"`` (``train_subjects`` / ``test_subjects``, default odd / even) or
            ``"random_half"`` (per action, a seeded random ``train_fraction`` trains, the rest tests).
        subset: None (all 20 actions) or ``"AS1"`` / ``"AS2"`` / ``"AS3"``; samples of other actions are unused.
        seed: the draw of ``random_half``.
    """
    if split not in MSR_SPLITS:
        raise ValueError(f"unknown MSR Action3D split {split!r}; known splits: {', '.join(MSR_SPLITS)}")
    actions, subjects = _ints(data, "actions"), _ints(data, "subjects")
    in_subset = np.isin(actions, subset_actions(subset)) if subset else np.ones(len(actions), dtype=bool)
    if split == "cross_subject":
        train, test = subject_masks(
            subjects,
            CROSS_SUBJECT_TRAIN if train_subjects is None else train_subjects,
            CROSS_SUBJECT_TEST if test_subjects is None else test_subjects,
            label="cross_subject",
        )
        train, test = in_subset & train, in_subset & test
        return np.flatnonzero(train), np.flatnonzero(test)
    if train_subjects is not None or test_subjects is not None:
        raise ValueError("train_subjects / test_subjects are only used by split='cross_subject'")
    if not 0.0 < train_fraction < 1.0:
        raise ValueError(f"train_fraction must be between 0 and 1 (exclusive), got {train_fraction}")
    rng = np.random.default_rng(seed)
    train = []
    for action in np.unique(actions[in_subset]):  # sorted, so the draw depends on the seed only
        members = np.flatnonzero(in_subset & (actions == action))
        n_train = min(max(round(train_fraction * len(members)), 1), len(members) - 1)
        train.extend(rng.choice(members, size=n_train, replace=False).tolist())
    train_mask = np.zeros(len(actions), dtype=bool)
    train_mask[train] = True
    return np.flatnonzero(train_mask), np.flatnonzero(in_subset & ~train_mask)


def subset_actions(subset: str | None) -> tuple[int, ...]:
    """The 1-based action IDs of ``subset`` (None: all 20), sorted."""
    if subset is None:
        return tuple(range(1, len(ACTION_NAMES) + 1))
    if subset not in ACTION_SUBSETS:
        raise ValueError(f"unknown MSR Action3D subset {subset!r}; known: {', '.join(ACTION_SUBSETS)} or null")
    return tuple(sorted(ACTION_SUBSETS[subset]))


def _ints(data, key: str) -> np.ndarray:
    value = data.get(key) if isinstance(data, dict) else getattr(data, key, None)
    if value is None:
        raise KeyError(f"{type(data).__name__} has no per-sample {key!r} array")
    return np.asarray(value, dtype=np.int64)
