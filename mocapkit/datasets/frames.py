"""Frame sampling shared by the data modules (training, evaluation) and ONNX prediction; numpy only.

A model trained on sequences subsampled to ``max_frames`` frames must see the same sampling when it is
deployed: the data modules apply :func:`uniform_frame_indices` to every sample, and ``mocapkit predict``
applies it to every file with the ``max_frames`` that ``mocapkit export`` stored in the ONNX metadata.
"""
from __future__ import annotations

import numpy as np


def uniform_frame_indices(length: int, max_frames: int | None) -> np.ndarray:
    """Indices of ``min(length, max_frames)`` frames spread evenly over ``length`` frames (all when None)."""
    if max_frames is None or length <= max_frames:
        return np.arange(length)
    return np.linspace(0, length - 1, max_frames).round().astype(np.int64)
