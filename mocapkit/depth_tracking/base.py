"""The one contract of every full-body pose estimator from depth video (Lou 2012 ch. 3 and its baselines).

An estimator is a scikit-learn estimator (parameters stored untouched in ``__init__``, learned state in attributes
ending in ``_``) with two methods:

``fit(sequences)``
    learn from training performers' :class:`~mocapkit.datasets.formats.depth_images.DepthSequence` s that carry
    ground-truth ``joints`` (the mocap they were rendered from): the tracker builds its motion-prior database from
    the joints, the regressor trains its network on depth → joints, the GP baseline on sensor skeleton → joints.
    Returns ``self``.
``predict(sequence) -> [T, 16, 3]``
    float32 positions of the 16 :data:`TRACKED_JOINTS` in every frame, **camera coordinates** (metres, x right,
    y down, z forward), whatever the method uses of the sequence (depth, colour, the sensor's skeleton).

Errors are :func:`joint_error_mm`: the per-frame mean over the 16 joints of the Euclidean distance (Lou 2012 §3.4,
"16 joints including root"), in millimetres.
"""

from __future__ import annotations

import numpy as np

from mocapkit.datasets.formats.depth_images import DepthSequence
from mocapkit.motion.layouts import LANDMARK_NAMES

#: The 16 joints the estimators report and are scored on: the Kinect v1 skeleton without hands and feet, the ends
#: of the tracker's 15 bones (HipCenter, Spine, ShoulderCenter, Head, both shoulders, elbows, wrists, hips, knees,
#: ankles), in :data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order.
TRACKED_JOINTS: tuple[str, ...] = tuple(name for name in LANDMARK_NAMES if not name.endswith(("hand", "foot")))
#: Index of each of :data:`TRACKED_JOINTS` in a Kinect-20 (:data:`~mocapkit.motion.layouts.LANDMARK_NAMES`) array.
KINECT20_INDEX: np.ndarray = np.array([LANDMARK_NAMES.index(name) for name in TRACKED_JOINTS])


class DepthInputError(ValueError):
    """A depth sequence an estimator cannot work on; the message names the file and the frame."""


def tracked_joints(kinect20: np.ndarray) -> np.ndarray:
    """The 16 :data:`TRACKED_JOINTS` of Kinect-20 positions ``[..., 20, 3]`` → ``[..., 16, 3]``."""
    return np.asarray(kinect20)[..., KINECT20_INDEX, :]


def joint_error_mm(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per-frame mean Euclidean error over the joints, millimetres: ``[T]`` from two ``[T, 16, 3]`` (metres)."""
    return 1000.0 * np.linalg.norm(np.asarray(estimate, float) - np.asarray(truth, float), axis=-1).mean(axis=-1)


def check_sequence(sequence: DepthSequence, needs: tuple[str, ...] = (), what: str = "predict") -> None:
    """Reject a sequence no estimator can work on, naming the file and the frame.

    Args:
        sequence: the depth video.
        needs: attributes that must be present (``"joints"``, ``"sensor_joints"``, ``"colour"``).
        what: the operation, for the message.

    Raises:
        DepthInputError: no frames, a depth array that is not uint16 ``[T, H, W]`` of the intrinsics' size, a frame
            with no depth measurement at all, or a needed attribute missing or of the wrong shape.
    """
    label = sequence.source or "depth sequence"
    depth = sequence.depth_mm
    if not isinstance(depth, np.ndarray) or depth.ndim != 3 or depth.dtype != np.uint16:
        raise DepthInputError(
            f"{label}: depth must be uint16 [frames, height, width] millimetres, got "
            f"{getattr(depth, 'dtype', type(depth).__name__)} {list(np.shape(depth))}"
        )
    if depth.shape[0] == 0:
        raise DepthInputError(f"{label}: no frames, {what} needs at least one")
    if depth.shape[1:] != sequence.intrinsics.shape:
        raise DepthInputError(
            f"{label}: depth images are {depth.shape[2]}×{depth.shape[1]} but the camera intrinsics are "
            f"{sequence.intrinsics.width}×{sequence.intrinsics.height}"
        )
    empty = ~depth.reshape(depth.shape[0], -1).any(axis=1)
    if empty.any():
        raise DepthInputError(
            f"{label}: frame {int(np.flatnonzero(empty)[0])} has no depth measurement at all (all background); "
            f"{int(empty.sum())} such frame(s)"
        )
    for name in needs:
        value = getattr(sequence, name)
        if value is None:
            raise DepthInputError(f"{label}: {what} needs the sequence's {name}, which it does not have")
        if name in ("joints", "sensor_joints"):
            if value.shape[:1] != depth.shape[:1] or value.ndim != 3 or value.shape[2] != 3:
                raise DepthInputError(f"{label}: {name} must be [{depth.shape[0]}, J, 3], got {list(value.shape)}")
            bad = ~np.isfinite(value).all(axis=(1, 2))
            if bad.any():
                raise DepthInputError(f"{label}: {name} are not finite in frame {int(np.flatnonzero(bad)[0])}")


__all__ = ["KINECT20_INDEX", "TRACKED_JOINTS", "DepthInputError", "check_sequence", "joint_error_mm", "tracked_joints"]
