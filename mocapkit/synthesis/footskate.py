"""Footskate cleanup of synthesised AMC motion: find the stances, ground the feet and halt them by moving the
root, pin what is left with two-bone leg IK.

Zhou 2014 ch. 4 §3.6 step 4 post-processes variants with an unspecified blending technique or "automatic
footskate cleanup"; gap 19 (../shared/spec/thesis-zhou-2014-retrieval-synthesis.md) asks for contact detection by
foot height and speed thresholds and pinning with two-bone IK, kept optional. This module does that, on AMC
values (so the result is still a valid AMC motion on the same skeleton):

1. **Legs**: the first two bones with dofs of the ``RL`` and ``LL`` partitions
   (:func:`~mocapkit.synthesis.representation.partitions`), the thigh (hip → knee) and the shin (knee → ankle,
   CMU/HDM05 ``femur``/``tibia``). The shin is a one-dof hinge (HDM05/CMU ``tibia rx``) or a three-dof joint
   (BVH rigs converted by :mod:`mocapkit.datasets.formats.bvh_to_amc`); a leg with neither is left alone and
   reported.
2. **Contacts** (:func:`detect_contacts`): runs of frames where the ankle (the end of the shin) barely moves
   vertically, near the lowest point of the run, when that point is low (within ``max_height`` of the floor).
   Sampled variants float above the floor or sink into it by centimetres and their planted feet slide, so
   neither the floor height nor the horizontal speed can tell a stance.
3. **Root** (:func:`root_shift`, ``move_root``): the root is lowered or raised so that each stance stands on
   the floor, and (``"stance"``, the default, and ``"full"``) its horizontal step loses the planted feet's step,
   so the body moves over a still foot instead of the foot sliding under the body: over the contacts' own steps
   (``"stance"``) or also over the blend ramps around them, where the foot lands and lifts off (``"full"``, the
   former default, which slows real clips down: :func:`root_shift`).
4. **Targets**: during a contact run the ankle is pinned at its mean horizontal position over the run, on the
   floor; over ``blend_frames`` frames before and after, the target blends linearly back to the free ankle.
5. **Two-bone IK** per frame with a target: the knee hinge angle is solved in closed form so that the hip–ankle
   distance equals the hip–target distance (clamped to what the bone lengths reach; a three-dof knee turns
   about the normal of its leg's plane, keeping its twist and splay), then the thigh is turned
   about the hip by the smallest rotation that points the ankle at the target. Only the root's translation and
   the thigh's and the shin's AMC values change; the foot keeps its angles relative to the shin.

Why the root moves: a generator samples the body's travel and the legs' swing as different outputs (SLFM's
literal model even in partitions of their own, gap 17), so the legs' stance need not follow the travel; on HDM05
jogs the planted ankles of the literal model's variants slid at 1.65 m/s. Pinning them with the IK alone
stretches the legs against the travel (jerk 2.4× the training clips'); halting them through the root lets the
feet set the travel instead, at the price of a travel speed that is the legs' and not the sampled one. The
numbers behind the defaults are in :func:`cleanup_footskate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import AsfSkeleton, forward_kinematics
from mocapkit.motion.frames import true_runs
from mocapkit.synthesis.representation import dof_axes, euler_near, partitions

#: The ways :func:`cleanup_footskate` may move the root (its ``move_root``).
ROOT_MOVES = ("full", "stance", "vertical", "none")
#: The ``footskate_root`` of every generator (:class:`~mocapkit.synthesis.base.MotionSynthesizer`) unless set:
#: ``"stance"``, which keeps more of a real clip's travel than ``"full"``. Chosen on training clips only
#: (``scripts/selection/select_synthesis_defaults.py --param footskate_root full stance``); the rule and the
#: numbers: docs/decisions.md#synthesis-footskate-root.
DEFAULT_ROOT_MOVE = "stance"


@dataclass
class FootskateReport:
    """What :func:`cleanup_footskate` did.

    Attributes:
        contacts: per cleaned leg (its thigh bone name) a bool ``[T]`` contact mask.
        sliding_before: mean horizontal ankle speed during contacts before the cleanup, m/s (NaN without contacts).
        sliding_after: the same after the cleanup.
        skipped_legs: legs left alone (no one- or three-dof shin), with the reason.
        root_shift: float64 ``[T, 3]`` metres added to the root's position (:func:`root_shift`; zeros when the
            root was not moved).
    """

    contacts: dict[str, np.ndarray]
    sliding_before: float
    sliding_after: float
    skipped_legs: list[str]
    root_shift: np.ndarray


def planted_ankle_height(clips) -> float | None:
    """The floor of :func:`cleanup_footskate` from real clips: the mean over ``clips`` (AMC
    :class:`~mocapkit.motion.container.Motion`, ``metadata["asf"]`` their skeleton) of each clip's lowest
    ankle height over both legs, metres; None when the skeleton has no legs (``LL``/``RL`` partitions with a
    shin)."""
    skeleton = clips[0].metadata["asf"]
    shins = [part[1] for name, part in partitions(skeleton).items() if name in ("LL", "RL") and len(part) > 1]
    if not shins:
        return None
    ankles = [skeleton.joint_names.index(shin) for shin in shins]
    return float(np.mean([clip.positions[:, ankles, 1].min() for clip in clips]))


def _smoothed(signal: np.ndarray, frames: int) -> np.ndarray:
    """Moving average of ``[T, ...]`` along frames over ``frames`` frames (at most ``T``; edges padded with their
    values)."""
    return uniform_filter1d(signal, size=max(1, min(int(frames), len(signal))), axis=0, mode="nearest")


def detect_contacts(
    ankle: np.ndarray,
    fps: float,
    floor: float,
    max_height: float = 0.12,
    height_tolerance: float = 0.03,
    vertical_speed: float = 0.3,
    min_contact_frames: int = 3,
    smoothing_frames: int = 9,
) -> np.ndarray:
    """bool ``[T]``: the frames where a foot is planted (stance).

    A stance is a run of frames where the ankle barely moves **vertically** (the moving average over
    ``smoothing_frames`` frames of its height changes slower than ``vertical_speed`` m/s), restricted to the
    frames within ``height_tolerance`` of the run's lowest ankle height, when that lowest height is at most
    ``max_height`` above ``floor`` (a foot held still high up, as at the top of a knee lift, is no stance). Runs
    shorter than ``min_contact_frames`` are dropped. Horizontal speed plays no part: a foot that slides along the
    floor is exactly what the cleanup has to find, and sampled motion floats or sinks by centimetres, so the
    stance height is the run's own rather than the floor's.

    Args:
        ankle: float64 ``[T, 3]`` ankle positions, metres, ``y`` up.
        fps: frames per second.
        floor: the ankle height of a planted foot, metres.
    """
    contact = np.zeros(len(ankle), dtype=bool)
    if len(ankle) < 2:
        return contact
    height = _smoothed(ankle[:, 1], smoothing_frames)
    still = np.abs(np.gradient(height)) * fps < vertical_speed
    for start, stop in true_runs(still):
        lowest = float(ankle[start:stop, 1].min())
        if lowest <= floor + max_height:
            contact[start:stop] = ankle[start:stop, 1] <= lowest + height_tolerance
    for start, stop in true_runs(contact):
        if stop - start < min_contact_frames:
            contact[start:stop] = False
    return contact


def _pin_targets(
    ankle: np.ndarray, contact: np.ndarray, blend_frames: int, floor: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Ankle targets ``[T, 3]`` and their weights ``[T]`` (1 in contacts, linear ramps ``blend_frames`` long).

    Each contact run's target is the ankle's mean position over the run, at height ``floor`` when given."""
    T = len(ankle)
    weight = np.zeros(T)
    pin = ankle.copy()
    for start, stop in true_runs(contact):
        point = ankle[start:stop].mean(axis=0)
        if floor is not None:
            point[1] = floor
        lo, hi = max(0, start - blend_frames), min(T, stop + blend_frames)
        for t in range(lo, hi):
            w = 1.0 if start <= t < stop else 1.0 - (start - t if t < start else t - stop + 1) / (blend_frames + 1)
            if w > weight[t]:
                weight[t] = w
                pin[t] = point
    return ankle + weight[:, None] * (pin - ankle), weight


def _follow(path: np.ndarray, slack: float) -> np.ndarray:
    """``[T, 2]``: a path that stays within ``slack`` of ``path`` and moves only when ``path`` pulls it further
    (a dead-band follower starting at ``path[0]``)."""
    out = np.empty_like(path)
    out[0] = path[0]
    for t in range(1, len(path)):
        gap = out[t - 1] - path[t]
        norm = float(np.hypot(*gap))
        out[t] = path[t] + (gap if norm <= slack else gap * (slack / norm))
    return out


def root_shift(
    ankles: list[np.ndarray],
    contacts: list[np.ndarray],
    floor: float,
    blend_frames: int = 6,
    slack: float = 0.0,
    ramps: bool = True,
) -> np.ndarray:
    """float64 ``[T, 3]`` metres: the shift of the root that grounds and halts the planted feet.

    - **Horizontal** (x, z): the root's step in each frame loses the weighted mean horizontal step of the
      planted ankles (weights: 1 in a contact and, with ``ramps``, linear ramps ``blend_frames`` long around it,
      as the IK pins; without, 1 for the steps whose both frames are in the contact and 0 for the others, the
      per-frame corrections then averaged over ``2·blend_frames + 1`` frames so that the body does not jolt where a
      contact begins or ends), so that a planted foot stands still while the body moves over
      it; the shift is the running sum of those corrections (0 at frame 0). The ramps cover the frames where the
      foot lands and lifts off, when it swings forward fast: their steps, taken out of the root's, slow the body
      down (real HDM05 jogs by 24 %, real Bandai walks by half; docs/decisions.md#synthesis-footskate-root).
    - **Vertical** (y): in contact frames, ``floor`` minus the mean height of the planted ankles over their
      contact runs (each run lifted or lowered as a whole, so the foot's own small motion within a stance is
      kept); between contacts linearly interpolated, then smoothed over ``2·blend_frames + 1`` frames; 0
      everywhere without contacts.

    Args:
        ankles: per leg, float64 ``[T, 3]`` ankle positions (metres, y up).
        contacts: per leg, bool ``[T]`` (:func:`detect_contacts`).
        floor: the ankle height of a planted foot, metres.
        slack: metres the horizontal shift may lag behind the full correction (a dead-band follower, then
            smoothed like the vertical shift): the legs' IK absorbs slides within it, so an in-place motion
            whose planted feet slide back and forth keeps its pelvis in place; 0 (default): the full correction.
        ramps: whether the horizontal correction also takes the ankles' steps in the blend ramps around contacts.
    """
    T = len(ankles[0])
    step, total = np.zeros((T, 2)), np.zeros(T)
    lift, count = np.zeros(T), np.zeros(T)
    for ankle, contact in zip(ankles, contacts):
        if ramps:
            _, weight = _pin_targets(ankle, contact, blend_frames)
        else:  # the steps t-1 → t with the foot planted at both ends
            weight = (contact & np.concatenate([[False], contact[:-1]])).astype(np.float64)
        if T > 1:
            step += weight[:, None] * np.diff(ankle[:, [0, 2]], axis=0, prepend=ankle[:1, [0, 2]])
        total += weight
        for start, stop in true_runs(contact):
            lift[start:stop] += floor - ankle[start:stop, 1].mean()
            count[start:stop] += 1
    shift = np.zeros((T, 3))
    correction = step / np.maximum(total, 1.0)[:, None]
    if not ramps:  # switched on and off at the contacts' ends: spread each step over 2·blend_frames + 1 frames
        correction = _smoothed(correction, 2 * blend_frames + 1)
    shift[:, [0, 2]] = -np.cumsum(correction, axis=0)
    if slack > 0 and T > 1:
        shift[:, [0, 2]] = _smoothed(_follow(shift[:, [0, 2]], slack), 2 * blend_frames + 1)
    planted = np.flatnonzero(count)
    if len(planted):
        vertical = np.interp(np.arange(T), planted, lift[planted] / count[planted])
        shift[:, 1] = _smoothed(vertical, 2 * blend_frames + 1)
    return shift


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
    ``current``; ``h, w`` are ``[T, 3]``, ``axis`` a unit ``[3]`` or one per frame, ``[T, 3]``.

    ``R_axis(θ) w = w_par + cos θ w_perp + sin θ (axis × w)``, so ``hᵀ R w = c + a cos θ + b sin θ``.
    """
    w_par = np.sum(w * axis, axis=-1)[:, None] * axis
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


def _flexion_axes(thigh: np.ndarray, shin: np.ndarray) -> np.ndarray:
    """``[T, 3]`` unit normals of the planes of ``thigh`` and ``shin`` vectors (``[T, 3]``): the axes a three-dof
    knee bends about. A straight leg has no plane: it takes the axis of the nearest frame that has one (the
    ``x`` axis of the shin's frame, sideways in a T-pose rest, when no frame has)."""
    normal = np.cross(thigh, shin)
    size = np.linalg.norm(normal, axis=1)
    valid = size > 1e-3 * np.linalg.norm(thigh, axis=1) * np.linalg.norm(shin, axis=1)
    if not valid.any():
        return np.tile([1.0, 0.0, 0.0], (len(thigh), 1))
    frames = np.flatnonzero(valid)
    nearest = frames[np.clip(np.searchsorted(frames, np.arange(len(thigh))), 0, len(frames) - 1)]
    earlier = frames[np.clip(np.searchsorted(frames, np.arange(len(thigh))) - 1, 0, len(frames) - 1)]
    pick = np.where(np.abs(earlier - np.arange(len(thigh))) < np.abs(nearest - np.arange(len(thigh))), earlier, nearest)
    return normal[pick] / size[pick, None]


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
    speeds = [
        np.linalg.norm(np.gradient(a[:, [0, 2]], axis=0), axis=1)[c] * fps
        for a, c in zip(ankles, contacts)
        if c.any() and len(a) > 1
    ]
    return float(np.mean(np.concatenate(speeds))) if speeds else float("nan")


def cleanup_footskate(
    values: dict[str, np.ndarray],
    skeleton: AsfSkeleton,
    fps: float,
    floor: float | None = None,
    max_height: float = 0.12,
    height_tolerance: float = 0.03,
    vertical_speed: float = 0.3,
    min_contact_frames: int = 3,
    blend_frames: int = 12,
    move_root: str = DEFAULT_ROOT_MOVE,
    root_slack: float = 0.0,
) -> tuple[dict[str, np.ndarray], FootskateReport]:
    """Ground and pin planted feet (module docstring).

    Args:
        values: AMC values, bone → float64 ``[T, len(dof)]`` (degrees; root translation in ASF units).
        skeleton: their skeleton.
        fps: frames per second.
        floor: the ankle height (metres) of a planted foot; default: the lowest ankle height of the clip over both
            legs (a synthesiser passes its training clips' value, which one low sampled frame cannot move).
        max_height, height_tolerance, vertical_speed, min_contact_frames: contact detection
            (:func:`detect_contacts`).
        blend_frames: frames over which a pin fades in before and out after a contact.
        move_root: how the root's translation is shifted before the IK (:func:`root_shift`; default
            :data:`DEFAULT_ROOT_MOVE`): ``"stance"`` grounds and halts the planted feet over their contacts
            (``ramps=False``), so the body's travel follows its feet; ``"full"`` the same over the contacts and
            the blend ramps around them; ``"vertical"`` only grounds them and keeps the sampled path (the IK then
            pins what the legs reach); ``"none"`` leaves the root alone.
        root_slack: the ``slack`` of :func:`root_shift` (metres).

    ``blend_frames=12`` and ``move_root="full"`` (the default before ``"stance"``: :data:`DEFAULT_ROOT_MOVE`) were
    chosen on training clips only: SLFM variants (literal model, no cross-partition inputs) of the seed-0 splits of
    the four HDM05 types of ``mocapkit compare synthesis_hdm05``, scored against their own 10 training clips by the
    mean over the types of the mean ``|log(variant / clips)|`` of four proxies (foot skating, jerk, share of contact
    frames, feature distance against the clips' leave-one-out distance): full/12 0.78, full/6 0.83, vertical/12
    0.93, vertical/6 0.95, none/12 1.06, none/6 1.12, no cleanup 1.46. The seed-1 splits hold some of those clips
    among their held-out references. ``"stance"`` replaced ``"full"`` by a second rule (:data:`DEFAULT_ROOT_MOVE`).
    ``root_slack`` on the same variants (full/12): 0 → 0.78, 0.05 → 0.79, 0.1 → 0.80, 0.2 → 0.82; slack helps
    squats (feature distance 2.28 → 1.60 at 0.05, the clips' own 0.66) and costs the elbow-to-knee (2.15 → 2.22).

    Raises:
        ValueError: an unknown ``move_root``.

    Returns:
        The cleaned values (a new dict; only the root's translation and the legs' thigh and shin values change)
        and a :class:`FootskateReport`.
    """
    if move_root not in ROOT_MOVES:
        raise ValueError(f"move_root={move_root!r}: expected one of {list(ROOT_MOVES)}")
    out = {bone: np.array(v, dtype=np.float64) for bone, v in values.items()}
    positions, local = forward_kinematics(skeleton, out)
    index = {name: j for j, name in enumerate(skeleton.joint_names)}
    parts = partitions(skeleton)
    legs, skipped = [], []
    for name in ("LL", "RL"):
        chain = parts[name]
        if (
            len(chain) < 2
            or skeleton.parent_names.get(chain[1]) != chain[0]
            or len(dof_axes(skeleton.bone(chain[1]).dof)) not in (1, 3)
        ):
            skipped.append(f"{name}: needs a thigh and a one- or three-dof shin below it, has {list(chain[:2])}")
            continue
        legs.append((chain[0], chain[1]))
    if not legs:
        return out, FootskateReport({}, float("nan"), float("nan"), skipped, np.zeros((len(positions), 3)))
    if floor is None:
        floor = min(float(positions[:, index[shin], 1].min()) for _, shin in legs)
    before = [positions[:, index[shin]].astype(np.float64) for _, shin in legs]
    masks = [
        detect_contacts(ankle, fps, floor, max_height, height_tolerance, vertical_speed, min_contact_frames)
        for ankle in before
    ]
    contacts = {thigh: mask for (thigh, _), mask in zip(legs, masks)}
    shift = np.zeros((len(positions), 3))
    if move_root != "none" and any(mask.any() for mask in masks):
        shift = root_shift(before, masks, floor, blend_frames, root_slack, ramps=move_root != "stance")
        order = [channel.upper() for channel in skeleton.root_order]
        if "root" not in out:
            out["root"] = np.zeros((len(positions), len(order)))
        for axis in range(3):
            channel = "T" + "XYZ"[axis]
            if channel in order and (axis == 1 or move_root != "vertical"):
                out["root"][:, order.index(channel)] += shift[:, axis] / skeleton.metres_per_unit
            else:
                shift[:, axis] = 0.0
        positions, local = forward_kinematics(skeleton, out)
    glob = _global_rotations(skeleton, local)
    offsets = skeleton.offsets()
    after = []
    for (thigh, shin), contact in zip(legs, masks):
        j_thigh, j_shin = index[thigh], index[shin]
        j_hip = skeleton.parents[j_thigh]
        ankle = positions[:, j_shin].astype(np.float64)
        after.append(ankle.copy())
        target, weight = _pin_targets(ankle, contact, blend_frames, floor)
        frames = np.flatnonzero(weight > 0)
        if len(frames) == 0:
            continue
        hip, knee = positions[frames, j_hip], positions[frames, j_thigh]
        # knee: hinge angle giving |ankle - hip| == |target - hip|
        c_shin = _bone_frame(skeleton, shin)
        shin_axes = dof_axes(skeleton.bone(shin).dof)
        frame_shin = glob[frames, j_thigh] @ c_shin  # G: shin offset = G · M · w
        w = c_shin.T @ offsets[j_shin]
        l_thigh, l_shin = np.linalg.norm(offsets[j_thigh]), np.linalg.norm(offsets[j_shin])
        reach = np.clip(
            np.linalg.norm(target[frames] - hip, axis=1), abs(l_thigh - l_shin) + 1e-6, l_thigh + l_shin - 1e-6
        )
        h = np.einsum("tji,tj->ti", frame_shin, knee - hip)  # Gᵀ (knee - hip)
        wanted = (reach**2 - l_thigh**2 - l_shin**2) / 2
        if len(shin_axes) == 1:  # a hinge: M = R_axis(θ)
            hinge_axis = np.eye(3)["xyz".index(shin_axes)]
            theta = _hinge_angle(h, np.tile(w, (len(frames), 1)), hinge_axis, wanted, np.radians(out[shin][frames, 0]))
            out[shin][frames, 0] = np.degrees(theta)
            bent = Rotation.from_rotvec(theta[:, None] * hinge_axis).apply(np.tile(w, (len(frames), 1)))
        else:  # M' = R_a(φ) · M, a ⊥ thigh and shin
            m_shin = Rotation.from_euler(shin_axes, np.radians(out[shin][frames]))
            shin_now = m_shin.apply(w)
            flexion = _flexion_axes(h, shin_now)
            phi = _hinge_angle(h, shin_now, flexion, wanted, np.zeros(len(frames)))
            turned = Rotation.from_rotvec(phi[:, None] * flexion) * m_shin
            out[shin][frames] = np.degrees(euler_near(turned, shin_axes, np.radians(out[shin][frames])))
            bent = turned.apply(w)
        new_ankle = knee + np.einsum("tij,tj->ti", frame_shin, bent)
        # thigh: turn about the hip so the ankle points at the target
        turn = _minimal_rotation(new_ankle - hip, target[frames] - hip)
        after[-1][frames] = hip + np.einsum("tij,tj->ti", turn, new_ankle - hip)
        thigh_global = turn @ glob[frames, j_thigh]
        c_thigh = _bone_frame(skeleton, thigh)
        m_thigh = c_thigh.T @ np.swapaxes(glob[frames, j_hip], 1, 2) @ thigh_global @ c_thigh
        axes = dof_axes(skeleton.bone(thigh).dof)
        out[thigh][frames] = np.degrees(euler_near(Rotation.from_matrix(m_thigh), axes, np.radians(out[thigh][frames])))
    return out, FootskateReport(contacts, _sliding(before, masks, fps), _sliding(after, masks, fps), skipped, shift)
