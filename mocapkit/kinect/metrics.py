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


#: Joint-angle limits of :func:`joint_angle_violations`: ``{joint: (parent joint, child joint, largest flexion in
#: degrees)}``. Flexion is the angle between the bone into the joint and the bone out of it (0° straight); the
#: active ranges of motion are about 145° (elbow), 140° (knee) and 45–60° (neck), so a skeleton beyond these bends
#: further than a body can (a hand folded onto its shoulder, a neck at a right angle).
ANGLE_LIMITS_DEG: dict[str, tuple[str, str, float]] = {
    "l_elbow": ("l_shoulder", "l_wrist", 150.0),
    "r_elbow": ("r_shoulder", "r_wrist", 150.0),
    "l_knee": ("l_hip", "l_ankle", 150.0),
    "r_knee": ("r_hip", "r_ankle", 150.0),
    "neck": ("spine", "head", 60.0),
}

#: The left/right joint pairs :func:`swap_events` watches (the ones Kinect v1 confuses: the limbs' ends).
SWAP_PAIRS: tuple[tuple[str, str], ...] = (
    ("l_knee", "r_knee"),
    ("l_ankle", "r_ankle"),
    ("l_foot", "r_foot"),
    ("l_elbow", "r_elbow"),
    ("l_wrist", "r_wrist"),
    ("l_hand", "r_hand"),
)


def flexion_deg(clip: np.ndarray) -> dict[str, np.ndarray]:
    """``{joint: float64 [T]}``: the flexion of each joint of :data:`ANGLE_LIMITS_DEG` in degrees (0 = straight)."""
    from mocapkit.motion.layouts import LANDMARK_NAMES

    x = np.asarray(clip, dtype=np.float64)
    out = {}
    for joint, (parent, child, _) in ANGLE_LIMITS_DEG.items():
        j, p, c = (LANDMARK_NAMES.index(n) for n in (joint, parent, child))
        a, b = x[:, j] - x[:, p], x[:, c] - x[:, j]
        cos = (a * b).sum(-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
        out[joint] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def joint_angle_violations(clip: np.ndarray) -> float:
    """Joint-angle limit violations: the share (%) of (frame, joint) entries of the joints of
    :data:`ANGLE_LIMITS_DEG` whose flexion exceeds the joint's limit."""
    flex = flexion_deg(clip)
    over = [flex[j] > limit for j, (_, _, limit) in ANGLE_LIMITS_DEG.items()]
    return float(100.0 * np.mean(over))


def swap_events(clip: np.ndarray, lag: int = 1, min_move_m: float = 0.1, ratio: float = 0.5) -> int:
    """Left/right swap events without ground truth: the frames ``t`` where, for some pair of :data:`SWAP_PAIRS`,
    the crossed assignment explains the motion from ``t − lag`` far better than the straight one —
    ``‖L_t − R_{t−lag}‖ + ‖R_t − L_{t−lag}‖ < ratio · (‖L_t − L_{t−lag}‖ + ‖R_t − R_{t−lag}‖)`` with the straight
    sum above ``min_move_m`` metres (both sides jump onto the other's place). A swap and its undoing are two
    events. ``lag``: frames between the compared postures (2 for a 15 fps file resampled to 30 fps, whose jumps
    are spread over two frames)."""
    from mocapkit.motion.layouts import LANDMARK_NAMES

    x = np.asarray(clip, dtype=np.float64)
    lag = int(lag)
    if len(x) <= lag:
        return 0
    event = np.zeros(len(x) - lag, dtype=bool)
    for left, right in SWAP_PAIRS:
        L, R = x[:, LANDMARK_NAMES.index(left)], x[:, LANDMARK_NAMES.index(right)]
        straight = np.linalg.norm(L[lag:] - L[:-lag], axis=-1) + np.linalg.norm(R[lag:] - R[:-lag], axis=-1)
        crossed = np.linalg.norm(L[lag:] - R[:-lag], axis=-1) + np.linalg.norm(R[lag:] - L[:-lag], axis=-1)
        event |= (straight > min_move_m) & (crossed < ratio * straight)
    # a jump spread over ``lag`` frames fires on consecutive frames: count runs, not frames
    return int((event & ~np.concatenate([[False], event[:-1]])).sum())


#: The keys of :func:`steadiness`, in report order.
STEADINESS_KEYS = ("bone_sd_cm", "jitter_cm", "angle_violations_pct", "swap_events")


def steadiness(clip: np.ndarray, swap_lag: int = 1) -> dict[str, float]:
    """The real-data proxies of one clip ``[T, 20, 3]`` (m; ≥ 3 frames), which need no ground truth:
    ``{"bone_sd_cm", "jitter_cm", "angle_violations_pct", "swap_events"}`` (:func:`bone_length_sd_cm`,
    :func:`jitter_cm`, :func:`joint_angle_violations`, :func:`swap_events` with ``lag=swap_lag``)."""
    return {
        "bone_sd_cm": bone_length_sd_cm(clip),
        "jitter_cm": jitter_cm(clip),
        "angle_violations_pct": joint_angle_violations(clip),
        "swap_events": float(swap_events(clip, lag=swap_lag)),
    }


def steadiness_summary(before: list[dict], after: list[dict]) -> dict[str, float]:
    """Per-file proxies (:func:`steadiness`) before and after a correction, summarised over files: for each key
    ``K`` the means ``K_before`` / ``K_after`` and ``K_not_worse`` (the share of files with after ≤ before, 0–1);
    ``new_swap_events``: the sum over files of the events the correction added (after − before, where positive);
    ``files``."""
    if len(before) != len(after) or not before:
        raise ValueError(f"steadiness_summary: as many files before as after expected, got {len(before)}, {len(after)}")
    out: dict[str, float] = {"files": float(len(before))}
    for key in STEADINESS_KEYS:
        b = np.array([f[key] for f in before], dtype=np.float64)
        a = np.array([f[key] for f in after], dtype=np.float64)
        out[f"{key}_before"] = float(b.mean())
        out[f"{key}_after"] = float(a.mean())
        out[f"{key}_not_worse"] = float(np.mean(a <= b + 1e-9))
    out["new_swap_events"] = float(sum(max(0.0, f["swap_events"] - g["swap_events"]) for f, g in zip(after, before)))
    return out


def high_frequency_share(clip: np.ndarray, fps: float, split_hz: float = 3.0) -> float:
    """The noise spectrum in one number: the share (0–1) of the power of every joint's frame-to-frame velocity
    (``x_{t+1} − x_t``, summed over joints and axes) above ``split_hz`` (up to the Nyquist frequency ``fps/2``).
    Body motion lives below a few Hz, so sensor jitter raises this share; compare clips at one frame rate."""
    v = np.diff(np.asarray(clip, dtype=np.float64), axis=0)
    v = v - v.mean(axis=0)
    power = (np.abs(np.fft.rfft(v, axis=0)) ** 2).reshape(v.shape[0] // 2 + 1, -1).sum(axis=1)
    freq = np.fft.rfftfreq(v.shape[0], d=1.0 / float(fps))
    total = power[1:].sum()
    return float(power[1:][freq[1:] > split_hz].sum() / total) if total > 0 else 0.0


def state_runs(state: np.ndarray, value: int, fps: float) -> tuple[float, float]:
    """``(share of (frame, joint) entries with tracking state value (0–1), mean duration of its runs in s)``;
    ``state`` ``[T, 20]`` SDK states (2 tracked, 1 inferred, 0 not tracked). The duration is NaN without runs."""
    hit = np.asarray(state) == value
    starts = hit & ~np.concatenate([np.zeros((1, hit.shape[1]), bool), hit[:-1]], axis=0)
    runs = int(starts.sum())
    return float(hit.mean()), (float(hit.sum() / runs / fps) if runs else float("nan"))
