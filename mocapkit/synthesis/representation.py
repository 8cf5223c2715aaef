"""Per-frame pose features for motion-variation synthesis: exp-map joint rotations and a root made relative.

Zhou 2014 ch. 4 eq. 4.1 (../shared/spec/thesis-zhou-2014-retrieval-synthesis.md §3.1, §3.4, gaps 16 and 18)
describes a frame as the root position, the root orientation and every joint's rotation as an exponential map
(a 3-vector). This module turns an AMC clip (:func:`~mocapkit.datasets.formats.asf_amc.read_amc`) into that
representation and back:

- **joints**: for every non-root bone with dofs, the exp-map (rotation vector, radians) of its AMC rotation
  ``M_b = Euler(AMC values, dof order)`` (the ``M`` of the FK convention ``C·M·C⁻¹`` in
  :mod:`mocapkit.datasets.formats.asf_amc`; missing axes are 0). Vectors start with ``|v| <= pi`` (scipy's
  ``as_rotvec``); where a rotation angle passes through ``pi`` between two frames the alternative vector
  ``(1 - 2 pi/|v|) v`` (same rotation, ``|v| > pi``) is kept instead, so the curve stays continuous (gap 18).
  This does happen on HDM05: knees beyond 180° in deep squats (``rtibia rx`` up to 199°), wrists near ±180°; there
  continuity wins over ``|v| <= pi``, as the exp-maps are regression outputs and inputs.
- **root** (gap 16), 7 numbers per frame, all invariant to where the clip starts and which way it faces:
  ``dx, dz`` the ground-plane translation since the previous frame expressed in the previous frame's heading
  frame (ASF length units; row 0 = 0); ``dyaw`` the change of heading about the vertical ``y`` axis (radians,
  row 0 = 0); ``height`` the root's world ``y`` (ASF units, ``root_position`` included); ``tilt`` the exp-map
  of the root rotation with its heading removed. The heading of a global root rotation ``R`` is the yaw of its
  forward axis: ``yaw = atan2(f_x, f_z)`` with ``f = R·e_z`` (HDM05 and CMU skeletons face ``+z`` at rest);
  ``tilt = log(Ry(-yaw)·R)``.

Decoding maps features back to AMC values (degrees, root translation in ASF units). A bone with fewer than three
dofs is **projected** onto its dofs: its rotation is decomposed with scipy ``as_euler`` in the extrinsic order
"its dof axes, then the missing axes" (e.g. ``rx rz`` → ``"xzy"``), of the two Euler solutions the one whose
missing-axis angles are smallest is taken, and those are dropped. For rotations built from the bone's own dofs
(what :func:`encode` produces) the dropped angles are zero and the round trip is exact; for sampled exp-maps it
removes the off-dof part. Euler angles are chosen continuous over time (of the two solutions, the one nearest
the previous frame; then unwrapped), so decoded AMC curves have no 360° jumps.

:func:`partitions` splits a skeleton into the five partitions of Zhou Fig. 4.1 (§3.2).
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import AsfSkeleton
from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import direction_yaw
from mocapkit.synthesis.clips import DofLayout, SynthesisInputError, clip_label, clip_segment, dof_matrix, resample_clip

ROOT_FEATURES = 7
"""Columns of :attr:`FeatureClip.root`: ``dx, dz, dyaw, height, tilt_x, tilt_y, tilt_z``."""

PARTITION_NAMES = ("RA", "LA", "RL", "LL", "TH")


@dataclass
class FeatureClip:
    """Per-frame features of one clip (Zhou eq. 4.1 with the root made relative, §3.4 and gap 16).

    Attributes:
        root: float64 ``[T, 7]``: ``[dx, dz, dyaw, height, tilt_x, tilt_y, tilt_z]`` (module docstring; ``dx, dz,
            height`` in ASF length units, angles in radians; row 0 has ``dx = dz = dyaw = 0``).
        joints: float64 ``[T, B, 3]``: exp-map (radians, continuous over time; ``|v| <= pi`` unless the rotation
            angle crosses ``pi`` during the clip, see the module docstring) of each non-root bone's AMC rotation
            ``M_b``.
        bones: the ``B`` non-root bones with dofs, in :class:`~mocapkit.synthesis.clips.DofLayout` order.
    """

    root: np.ndarray
    joints: np.ndarray
    bones: tuple[str, ...]

    def flat(self) -> np.ndarray:
        """float64 ``[T, 7 + 3B]``: the root columns, then the joints' exp-maps bone by bone."""
        return np.concatenate([self.root, self.joints.reshape(len(self.joints), -1)], axis=1)

    @classmethod
    def from_flat(cls, flat: np.ndarray, bones: tuple[str, ...]) -> FeatureClip:
        """The inverse of :meth:`flat` for the bones ``bones``."""
        flat = np.asarray(flat, dtype=np.float64)
        if flat.ndim != 2 or flat.shape[1] != ROOT_FEATURES + 3 * len(bones):
            raise ValueError(
                f"flat features must be [frames, {ROOT_FEATURES + 3 * len(bones)}] for {len(bones)} "
                f"bones, got {list(flat.shape)}"
            )
        return cls(
            root=flat[:, :ROOT_FEATURES].copy(),
            joints=flat[:, ROOT_FEATURES:].reshape(len(flat), len(bones), 3).copy(),
            bones=tuple(bones),
        )


# --------------------------------------------------------------------------- rotations


def dof_axes(dofs: tuple[str, ...]) -> str:
    """The lower-case rotation axes of AMC channels, e.g. ``("rx", "rz")`` → ``"xz"``, ``("RX", "RY", "RZ")`` →
    ``"xyz"`` (translation channels are skipped)."""
    return "".join(d[1].lower() for d in dofs if d[0].lower() == "r")


def _rotation(axes: str, angles_rad: np.ndarray) -> Rotation:
    """``Euler(angles, axes)``: fixed-axis rotations, first axis applied first (scipy extrinsic lower case)."""
    angles_rad = np.asarray(angles_rad, dtype=np.float64).reshape(-1, len(axes))
    if not axes:
        return Rotation.identity(len(angles_rad))
    return Rotation.from_euler(axes, angles_rad)


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (radians) wrapped to ``(-pi, pi]``."""
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


def continuous_expmap(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vectors ``[T, 3]`` (``|v| <= pi``) made continuous over time (gap 18).

    Where frame ``t`` is nearer the previous frame's vector in its alternative form ``(1 - 2 pi/|v|) v`` (same
    rotation, angle ``2 pi - |v|``), that form is used; this only happens when the rotation angle crosses ``pi``.
    """
    v = np.array(rotvec, dtype=np.float64)
    norms = np.linalg.norm(v, axis=-1)
    for t in range(1, len(v)):
        if norms[t] < 1e-12:
            continue
        alternative = (1.0 - 2.0 * np.pi / norms[t]) * v[t]
        if np.linalg.norm(alternative - v[t - 1]) < np.linalg.norm(v[t] - v[t - 1]):
            v[t] = alternative
    return v


def _euler_solutions(rotation: Rotation, order: str) -> tuple[np.ndarray, np.ndarray]:
    """The two extrinsic Tait–Bryan solutions ``[N, 3]`` (radians) of ``rotation`` in ``order``: scipy's (middle
    angle in ``[-pi/2, pi/2]``) and ``(a + pi, pi - b, c + pi)``, both wrapped to ``(-pi, pi]``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: either solution is still exact
        first = rotation.as_euler(order)
    second = _wrap(np.stack([first[:, 0] + np.pi, np.pi - first[:, 1], first[:, 2] + np.pi], axis=1))
    return first, second


def _continuous_angles(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per frame the solution (``[T, k]``) nearest the previous frame's choice, then unwrapped over time; each
    channel shifted by a multiple of ``2 pi`` so that frame 0 lies in ``(-pi, pi]``.

    The map between the two Euler solutions keeps wrapped distances (``d(s1_t, s1_t-1) = d(s2_t, s2_t-1)``), so
    the choice only switches where ``first`` jumps to the other branch: the branch is the running parity of those
    jumps (vectorised; no loop over frames).
    """
    if len(first) > 1:
        stay = np.sum(_wrap(first[1:] - first[:-1]) ** 2, axis=1)
        switch = np.sum(_wrap(second[1:] - first[:-1]) ** 2, axis=1)
        parity = np.concatenate([[0], np.cumsum(switch < stay) % 2]).astype(bool)
        chosen = np.where(parity[:, None], second, first)
    else:
        chosen = first.copy()
    chosen = np.unwrap(chosen, axis=0)
    return chosen - 2 * np.pi * np.round((chosen[:1] - _wrap(chosen[:1])) / (2 * np.pi))


def rotation_to_dofs(rotation: Rotation, axes: str) -> np.ndarray:
    """float64 ``[T, len(axes)]`` radians: the angles of ``axes`` (a bone's dof axes, e.g. ``"xz"``) that best
    reproduce a sequence of ``T`` rotations, continuous over time.

    Three axes: an exact Euler decomposition in ``axes`` order. Fewer: the projection of the module docstring
    (decompose in ``axes`` + the missing axes, keep the solution with the smallest missing angles, drop them).
    """
    if not axes:
        return np.zeros((len(rotation), 0))
    missing = "".join(a for a in "xyz" if a not in axes)
    first, second = _euler_solutions(rotation, axes + missing)
    k = len(axes)
    if missing:
        dropped_first = np.sum(_wrap(first[:, k:]) ** 2, axis=1)
        dropped_second = np.sum(_wrap(second[:, k:]) ** 2, axis=1)
        use_second = dropped_second < dropped_first
        best = np.where(use_second[:, None], second, first)[:, :k]
        return _continuous_angles(best, best)
    return _continuous_angles(first, second)


def euler_near(rotation: Rotation, axes: str, reference: np.ndarray) -> np.ndarray:
    """float64 ``[N, len(axes)]`` radians: per rotation, the dof angles (exact Euler decomposition for three axes,
    the projection of :func:`rotation_to_dofs` for fewer) nearest ``reference`` ``[N, len(axes)]`` radians: of
    the two Euler solutions the nearer one (three axes), then each angle moved by the multiple of ``2 pi`` that
    brings it closest to its reference."""
    reference = np.asarray(reference, dtype=np.float64).reshape(len(rotation), len(axes))
    missing = "".join(a for a in "xyz" if a not in axes)
    first, second = _euler_solutions(rotation, axes + missing)
    k = len(axes)
    if missing:
        use_second = np.sum(_wrap(second[:, k:]) ** 2, axis=1) < np.sum(_wrap(first[:, k:]) ** 2, axis=1)
    else:
        use_second = np.sum(_wrap(second - reference) ** 2, axis=1) < np.sum(_wrap(first - reference) ** 2, axis=1)
    angles = np.where(use_second[:, None], second, first)[:, :k]
    return reference + _wrap(angles - reference)


def project_expmap(rotvec: np.ndarray, axes: str) -> np.ndarray:
    """Exp-maps ``[..., 3]`` projected onto a bone's dof axes (:func:`rotation_to_dofs` per vector, no time
    continuity needed) and mapped back to exp-maps; three axes: unchanged."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    if len(axes) == 3:
        return rotvec
    flat = rotvec.reshape(-1, 3)
    if not axes:
        return np.zeros_like(rotvec)
    missing = "".join(a for a in "xyz" if a not in axes)
    first, second = _euler_solutions(Rotation.from_rotvec(flat), axes + missing)
    k = len(axes)
    use_second = np.sum(_wrap(second[:, k:]) ** 2, axis=1) < np.sum(_wrap(first[:, k:]) ** 2, axis=1)
    angles = np.where(use_second[:, None], second, first)[:, :k]
    return _rotation(axes, angles).as_rotvec().reshape(rotvec.shape)


def heading(rotation: Rotation) -> np.ndarray:
    """float64 ``[T]`` radians: the yaw about ``+y`` of each rotation's forward axis ``R·e_z``
    (:func:`~mocapkit.motion.geometry.direction_yaw`, the convention of a body facing ``+z``)."""
    return direction_yaw(rotation.apply(np.array([0.0, 0.0, 1.0])))


def yaw_rotation(yaw: np.ndarray) -> Rotation:
    """Rotations about ``+y`` by ``yaw`` (radians, ``[T]``)."""
    yaw = np.asarray(yaw, dtype=np.float64).reshape(-1)
    return Rotation.from_rotvec(np.outer(yaw, [0.0, 1.0, 0.0]))


# --------------------------------------------------------------------------- encode / decode


def _root_rotation_parts(skeleton: AsfSkeleton) -> tuple[list[int], list[int], str, Rotation]:
    """Columns of the root's translation and rotation channels, the rotation axes, and the root frame ``C``."""
    order = tuple(skeleton.root_order)
    translation = [k for k, ch in enumerate(order) if ch[0].upper() == "T"]
    rotation_cols = [k for k, ch in enumerate(order) if ch[0].upper() == "R"]
    axes = "".join(order[k][1].lower() for k in rotation_cols)
    c = np.asarray(skeleton.root_orientation, dtype=np.float64)
    if skeleton.angle_unit == "deg":
        c = np.radians(c)
    return translation, rotation_cols, axes, _rotation(skeleton.root_axis.lower(), c[None])[0]


def encode(motion: Motion) -> FeatureClip:
    """The :class:`FeatureClip` of an AMC motion (:func:`~mocapkit.datasets.formats.asf_amc.read_amc` or
    :func:`~mocapkit.datasets.formats.asf_amc.amc_motion`; it needs ``metadata["amc_values"]`` and ``["asf"]``).
    """
    skeleton: AsfSkeleton = motion.metadata["asf"]
    matrix, layout = dof_matrix(motion)
    T = len(matrix)
    # root: world translation (ASF units) and global rotation R = C·M·C⁻¹
    root_values = matrix[:, layout.columns("root")]
    translation_cols, rotation_cols, axes, frame = _root_rotation_parts(skeleton)
    position = np.tile(np.asarray(skeleton.root_position, dtype=np.float64), (T, 1))
    for k in translation_cols:
        position[:, "xyz".index(skeleton.root_order[k][1].lower())] += root_values[:, k]
    rotation = frame * _rotation(axes, np.radians(root_values[:, rotation_cols])) * frame.inv()
    yaw = heading(rotation)
    tilt = continuous_expmap((yaw_rotation(-yaw) * rotation).as_rotvec())
    step = np.zeros((T, 3))
    step[1:] = yaw_rotation(-yaw[:-1]).apply(position[1:] - position[:-1])
    root = np.zeros((T, ROOT_FEATURES))
    root[:, 0] = step[:, 0]
    root[:, 1] = step[:, 2]
    root[1:, 2] = _wrap(np.diff(yaw))
    root[:, 3] = position[:, 1]
    root[:, 4:7] = tilt
    bones = layout.bones[1:]
    joints = np.zeros((T, len(bones), 3))
    for i, (bone, dofs) in enumerate(zip(bones, layout.dofs[1:])):
        rotvec = _rotation(dof_axes(dofs), np.radians(matrix[:, layout.columns(bone)])).as_rotvec()
        joints[:, i] = continuous_expmap(rotvec)
    return FeatureClip(root=root, joints=joints, bones=tuple(bones))


def angle_flips(motion: Motion, max_turn_speed: float = 5400.0) -> list[tuple[int, str, float]]:
    """Frames where a bone's AMC rotation turns faster than a limb can: ``(frame, bone, degrees)`` for every bone
    whose rotation from frame ``k - 1`` to ``k`` exceeds ``max_turn_speed / fps`` degrees (default 45° per frame at
    120 Hz; the fastest real turns in the HDM05 types of the synthesis benchmark are under 10° per frame).

    Such a turn is a change of representation, not of posture. HDM05's deep squats of performer ``dg`` have them:
    in ``HDM_dg_squat1Reps_025_120`` at frame 83 ``lfemur`` turns by 180° (AMC ``160, -76, -39`` → ``200, 104,
    -39``) while ``ltibia`` goes ``202°`` → ``158°`` and the joint positions move by millimetres, the solver
    having switched to an equivalent leg configuration once the knee passed 180°. A regression on joint angles
    must not learn those jumps as motion.
    """
    features = encode(motion)
    limit = float(max_turn_speed) / float(motion.fps)
    flips = []
    for b, bone in enumerate(features.bones):
        v = features.joints[:, b]
        turn = np.degrees((Rotation.from_rotvec(v[:-1]).inv() * Rotation.from_rotvec(v[1:])).magnitude())
        flips.extend((int(k) + 1, bone, float(turn[k])) for k in np.flatnonzero(turn > limit))
    return sorted(flips)


@dataclass
class ContinuousPieces:
    """Training clips cut at their joint-angle flips (:func:`continuous_pieces`).

    Attributes:
        pieces: the pieces, AMC motions at the requested frame rate, in clip order.
        clip_index: per piece, the index of the clip it comes from.
        starts_clip: per piece, whether it begins at its clip's first frame.
        flips: ``(clip, frame, bone, degrees)`` of every flip found (frames of the clip as given).
        unused: ``(clip, start, stop)`` of the pieces left out as too short.
    """

    pieces: list[Motion]
    clip_index: list[int]
    starts_clip: list[bool]
    flips: list[tuple[str, int, str, float]]
    unused: list[tuple[str, int, int]]


def continuous_pieces(
    clips: list[Motion], fps: float, min_frames: int, max_turn_speed: float | None = 5400.0, what: str = "fit"
) -> ContinuousPieces:
    """The clips cut at their :func:`angle_flips` and resampled to ``fps``
    (:func:`~mocapkit.synthesis.clips.resample_clip`), so that a model of successive frames never learns a flip as
    motion; pieces of fewer than ``min_frames`` frames at ``fps`` are left out. One warning per clip with flips
    names it, every flip and every piece left out (``what`` prefixes it). ``max_turn_speed=None``: no cutting.
    """
    out = ContinuousPieces([], [], [], [], [])
    for c, clip in enumerate(clips):
        flips = angle_flips(clip, max_turn_speed) if max_turn_speed is not None else []
        out.flips.extend((clip_label(clip), frame, bone, degrees) for frame, bone, degrees in flips)
        cuts = [0, *sorted({frame for frame, _, _ in flips}), clip.num_frames]
        unused = []
        for start, stop in itertools.pairwise(cuts):
            piece = clip if (start, stop) == (0, clip.num_frames) else clip_segment(clip, start, stop)
            piece = resample_clip(piece, fps)
            if piece.num_frames >= min_frames:
                out.pieces.append(piece)
                out.clip_index.append(c)
                out.starts_clip.append(start == 0)
            else:
                unused.append(f"{start}–{stop - 1}")
                out.unused.append((clip_label(clip), start, stop))
        if flips:
            turns = ", ".join(f"{bone} {degrees:.0f}° at frame {frame}" for frame, bone, degrees in flips)
            warnings.warn(
                f"{what}: {clip_label(clip)}: joint-angle flips ({turns}: changes of representation, not "
                "motion); the clip is cut there" + (f", frames {', '.join(unused)} too short to use" if unused else ""),
                stacklevel=3,
            )
    return out


def root_start(motion: Motion) -> tuple[tuple[float, float], float]:
    """``(start_xz, start_yaw)`` of a clip's first frame (ASF units, radians): what :func:`decode` needs to put
    decoded features back where the clip was."""
    skeleton: AsfSkeleton = motion.metadata["asf"]
    matrix, layout = dof_matrix(motion)
    root_values = matrix[:1, layout.columns("root")]
    translation_cols, rotation_cols, axes, frame = _root_rotation_parts(skeleton)
    position = np.asarray(skeleton.root_position, dtype=np.float64).copy()
    for k in translation_cols:
        position["xyz".index(skeleton.root_order[k][1].lower())] += root_values[0, k]
    rotation = frame * _rotation(axes, np.radians(root_values[:, rotation_cols])) * frame.inv()
    return (float(position[0]), float(position[2])), float(heading(rotation)[0])


def decode(
    features: FeatureClip | np.ndarray,
    skeleton: AsfSkeleton,
    start_xz: tuple[float, float] = (0.0, 0.0),
    start_yaw: float = 0.0,
) -> dict[str, np.ndarray]:
    """AMC values from features: bone → float64 ``[T, len(dof)]`` (degrees; root translation in ASF units), ready
    for :func:`~mocapkit.datasets.formats.asf_amc.amc_motion` or ``write_amc``.

    Args:
        features: a :class:`FeatureClip`, or its :meth:`FeatureClip.flat` matrix for the skeleton's bones.
        skeleton: the skeleton to decode onto (its dofs decide the projection of reduced-dof bones).
        start_xz: world ``(x, z)`` of the root at frame 0, ASF units (:func:`root_start` of the original clip
            reproduces it).
        start_yaw: heading at frame 0, radians. The path is integrated from ``dx, dz, dyaw`` (§3.6 step 3):
            ``yaw_t = start_yaw + sum_{s<=t} dyaw_s`` and ``p_t = p_{t-1} + Ry(yaw_{t-1})·(dx_t, 0, dz_t)``.
    """
    layout = DofLayout.of(skeleton)
    if isinstance(features, np.ndarray):
        features = FeatureClip.from_flat(features, layout.bones[1:])
    if tuple(features.bones) != layout.bones[1:]:
        raise ValueError(
            f"the features are for bones {list(features.bones)[:4]}..., the skeleton "
            f"{skeleton.source or skeleton.name} has {list(layout.bones[1:])[:4]}..."
        )
    root = np.asarray(features.root, dtype=np.float64)
    T = len(root)
    yaw = start_yaw + np.cumsum(root[:, 2])
    previous_yaw = np.concatenate([[start_yaw], yaw[:-1]])
    step = yaw_rotation(previous_yaw).apply(np.stack([root[:, 0], np.zeros(T), root[:, 1]], axis=1))
    position = np.zeros((T, 3))
    position[:, 0] = start_xz[0] + np.cumsum(step[:, 0])
    position[:, 2] = start_xz[1] + np.cumsum(step[:, 2])
    position[:, 1] = root[:, 3]
    translation_cols, rotation_cols, axes, frame = _root_rotation_parts(skeleton)
    rotation = yaw_rotation(yaw) * Rotation.from_rotvec(root[:, 4:7])
    root_values = np.zeros((T, len(skeleton.root_order)))
    for k in translation_cols:
        axis = "xyz".index(skeleton.root_order[k][1].lower())
        root_values[:, k] = position[:, axis] - float(skeleton.root_position[axis])
    root_values[:, rotation_cols] = np.degrees(rotation_to_dofs(frame.inv() * rotation * frame, axes))
    values = {"root": root_values}
    for i, (bone, dofs) in enumerate(zip(layout.bones[1:], layout.dofs[1:])):
        values[bone] = np.degrees(rotation_to_dofs(Rotation.from_rotvec(features.joints[:, i]), dof_axes(dofs)))
    return values


def decode_flat(
    flat: np.ndarray,
    layout: DofLayout,
    skeleton: AsfSkeleton,
    start_xz: tuple[float, float] = (0.0, 0.0),
    start_yaw: float = 0.0,
) -> dict[str, np.ndarray]:
    """:func:`decode` of a flat ``[T, 7 + 3B]`` matrix whose bones are ``layout.bones[1:]``; refuses a layout that
    is not the skeleton's."""
    if DofLayout.of(skeleton) != layout:
        raise ValueError(f"the layout does not match the skeleton {skeleton.source or skeleton.name}")
    return decode(np.asarray(flat, dtype=np.float64), skeleton, start_xz=start_xz, start_yaw=start_yaw)


# --------------------------------------------------------------------------- partitions


LATERAL_FRACTION = 0.018
"""A child subtree of a torso joint is a limb when all its end joints (leaves) lie to one side of the branch joint,
each by more than this fraction of the rest pose's height (sideways, ``x``). Measured on HDM05/CMU ASF and on the
BVH rigs converted by :mod:`mocapkit.datasets.formats.bvh_to_amc` (Bandai, CMU-BVH, Mixamo, two other exporters):
every leg ends to one side, beyond this; torso subtrees end on both sides (both hands) or in the middle (the head),
also when both arms are not mirror images (the mean offset of such a subtree reaches 0.017 of the height on some
Bandai reference frames, which is why the test reads the ends and not the mean)."""

MIN_LIMB_REACH = 0.2
"""A limb reaches at least this fraction of the rest pose's height from its branch joint (arms about 0.35, legs
0.5): Mixamo's eyes, beside the head, are not arms."""

LEG_REACH = 0.25
"""A limb is a leg when its lowest rest joint lies in the bottom ``LEG_REACH`` of the skeleton's rest height (the
feet), else an arm (arms that hang down, in a rest pose other than a T-pose, end at the hips, not at the floor)."""


def partitions(skeleton: AsfSkeleton) -> dict[str, tuple[str, ...]]:
    """The five partitions of Zhou Fig. 4.1 (§3.2): ``"RA", "LA", "RL", "LL", "TH"`` → bones top-down.

    Only the root and bones with dofs are listed (a fixed bone such as ``lhipjoint`` has nothing to model); the
    root is the first member of ``"TH"``. Built from the rest pose, not from names: walking down from the root
    through the torso, a child subtree of a branching joint whose end joints all lie to one side (by more than
    :data:`LATERAL_FRACTION` of the rest pose's height, with a reach of at least :data:`MIN_LIMB_REACH` of it) is a
    limb; left is ``+x`` (CMU/HDM05 ``l*`` bones); a limb that reaches the bottom :data:`LEG_REACH` of the rest
    pose's height is a leg, else an arm. Within a partition, bones are in breadth-first hierarchy order (ancestors
    before descendants).

    Raises:
        SynthesisInputError: the skeleton does not have exactly one left/right arm and leg.
    """
    rest = dict(zip(skeleton.joint_names, skeleton.rest_positions()))
    has_dofs = {b.name for b in skeleton.bones if b.dof} | {"root"}

    def subtree(top: str) -> list[str]:
        out = [top]
        for joint in out:
            out.extend(skeleton.hierarchy.get(joint, []))
        return out

    heights = np.array([p[1] for p in rest.values()])
    height = heights.max() - heights.min()
    foot_level = heights.min() + LEG_REACH * height
    torso, limbs, frontier = ["root"], {}, ["root"]
    while frontier:
        joint = frontier.pop(0)
        children = skeleton.hierarchy.get(joint, [])
        for child in children:
            members = subtree(child)
            offsets = np.array([rest[m] - rest[joint] for m in members])
            reach = float(np.max(np.linalg.norm(offsets, axis=1)))
            ends = np.array([rest[m][0] - rest[joint][0] for m in members if not skeleton.hierarchy.get(m)])
            one_side = bool(np.all(ends > LATERAL_FRACTION * height) or np.all(ends < -LATERAL_FRACTION * height))
            if len(children) > 1 and reach > MIN_LIMB_REACH * height and one_side:
                reaches_feet = min(rest[m][1] for m in members) <= foot_level
                name = ("L" if ends.mean() > 0 else "R") + ("L" if reaches_feet else "A")
                if name in limbs:
                    raise SynthesisInputError(
                        f"{skeleton.source or skeleton.name}: two {name} limbs ({limbs[name][0]}"
                        f", {child}); cannot split it into Zhou's five partitions"
                    )
                limbs[name] = members
            else:
                torso.append(child)
                frontier.append(child)
    missing = [p for p in PARTITION_NAMES[:4] if p not in limbs]
    if missing:
        raise SynthesisInputError(
            f"{skeleton.source or skeleton.name}: no {', '.join(missing)} limb found; cannot "
            f"split it into Zhou's five partitions (arms, legs, torso)"
        )
    out = {name: tuple(b for b in limbs[name] if b in has_dofs) for name in PARTITION_NAMES[:4]}
    out["TH"] = tuple(b for b in torso if b in has_dofs)
    return out


def partition_ancestors(skeleton: AsfSkeleton, partition: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """Per bone of a partition, its ancestors within the partition, top-down: Zhou's ``A_i`` (§3.3)."""
    parent = skeleton.parent_names
    members = set(partition)
    out = {}
    for bone in partition:
        chain, joint = [], parent.get(bone)
        while joint is not None:
            if joint in members:
                chain.append(joint)
            joint = parent.get(joint)
        out[bone] = tuple(reversed(chain))
    return out
