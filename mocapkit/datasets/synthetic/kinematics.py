"""A forward-kinematics model of the Kinect v2 / NTU 25-joint skeleton (numpy only).

The map, in the order the synthetic generator uses it:

1. :class:`BodyProportions` → :func:`rest_offsets`: the rest pose as one offset
   vector per joint, ``[25, 3]`` metres, each expressed in its parent's frame.
   Rest pose: standing upright, arms hanging at the sides.
2. Named degrees of freedom (:data:`DOFS`, e.g. ``"r_elbow"``) → :func:`dofs_to_euler`:
   per-joint Euler angles ``[T, 25, 3]`` (radians).
3. :func:`euler_to_matrix` → local rotations ``[T, 25, 3, 3]``.
4. :func:`forward_kinematics`: compose the local rotations down the tree
   (parents from :data:`~mocapkit.motion.layouts.NTU25`) into joint positions
   ``[T, 25, 3]``, vectorised over frames.

Body frame (the frame a person's rest pose is written in):
``+x`` = the person's right, ``+y`` = up, ``-z`` = forward (where the person faces).
This is Kinect camera space for a person facing the camera: Kinect's ``+x``
points to the camera's left, which is the right of someone facing it.

Rotation convention ("rotation stored at the child"): the local rotation of
joint ``c`` turns the bone ``parent(c) → c`` (and everything below it) about
the parent joint, relative to the parent bone's frame::

    G[c]   = G[parent(c)] @ L[c]                        # global frame of bone parent(c)→c
    pos[c] = pos[parent(c)] + G[c] @ offset[c]

so the rotation stored at ``ElbowRight`` is the shoulder's rotation (it swings
the upper arm) and the one stored at ``WristRight`` is the elbow's. Storing it
at the child lets branching joints (SpineBase, SpineShoulder, the hands) turn
each branch independently. Each ``L[c] = Rz(z) @ Rx(x) @ Ry(y)``: twist about
the bone axis first, then flexion (about x), then abduction (about z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit.motion.layouts import NTU25

J = {name: i for i, name in enumerate(NTU25.joint_names)}  #: joint name → index in NTU25
NUM_JOINTS = NTU25.num_joints

#: Joints of the left side; their y (twist) and z (abduction) angles are mirrored
#: so that one set of DOF values means the same anatomical motion on both sides.
LEFT_JOINTS = frozenset(i for i, n in enumerate(NTU25.joint_names) if n.endswith("Left"))


def _topological_order(parents: tuple[int, ...]) -> list[int]:
    """Joint indices with every parent before its children (root first)."""
    order, frontier = [], [j for j, p in enumerate(parents) if p < 0]
    while frontier:
        j = frontier.pop(0)
        order.append(j)
        frontier.extend(c for c, p in enumerate(parents) if p == j)
    return order


TOPO_ORDER = _topological_order(NTU25.parents)


# --------------------------------------------------------------------------- body proportions


@dataclass(frozen=True)
class BodyProportions:
    """Segment lengths of one person, metres.

    Build one with :meth:`from_height`; :attr:`height` (floor to top of head)
    is then close to the requested height.
    """

    pelvis_width: float = 0.17  # HipLeft ↔ HipRight
    hip_drop: float = 0.06  # SpineBase → hip joints, downward
    lower_spine: float = 0.25  # SpineBase → SpineMid
    upper_spine: float = 0.24  # SpineMid → SpineShoulder
    neck: float = 0.08  # SpineShoulder → Neck
    head: float = 0.12  # Neck → Head (Kinect's Head joint is mid-head)
    shoulder_width: float = 0.36  # ShoulderLeft ↔ ShoulderRight
    upper_arm: float = 0.28
    forearm: float = 0.25
    hand: float = 0.08  # Wrist → Hand
    hand_tip: float = 0.07  # Hand → HandTip
    thigh: float = 0.42
    shin: float = 0.40
    ankle_height: float = 0.07  # Ankle above the floor
    foot: float = 0.13  # Ankle → Foot (forward)

    @property
    def height(self) -> float:
        """Standing height, floor to top of head (top of head ≈ Head joint + 0.09 m), metres."""
        return (
            self.ankle_height
            + self.shin
            + self.thigh
            + self.hip_drop
            + self.lower_spine
            + self.upper_spine
            + self.neck
            + self.head
            + 0.09
        )

    @classmethod
    def from_height(cls, height: float, limb_ratios: np.ndarray | None = None) -> BodyProportions:
        """Average adult proportions scaled to ``height`` metres.

        Args:
            height: standing height in metres (adults: about 1.5–1.9).
            limb_ratios: optional ``[4]`` multipliers for (arms, legs, torso, shoulder width),
                e.g. ``1 + 0.05 * rng.standard_normal(4)``; the result is rescaled so the
                height stays ``height``.
        """
        r = np.ones(4) if limb_ratios is None else np.asarray(limb_ratios, dtype=float)
        base = cls()
        arms, legs, torso, width = (float(v) for v in r)
        shaped = cls(
            pelvis_width=base.pelvis_width * width,
            hip_drop=base.hip_drop,
            lower_spine=base.lower_spine * torso,
            upper_spine=base.upper_spine * torso,
            neck=base.neck,
            head=base.head,
            shoulder_width=base.shoulder_width * width,
            upper_arm=base.upper_arm * arms,
            forearm=base.forearm * arms,
            hand=base.hand,
            hand_tip=base.hand_tip,
            thigh=base.thigh * legs,
            shin=base.shin * legs,
            ankle_height=base.ankle_height,
            foot=base.foot,
        )
        s = height / shaped.height
        return cls(**{k: v * s for k, v in shaped.__dict__.items()})


def rest_offsets(body: BodyProportions) -> np.ndarray:
    """Rest-pose offset of every joint from its parent, in the body frame, ``[25, 3]`` metres.

    Standing upright, arms hanging slightly away from the body, feet pointing
    forward (``-z``). The root (SpineBase) offset is zero.
    """
    b = body
    off = np.zeros((NUM_JOINTS, 3))
    half_sh, half_pel = b.shoulder_width / 2, b.pelvis_width / 2
    off[J["SpineMid"]] = (0, b.lower_spine, 0)
    off[J["SpineShoulder"]] = (0, b.upper_spine, 0)
    off[J["Neck"]] = (0, b.neck, 0)
    off[J["Head"]] = (0, b.head, 0.01)
    for side, sx in (("Left", -1.0), ("Right", 1.0)):
        off[J["Shoulder" + side]] = (sx * half_sh, -0.04, 0.01)
        off[J["Elbow" + side]] = (sx * 0.02, -b.upper_arm, 0)
        off[J["Wrist" + side]] = (0, -b.forearm, -0.01)
        off[J["Hand" + side]] = (0, -b.hand, 0)
        off[J["HandTip" + side]] = (0, -b.hand_tip, -0.005)
        off[J["Thumb" + side]] = (-sx * 0.015, -0.03, -0.035)
        off[J["Hip" + side]] = (sx * half_pel, -b.hip_drop, 0)
        off[J["Knee" + side]] = (0, -b.thigh, -0.01)
        off[J["Ankle" + side]] = (0, -b.shin, 0.02)
        off[J["Foot" + side]] = (sx * 0.01, -b.ankle_height * 0.6, -b.foot)
    return off


# --------------------------------------------------------------------------- named degrees of freedom

#: Root DOFs, not joint rotations: ``root_fwd`` / ``root_side`` move the body (metres,
#: along its initial forward / right), ``root_up`` lifts it off the floor (metres, jumps),
#: ``root_yaw`` turns it about the vertical (degrees, positive = turn left).
ROOT_DOFS = ("root_fwd", "root_side", "root_up", "root_yaw")

#: Joint DOFs: name → (joint whose local rotation it sets, Euler axis 0=x 1=y 2=z, sign).
#: Angles in degrees, 0 = rest pose. The sign makes positive values the anatomical
#: direction named: flexion = forward, abduction = away from the body, bend = forward,
#: shoulder twist = external rotation (lifts a bent forearm of an abducted arm).
DOFS: dict[str, tuple[int, int, float]] = {
    "spine_bend": (J["SpineMid"], 0, -1.0),
    "spine_side": (J["SpineMid"], 2, 1.0),  # lean to the person's right
    "spine_twist": (J["SpineMid"], 1, 1.0),  # upper body turns left
    "chest_bend": (J["SpineShoulder"], 0, -1.0),
    "head_nod": (J["Head"], 0, -1.0),
}
for _s, _side in (("l", "Left"), ("r", "Right")):
    DOFS.update(
        {
            f"{_s}_clavicle": (J["Shoulder" + _side], 2, 1.0),  # shrug: shoulder up (abduct the collar bone)
            f"{_s}_shoulder_flex": (J["Elbow" + _side], 0, 1.0),
            f"{_s}_shoulder_abd": (J["Elbow" + _side], 2, 1.0),
            f"{_s}_shoulder_twist": (J["Elbow" + _side], 1, -1.0),
            f"{_s}_elbow": (J["Wrist" + _side], 0, 1.0),
            f"{_s}_wrist": (J["Hand" + _side], 0, 1.0),
            f"{_s}_hip_flex": (J["Knee" + _side], 0, 1.0),
            f"{_s}_hip_abd": (J["Knee" + _side], 2, 1.0),
            f"{_s}_knee": (J["Ankle" + _side], 0, -1.0),
            f"{_s}_ankle": (J["Foot" + _side], 0, -1.0),  # plantar flexion: toes down
        }
    )

DOF_NAMES: tuple[str, ...] = ROOT_DOFS + tuple(DOFS)


def dofs_to_euler(values: np.ndarray, names: tuple[str, ...] = DOF_NAMES) -> np.ndarray:
    """Joint DOF values (degrees) → per-joint Euler angles (radians), ``[T, 25, 3]``.

    Args:
        values: ``[T, len(names)]`` DOF values; root DOFs are ignored here.
        names: the DOF name of each column.

    Left-side joints get their y and z angles negated (mirror image of the right side).
    """
    values = np.asarray(values, dtype=float)
    euler = np.zeros((values.shape[0], NUM_JOINTS, 3))
    for k, name in enumerate(names):
        if name in DOFS:
            joint, axis, sign = DOFS[name]
            if joint in LEFT_JOINTS and axis != 0:
                sign = -sign
            euler[:, joint, axis] += sign * np.deg2rad(values[:, k])
    return euler


# --------------------------------------------------------------------------- rotations and FK


def rot_x(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about x for angles ``a`` (radians), ``[..., 3, 3]``."""
    a = np.asarray(a, dtype=float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], -1).reshape(a.shape + (3, 3))


def rot_y(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about y (the vertical) for angles ``a`` (radians), ``[..., 3, 3]``."""
    a = np.asarray(a, dtype=float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(a.shape + (3, 3))


def rot_z(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about z for angles ``a`` (radians), ``[..., 3, 3]``."""
    a = np.asarray(a, dtype=float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(a.shape + (3, 3))


def euler_to_matrix(euler: np.ndarray) -> np.ndarray:
    """Euler angles ``[..., 3]`` (x, y, z radians) → ``Rz @ Rx @ Ry``, ``[..., 3, 3]``."""
    return rot_z(euler[..., 2]) @ rot_x(euler[..., 0]) @ rot_y(euler[..., 1])


def forward_kinematics(
    offsets: np.ndarray, local_rot: np.ndarray, root_rot: np.ndarray | None = None, root_pos: np.ndarray | None = None
) -> np.ndarray:
    """Joint positions from local rotations, composed down the NTU25 tree.

    Args:
        offsets: ``[25, 3]`` rest offsets from :func:`rest_offsets` (metres, parent frame).
        local_rot: ``[T, 25, 3, 3]`` local rotation of every joint (see the module
            docstring: the rotation at joint ``c`` turns the bone ``parent(c) → c``).
            The root's entry turns the whole body.
        root_rot: ``[T, 3, 3]`` global orientation of the root (default identity).
        root_pos: ``[T, 3]`` root (SpineBase) position in metres (default origin).

    Returns:
        ``[T, 25, 3]`` positions in metres, in the frame ``root_rot`` / ``root_pos`` live in.
    """
    T = local_rot.shape[0]
    glob = np.empty((T, NUM_JOINTS, 3, 3))
    pos = np.empty((T, NUM_JOINTS, 3))
    root = TOPO_ORDER[0]
    rr = np.broadcast_to(np.eye(3), (T, 3, 3)) if root_rot is None else root_rot
    glob[:, root] = rr @ local_rot[:, root]
    pos[:, root] = 0.0 if root_pos is None else root_pos
    parents = NTU25.parents
    for c in TOPO_ORDER[1:]:
        p = parents[c]
        glob[:, c] = glob[:, p] @ local_rot[:, c]
        pos[:, c] = pos[:, p] + glob[:, c] @ offsets[c]
    return pos
