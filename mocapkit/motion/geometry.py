"""Skeleton geometry, in one place: the up axis, the heading of a body, its body frame, and the 20 normalised
landmarks every retrieval feature is computed on. numpy only; :mod:`mocapkit.models.body_frame` is the torch
counterpart the networks use (same conventions, same names where the concept is the same).

**Up axis and headings.** A motion's ``up_axis`` (``"x"``, ``"y"`` or ``"z"``, :data:`AXES`) is vertical; the
other two axes, in increasing order, are its horizontal axes ``(h1, h2)`` (:func:`horizontal_axes`: x and z for
y-up data, x and y for z-up, y and z for x-up). A *heading* is an angle in the ``(h1, h2)`` plane about the up
axis, in radians, measured from a reference direction ``along`` towards ``+h2``:

* ``along="+x"`` (``+h1``): :func:`hip_line_heading` is the angle of the hip line (left → right hip) from
  ``+h1``, and :func:`turn_about_up` by it lays the hip line onto ``+h1``. :meth:`Motion.torso_aligned
  <mocapkit.motion.container.Motion.torso_aligned>`, the pose prior and the synthesis metrics use it, and so
  do the refiners' :class:`~mocapkit.models.refiners.PoseNormalizer` (``heading_cos_sin``) and the energy image;
* ``along="-x"`` (``−h1``): the hip line is measured from, and turned onto, ``−x``; for y-up data the body then
  faces ``+z`` with its left side at ``+x``, and the heading is the body's yaw about ``+y`` (the yaw of
  :func:`facing_direction`, from ``+z``; :func:`direction_yaw`). Zhou's normalisation
  (:func:`normalised_landmarks`, the Kinect reconstruction's per-posture frame) and the BVH re-rig use it.

The two conventions differ by π (the heading of a hip line from ``−x`` is π minus its heading from ``+x``); both
are kept, as a parameter, because each is what trained models and shipped numbers were computed with. A line
with no horizontal part has heading 0 (``arctan2(0, 0)``) and is not turned.

**Body frame.** The origin (:func:`body_origin`: the root in the first present frame, or its median over the
present frames) and the body size (:func:`body_size`: the mean or median length of a segment such as pelvis →
neck) that the clip features divide by; the networks use the torch twins (``body0_first``, ``body0_origin``,
``body0_size`` in :mod:`mocapkit.models.body_frame`).

**Normalised landmarks.** Motions of any layout (HDM05/CMU ASF, Bandai or Mixamo BVH, Kinect MSR-20 / NTU-25,
C3D with joint names) become ``[frames, 20, 3]`` arrays in :data:`~mocapkit.motion.layouts.LANDMARK_NAMES`
order, so that a database may mix formats and a query need not share the database's layout
(:func:`~mocapkit.motion.layouts.find_landmarks` says which joint is which landmark).
:func:`normalised_landmarks` does, in this order (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md``
§1.7, with the choices of its §7 item 5 stated):

1. **frame rate**: resample to ``fps`` (30 by default; HDM05 is 120 Hz, Bandai 30, MSR Action3D 15);
2. **gaps**: missing entries (``motion.missing``: C3D gaps, untracked Kinect frames) filled by linear
   interpolation in time, the nearest observed value at the ends; a landmark never observed takes its parent's
   positions; a clip with no observed pelvis, or no observed entry at all, raises :class:`SkeletonInputError`;
3. **up axis**: a z-up motion is turned to y-up;
4. **retarget** to one template skeleton (eqs. 3.2–3.3): from the pelvis outwards, each landmark keeps its
   direction from its parent and takes the template's bone length (:data:`TEMPLATE_BONES`, metres; a bone of
   length zero in the source, such as a wrist that is also the hand, stays zero), so every body has one size;
5. **translation**: the pelvis moved to the origin in every frame;
6. **heading** (yaw about the vertical, ``along="-x"``): ``"frame"`` turns every frame so that the hip line
   (left → right) points along −x, i.e. the body faces +z (Zhou ch. 5's per-posture choice, robust to turning);
   ``"clip"`` turns the whole clip by its mean hip-line heading (keeps turning within the clip); ``"none"``
   keeps it.

Output units are metres of the template body (about 1.7 m tall). :func:`landmark_track` returns, beside the
landmarks, what steps 5 and 6 take away: the body's heading in the file's frame and the pelvis's path through it,
scaled to the template body (what a retrieval feature needs to tell a walk to the left from a walk to the right).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from mocapkit.motion.layouts import (
    LANDMARK_NAMES,
    LANDMARK_PARENTS,
    find_landmarks,
)

#: Index of each coordinate axis by name, as a motion's ``up_axis`` names it.
AXES = {"x": 0, "y": 1, "z": 2}
#: The reference directions of a heading (module docstring): the first horizontal axis, or its opposite.
ALONG = ("+x", "-x")

#: Template bone lengths (metres) of the landmark tree, child landmark → length to its parent: an adult of about
#: 1.7 m (the proportions of the HDM05 actors' ASF skeletons, rounded).
TEMPLATE_BONES: dict[str, float] = {
    "spine": 0.20,
    "neck": 0.30,
    "head": 0.20,
    "l_shoulder": 0.18,
    "l_elbow": 0.28,
    "l_wrist": 0.25,
    "l_hand": 0.08,
    "r_shoulder": 0.18,
    "r_elbow": 0.28,
    "r_wrist": 0.25,
    "r_hand": 0.08,
    "l_hip": 0.10,
    "l_knee": 0.42,
    "l_ankle": 0.41,
    "l_foot": 0.14,
    "r_hip": 0.10,
    "r_knee": 0.42,
    "r_ankle": 0.41,
    "r_foot": 0.14,
}
HEADINGS = ("frame", "clip", "none")
#: Landmark indices used by the features: hips (heading), and the pelvis (origin).
L_HIP, R_HIP, PELVIS = LANDMARK_NAMES.index("l_hip"), LANDMARK_NAMES.index("r_hip"), 0
#: (hip, knee, ankle) landmark indices of each leg: the body's scale for the pelvis path of :func:`landmark_track`.
LEGS = tuple(tuple(LANDMARK_NAMES.index(f"{side}_{j}") for j in ("hip", "knee", "ankle")) for side in "lr")


class SkeletonInputError(ValueError):
    """A motion whose skeleton cannot be normalised (too short, no body landmarks, nothing observed); the message
    names the file."""


# --------------------------------------------------------------------------------------------- up axis, heading


def horizontal_axes(up: str = "y") -> tuple[int, int]:
    """``(h1, h2)``: the indices of the two axes other than ``up`` (``"x"``, ``"y"`` or ``"z"``), in increasing
    order: ``(0, 2)`` for y-up, ``(0, 1)`` for z-up, ``(1, 2)`` for x-up."""
    if up not in AXES:
        raise ValueError(f"up axis must be one of {sorted(AXES)}, got {up!r}")
    h1, h2 = (a for a in range(3) if a != AXES[up])
    return h1, h2


def _check_along(along: str) -> None:
    if along not in ALONG:
        raise ValueError(f"along must be one of {ALONG}, got {along!r}")


def lateral_line(positions: np.ndarray, left: int | Sequence[int], right: int | Sequence[int]) -> np.ndarray:
    """The body's left → right line ``[..., 3]`` of ``positions`` ``[..., J, 3]``: ``positions[..., right, :] −
    positions[..., left, :]``; with sequences of joints (e.g. hips and shoulders), the sum of the pairs' lines."""
    if np.ndim(left) == 0:
        return positions[..., right, :] - positions[..., left, :]
    if len(left) != len(right) or not len(left):
        raise ValueError(f"left and right joints must pair up, got {list(left)} and {list(right)}")
    line = positions[..., right[0], :] - positions[..., left[0], :]
    for l_joint, r_joint in zip(left[1:], right[1:]):
        line = line + (positions[..., r_joint, :] - positions[..., l_joint, :])
    return line


def hip_line_heading(
    positions: np.ndarray, left: int | Sequence[int], right: int | Sequence[int], up: str = "y", along: str = "+x"
) -> np.ndarray:
    """Heading (radians, in (−π, π]) of the hip line (joint ``left`` → ``right``; sequences: the sum of the pairs'
    lines, :func:`lateral_line`) of ``positions`` ``[..., J, 3]`` → ``[...]``: its angle about the ``up`` axis from
    ``along`` (``"+x"``: the first horizontal axis, ``"-x"``: its opposite) towards the second horizontal axis.
    With ``along="-x"`` on y-up data it is the body's yaw about +y (facing +z is 0). 0 for a vertical or empty
    line."""
    _check_along(along)
    h1, h2 = horizontal_axes(up)
    line = lateral_line(positions, left, right)
    first = line[..., h1] if along == "+x" else -line[..., h1]
    return np.arctan2(line[..., h2], first)


def turn_about_up(
    positions: np.ndarray, angle: np.ndarray | float, up: str = "y", along: str = "+x", inverse: bool = False
) -> np.ndarray:
    """``positions`` ``[N, ..., 3]`` turned about the ``up`` axis, item ``n`` by the heading ``angle[n]`` (``[N]``,
    or one angle for all) so that the direction of that heading (:func:`hip_line_heading` with the same
    ``along``) comes onto ``along``; with ``inverse``, back from it. A new array of the input's dtype.

    With ``along="+x"`` the turn is ``h1' = c·h1 + s·h2``, ``h2' = −s·h1 + c·h2``; ``"-x"`` turns the other way
    (``s → −s``), which for y-up data is ``x' = c·x − s·z``, ``z' = s·x + c·z``.
    """
    _check_along(along)
    h1, h2 = horizontal_axes(up)
    angle = np.asarray(angle)
    shape = angle.shape + (1,) * (positions.ndim - 1 - angle.ndim)
    c, s = np.cos(angle).reshape(shape), np.sin(angle).reshape(shape)
    if (along == "-x") != bool(inverse):
        s = -s
    out = positions.copy()
    out[..., h1] = c * positions[..., h1] + s * positions[..., h2]
    out[..., h2] = -s * positions[..., h1] + c * positions[..., h2]
    return out


def facing_direction(
    positions: np.ndarray, left: int | Sequence[int], right: int | Sequence[int], up: str = "y", eps: float = 1e-9
) -> np.ndarray:
    """Unit horizontal forward direction ``[..., 3]`` of ``positions`` ``[..., J, 3]``: ``(left − right) × up``
    of the hip line (:func:`lateral_line`), i.e. ``+z`` for a y-up body whose left side is at ``+x``; divided by
    ``max(|·|, eps)`` (a vertical hip line gives 0)."""
    horizontal_axes(up)  # checks ``up``
    line = lateral_line(positions, left, right)  # right − left
    # (left − right) × e_up, with (p, q) the axes after ``up`` in cyclic order (e_p × e_q = e_up):
    # forward_p = −line_q, forward_q = line_p (y-up: forward = (line_z, 0, −line_x))
    p, q = (AXES[up] + 1) % 3, (AXES[up] + 2) % 3
    forward = np.zeros(line.shape, dtype=np.result_type(line, np.float32))
    forward[..., p] = -line[..., q]
    forward[..., q] = line[..., p]
    return forward / np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), eps)


def direction_yaw(direction: np.ndarray) -> np.ndarray:
    """Yaw about +y (radians) of y-up directions ``[..., 3]`` (any length), from ``+z`` towards ``+x``:
    ``arctan2(d_x, d_z)``; the heading of :func:`facing_direction` with ``along="-x"``."""
    direction = np.asarray(direction)
    return np.arctan2(direction[..., 0], direction[..., 2])


# --------------------------------------------------------------------------------------------- body frame


def body_origin(positions: np.ndarray, present: np.ndarray, joint: int, statistic: str = "first") -> np.ndarray:
    """Where a body is: ``joint``'s position ``[3]`` in the first frame where ``present`` (bool ``[T]``) is True
    (``"first"``; frame 0 if none), or its per-coordinate median over those frames (``"median"``; 0 if none) —
    the numpy twins of ``body0_first`` and ``body0_origin`` in :mod:`mocapkit.models.body_frame`."""
    present = np.asarray(present, dtype=bool)
    if statistic == "first":
        return positions[int(np.argmax(present)), joint]
    if statistic == "median":
        values = positions[present, joint]
        return np.median(values, axis=0) if len(values) else np.zeros(positions.shape[-1], positions.dtype)
    raise ValueError(f"statistic must be 'first' or 'median', got {statistic!r}")


def body_size(
    positions: np.ndarray,
    present: np.ndarray,
    lower: int,
    upper: int,
    statistic: str = "median",
    floor: float = 1e-3,
    default: float | None = None,
) -> float:
    """How big a body is: the ``statistic`` (``"median"`` or ``"mean"``) over the frames where ``present`` (bool
    ``[T]``) of the distance between joints ``lower`` and ``upper`` (e.g. pelvis → neck) of ``positions``
    ``[T, J, 3]``; at least ``floor``; ``default`` (else ``floor``) when no frame is present. ``"median"`` is
    the numpy twin of ``body0_size`` in :mod:`mocapkit.models.body_frame`."""
    length = np.linalg.norm(positions[:, upper] - positions[:, lower], axis=-1)  # [T]
    present = np.asarray(present, dtype=bool)
    if not present.any():
        return max(float(floor if default is None else default), floor)
    if statistic == "median":
        size = float(np.median(length[present]))
    elif statistic == "mean":
        weight = present.astype(length.dtype)
        size = float((length * weight).sum() / weight.sum())
    else:
        raise ValueError(f"statistic must be 'median' or 'mean', got {statistic!r}")
    return max(size, floor)


# --------------------------------------------------------------------------------------------- landmarks


# ``motion`` below is a :class:`~mocapkit.motion.container.Motion`, not imported: the container imports this module
# (Motion.torso_aligned), and the two may not import each other.
def _label(motion) -> str:
    return motion.source or motion.name or "motion"


def landmark_positions(motion) -> tuple[np.ndarray, np.ndarray]:
    """The landmarks of ``motion`` (a Motion) as they are: ``(positions [T, 20, 3] float64 m, observed [T, 20] bool)``.

    A landmark the skeleton lacks is unobserved in every frame.

    Raises:
        SkeletonInputError: fewer than the pelvis, both hips and a head or neck among the joints (names the file
            and lists the joints).
    """
    found = find_landmarks(motion.joint_names, motion.layout_name)
    needed = {"pelvis", "l_hip", "r_hip"}
    if not needed <= set(found) or not {"neck", "head"} & set(found):
        raise SkeletonInputError(
            f"{_label(motion)}: cannot tell the body landmarks (pelvis, hips, neck or head) among the joints "
            f"{list(motion.joint_names)[:12]}{'...' if motion.num_joints > 12 else ''}; known layouts are the "
            "Kinect (MSR-20, NTU-25), ASF (HDM05, CMU) and BVH rigs with Hips/UpperLeg/UpLeg-style names"
        )
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
    if up_axis == "z":  # (x, y, z) z-up → (x, z, −y) y-up, right-handed
        return np.stack([positions[..., 0], positions[..., 2], -positions[..., 1]], axis=-1)
    return np.stack([positions[..., 1], positions[..., 0], -positions[..., 2]], axis=-1)  # x-up


def turn_up_axis(positions: np.ndarray, up_axis: str, to: str) -> np.ndarray:
    """``[..., 3]`` positions with ``up_axis`` up turned so that ``to`` is up: :func:`to_y_up`
    of ``up_axis`` followed by the inverse of ``to``'s, both right-handed. Each output coordinate is one input
    coordinate, possibly negated (no arithmetic), so turning back gives the same bits and NaN stays in its entry."""
    if up_axis not in AXES or to not in AXES:
        raise ValueError(f"up axes must be x, y or z, got {up_axis!r} and {to!r}")
    # to_y_up is linear: p_y = p @ A[axis]; the turn is p @ A[up_axis] @ A[to].T, a signed permutation
    turn = to_y_up(np.eye(3), up_axis) @ to_y_up(np.eye(3), to).T
    source, sign = np.argmax(np.abs(turn), axis=0), turn[np.argmax(np.abs(turn), axis=0), np.arange(3)]
    positions = np.asarray(positions)
    return np.stack([positions[..., s] if g > 0 else -positions[..., s] for s, g in zip(source, sign)], axis=-1)


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
    (facing +z, ``along="-x"``): per frame (``"frame"``), by the clip's mean heading (``"clip"``), or not at all
    (``"none"``)."""
    if heading not in HEADINGS:
        raise ValueError(f"heading must be one of {HEADINGS}, got {heading!r}")
    if heading == "none":
        return positions
    angle = hip_line_heading(positions, L_HIP, R_HIP, along="-x")  # [T]
    if heading == "clip":
        angle = np.full_like(angle, np.arctan2(np.sin(angle).mean(), np.cos(angle).mean()))
    return turn_about_up(positions, angle, along="-x")


class LandmarkTrack(NamedTuple):
    """One clip's normalised landmarks and the frame they were taken out of (:func:`landmark_track`)."""

    #: float32 ``[T, 20, 3]``: :func:`normalised_landmarks` (pelvis-centred, turned by the ``heading`` option).
    landmarks: np.ndarray
    #: float64 ``[T]`` radians: the hip line's heading in the file's (y-up) frame, ``along="-x"``, per frame,
    #: whatever the ``heading`` option (turning ``landmarks`` back by it gives the unturned posture).
    heading: np.ndarray
    #: float64 ``[T, 3]`` metres of the template body: the pelvis in the file's y-up frame, scaled by the template's
    #: leg length over the clip's (hip → knee → ankle, median over frames), so that strides compare across bodies
    #: (unscaled when the clip's legs are under a quarter of the template's: no knees or ankles to measure).
    pelvis: np.ndarray
    #: float32 ``[T, J, 3]`` metres, or None: every joint of the file, root-centred, not turned or retargeted
    #: (filled by the retrieval methods that compare them, :func:`mocapkit.retrieval.dtw.root_centred_joints`).
    joints: np.ndarray | None = None


def landmark_track(motion, fps: float = 30.0, heading: str = "frame", min_frames: int = 2) -> LandmarkTrack:
    """:func:`normalised_landmarks` of ``motion`` with the heading and the pelvis path that steps 5 and 6 remove.

    Raises:
        SkeletonInputError: no body landmarks, no observed pelvis, non-finite observed values, or fewer than
            ``min_frames`` frames after resampling (each names the file).
    """
    if heading not in HEADINGS:
        raise ValueError(f"heading must be one of {HEADINGS}, got {heading!r}")
    if fps is not None and float(fps) != motion.fps:
        motion = motion.resample(float(fps))
    if motion.num_frames < max(int(min_frames), 1):
        raise SkeletonInputError(
            f"{_label(motion)}: {motion.num_frames} frames at {motion.fps:g} fps; at least "
            f"{min_frames} are needed (a clip of {min_frames / motion.fps:.2f} s)"
        )
    positions, observed = landmark_positions(motion)
    if not observed.any():
        raise SkeletonInputError(
            f"{_label(motion)}: no landmark is observed in any of its {motion.num_frames} "
            "frames (every value missing or zero)"
        )
    if not observed[:, PELVIS].any():
        raise SkeletonInputError(f"{_label(motion)}: the pelvis landmark is never observed")
    if not np.isfinite(positions[observed]).all():
        raise SkeletonInputError(f"{_label(motion)}: non-finite observed positions")
    world = to_y_up(_fill_gaps(positions, observed), motion.up_axis)
    leg = np.mean(
        [
            np.median(
                np.linalg.norm(world[:, knee] - world[:, hip], axis=-1)
                + np.linalg.norm(world[:, ankle] - world[:, knee], axis=-1)
            )
            for hip, knee, ankle in LEGS
        ]
    )
    template_leg = TEMPLATE_BONES["l_knee"] + TEMPLATE_BONES["l_ankle"]
    # a leg shorter than a quarter of the template's is a skeleton without knees or ankles (filled from their
    # parents), not a small body: its path stays in the file's metres
    pelvis = world[:, PELVIS] * (template_leg / float(leg) if leg > template_leg / 4 else 1.0)
    p = retarget(world)
    p = p - p[:, PELVIS : PELVIS + 1]
    angle = hip_line_heading(p, L_HIP, R_HIP, along="-x")
    return LandmarkTrack(face_forward(p, heading).astype(np.float32), angle.astype(np.float64), pelvis)


def normalised_landmarks(motion, fps: float = 30.0, heading: str = "frame", min_frames: int = 2) -> np.ndarray:
    """float32 ``[frames, 20, 3]``: ``motion``'s landmarks resampled, gap-filled, y-up, retargeted, pelvis at the
    origin and turned by ``heading`` (the module docstring gives each step).

    Raises:
        SkeletonInputError: no body landmarks, no observed pelvis, non-finite observed values, or fewer than
            ``min_frames`` frames after resampling (each names the file).
    """
    return landmark_track(motion, fps=fps, heading=heading, min_frames=min_frames).landmarks
