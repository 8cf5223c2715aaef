"""The one skeleton every retrieval feature is computed on: 20 body landmarks, normalised (Zhou 2014 §1.7).

Motions of any layout (HDM05/CMU ASF, Bandai or Mixamo BVH, Kinect MSR-20 / NTU-25, C3D with joint names)
become ``[frames, 20, 3]`` arrays in :data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order, so that
a database may mix formats and a query need not share the database's layout
(:func:`~mocapkit.motion.layouts.find_landmarks` says which joint is which landmark).

:func:`normalised_landmarks` does, in this order (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md``
§1.7, with the choices of its §7 item 5 stated):

1. **frame rate**: resample to ``fps`` (30 by default; HDM05 is 120 Hz, Bandai 30, MSR Action3D 15);
2. **gaps**: missing entries (``motion.missing``: C3D gaps, untracked Kinect frames) filled by linear
   interpolation in time, the nearest observed value at the ends; a landmark never observed takes its parent's
   positions; a clip with no observed pelvis, or no observed entry at all, raises :class:`RetrievalInputError`;
3. **up axis**: a z-up motion is turned to y-up;
4. **retarget** to one template skeleton (eqs. 3.2–3.3): from the pelvis outwards, each landmark keeps its
   direction from its parent and takes the template's bone length (:data:`TEMPLATE_BONES`, metres; a bone of
   length zero in the source, such as a wrist that is also the hand, stays zero), so every body has one size;
5. **translation**: the pelvis moved to the origin in every frame;
6. **heading** (yaw about the vertical): ``"frame"`` turns every frame so that the hip line (left → right)
   points along −x, i.e. the body faces +z (Zhou ch. 5's per-posture choice, robust to turning); ``"clip"`` turns
   the whole clip by its mean hip-line heading (keeps turning within the clip); ``"none"`` keeps it.

Output units are metres of the template body (about 1.7 m tall).
"""
from __future__ import annotations

import numpy as np

from mocapkit.motion.layouts import (
    LANDMARK_NAMES,
    LANDMARK_PARENTS,
    find_landmarks,
)
from mocapkit.motion.container import Motion

#: Template bone lengths (metres) of the landmark tree, child landmark → length to its parent: an adult of about
#: 1.7 m (the proportions of the HDM05 actors' ASF skeletons, rounded).
TEMPLATE_BONES: dict[str, float] = {
    "spine": 0.20, "neck": 0.30, "head": 0.20,
    "l_shoulder": 0.18, "l_elbow": 0.28, "l_wrist": 0.25, "l_hand": 0.08,
    "r_shoulder": 0.18, "r_elbow": 0.28, "r_wrist": 0.25, "r_hand": 0.08,
    "l_hip": 0.10, "l_knee": 0.42, "l_ankle": 0.41, "l_foot": 0.14,
    "r_hip": 0.10, "r_knee": 0.42, "r_ankle": 0.41, "r_foot": 0.14,
}
HEADINGS = ("frame", "clip", "none")
#: Landmark indices used by the features: hips (heading), and the pelvis (origin).
L_HIP, R_HIP, PELVIS = LANDMARK_NAMES.index("l_hip"), LANDMARK_NAMES.index("r_hip"), 0


class RetrievalInputError(ValueError):
    """A motion retrieval cannot use (too short, no landmarks, nothing observed); the message names the file."""


def _label(motion: Motion) -> str:
    return motion.source or motion.name or "motion"


def landmark_positions(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """The landmarks of ``motion`` as they are: ``(positions [T, 20, 3] float64 m, observed [T, 20] bool)``.

    A landmark the skeleton lacks is unobserved in every frame.

    Raises:
        RetrievalInputError: fewer than the pelvis, both hips and a head or neck among the joints (names the file
            and lists the joints).
    """
    found = find_landmarks(motion.joint_names, motion.layout_name)
    needed = {"pelvis", "l_hip", "r_hip"}
    if not needed <= set(found) or not {"neck", "head"} & set(found):
        raise RetrievalInputError(
            f"{_label(motion)}: cannot tell the body landmarks (pelvis, hips, neck or head) among the joints "
            f"{list(motion.joint_names)[:12]}{'...' if motion.num_joints > 12 else ''}; known layouts are the "
            "Kinect (MSR-20, NTU-25), ASF (HDM05, CMU) and BVH rigs with Hips/UpperLeg/UpLeg-style names")
    T = motion.num_frames
    positions = np.full((T, len(LANDMARK_NAMES), 3), np.nan)
    observed = np.zeros((T, len(LANDMARK_NAMES)), dtype=bool)
    for k, name in enumerate(LANDMARK_NAMES):
        if name in found:
            j = found[name]
            positions[:, k] = motion.positions[:, j]
            observed[:, k] = ~motion.missing[:, j]
    return positions, observed


def _fill_gaps(positions: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Linear interpolation over time of unobserved entries; never-observed landmarks copy their parent."""
    T = positions.shape[0]
    out = positions.copy()
    t = np.arange(T)
    for k in range(positions.shape[1]):
        seen = observed[:, k]
        if seen.all() or not seen.any():
            continue
        for axis in range(3):
            out[:, k, axis] = np.interp(t, t[seen], positions[seen, k, axis])
    for k, parent in enumerate(LANDMARK_PARENTS):  # parents come first in LANDMARK_NAMES
        if not observed[:, k].any():
            out[:, k] = out[:, parent] if parent >= 0 else 0.0
    return out


def to_y_up(positions: np.ndarray, up_axis: str) -> np.ndarray:
    """``[..., 3]`` positions with ``up_axis`` ("x", "y" or "z") turned to y-up, right-handed."""
    if up_axis == "y":
        return positions
    if up_axis == "z":                      # (x, y, z) z-up → (x, z, −y) y-up, right-handed
        return np.stack([positions[..., 0], positions[..., 2], -positions[..., 1]], axis=-1)
    return np.stack([positions[..., 1], positions[..., 0], -positions[..., 2]], axis=-1)  # x-up


def retarget(positions: np.ndarray, lengths: np.ndarray | None = None) -> np.ndarray:
    """Zhou eqs. 3.2–3.3 on landmarks ``[T, 20, 3]``: every bone keeps its direction and takes the template length
    (:data:`TEMPLATE_BONES`), or ``lengths`` (``[T, 20]`` or ``[20]``, m: each landmark's bone to its parent)."""
    out = positions.copy()
    for k, parent in enumerate(LANDMARK_PARENTS):
        if parent < 0:
            continue
        bone = positions[:, k] - positions[:, parent]
        length = np.linalg.norm(bone, axis=-1, keepdims=True)
        direction = np.where(length > 1e-6, bone / np.maximum(length, 1e-12), 0.0)
        target = TEMPLATE_BONES[LANDMARK_NAMES[k]] if lengths is None else np.asarray(lengths)[..., k, None]
        out[:, k] = out[:, parent] + direction * target
    return out


def face_forward(positions: np.ndarray, heading: str = "frame") -> np.ndarray:
    """Turn pelvis-centred y-up landmarks ``[T, 20, 3]`` about y so that the hip line points along −x
    (facing +z): per frame (``"frame"``), by the clip's mean heading (``"clip"``), or not at all (``"none"``)."""
    if heading not in HEADINGS:
        raise ValueError(f"heading must be one of {HEADINGS}, got {heading!r}")
    if heading == "none":
        return positions
    hips = positions[:, R_HIP] - positions[:, L_HIP]                 # [T, 3]
    angle = np.arctan2(hips[:, 2], -hips[:, 0])                       # angle of the hip line from −x in the xz plane
    if heading == "clip":
        angle = np.full_like(angle, np.arctan2(np.sin(angle).mean(), np.cos(angle).mean()))
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    x, z = positions[..., 0], positions[..., 2]
    out = positions.copy()
    out[..., 0] = c * x - s * z
    out[..., 2] = s * x + c * z
    return out


def normalised_landmarks(motion: Motion, fps: float = 30.0, heading: str = "frame", min_frames: int = 2) -> np.ndarray:
    """float32 ``[frames, 20, 3]``: ``motion``'s landmarks resampled, gap-filled, y-up, retargeted, pelvis at the
    origin and turned by ``heading`` (the module docstring gives each step).

    Raises:
        RetrievalInputError: no body landmarks, no observed pelvis, non-finite observed values, or fewer than
            ``min_frames`` frames after resampling (each names the file).
    """
    if heading not in HEADINGS:
        raise ValueError(f"heading must be one of {HEADINGS}, got {heading!r}")
    if fps is not None and float(fps) != motion.fps:
        motion = motion.resample(float(fps))
    if motion.num_frames < max(int(min_frames), 1):
        raise RetrievalInputError(f"{_label(motion)}: {motion.num_frames} frames at {motion.fps:g} fps; retrieval "
                                  f"needs at least {min_frames} (a clip of {min_frames / motion.fps:.2f} s)")
    positions, observed = landmark_positions(motion)
    if not observed.any():
        raise RetrievalInputError(f"{_label(motion)}: no landmark is observed in any of its {motion.num_frames} "
                                  "frames (every value missing or zero)")
    if not observed[:, PELVIS].any():
        raise RetrievalInputError(f"{_label(motion)}: the pelvis landmark is never observed")
    if not np.isfinite(positions[observed]).all():
        raise RetrievalInputError(f"{_label(motion)}: non-finite observed positions")
    p = _fill_gaps(positions, observed)
    p = to_y_up(p, motion.up_axis)
    p = retarget(p)
    p = p - p[:, PELVIS:PELVIS + 1]
    return face_forward(p, heading).astype(np.float32)
