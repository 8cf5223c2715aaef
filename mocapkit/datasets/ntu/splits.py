"""Evaluation splits: NTU X-Sub / X-View / X-Set, custom subject splits, and validation hold-outs.

Every function works on plain per-sample arrays, so other datasets can reuse
them. ``data`` is anything with ``subjects`` / ``cameras`` / ``setups`` arrays
(one entry per sample, 1-based IDs as in the NTU names): an
:class:`~mocapkit.datasets.ntu.cache.NTUCache`, a ``dict`` or any object with
those attributes. Only the arrays a split needs must be present.

Protocol facts (Shahroudy et al. 2016; Liu et al. 2019 for NTU-120):

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

from mocapkit.datasets.splits import subject_masks

NTU60_XSUB_TRAIN_SUBJECTS: tuple[int, ...] = (
    1,
    2,
    4,
    5,
    8,
    9,
    13,
    14,
    15,
    16,
    17,
    18,
    19,
    25,
    27,
    28,
    31,
    34,
    35,
    38,
)
NTU120_XSUB_TRAIN_SUBJECTS: tuple[int, ...] = (
    1,
    2,
    4,
    5,
    8,
    9,
    13,
    14,
    15,
    16,
    17,
    18,
    19,
    25,
    27,
    28,
    31,
    34,
    35,
    38,
    45,
    46,
    47,
    49,
    50,
    52,
    53,
    54,
    55,
    56,
    57,
    58,
    59,
    70,
    74,
    78,
    80,
    81,
    82,
    83,
    84,
    85,
    86,
    89,
    91,
    92,
    93,
    94,
    95,
    97,
    98,
    100,
    103,
)
NTU_XVIEW_TRAIN_CAMERAS: tuple[int, ...] = (2, 3)
NTU_XVIEW_TEST_CAMERAS: tuple[int, ...] = (1,)
#: Last setup of NTU-60 (NTU-120 adds S018–S032).
NTU60_MAX_SETUP = 17

SPLITS = ("ntu60_xsub", "ntu60_xview", "ntu120_xsub", "ntu120_xset", "custom")


def split_indices(
    data, split: str, train_subjects: Iterable[int] | None = None, test_subjects: Iterable[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
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


def split_summary(
    data, splits: Iterable[str] = ("ntu60_xsub", "ntu60_xview", "ntu120_xsub", "ntu120_xset"), **custom
) -> dict[str, dict[str, int]]:
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
