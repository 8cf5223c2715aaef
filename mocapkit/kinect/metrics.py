"""Scores of Kinect posture reconstruction (Zhou 2014 ch. 5, ``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md``
§4.6): the joint error against mocap where there is ground truth, and, for real Kinect clips without it, how
steady the skeleton is (bone-length stability, jitter).

Every function takes Kinect-20 clips ``[T, 20, 3]`` in metres (joints in
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order, parents
:data:`~mocapkit.motion.layouts.LANDMARK_PARENTS`) and answers in centimetres.
"""

from __future__ import annotations

import numpy as np

from mocapkit.motion.container import point_distance
from mocapkit.motion.layouts import LANDMARK_PARENTS


def joint_error_cm(a: np.ndarray, b: np.ndarray, per_joint: bool = False):
    """Zhou eqs 5.7–5.9 with the per-frame mean (digest §7 item 29): the mean over frames and joints of the
    Euclidean distance between ``a`` and ``b`` (``[T, J, 3]`` metres), in cm; ``per_joint``: float64 ``[J]``, the
    mean over frames of each joint."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim < 2 or a.shape[-1] != 3:
        raise ValueError(
            f"joint_error_cm: two [T, J, 3] arrays of one shape expected, got {list(a.shape)} and {list(b.shape)}"
        )
    err = point_distance(a, b).reshape(-1, a.shape[-2]) * 100.0
    return err.mean(0) if per_joint else float(err.mean())


def bone_length_sd_cm(clip: np.ndarray) -> float:
    """Bone-length instability: per bone, the standard deviation over frames of its length; the mean over the 19
    bones, in cm (0 for a rigid skeleton; a clip needs ≥ 2 frames)."""
    x = np.asarray(clip, dtype=np.float64)
    children = [j for j, p in enumerate(LANDMARK_PARENTS) if p >= 0]
    lengths = point_distance(x[:, children], x[:, [LANDMARK_PARENTS[j] for j in children]])
    return float(100.0 * lengths.std(axis=0).mean())


def jitter_cm(clip: np.ndarray) -> float:
    """Jitter: the mean over frames and joints of the norm of the second difference ``x_{t+1} − 2x_t + x_{t−1}``
    (cm; a constant-velocity motion scores 0, so it measures acceleration plus noise: compare clips of one motion
    at one frame rate). A clip needs ≥ 3 frames."""
    x = np.asarray(clip, dtype=np.float64)
    return float(100.0 * np.linalg.norm(np.diff(x, n=2, axis=0), axis=-1).mean())
