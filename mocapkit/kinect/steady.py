"""Output options every Kinect corrector can apply after its correction, so that a corrected skeleton keeps what a
real one has (docs/results/kinect.md#real-kinect-skeletons):

1. ``tracked_correction`` (0–1): the share of the correction applied to the joints the sensor TRACKED; INFERRED and
   NOT_TRACKED joints always get the whole correction. 1 (default): correct every joint; 0: a tracked joint stays
   as the sensor gave it, so only the joints the sensor guessed change.
2. ``smooth_window`` (frames, odd; 0 off): a Savitzky–Golay filter (quadratic, centred, so without lag:
   :func:`scipy.signal.savgol_filter`) of every joint's trajectory.
3. ``rigid_bones``: every bone takes the clip's median length along its own direction, from the pelvis outwards
   (:func:`~mocapkit.motion.geometry.retarget`): bone-length sd 0 by construction.

They run in this order in :func:`steady_output`; clips are ``[T, 20, 3]`` metres in
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order, states ``[T, 20]`` SDK tracking states.
"""

from __future__ import annotations

import numpy as np

from mocapkit.datasets.synthetic.kinect_noise import TRACKED
from mocapkit.motion.geometry import retarget
from mocapkit.motion.layouts import LANDMARK_PARENTS

#: The parameters of :func:`steady_output`, as estimator parameters (applied at prediction time).
STEADY_PARAMS = ("tracked_correction", "smooth_window", "rigid_bones")


def check_steady_params(tracked_correction, smooth_window, rigid_bones, owner: str) -> None:
    """A ValueError naming ``owner`` and the parameter when one of :data:`STEADY_PARAMS` is out of range."""
    if isinstance(tracked_correction, bool) or not isinstance(tracked_correction, (int, float, np.floating)):
        raise ValueError(f"{owner}: tracked_correction must be a number in [0, 1], got {tracked_correction!r}")
    if not 0.0 <= float(tracked_correction) <= 1.0:
        raise ValueError(f"{owner}: tracked_correction must be in [0, 1], got {tracked_correction!r}")
    if (
        isinstance(smooth_window, bool)
        or not isinstance(smooth_window, (int, np.integer))
        or smooth_window < 0
        or (smooth_window and (smooth_window < 5 or smooth_window % 2 == 0))
    ):
        raise ValueError(
            f"{owner}: smooth_window must be 0 (off) or an odd number of frames ≥ 5, got {smooth_window!r}"
        )
    if not isinstance(rigid_bones, (bool, np.bool_)):
        raise ValueError(f"{owner}: rigid_bones must be True or False, got {rigid_bones!r}")  # noqa: TRY004


def zero_lag_smooth(clip: np.ndarray, window: int) -> np.ndarray:
    """Every joint's trajectory through a centred quadratic Savitzky–Golay filter of ``window`` frames (odd ≥ 5;
    a shorter clip uses the longest odd window it holds, and one under 5 frames is returned as it is). No lag: a
    symmetric filter shifts nothing in time; it keeps a quadratic motion exactly."""
    from scipy.signal import savgol_filter

    x = np.asarray(clip)
    w = min(int(window), len(x) if len(x) % 2 else len(x) - 1)
    if w < 5:
        return x.copy()
    return savgol_filter(x, w, 2, axis=0, mode="interp").astype(x.dtype, copy=False)


def rigid(clip: np.ndarray) -> np.ndarray:
    """Every bone at the clip's median length along its own direction, from the pelvis outwards."""
    x = np.asarray(clip, dtype=np.float64)
    child = [j for j, p in enumerate(LANDMARK_PARENTS) if p >= 0]
    lengths = np.zeros(len(LANDMARK_PARENTS))
    lengths[child] = np.median(
        np.linalg.norm(x[:, child] - x[:, [LANDMARK_PARENTS[j] for j in child]], axis=-1), axis=0
    )
    return retarget(x, lengths).astype(np.asarray(clip).dtype, copy=False)


def steady_output(
    raw: np.ndarray,
    corrected: np.ndarray,
    state: np.ndarray | None,
    tracked_correction: float = 1.0,
    smooth_window: int = 0,
    rigid_bones: bool = False,
) -> np.ndarray:
    """The options of the module docstring on one clip: ``raw`` the corrector's input, ``corrected`` its output
    (both ``[T, 20, 3]``), ``state`` ``[T, 20]`` (None: every joint tracked). Returns ``[T, 20, 3]``, the dtype
    of ``corrected``; with the defaults ``corrected`` itself."""
    out = corrected
    if float(tracked_correction) < 1.0:
        tracked = np.ones(corrected.shape[:2], dtype=bool) if state is None else np.asarray(state) == TRACKED
        share = np.where(tracked, float(tracked_correction), 1.0)[..., None]
        out = (raw + share * (corrected - raw)).astype(corrected.dtype, copy=False)
    if smooth_window:
        out = zero_lag_smooth(out, smooth_window)
    if rigid_bones:
        out = rigid(out)
    return out


__all__ = ["STEADY_PARAMS", "check_steady_params", "rigid", "steady_output", "zero_lag_smooth"]
