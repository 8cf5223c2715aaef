"""Frame sampling shared by the data modules (training, evaluation) and ONNX prediction, and the runs of a
per-frame mask (gaps, contacts, hidden joints) that refinement, synthesis and the Kinect simulator walk, and the
overlapping windows a sequence network runs over a long take (:func:`refine_windows`); numpy only.

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


def window_starts(frames: int, window: int, overlap: int) -> list[int]:
    """First frames of the windows that cover ``frames`` frames (one window when ``frames ≤ window``)."""
    if frames <= window:
        return [0]
    hop = max(1, window - overlap)
    starts = list(range(0, frames - window + 1, hop))
    if starts[-1] != frames - window:
        starts.append(frames - window)
    return starts


def blend_weights(length: int, overlap: int, first: bool, last: bool) -> np.ndarray:
    """``[length]`` weights of one window: linear ramps over ``overlap`` frames at the ends that have a neighbour."""
    weights = np.ones(length, dtype=np.float64)
    ramp = min(int(overlap), length // 2)
    if ramp > 0:
        up = (np.arange(ramp) + 1.0) / (ramp + 1.0)
        if not first:
            weights[:ramp] = up
        if not last:
            weights[length - ramp :] = up[::-1]
    return weights


def refine_windows(predict, positions: np.ndarray, missing: np.ndarray, window: int, overlap: int) -> np.ndarray:
    """Run ``predict(positions [N, W, J, 3] float32, missing [N, W, J] bool) -> [N, W, J, 3]`` over overlapping
    windows of one take (``positions [T, J, 3]``, ``missing [T, J]``) and blend the windows into ``[T, J, 3]``."""
    frames = positions.shape[0]
    starts = window_starts(frames, window, overlap)
    length = min(frames, window)
    batch_p = np.stack([positions[s : s + length] for s in starts]).astype(np.float32)
    batch_m = np.stack([missing[s : s + length] for s in starts])
    out = np.asarray(predict(batch_p, batch_m), dtype=np.float64)
    total = np.zeros(positions.shape, dtype=np.float64)
    weight = np.zeros(frames, dtype=np.float64)
    for i, s in enumerate(starts):
        w = blend_weights(length, overlap, first=i == 0, last=i == len(starts) - 1)
        total[s : s + length] += w[:, None, None] * out[i]
        weight[s : s + length] += w
    return total / weight[:, None, None]
