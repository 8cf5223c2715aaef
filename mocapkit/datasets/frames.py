"""Frame sampling shared by the data modules (training, evaluation) and ONNX prediction, and the runs of a
per-frame mask (gaps, contacts, hidden joints) that refinement, synthesis and the Kinect simulator walk; numpy only.

A model trained on sequences subsampled to ``max_frames`` frames must see the same sampling when it is
deployed: the data modules apply :func:`uniform_frame_indices` to every sample, and ``mocapkit predict``
applies it to every file with the ``max_frames`` that ``mocapkit export`` stored in the ONNX metadata.
"""
from __future__ import annotations

import numpy as np


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the runs of True in a 1-D bool array, ``stop`` exclusive (``mask[start:stop]``)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[False], np.asarray(mask, dtype=bool), [False]]).astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def uniform_frame_indices(length: int, max_frames: int | None) -> np.ndarray:
    """Indices of ``min(length, max_frames)`` frames spread evenly over ``length`` frames (all when None)."""
    if max_frames is None or length <= max_frames:
        return np.arange(length)
    return np.linspace(0, length - 1, max_frames).round().astype(np.int64)
