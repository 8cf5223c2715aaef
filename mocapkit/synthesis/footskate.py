"""Footskate cleanup of synthesised AMC motion: detect foot contacts, pin the feet with two-bone leg IK.

Zhou 2014 ch. 4 §3.6 step 4 post-processes variants with an unspecified blending technique or "automatic
footskate cleanup"; gap 19 (../shared/spec/thesis-zhou-2014-retrieval-synthesis.md) asks for contact detection by
foot height and speed thresholds and pinning with two-bone IK, kept optional. This module does exactly that, on
AMC values (so the result is still a valid AMC motion on the same skeleton):

1. **Legs**: the first two bones with dofs of the ``RL`` and ``LL`` partitions
   (:func:`~mocapkit.synthesis.representation.partitions`), the thigh (hip → knee) and the shin (knee → ankle,
   CMU/HDM05 ``femur``/``tibia``). The shin must be a one-dof hinge (HDM05/CMU ``tibia rx``); a leg without one
   is left alone and reported.
2. **Contacts** (:func:`detect_contacts`): frames where the ankle (the end of the shin) is within
   ``height_tolerance`` metres of the floor (given, or the lowest ankle height of the clip over both legs) and its
   moving-average path moves slower than ``speed_threshold`` m/s; runs shorter than ``min_contact_frames`` are
   dropped.
3. **Targets**: during a contact run the ankle is pinned at its mean position over the run; over
   ``blend_frames`` frames before and after, the target blends linearly back to the unmodified ankle.
4. **Two-bone IK** per frame with a target: the knee hinge angle is solved in closed form so that the hip–ankle
   distance equals the hip–target distance (clamped to what the bone lengths reach), then the thigh is turned
   about the hip by the smallest rotation that points the ankle at the target. Only the thigh's and the shin's
   AMC values change; the foot keeps its angles relative to the shin.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import AsfSkeleton, forward_kinematics
from mocapkit.synthesis.representation import dof_axes, euler_near, partitions


@dataclass
class FootskateReport:
    """What :func:`cleanup_footskate` did.

    Attributes:
        contacts: per cleaned leg (its thigh bone name) a bool ``[T]`` contact mask.
        sliding_before: mean horizontal ankle speed during contacts before the cleanup, m/s (NaN without contacts).
        sliding_after: the same after the cleanup.
        skipped_legs: legs left alone (no one-dof shin), with the reason.
    """

    contacts: dict[str, np.ndarray]
    sliding_before: float
    sliding_after: float
    skipped_legs: list[str]


def detect_contacts(ankle: np.ndarray, fps: float, floor: float, height_tolerance: float = 0.05,
                    speed_threshold: float = 1.0, min_contact_frames: int = 3, smoothing_frames: int = 9
                    ) -> np.ndarray:
    """bool ``[T]``: the frames where a foot is planted.

    Args:
        ankle: float64 ``[T, 3]`` ankle positions, metres, ``y`` up.
        fps: frames per second.
        floor: floor height, metres.
        height_tolerance: the ankle is at most this far above ``floor`` (metres).
        speed_threshold: and moves slower than this (m/s, central differences of the ankle path averaged over
            ``smoothing_frames`` frames, so that frame-to-frame jitter of sampled motion does not hide a plant).
        min_contact_frames: shorter runs are not contacts.
    """
    if len(ankle) > 1:
        width = min(smoothing_frames, len(ankle))
        kernel = np.ones(width) / width
        padded = np.pad(ankle, ((width // 2, width - 1 - width // 2), (0, 0)), mode="edge")
        smooth = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(3)], axis=1)
        speed = np.linalg.norm(np.gradient(smooth, axis=0), axis=1) * fps
    else:
        speed = np.zeros(len(ankle))
    contact = (ankle[:, 1] < floor + height_tolerance) & (speed < speed_threshold)
    for start, stop in _runs(contact):
        if stop - start < min_contact_frames:
            contact[start:stop] = False
    return contact


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of each run of True."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _pin_targets(ankle: np.ndarray, contact: np.ndarray, blend_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Ankle targets ``[T, 3]`` and their weights ``[T]`` (1 in contacts, linear ramps ``blend_frames`` long)."""
    T = len(ankle)
    weight = np.zeros(T)
    pin = ankle.copy()
    for start, stop in _runs(contact):
        point = ankle[start:stop].mean(axis=0)
        lo, hi = max(0, start - blend_frames), min(T, stop + blend_frames)
        for t in range(lo, hi):
            w = 1.0 if start <= t < stop else 1.0 - (start - t if t < start else t - stop + 1) / (blend_frames + 1)
            if w > weight[t]:
                weight[t] = w
                pin[t] = point
    return ankle + weight[:, None] * (pin - ankle), weight


def _global_rotations(skeleton: AsfSkeleton, local: np.ndarray) -> np.ndarray:
    """``[T, J, 3, 3]`` global rotations from the local ones of :func:`forward_kinematics`."""
    glob = local.copy()
    index = {name: j for j, name in enumerate(skeleton.joint_names)}
    frontier = ["root"]
    for parent in frontier:  # breadth first: every parent before its children
        for child in skeleton.hierarchy.get(parent, []):
            glob[:, index[child]] = glob[:, index[parent]] @ local[:, index[child]]
            frontier.append(child)
    return glob


def _bone_frame(skeleton: AsfSkeleton, bone: str) -> np.ndarray:
    """The 3×3 bone frame ``C`` of ``bone``."""
    b = skeleton.bone(bone)
    axis = np.asarray(b.axis, dtype=np.float64)
    if skeleton.angle_unit == "deg":
        axis = np.radians(axis)
    return Rotation.from_euler(b.axis_order.lower(), axis).as_matrix()


def _hinge_angle(h: np.ndarray, w: np.ndarray, axis: np.ndarray, target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """The hinge angles ``[T]`` (radians) with ``hᵀ R_axis(θ) w == target`` (as near as reachable), nearest
    ``current``; ``h, w`` are ``[T, 3]``, ``axis`` a unit ``[3]``.

    ``R_axis(θ) w = w_par + cos θ w_perp + sin θ (axis × w)``, so ``hᵀ R w = c + a cos θ + b sin θ``.
    """
    w_par = (w @ axis)[:, None] * axis
    w_perp = w - w_par
    c = np.sum(h * w_par, axis=-1)
    a = np.sum(h * w_perp, axis=-1)
    b = np.sum(h * np.cross(axis, w), axis=-1)
    rho = np.hypot(a, b)
    phase = np.arctan2(b, a)
    spread = np.arccos(np.clip((target - c) / np.maximum(rho, 1e-12), -1.0, 1.0))
    candidates = np.stack([phase + spread, phase - spread], axis=1)
    delta = np.angle(np.exp(1j * (candidates - current[:, None])))
    return current + delta[np.arange(len(current)), np.argmin(np.abs(delta), axis=1)]


def _minimal_rotation(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``[T, 3, 3]``: the smallest rotation turning each ``u`` towards ``v`` (``[T, 3]``)."""
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    cross = np.cross(u, v)
    sin = np.linalg.norm(cross, axis=1)
    angle = np.arctan2(sin, np.sum(u * v, axis=1))
    axis = np.where(sin[:, None] > 1e-12, cross / np.maximum(sin, 1e-12)[:, None], 0.0)
    return Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


def _sliding(ankles: list[np.ndarray], contacts: list[np.ndarray], fps: float) -> float:
    speeds = [np.linalg.norm(np.gradient(a[:, [0, 2]], axis=0), axis=1)[c] * fps
              for a, c in zip(ankles, contacts) if c.any() and len(a) > 1]
    return float(np.mean(np.concatenate(speeds))) if speeds else float("nan")


def cleanup_footskate(values: dict[str, np.ndarray], skeleton: AsfSkeleton, fps: float, floor: float | None = None,
                      height_tolerance: float = 0.05, speed_threshold: float = 1.0, min_contact_frames: int = 3,
                      blend_frames: int = 6) -> tuple[dict[str, np.ndarray], FootskateReport]:
    """Pin planted feet (module docstring).

    Args:
        values: AMC values, bone → float64 ``[T, len(dof)]`` (degrees; root translation in ASF units).
        skeleton: their skeleton.
        fps: frames per second.
        floor: the ankle height (metres) of a planted foot; default: the lowest ankle height of the clip over both
            legs (a synthesiser passes its training clips' value, which one low sampled frame cannot move).
        height_tolerance, speed_threshold, min_contact_frames: contact detection (:func:`detect_contacts`).
        blend_frames: frames over which a pin fades in before and out after a contact.

    Returns:
        The cleaned values (a new dict; only the legs' thigh and shin values change) and a
        :class:`FootskateReport`.
    """
    out = {bone: np.array(v, dtype=np.float64) for bone, v in values.items()}
    positions, local = forward_kinematics(skeleton, out)
    index = {name: j for j, name in enumerate(skeleton.joint_names)}
    parts = partitions(skeleton)
    legs, skipped = [], []
    for name in ("LL", "RL"):
        chain = parts[name]
        if len(chain) < 2 or skeleton.parent_names.get(chain[1]) != chain[0] or len(skeleton.bone(chain[1]).dof) != 1:
            skipped.append(f"{name}: needs a thigh and a one-dof shin below it, has {list(chain[:2])}")
            continue
        legs.append((chain[0], chain[1]))
    if not legs:
        return out, FootskateReport({}, float("nan"), float("nan"), skipped)
    if floor is None:
        floor = min(float(positions[:, index[shin], 1].min()) for _, shin in legs)
    glob = _global_rotations(skeleton, local)
    offsets = skeleton.offsets()
    contacts, before, after = {}, [], []
    for thigh, shin in legs:
        j_thigh, j_shin = index[thigh], index[shin]
        j_hip = skeleton.parents[j_thigh]
        ankle = positions[:, j_shin].astype(np.float64)
        contact = detect_contacts(ankle, fps, floor, height_tolerance, speed_threshold, min_contact_frames)
        contacts[thigh] = contact
        before.append(ankle)
        after.append(ankle.copy())
        target, weight = _pin_targets(ankle, contact, blend_frames)
        frames = np.flatnonzero(weight > 0)
        if len(frames) == 0:
            continue
        hip, knee = positions[frames, j_hip], positions[frames, j_thigh]
        # knee: hinge angle giving |ankle - hip| == |target - hip|
        c_shin = _bone_frame(skeleton, shin)
        hinge_axis = np.eye(3)["xyz".index(dof_axes(skeleton.bone(shin).dof))]
        frame_shin = glob[frames, j_thigh] @ c_shin                       # G: shin offset = G · R(θ) · w
        w = c_shin.T @ offsets[j_shin]
        l_thigh, l_shin = np.linalg.norm(offsets[j_thigh]), np.linalg.norm(offsets[j_shin])
        reach = np.clip(np.linalg.norm(target[frames] - hip, axis=1), abs(l_thigh - l_shin) + 1e-6,
                        l_thigh + l_shin - 1e-6)
        h = np.einsum("tji,tj->ti", frame_shin, knee - hip)               # Gᵀ (knee - hip)
        theta = _hinge_angle(h, np.tile(w, (len(frames), 1)), hinge_axis, (reach**2 - l_thigh**2 - l_shin**2) / 2,
                             np.radians(out[shin][frames, 0]))
        out[shin][frames, 0] = np.degrees(theta)
        bent = Rotation.from_rotvec(theta[:, None] * hinge_axis).apply(np.tile(w, (len(frames), 1)))
        new_ankle = knee + np.einsum("tij,tj->ti", frame_shin, bent)
        # thigh: turn about the hip so the ankle points at the target
        turn = _minimal_rotation(new_ankle - hip, target[frames] - hip)
        after[-1][frames] = hip + np.einsum("tij,tj->ti", turn, new_ankle - hip)
        thigh_global = turn @ glob[frames, j_thigh]
        c_thigh = _bone_frame(skeleton, thigh)
        m_thigh = c_thigh.T @ np.swapaxes(glob[frames, j_hip], 1, 2) @ thigh_global @ c_thigh
        axes = dof_axes(skeleton.bone(thigh).dof)
        out[thigh][frames] = np.degrees(euler_near(Rotation.from_matrix(m_thigh), axes,
                                                   np.radians(out[thigh][frames])))
    masks = [contacts[thigh] for thigh, _ in legs]
    return out, FootskateReport(contacts, _sliding(before, masks, fps), _sliding(after, masks, fps), skipped)
