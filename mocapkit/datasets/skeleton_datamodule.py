"""What every skeleton data module shares: frame sampling and padded batches (loaders and the split
description come from :class:`~mocapkit.datasets.split_datamodule.SplitDataModule`). Batches are dicts::

    skeletons  float32 [B, M, T, J, 3]   metres; zero-padded to the longest sample in the batch
    labels     int64   [B]               0-based class
    lengths    int64   [B]               frames before padding
    indices    int64   [B]               sample index in the data set
    subjects   int64   [B]

Padding frames are all zero, which every model here treats as "no body".
"""
from __future__ import annotations

import numpy as np
import torch

from mocapkit.datasets.split_datamodule import SplitDataModule


def uniform_frame_indices(length: int, max_frames: int) -> np.ndarray:
    """Indices of ``min(length, max_frames)`` frames spread evenly over ``length`` frames."""
    if length <= max_frames:
        return np.arange(length)
    return np.linspace(0, length - 1, max_frames).round().astype(np.int64)


def pad_collate(items: list[dict]) -> dict:
    """Stack samples (``skeleton`` ``[M, T, J, 3]``, ``label``, ``index``, ``subject``), zero-padding the frame axis."""
    longest = max(it["skeleton"].shape[1] for it in items)
    first = items[0]["skeleton"]
    skeletons = first.new_zeros((len(items), first.shape[0], longest) + tuple(first.shape[2:]))
    for b, it in enumerate(items):
        skeletons[b, :, : it["skeleton"].shape[1]] = it["skeleton"]
    return {
        "skeletons": skeletons,
        "labels": torch.tensor([it["label"] for it in items]),
        "lengths": torch.tensor([it["skeleton"].shape[1] for it in items]),
        "indices": torch.tensor([it["index"] for it in items]),
        "subjects": torch.tensor([it["subject"] for it in items]),
    }


class SkeletonDataModule(SplitDataModule):
    """Base class of the skeleton data modules: batches padded by :func:`pad_collate`."""

    collate_fn = staticmethod(pad_collate)
