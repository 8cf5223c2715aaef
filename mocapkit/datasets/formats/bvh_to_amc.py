"""BVH motion as ASF/AMC, exactly: the re-rigging that lets tools which learn AMC joint angles (the variation
synthesisers of :mod:`mocapkit.synthesis`) take BVH rigs such as Bandai's.

**Why a re-rig.** AMC angles are rotations away from the ASF's rest pose, and the synthesisers read a clip's
heading, height and tilt from its root rotation against an *upright* rest that faces ``+z`` with its left side
at ``+x`` (HDM05 and CMU: :mod:`mocapkit.synthesis.representation`). A BVH's zero pose can be anything: Bandai's
lies on its side (at zero angles the spine points along ``+x``, the left leg along ``+x``, the right along ``-x``;
every joint frame carries its own "joint orient"). So the ASF written here takes a **reference posture** of the
BVH (:func:`bvh_rig`; by default frame 0 of a reference clip), turned about the vertical to face ``+z`` and
straightened into a T-pose, as its rest pose; its angles are rotations away from that rest.

**The mapping** (BVH forward kinematics as :mod:`mocapkit.datasets.formats.bvh`: ``G_j = G_p L_j``,
``x_j = x_p + G_p t_j``; ASF as :mod:`mocapkit.datasets.formats.asf_amc`). With **any** constant rotation per
joint, here ``A_j = S_j H G_j(reference)`` (``H``: the yaw that makes the reference face ``+z``; ``S_j``: the swing
that straightens the bone below ``j``, :func:`bvh_rig`), the rotations ``G'_j = G_j A_j⁻¹`` and rest offsets
``t'_c = A_p t_c`` place every joint where the BVH does (``G'_p t'_c = G_p t_c``); the rest pose (every
``G'_j`` the identity) has the bones along ``t'_c``. Then:

- the **ASF root** is the BVH joint where the body branches (the first joint from the top with more than one
  child: Bandai's and CMU-BVH's ``Hips``); a single-child chain above it (Bandai's static ``joint_Root``) is left
  out. Root rotation ``G'_r``, root translation ``x_r`` (the ASF's ``root_position`` is 0);
- one **ASF bone per other joint** ``c`` (named as the joint, so the ASF joint positions are the BVH joints'),
  from its parent ``p`` to ``c``: ``direction = t'_c / |t'_c|``, ``length = |t_c|``. Its rotation is ``p``'s:
  ``L_c = G'_{parent(p)}⁻¹ G'_p``, as three dofs ``rx ry rz`` (ASF ``axis 0 0 0 XYZ``). The root's children
  carry the identity and get **no dofs** (as CMU's ``lhipjoint``). Children of one joint carry **copies** of
  its rotation (Bandai's ``Neck``, ``Shoulder_L`` and ``Shoulder_R`` under ``Chest``): a model that samples them
  apart moves the shoulders against the chest, as CMU's clavicles do;
- **End Sites** are left out, as :func:`~mocapkit.datasets.formats.bvh.read_bvh` leaves them out of a Motion's
  joints by default, so a leaf joint's own rotation (``Head``, the hands, the toes), which moves nothing but its
  End Site, is dropped: the joints' positions are what the conversion keeps. (Bandai's End Sites have zero length
  in some takes and not in others; one skeleton for every take needs them gone.)

Bone lengths are the clip's own (per file, so clips of different performers keep their bodies); a non-root joint
whose translation changes during the clip cannot be an ASF bone and is an error naming the file and the joint.
Units: the ASF is in CMU/HDM05 length units (``length 0.45``: one unit = 0.0254/0.45 m), so lengths and
translations read like HDM05's. The result is checked: the ASF's forward kinematics must give the BVH's joint
positions to within :data:`TOLERANCE_M`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import INCH, AsfBone, AsfSkeleton, amc_motion
from mocapkit.datasets.formats.bvh import BvhSkeleton, local_transforms
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import hip_line_heading, lateral_line
from mocapkit.motion.layouts import find_landmarks

#: The ASF length multiplier of the result (CMU and HDM05's: one unit = 1/0.45 inch).
LENGTH_MULTIPLIER = 0.45
#: Largest joint-position difference (metres) between the ASF/AMC result and the BVH that :func:`bvh_to_amc` accepts.
TOLERANCE_M = 1e-4
#: A non-root joint's translation may wander this fraction of the skeleton's rest size and still be a fixed bone.
TRANSLATION_TOLERANCE = 1e-4


class BvhConversionError(MotionFormatError):
    """A BVH that cannot become an ASF/AMC pair; the message names the file and the joint."""


@dataclass(frozen=True)
class BvhRig:
    """The constant part of a BVH → ASF/AMC conversion, shared by every clip of one rig (module docstring).

    Attributes:
        joint_names: the BVH joints, file order (a clip converted with this rig must have exactly these).
        root: index of the joint that becomes the ASF root.
        rest_rotations: float64 ``[J, 3, 3]``, ``A_j`` per BVH joint (:func:`bvh_rig`).
        reference: where the rest posture comes from, e.g. ``"walk_01.bvh frame 0"`` (for reports).
        skeleton: the reference clip's hierarchy (channel orders, End Sites), for :func:`amc_to_bvh`.
        translations: float64 ``[J, 3]``, the reference clip's mean local translation per joint (file units).
        pose: float64 ``[J, 3, 3]`` local rotations and ``[J, 3]`` translations of the reference frame (the joints
            above the ASF root are written with these).
        scale: metres per file unit of the reference clip.
    """

    joint_names: tuple[str, ...]
    root: int
    rest_rotations: np.ndarray
    reference: str
    skeleton: BvhSkeleton
    translations: np.ndarray
    pose: tuple[np.ndarray, np.ndarray]
    scale: float


def _label(motion: Motion) -> str:
    return str(motion.source or motion.name or "<BVH motion>")


def _bvh_of(motion: Motion) -> BvhSkeleton:
    if not isinstance(motion, Motion) or not isinstance(motion.metadata.get("bvh"), BvhSkeleton):
        what = _label(motion) if isinstance(motion, Motion) else type(motion).__name__
        raise BvhConversionError(what, None, "not a BVH motion (read it with mocapkit.datasets.formats.bvh.read_bvh)")
    return motion.metadata["bvh"]


def _globals(motion: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float64 global rotations ``[F, J, 3, 3]``, positions ``[F, J, 3]`` (file units) and local translations
    ``[F, J, 3]`` (file units) of a BVH motion, recomputed from its raw channels."""
    skeleton = _bvh_of(motion)
    local, trans = local_transforms(
        skeleton, motion.metadata["channels"], motion.metadata.get("position_mode", "replace")
    )
    glob = np.empty_like(local)
    pos = np.empty_like(trans)
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            glob[:, j], pos[:, j] = local[:, j], trans[:, j]
        else:
            glob[:, j] = glob[:, p] @ local[:, j]
            pos[:, j] = pos[:, p] + np.einsum("fab,fb->fa", glob[:, p], trans[:, j])
    return glob, pos, trans


def _branch_root(skeleton: BvhSkeleton, label: str) -> int:
    """The first joint from the top with more than one child (the ASF root)."""
    roots = [j for j, p in enumerate(skeleton.parents) if p < 0]
    if len(roots) != 1:
        raise BvhConversionError(label, None, f"{len(roots)} ROOTs; an ASF skeleton has one")
    joint = roots[0]
    while True:
        children = [c for c, p in enumerate(skeleton.parents) if p == joint]
        if len(children) != 1:
            return joint
        joint = children[0]


def _facing_yaw(positions: np.ndarray, joint_names, label: str) -> np.ndarray:
    """``H`` ``[3, 3]``: the rotation about ``+y`` that turns a posture (``[J, 3]``, y up) to face ``+z``, its left
    side ``+x``, from the sum of its hip and shoulder lines (:func:`~mocapkit.motion.layouts.find_landmarks`;
    :func:`~mocapkit.motion.geometry.hip_line_heading`)."""
    marks = find_landmarks(joint_names)
    pairs = [(marks[f"l_{p}"], marks[f"r_{p}"]) for p in ("hip", "shoulder") if f"l_{p}" in marks and f"r_{p}" in marks]
    if not pairs:
        raise BvhConversionError(
            label,
            None,
            "cannot tell the rig's left from its right: no left/right hip or "
            "shoulder joints found by name (Left/Right, _L/_R or L_/R_ marks)",
        )
    left, right = [p[0] for p in pairs], [p[1] for p in pairs]
    line = lateral_line(positions, left, right)
    if np.hypot(line[2], line[0]) < 1e-9:
        raise BvhConversionError(
            label, None, "the reference posture's left-right axis is vertical; pick another reference frame"
        )
    yaw = hip_line_heading(positions, left, right, up="y", along="-x")  # the posture's yaw (facing +z: 0)
    return Rotation.from_rotvec([0.0, -yaw, 0.0]).as_matrix()


def _limb_sides(skeleton: BvhSkeleton, label: str) -> dict[int, str]:
    """Per joint, ``"left_arm"``, ``"right_arm"``, ``"left_leg"``, ``"right_leg"`` or ``"torso"``: the one limb
    whose end landmark (wrist, else elbow; ankle, else knee) its subtree holds, or, holding none, its parent's
    (hands, toes)."""
    marks = find_landmarks(skeleton.joint_names)
    ends = {
        "left_arm": ("l_wrist", "l_elbow"),
        "right_arm": ("r_wrist", "r_elbow"),
        "left_leg": ("l_ankle", "l_knee"),
        "right_leg": ("r_ankle", "r_knee"),
    }
    ends = {limb: next((marks[m] for m in names if m in marks), None) for limb, names in ends.items()}
    missing = [limb for limb, joint in ends.items() if joint is None]
    if missing:
        raise BvhConversionError(
            label,
            None,
            f"no {', '.join(missing)} found by joint name (elbow/wrist, knee/ankle "
            "with Left/Right, _L/_R or L_/R_ marks); the rest pose needs both arms and legs",
        )
    J = skeleton.num_joints
    inside = np.eye(J, dtype=bool)  # inside[a, b]: b in the subtree of a
    for j in range(J - 1, -1, -1):
        p = skeleton.parents[j]
        if p >= 0:
            inside[p] |= inside[j]
    side = {}
    for j in range(J):  # parents first
        holds = [limb for limb, end in ends.items() if inside[j, end]]
        parent = side.get(skeleton.parents[j], "torso")
        side[j] = holds[0] if len(holds) == 1 else parent if not holds else "torso"
    return side


#: The rest direction of a bone by the part it belongs to (y up, facing +z, left +x): a T-pose.
REST_DIRECTIONS = {
    "torso": (0.0, 1.0, 0.0),
    "left_arm": (1.0, 0.0, 0.0),
    "right_arm": (-1.0, 0.0, 0.0),
    "left_leg": (0.0, -1.0, 0.0),
    "right_leg": (0.0, -1.0, 0.0),
    "foot": (0.0, 0.0, 1.0),
}


def _swing(vector: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The smallest rotation ``[3, 3]`` that turns the direction of ``vector`` into ``target`` (unit)."""
    v = vector / np.linalg.norm(vector)
    axis = np.cross(v, target)
    sin, cos = np.linalg.norm(axis), float(np.dot(v, target))
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        other = np.eye(3)[np.argmin(np.abs(v))]
        return Rotation.from_rotvec(np.pi * np.cross(v, other) / np.linalg.norm(np.cross(v, other))).as_matrix()
    return Rotation.from_rotvec(axis / sin * np.arctan2(sin, cos)).as_matrix()


def bvh_rig(reference: Motion, frame: int = 0) -> BvhRig:
    """The rig of a BVH motion's conversion (module docstring): the rest pose is ``reference``'s posture at
    ``frame``, turned to face ``+z`` and then straightened into a T-pose. Convert every clip of one training set
    with one rig.

    The straightening: every torso joint with a torso child, and every limb joint from the shoulder or hip down
    (:func:`_limb_sides`, from the joint names), is swung by the smallest rotation that points the bone to its
    first child of the same part along :data:`REST_DIRECTIONS` (torso up, arms sideways, legs down, the bone
    below the ankle forward); clavicle and pelvis segments keep the reference posture's directions, and the
    root its pelvis's tilt. The rest pose then does not depend on what the performer was doing at
    ``frame`` (crossed legs, a bent neck), which matters to whatever reads the rest geometry
    (:func:`~mocapkit.synthesis.representation.partitions`).

    Raises:
        BvhConversionError: not a BVH motion, several ROOTs, no left/right landmarks, ``frame`` out of range.
    """
    skeleton = _bvh_of(reference)
    label = _label(reference)
    if not -reference.num_frames <= frame < reference.num_frames:
        raise BvhConversionError(label, None, f"reference frame {frame} of a {reference.num_frames}-frame clip")
    glob, pos, trans = _globals(reference)
    turn = _facing_yaw(pos[frame], skeleton.joint_names, label)
    root = _branch_root(skeleton, label)
    side = _limb_sides(skeleton, label)
    marks = find_landmarks(skeleton.joint_names)
    ankles = {marks.get("l_ankle"), marks.get("r_ankle")} - {None}
    # a limb is straightened from its shoulder or hip joint down (the parent of its elbow or knee; of its end's
    # parent without one); the clavicle and pelvis segments above keep the reference posture's directions
    middles = {
        "left_arm": ("l_elbow", "l_wrist"),
        "right_arm": ("r_elbow", "r_wrist"),
        "left_leg": ("l_knee", "l_ankle"),
        "right_leg": ("r_knee", "r_ankle"),
    }
    upper = {}
    for limb, (middle, end) in middles.items():
        joint = marks[middle] if middle in marks else skeleton.parents[marks[end]]
        upper[limb] = skeleton.parents[joint]
    rest = turn @ glob[frame]
    for j in range(skeleton.num_joints):
        children = [c for c, p in enumerate(skeleton.parents) if p == j and side[c] == side[j]]
        if j == root or not children or np.linalg.norm(trans[frame, children[0]]) == 0:
            continue
        if side[j] != "torso" and j != upper[side[j]] and upper[side[j]] not in _ancestors(skeleton, j):
            continue
        c = children[0]
        below_ankle = side[j].endswith("leg") and any(a in ankles for a in _ancestors(skeleton, c))
        target = np.asarray(REST_DIRECTIONS["foot" if below_ankle else side[j]])
        rest[j] = _swing(rest[j] @ trans[frame, c], target) @ rest[j]
    local, _ = local_transforms(
        skeleton, reference.metadata["channels"][[frame]], reference.metadata.get("position_mode", "replace")
    )
    return BvhRig(
        joint_names=tuple(skeleton.joint_names),
        root=root,
        rest_rotations=rest,
        reference=f"{label} frame {frame % reference.num_frames}",
        skeleton=skeleton,
        translations=trans.mean(axis=0),
        pose=(local[0], trans[frame]),
        scale=float(reference.metadata["scale"]),
    )


def _subtree(parents, root: int) -> list[int]:
    """``root`` and its descendants, in file order (BVH lists parents before children)."""
    out = {root}
    for j, p in enumerate(parents):
        if p in out:
            out.add(j)
    return sorted(out)


def _ancestors(skeleton: BvhSkeleton, joint: int) -> list[int]:
    """``joint``'s parent, grandparent, … up to the ROOT."""
    out, p = [], skeleton.parents[joint]
    while p >= 0:
        out.append(p)
        p = skeleton.parents[p]
    return out


def _euler_degrees(matrices: np.ndarray) -> np.ndarray:
    """AMC values ``[F, 3]`` (degrees, ``rx ry rz`` = fixed-axis x then y then z) of rotations ``[F, 3, 3]``,
    unwrapped over time so that no value jumps by 360°."""
    return np.unwrap(Rotation.from_matrix(matrices).as_euler("xyz", degrees=True), period=360.0, axis=0)


def bvh_to_amc(motion: Motion, rig: BvhRig | None = None) -> Motion:
    """A BVH motion (:func:`~mocapkit.datasets.formats.bvh.read_bvh`) as an AMC motion on a new ASF skeleton
    (module docstring), what :func:`~mocapkit.datasets.formats.asf_amc.read_amc` would return for it.

    Args:
        motion: the BVH motion (raw channels in its metadata).
        rig: the shared rest pose (:func:`bvh_rig`); ``None``: this motion's frame 0.

    Returns:
        An AMC :class:`~mocapkit.motion.container.Motion` (``positions`` float32 ``[F, J', 3]`` metres,
        ``J'`` = the joints from the ASF root down, named as the BVH's; the root is ``"root"``), with
        ``metadata["asf"]`` (the skeleton, named after the clip), ``metadata["amc_values"]`` (degrees, root
        translation in ASF units), ``metadata["bvh_rig"]`` (the rig) and ``metadata["bvh_dropped_joints"]`` (the
        joints above the ASF root).

    Raises:
        BvhConversionError: not a BVH motion; joints that differ from the rig's; a non-root joint whose
            translation changes during the clip; a result whose positions differ from the BVH's by more than
            :data:`TOLERANCE_M` (each names the file, and the joint where there is one).
    """
    skeleton = _bvh_of(motion)
    label = _label(motion)
    rig = bvh_rig(motion) if rig is None else rig
    if tuple(skeleton.joint_names) != rig.joint_names:
        raise BvhConversionError(
            label,
            None,
            f"its joints differ from the rig's ({rig.reference}): "
            f"{sorted(set(skeleton.joint_names) ^ set(rig.joint_names))[:6]}",
        )
    metres_per_file_unit = float(motion.metadata["scale"])
    asf_unit = INCH / LENGTH_MULTIPLIER  # metres per ASF length unit
    glob, pos, trans = _globals(motion)
    root = rig.root
    parents = skeleton.parents
    below = set(_subtree(parents, root))
    wander = np.abs(trans - trans[:1]).max(axis=0).max(axis=1)
    limit = TRANSLATION_TOLERANCE * max(skeleton.rest_size(), 1e-9)
    for j in sorted(below - {root}):
        if wander[j] > limit:
            frame = int(np.abs(trans[:, j] - trans[0, j]).max(axis=1).argmax())
            raise BvhConversionError(
                label,
                None,
                f"joint {skeleton.joint_names[j]!r} moves against its parent "
                f"(its translation changes by {wander[j]:.4g} file units by frame {frame + 1}); an "
                "ASF bone has a fixed length",
            )
    rest = rig.rest_rotations
    g_new = glob @ np.swapaxes(rest, -1, -2)[None]  # G'_j = G_j A_jᵀ, [F, J, 3, 3]
    offsets = trans.mean(axis=0)  # fixed bones: their mean translation (file units)

    bones, hierarchy, values = [], {"root": []}, {}
    name_of = {j: ("root" if j == root else skeleton.joint_names[j]) for j in below}

    def add_bone(name: str, parent_joint: int, vector: np.ndarray, rotation: np.ndarray | None) -> None:
        length = float(np.linalg.norm(vector))
        direction = vector / length if length > 0 else np.array([0.0, 1.0, 0.0])
        dof = ("rx", "ry", "rz") if rotation is not None else ()
        bones.append(
            AsfBone(
                id=len(bones) + 1,
                name=name,
                direction=direction,
                length=length * metres_per_file_unit / asf_unit,
                dof=dof,
                limits=[(-np.inf, np.inf)] * len(dof),
            )
        )
        hierarchy.setdefault(name_of[parent_joint], []).append(name)
        if rotation is not None:
            values[name] = _euler_degrees(rotation)

    for c in sorted(below - {root}):
        p = parents[c]
        local = None if p == root else np.swapaxes(g_new[:, parents[p]], -1, -2) @ g_new[:, p]
        add_bone(skeleton.joint_names[c], p, rest[p] @ offsets[c], local)
    values["root"] = np.concatenate(
        [pos[:, root] * metres_per_file_unit / asf_unit, _euler_degrees(g_new[:, root])], axis=1
    )
    asf = AsfSkeleton(
        name=motion.name or "bvh",
        units={"mass": 1.0, "length": LENGTH_MULTIPLIER, "angle": "deg"},
        documentation=f"converted from {label} by mocapkit.datasets.formats.bvh_to_amc; rest pose: {rig.reference}",
        bones=bones,
        hierarchy={k: v for k, v in hierarchy.items() if v},
        source=None,
    )
    dropped = tuple(skeleton.joint_names[j] for j in range(len(parents)) if j not in below)
    out = amc_motion(
        asf,
        values,
        fps=motion.fps,
        angle_unit="deg",
        name=motion.name,
        source=motion.source,
        metadata={"asf_path": None, "bvh_rig": rig, "bvh_dropped_joints": dropped},
    )
    kept = sorted(below)  # the ASF's joints, in order: root, then the bones
    error = float(np.abs(out.positions.astype(np.float64) - pos[:, kept] * metres_per_file_unit).max(initial=0.0))
    if error > TOLERANCE_M:
        raise BvhConversionError(
            label, None, f"the ASF/AMC conversion misplaces joints by {error:.3g} m (> {TOLERANCE_M:g} m)"
        )
    return out


def amc_to_bvh(motion: Motion, rig: BvhRig) -> Motion:
    """An AMC motion on the ASF skeleton of ``rig`` (what :func:`bvh_to_amc` made, or a synthesised variant of it)
    back in the rig's own BVH hierarchy, joint frames and channel orders: the inverse of the re-rig, so that
    :func:`~mocapkit.datasets.formats.bvh.write_bvh` writes a file the original rig's tools take.

    Per BVH joint ``j`` from the ASF root down, ``G_j = G'_j A_j`` with ``G'_j`` the rotation of the ASF bone of
    ``j``'s first child (the root: the ASF root's; a leaf, whose rotation the conversion dropped: its parent's,
    so it keeps the rest pose's bend). The joints above the ASF root keep the reference frame's pose. Local
    translations are the reference clip's (bone lengths of the reference body: that of the variants'
    reference skeleton), the root's follows the motion. The other children of a joint with several
    (Bandai's shoulders under ``Chest``) carry copies of its rotation in the ASF, which a synthesiser samples
    apart: where such a joint has its own position channels (Bandai's all do) they place it where the motion
    has it, so the result is exact; where it has none, it follows the first child's copy and the check below
    fails.

    Returns:
        A BVH :class:`~mocapkit.motion.container.Motion` (as :func:`~mocapkit.datasets.formats.bvh.read_bvh`
        returns), its joints placed as ``motion``'s to within :data:`TOLERANCE_M` where the bodies agree.

    Raises:
        BvhConversionError: ``motion`` is not an AMC motion of the rig's joints, or a joint of the rig has one or
            two rotation channels (a rotation cannot be written there exactly).
    """
    from mocapkit.datasets.formats.asf_amc import forward_kinematics
    from mocapkit.datasets.formats.bvh import bvh_motion

    label = _label(motion)
    skeleton = rig.skeleton
    root = rig.root
    parents = skeleton.parents
    below = _subtree(parents, root)
    names = ("root",) + tuple(skeleton.joint_names[j] for j in below[1:])
    asf = motion.metadata.get("asf")
    if asf is None or "amc_values" not in motion.metadata or tuple(asf.joint_names) != names:
        raise BvhConversionError(label, None, f"not an AMC motion on the ASF skeleton of the rig ({rig.reference})")
    positions, local_asf = forward_kinematics(
        asf, motion.metadata["amc_values"], angle_unit=motion.metadata.get("amc_angle_unit", "deg")
    )
    F = len(positions)
    world_asf = np.empty_like(local_asf)
    for k, p in enumerate(asf.parents):
        world_asf[:, k] = local_asf[:, k] if p < 0 else world_asf[:, p] @ local_asf[:, k]
    index = {j: k for k, j in enumerate(below)}  # BVH joint → ASF joint
    ref_local, ref_trans = rig.pose
    glob = np.empty((F, len(parents), 3, 3))
    for j, p in enumerate(parents):  # parents first
        if j not in index:  # above the ASF root: the reference frame's pose
            glob[:, j] = ref_local[j] if p < 0 else glob[:, p] @ ref_local[j]
            continue
        children = [c for c, q in enumerate(parents) if q == j and c in index]
        if j == root:
            primed = world_asf[:, 0]
        elif children:
            primed = world_asf[:, index[children[0]]]
        else:  # a leaf: G'_j = G'_p
            primed = glob[:, p] @ rig.rest_rotations[p].T
        glob[:, j] = primed @ rig.rest_rotations[j]
    primary = {j: next((c for c, q in enumerate(parents) if q == j), None) for j in index}
    moves_itself = {j: {"Xposition", "Yposition", "Zposition"} <= set(skeleton.channels[j]) for j in index}
    trans = np.tile(rig.translations, (F, 1, 1))
    world = np.zeros((F, len(parents), 3))  # file units
    for j, p in enumerate(parents):
        if j not in index:
            trans[:, j] = ref_trans[j]
        if j == root:
            above = world[:, p] if p >= 0 else 0.0
            g_parent = glob[:, p] if p >= 0 else np.eye(3)
            trans[:, j] = np.einsum("...ba,...b->...a", g_parent, positions[:, 0] / rig.scale - above)
        elif j in index and p in index and primary[p] != j and moves_itself[j]:
            # a sibling whose copy of the parent's rotation was sampled apart: its position channels place it
            trans[:, j] = np.einsum(
                "fba,fb->fa", glob[:, p], (positions[:, index[j]] - positions[:, index[p]]) / rig.scale
            )
        if p >= 0:
            world[:, j] = world[:, p] + np.einsum("fab,fb->fa", glob[:, p], trans[:, j])
        else:
            world[:, j] = trans[:, j]
    columns = []
    for j, p in enumerate(parents):
        local = glob[:, j] if p < 0 else np.swapaxes(glob[:, p], 1, 2) @ glob[:, j]
        chans = skeleton.channels[j]
        rotations = [c for c in chans if c.endswith("rotation")]
        if len(rotations) not in (0, 3):
            raise BvhConversionError(
                label,
                None,
                f"joint {skeleton.joint_names[j]!r} has {len(rotations)} rotation "
                "channel(s); only joints with three or none can be written",
            )
        euler = (
            np.unwrap(
                Rotation.from_matrix(local).as_euler("".join(c[0] for c in rotations), degrees=True),
                period=360.0,
                axis=0,
            )
            if rotations
            else np.zeros((F, 0))
        )
        column, r = [], 0
        for c in chans:
            if c.endswith("rotation"):
                column.append(euler[:, r])
                r += 1
            else:
                column.append(trans[:, j, "XYZ".index(c[0])])
        columns.extend(column)
    values = np.stack(columns, axis=1) if columns else np.zeros((F, 0))
    frame_time = 1.0 / motion.fps
    out = bvh_motion(skeleton, values, frame_time, rig.scale, name=motion.name, source=motion.source)
    error = float(np.abs(out.positions[:, below].astype(np.float64) - positions).max(initial=0.0))
    if error > TOLERANCE_M:
        raise BvhConversionError(
            label,
            None,
            f"writing it in the rig of {rig.reference} misplaces joints by "
            f"{error:.3g} m (> {TOLERANCE_M:g} m): bone lengths other than the reference "
            "clip's, or children of one joint moved apart (their copies of its rotation "
            "sampled apart) with no position channels to hold them",
        )
    return out
