"""The tracker's articulated body: 15 bones, 34 degrees of freedom (Lou 2012 §3.2), forward kinematics in PyTorch,
capsule surfaces, and inverse kinematics onto joint positions.

**Bones and DOF** (the thesis gives neither the bone list nor the parameterisation, digest §4 item 14; ours). The
16 joints are :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS`; each bone runs from one joint to the next and
turns with its parent bone:

==============  ===========================  ==========  ==============================================
bone            joints                       DOF         rotation (axes of the parent bone's frame)
==============  ===========================  ==========  ==============================================
(root)          —                            0–5         translation (m) and rotation vector
lower_back      HipCenter → Spine            6–8         ball (rotation vector)
chest           Spine → ShoulderCenter       9–11        ball
head            ShoulderCenter → Head        12–13       x (nod), z (tilt)
l_clavicle      ShoulderCenter → l_shoulder  14–15       y (forward/back), z (up/down)
l_upper_arm     l_shoulder → l_elbow         16–18       ball
l_forearm       l_elbow → l_wrist            19          x (hinge)
r_clavicle      ShoulderCenter → r_shoulder  20–21       y, z
r_upper_arm     r_shoulder → r_elbow         22–24       ball
r_forearm       r_elbow → r_wrist            25          x (hinge)
l_pelvis        HipCenter → l_hip            —           rigid with the root
l_thigh         l_hip → l_knee               26–28       ball
l_shin          l_knee → l_ankle             29          x (hinge)
r_pelvis        HipCenter → r_hip            —           rigid
r_thigh         r_hip → r_knee               30–32       ball
r_shin          r_knee → r_ankle             33          x (hinge)
==============  ===========================  ==========  ==============================================

6 root + 28 joint DOF = 34. A rotation is a rotation vector (axis × angle, radians) whose unused components are 0;
the rest pose (all joint DOF 0) stands upright with the arms down, the body's frame x = left, y = up, z = forward.
A bone's world rotation is its parent's times its own; its end joint is its start joint plus the rotation applied
to ``length × rest direction``. Hinges bend about the parent bone's x axis, which the ball joint above turns, so an
elbow or knee bends in any plane the shoulder or hip chooses.

**From a mocap skeleton (the thesis's "62 → 34 DOF" preprocessing, unspecified):** the 16 joints of the
Kinect-20 landmarks of any mocap layout; bone lengths are the median lengths over the take
(:func:`skeleton_from_joints`), and :func:`fit_pose` finds the DOF whose joints are nearest (least squares,
Gauss–Newton, batched over frames).

**Surface:** one capsule per bone (:data:`CAPSULE_RADII`, metres for a 1.75 m person, scaled with the stature):
the head is a capsule from ShoulderCenter whose end sphere is the skull, the trunk two capsules, clavicle and
pelvis capsules fill the shoulders and hips. No hands or feet: the thesis's model has none either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from mocapkit.depth_tracking.base import TRACKED_JOINTS

_J = {name: k for k, name in enumerate(TRACKED_JOINTS)}


@dataclass(frozen=True)
class Bone:
    """One bone: its parent bone (−1: the root), start and end joint (indices of TRACKED_JOINTS), rest direction
    in the parent's frame, and the axes its DOF turn about (``""``: rigid)."""

    name: str
    parent: int
    start: int
    end: int
    rest: tuple[float, float, float]
    axes: str


_DOWN, _UP = (0.0, -1.0, 0.0), (0.0, 1.0, 0.0)
BONES: tuple[Bone, ...] = (
    Bone("lower_back", -1, _J["pelvis"], _J["spine"], _UP, "xyz"),
    Bone("chest", 0, _J["spine"], _J["neck"], _UP, "xyz"),
    Bone("head", 1, _J["neck"], _J["head"], _UP, "xz"),
    Bone("l_clavicle", 1, _J["neck"], _J["l_shoulder"], (1.0, 0.0, 0.0), "yz"),
    Bone("l_upper_arm", 3, _J["l_shoulder"], _J["l_elbow"], _DOWN, "xyz"),
    Bone("l_forearm", 4, _J["l_elbow"], _J["l_wrist"], _DOWN, "x"),
    Bone("r_clavicle", 1, _J["neck"], _J["r_shoulder"], (-1.0, 0.0, 0.0), "yz"),
    Bone("r_upper_arm", 6, _J["r_shoulder"], _J["r_elbow"], _DOWN, "xyz"),
    Bone("r_forearm", 7, _J["r_elbow"], _J["r_wrist"], _DOWN, "x"),
    Bone("l_pelvis", -1, _J["pelvis"], _J["l_hip"], (1.0, -0.5, 0.0), ""),
    Bone("l_thigh", 9, _J["l_hip"], _J["l_knee"], _DOWN, "xyz"),
    Bone("l_shin", 10, _J["l_knee"], _J["l_ankle"], _DOWN, "x"),
    Bone("r_pelvis", -1, _J["pelvis"], _J["r_hip"], (-1.0, -0.5, 0.0), ""),
    Bone("r_thigh", 12, _J["r_hip"], _J["r_knee"], _DOWN, "xyz"),
    Bone("r_shin", 13, _J["r_knee"], _J["r_ankle"], _DOWN, "x"),
)
NUM_BONES = len(BONES)
ROOT_DOF = 6
NUM_DOF = ROOT_DOF + sum(len(b.axes) for b in BONES)
#: First DOF index of each bone (its DOF are consecutive), −1 for rigid bones.
_DOF_START = []
_k = ROOT_DOF
for _b in BONES:
    _DOF_START.append(_k if _b.axes else -1)
    _k += len(_b.axes)
del _k, _b
#: Capsule radius of each bone, metres, for a 1.75 m person (the Kinect simulator's body, kinect_noise.CAPSULES).
CAPSULE_RADII: dict[str, float] = {
    "lower_back": 0.13,
    "chest": 0.11,
    "head": 0.09,
    "l_clavicle": 0.07,
    "l_upper_arm": 0.05,
    "l_forearm": 0.04,
    "r_clavicle": 0.07,
    "r_upper_arm": 0.05,
    "r_forearm": 0.04,
    "l_pelvis": 0.09,
    "l_thigh": 0.075,
    "l_shin": 0.055,
    "r_pelvis": 0.09,
    "r_thigh": 0.075,
    "r_shin": 0.055,
}
#: The five joints of the thesis's initialisation (§3.2.3): head, wrists, ankles.
INIT_JOINTS = tuple(_J[name] for name in ("head", "l_wrist", "r_wrist", "l_ankle", "r_ankle"))
assert NUM_DOF == 34


@dataclass(frozen=True)
class Skeleton:
    """A performer's body: bone lengths ``[15]`` (m), rest directions ``[15, 3]`` (unit, parent frame) and capsule
    radii ``[15]`` (m)."""

    lengths: np.ndarray
    rest: np.ndarray
    radii: np.ndarray

    @property
    def stature(self) -> float:
        """Approximate standing height (m): ankle → hip → HipCenter → Spine → ShoulderCenter → head + the skull."""
        by = {b.name: length for b, length in zip(BONES, self.lengths)}
        return float(
            by["l_shin"] + by["l_thigh"] + by["lower_back"] + by["chest"] + by["head"] + 0.5 * by["l_pelvis"] + 0.15
        )

    def tensors(self, device=None, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(offsets [15, 3], radii [15])`` as tensors: offset = length × rest direction, in the parent frame."""
        offsets = torch.as_tensor(self.lengths[:, None] * self.rest, dtype=dtype, device=device)
        return offsets, torch.as_tensor(self.radii, dtype=dtype, device=device)


def skeleton_from_joints(joints: np.ndarray, girth: float = 1.0) -> Skeleton:
    """The performer's :class:`Skeleton` from the 16 joints of a take ``[T, 16, 3]`` (metres): median bone lengths;
    the pelvis bones' rest direction from the median hip drop; capsule radii scaled with the stature (× ``girth``)."""
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (len(TRACKED_JOINTS), 3) or len(joints) == 0:
        raise ValueError(f"joints must be [T, {len(TRACKED_JOINTS)}, 3] metres, got {list(joints.shape)}")
    lengths = np.array([np.median(np.linalg.norm(joints[:, b.end] - joints[:, b.start], axis=-1)) for b in BONES])
    rest = np.array([b.rest for b in BONES], dtype=np.float64)
    # hips: half the hip width sideways, the hip centre's drop below HipCenter downwards
    mid = 0.5 * (joints[:, _J["l_hip"]] + joints[:, _J["r_hip"]])
    half_width = 0.5 * np.median(np.linalg.norm(joints[:, _J["l_hip"]] - joints[:, _J["r_hip"]], axis=-1))
    drop = np.median(np.linalg.norm(mid - joints[:, _J["pelvis"]], axis=-1))
    for k, b in enumerate(BONES):
        if b.name in ("l_pelvis", "r_pelvis"):
            side = 1.0 if b.name == "l_pelvis" else -1.0
            rest[k] = np.array([side * half_width, -drop, 0.0]) / max(np.hypot(half_width, drop), 1e-9)
    skeleton = Skeleton(lengths, rest, np.ones(NUM_BONES))
    scale = girth * skeleton.stature / 1.75
    radii = np.array([CAPSULE_RADII[b.name] for b in BONES]) * scale
    return Skeleton(lengths, rest, radii)


def template_skeleton() -> Skeleton:
    """The :data:`~mocapkit.motion.geometry.TEMPLATE_BONES` body (about 1.7 m tall), for depth without a skeleton."""
    from mocapkit.motion.geometry import TEMPLATE_BONES

    joints = np.zeros((1, len(TRACKED_JOINTS), 3))
    for bone in BONES:
        rest = np.asarray(bone.rest) / np.linalg.norm(bone.rest)
        joints[0, bone.end] = joints[0, bone.start] + TEMPLATE_BONES[TRACKED_JOINTS[bone.end]] * rest
    return skeleton_from_joints(joints)


def rotation_matrices(rotvec: torch.Tensor) -> torch.Tensor:
    """Rotation vectors ``[..., 3]`` (radians) → matrices ``[..., 3, 3]`` (Rodrigues; smooth at 0 for autograd)."""
    theta2 = (rotvec * rotvec).sum(-1, keepdim=True)[..., None]  # [..., 1, 1]
    theta = torch.sqrt(theta2 + 1e-12)
    small = theta2 < 1e-8
    # sin θ / θ and (1 − cos θ) / θ², with their Taylor series near 0
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / (theta2 + 1e-12))
    x, y, z = rotvec.unbind(-1)
    zero = torch.zeros_like(x)
    k = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).reshape(*rotvec.shape[:-1], 3, 3)
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device).expand_as(k)
    return eye + a * k + b * (k @ k)


_AXIS = {"x": 0, "y": 1, "z": 2}


def _bone_rotvec(q: torch.Tensor, k: int) -> torch.Tensor | None:
    """The rotation vector ``[..., 3]`` of bone ``k``'s own DOF, None for a rigid bone."""
    bone = BONES[k]
    if not bone.axes:
        return None
    start = _DOF_START[k]
    parts = [torch.zeros_like(q[..., 0])] * 3
    for i, axis in enumerate(bone.axes):
        parts[_AXIS[axis]] = q[..., start + i]
    return torch.stack(parts, dim=-1)


def forward_kinematics(q: torch.Tensor, offsets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Joints and bone frames of poses ``q`` ``[..., 34]``.

    Args:
        q: DOF (module table): root translation (m), root rotation vector, joint rotations (radians).
        offsets: ``[15, 3]`` each bone's length × rest direction (:meth:`Skeleton.tensors`).

    Returns:
        ``(joints [..., 16, 3], rotations [..., 15, 3, 3])``: joint positions (the root translation is HipCenter)
        and each bone's world rotation.
    """
    root_r = rotation_matrices(q[..., 3:6])
    joints: list[torch.Tensor | None] = [None] * len(TRACKED_JOINTS)
    joints[_J["pelvis"]] = q[..., 0:3]
    rotations: list[torch.Tensor] = []
    for k, bone in enumerate(BONES):
        parent_r = root_r if bone.parent < 0 else rotations[bone.parent]
        own = _bone_rotvec(q, k)
        r = parent_r if own is None else parent_r @ rotation_matrices(own)
        rotations.append(r)
        joints[bone.end] = joints[bone.start] + (r @ offsets[k, :, None])[..., 0]
    return torch.stack(joints, dim=-2), torch.stack(rotations, dim=-3)


def _skew(v: torch.Tensor) -> torch.Tensor:
    """``[..., 3]`` → the cross-product matrices ``[..., 3, 3]``."""
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).reshape(*v.shape[:-1], 3, 3)


def rotation_derivatives(rotvec: torch.Tensor, rotation: torch.Tensor) -> torch.Tensor:
    """``∂R/∂v_i`` ``[..., 3, 3, 3]`` (i first) of ``R = rotation_matrices(v)``, Gallego & Yezzi 2015 eq. 9:
    ``([v]× v_i + [v × (I − R) e_i]×) R / ‖v‖²``; ``[e_i]×`` at v = 0."""
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    theta2 = (rotvec * rotvec).sum(-1)[..., None, None, None]  # [..., 1, 1, 1]
    columns = (eye - rotation).transpose(-1, -2)  # row i = (I − R) e_i
    cross = torch.cross(rotvec[..., None, :].expand_as(columns), columns, dim=-1)  # [..., 3(i), 3]
    general = (rotvec[..., :, None, None] * _skew(rotvec)[..., None, :, :] + _skew(cross)) @ rotation[..., None, :, :]
    general = general / theta2.clamp_min(1e-12)
    small = _skew(eye).expand_as(general)
    return torch.where(theta2 < 1e-10, small, general)


def forward_kinematics_jacobian(
    q: torch.Tensor, offsets: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`forward_kinematics` of poses ``q`` ``[B, 34]`` with its exact derivatives (chain rule down the bone
    tree; far cheaper than autodiff through the 15 rotations).

    Returns:
        ``(joints [B, 16, 3], rotations [B, 15, 3, 3], d_joints [B, 34, 16, 3], d_rotations [B, 34, 15, 3, 3])``.
    """
    batch = q.shape[0]
    eye = torch.eye(3, dtype=q.dtype, device=q.device)
    root_r = rotation_matrices(q[:, 3:6])
    d_root = torch.zeros(batch, NUM_DOF, 3, 3, dtype=q.dtype, device=q.device)
    d_root[:, 3:6] = rotation_derivatives(q[:, 3:6], root_r)
    joints: list[torch.Tensor | None] = [None] * len(TRACKED_JOINTS)
    d_joints: list[torch.Tensor | None] = [None] * len(TRACKED_JOINTS)
    pelvis = _J["pelvis"]
    joints[pelvis] = q[:, 0:3]
    d_pelvis = torch.zeros(batch, NUM_DOF, 3, dtype=q.dtype, device=q.device)
    d_pelvis[:, 0:3] = eye
    d_joints[pelvis] = d_pelvis
    rotations: list[torch.Tensor] = []
    d_rotations: list[torch.Tensor] = []
    for k, bone in enumerate(BONES):
        parent_r = root_r if bone.parent < 0 else rotations[bone.parent]
        d_parent = d_root if bone.parent < 0 else d_rotations[bone.parent]
        own = _bone_rotvec(q, k)
        if own is None:
            r, d_r = parent_r, d_parent
        else:
            m = rotation_matrices(own)
            d_m = rotation_derivatives(own, m)  # [B, 3, 3, 3]
            r = parent_r @ m
            d_r = d_parent @ m[:, None]
            start = _DOF_START[k]
            for i, axis in enumerate(bone.axes):
                d_r[:, start + i] = d_r[:, start + i] + parent_r @ d_m[:, _AXIS[axis]]
        rotations.append(r)
        d_rotations.append(d_r)
        joints[bone.end] = joints[bone.start] + (r @ offsets[k, :, None])[..., 0]
        d_joints[bone.end] = d_joints[bone.start] + (d_r @ offsets[k, :, None])[..., 0]
    return (
        torch.stack(joints, dim=1),
        torch.stack(rotations, dim=1),
        torch.stack(d_joints, dim=2),
        torch.stack(d_rotations, dim=2),
    )


def body_points_jacobian(
    q: torch.Tensor, offsets: torch.Tensor, bone: torch.Tensor, local: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`body_points` at one pose ``q`` ``[34]`` and its Jacobian: ``(points [N, 3], J [N, 3, 34])``."""
    joints, rotations, d_joints, d_rotations = forward_kinematics_jacobian(q[None], offsets)
    start = torch.tensor([b.start for b in BONES], device=q.device)[bone]
    points = joints[0, start] + (rotations[0, bone] @ local[:, :, None])[:, :, 0]
    jac = d_joints[0][:, start] + (d_rotations[0][:, bone] @ local[None, :, :, None])[..., 0]  # [34, N, 3]
    return points, jac.permute(1, 2, 0)


def capsules(joints: torch.Tensor, radii: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The body's capsules at ``joints`` ``[16, 3]``: ``(a [15, 3], b [15, 3], radius [15])``, bone order."""
    start = torch.tensor([b.start for b in BONES], device=joints.device)
    end = torch.tensor([b.end for b in BONES], device=joints.device)
    return joints[start], joints[end], radii


def body_points(q: torch.Tensor, offsets: torch.Tensor, bone: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
    """World positions ``[N, 3]`` of body-attached points: point ``i`` sits at ``local[i]`` in bone ``bone[i]``'s
    frame, relative to the bone's start joint (the thesis's ``f(a_i; q)``)."""
    joints, rotations = forward_kinematics(q, offsets)
    start = torch.tensor([b.start for b in BONES], device=q.device)[bone]
    return joints[start] + (rotations[bone] @ local[:, :, None])[:, :, 0]


def local_coordinates(
    points: torch.Tensor, bone: torch.Tensor, joints: torch.Tensor, rotations: torch.Tensor
) -> torch.Tensor:
    """Inverse of :func:`body_points` at one pose: ``[N, 3]`` world points on bones ``bone`` → bone-frame offsets."""
    start = torch.tensor([b.start for b in BONES], device=points.device)[bone]
    return (rotations[bone].transpose(-1, -2) @ (points - joints[start])[:, :, None])[:, :, 0]


def root_pose(joints: np.ndarray) -> np.ndarray:
    """Root translation and rotation ``[..., 6]`` that put the rest body's pelvis on ``joints`` ``[..., 16, 3]``:
    HipCenter, with x along the hip line (right → left hip) and y along HipCenter → ShoulderCenter made
    orthogonal to it."""
    from scipy.spatial.transform import Rotation

    joints = np.asarray(joints, dtype=np.float64)
    x = joints[..., _J["l_hip"], :] - joints[..., _J["r_hip"], :]
    x /= np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-9)
    up = joints[..., _J["neck"], :] - joints[..., _J["pelvis"], :]
    y = up - (up * x).sum(-1, keepdims=True) * x
    y /= np.maximum(np.linalg.norm(y, axis=-1, keepdims=True), 1e-9)
    z = np.cross(x, y)
    matrix = np.stack([x, y, z], axis=-1)  # columns: the body axes in world coordinates
    rotvec = Rotation.from_matrix(matrix.reshape(-1, 3, 3)).as_rotvec().reshape(*matrix.shape[:-2], 3)
    return np.concatenate([joints[..., _J["pelvis"], :], rotvec], axis=-1)


def fit_pose(
    targets: torch.Tensor,
    offsets: torch.Tensor,
    q0: torch.Tensor,
    joint_weights: torch.Tensor | None = None,
    iterations: int = 30,
    damping: float = 1e-3,
    prior_weight: float = 0.0,
) -> torch.Tensor:
    """Inverse kinematics: poses ``[B, 34]`` whose joints are nearest ``targets`` ``[B, 16, 3]`` (least squares,
    Levenberg-damped Gauss–Newton from ``q0`` ``[B, 34]``, batched).

    Args:
        joint_weights: ``[16]`` weight of each joint (0: ignored; the initialisation uses the 5 INIT_JOINTS).
        damping: λ of ``(JᵀJ + λI) Δq = Jᵀr``; also keeps the unobserved DOF (a straight limb's twist) still.
        prior_weight: pulls the joint DOF towards 0 (the rest pose), for under-determined fits such as 5 joints.
    """
    weights = torch.ones(targets.shape[-2], dtype=targets.dtype, device=targets.device)
    if joint_weights is not None:
        weights = joint_weights.to(targets)
    w = weights.repeat_interleave(3).sqrt()  # [48]

    q = q0.clone()
    eye = torch.eye(NUM_DOF, dtype=torch.float64, device=q.device)
    reg = torch.zeros(NUM_DOF, dtype=torch.float64, device=q.device)
    reg[ROOT_DOF:] = prior_weight
    for _ in range(iterations):
        joints, _, d_joints, _ = forward_kinematics_jacobian(q, offsets)
        r = (targets - joints).reshape(len(q), -1) * w  # [B, 48]
        jac = d_joints.reshape(len(q), NUM_DOF, -1).transpose(1, 2) * w[:, None]  # [B, 48, 34]
        jt = jac.transpose(1, 2).double()
        a = jt @ jac.double() + damping * eye + torch.diag(reg)
        b = (jt @ r.double()[:, :, None])[:, :, 0] - reg * q.double()
        step = torch.linalg.solve(a, b).to(q.dtype)
        q = q + step
        if float(step.abs().max()) < 1e-6:
            break
    return q


__all__ = [
    "BONES",
    "CAPSULE_RADII",
    "INIT_JOINTS",
    "NUM_BONES",
    "NUM_DOF",
    "ROOT_DOF",
    "Bone",
    "Skeleton",
    "body_points",
    "body_points_jacobian",
    "capsules",
    "fit_pose",
    "forward_kinematics",
    "forward_kinematics_jacobian",
    "local_coordinates",
    "root_pose",
    "rotation_matrices",
    "skeleton_from_joints",
    "template_skeleton",
]
