"""Kinect v1 noise simulator: clean mocap → Kinect-v1-like 20-joint skeletons, for (kinect, mocap) training pairs.

Zhou 2014 ch. 5 trains its posture reconstruction (a GP per joint on the offset ``mocap − kinect``) on paired Kinect
SDK v1.8 + optical mocap recordings that are not public (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md``
§4.1, §7 item 32). This module makes stand-in pairs from clean mocap: :func:`kinect20_from_motion` maps any layout to
the Kinect v1 20-joint skeleton (digest §1.6; the order of
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES`), y-up, metres, at 30 fps, and :func:`simulate_kinect`
corrupts it the way a Kinect v1 does. **Results on simulated data are not comparable with the thesis's Table 5.2**
(digest §4.6, §7 item 32): the thesis's numbers come from real sensor data on its own motions.

Units: positions in metres, y up, in the world frame of the input (the simulated skeleton is not moved into the
camera's frame, so ``clean − noisy`` is the offset a reconstruction has to learn); times in seconds; errors reported
in centimetres (:func:`mocapkit.kinect.metrics.joint_error_cm`, digest §4.6 eqs 5.7–5.9 as a per-frame mean,
§7 item 29).

What is simulated, in this order (each a switch of :class:`KinectNoiseConfig`, named in :data:`COMPONENTS`):

a. **virtual depth camera** (always): per clip, a camera ``camera_height_m`` above the floor, ``camera_distance_m``
   from the subject's mean pelvis position, placed so that the subject's mean facing direction is turned by
   ``facing_yaw_deg`` from the camera, looking at the mean pelvis at mid-body height; it steps back (up to
   ``max_camera_distance_m``) until the pelvis stays ``min_subject_distance_m`` away and inside the horizontal field
   of view in every frame, and at most ``max_out_of_view_share`` of the joint entries fall outside the field of view
   (57° × 43°); joints still outside it are INFERRED;
b. ``surface_bias``: Kinect joints sit on the body surface seen by the camera, not at the joint centre: each joint
   moves towards the camera by a per-joint radius (torso 8–10 cm, limbs 3–6 cm);
c. ``joint_offsets``: systematic joint-definition differences (Kinect hips higher and wider than the mocap hip
   centres, ShoulderCenter lower, Head higher...), a few cm in the per-frame torso frame (outward, up, forward), so
   they depend on the pose and a regressor can learn them;
d. ``occlusion``: the body is a set of capsules (trunk, pelvis, head, limb segments, :data:`CAPSULES`). A joint
   is INFERRED when capsules that neither end at it nor contain it cover ``hidden_coverage`` of a disc of
   ``visible_radius_m`` around its visible surface (7 camera rays), when a limb joint touches another body part
   (``contact_margin_m``: touching parts merge in the depth image), when it is outside the field of view, or, for
   the limb joints, while the trunk tilts more than ``upright_limit_deg`` from vertical (deep bends, lying on the
   floor: Kinect v1's body-part classifier knows upright people). Its position blends a *snap* onto the
   occluder's front surface along the ray (``snap_weight``) with a *hold* (its offset from its parent at the last
   tracked frame, carried by the parent), plus a drift (low-pass noise of σ ``inferred_drift_m``, faded in over
   ``inferred_drift_time_constant_s``). An occlusion longer than ``not_tracked_after_s`` turns NOT_TRACKED for the
   rest of the run with probability ``not_tracked_probability`` (the position stays the inferred guess: the SDK's
   own value is undefined there, so use the state);
e. ``depth_noise``: white noise along the camera ray with σ = ``depth_sigma_at_1m_m`` · depth² (Kinect v1's axial
   error grows with the square of the distance); ``jitter``: temporally correlated (first-order low-pass) 3-D noise,
   per-joint σ, largest for hands, wrists and feet, ``inferred_jitter_factor`` times larger on joints not tracked,
   plus ``speed_jitter_s`` times the joint's speed (motion blur and tracking lag of fast hands and feet);
f. ``bone_jitter``: per-frame relative bone-length noise (low-pass), applied from the pelvis outwards;
g. ``swaps``: left/right confusions of the legs (knee, ankle, foot) and optionally the arms for short runs of
   frames, more likely the more side-on the body is to the camera, and a full left/right mirror while the subject
   faces away from the camera (``back_facing_mirror_deg``; Kinect v1 assumes a frontal user).

Everything random is drawn from one seed (a fixed stream per component, so switching one component off leaves the
others' noise unchanged); every component off returns the input exactly (all joints TRACKED).

Calibrations (``scripts/selection/calibrate_kinect_noise.py``), named by :meth:`KinectNoiseConfig.preset`:
``"mean_error"`` (the default config) puts the raw error over all 232 HDM05 cuts inside the thesis's 12.5–14.5 cm
(Table 5.2, digest §4.6), with occlusion and inference the largest part of it; ``"msr_steadiness"`` keeps that
error but cuts the frame-to-frame sensor noise to a tenth, so that tracked joints are about as steady as MSR
Action3D's real skeletons; ``"real_sensor"`` (what ``mocapkit kinect-fix train`` uses by default) has the
frame-to-frame statistics of real Kinect skeletons (white jitter, rare swaps, the NTU samples' INFERRED share, no
NOT_TRACKED runs; ``scripts/selection/kinect_real_calibration.py``). What each calibration measured and the rule it
was tuned by: docs/decisions.md#kinect-simulator-calibration, docs/decisions.md#steady-simulator-preset and
docs/decisions.md#real-sensor-simulator-preset.
"""

from __future__ import annotations

import math
import os
import warnings
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from mocapkit.motion.container import Motion
from mocapkit.motion.frames import true_runs
from mocapkit.motion.geometry import direction_yaw, facing_direction, landmark_positions, to_y_up
from mocapkit.motion.layouts import LANDMARK_NAMES, LANDMARK_PARENTS

#: Kinect SDK joint tracking states (``NUI_SKELETON_POSITION_TRACKING_STATE``).
TRACKED, INFERRED, NOT_TRACKED = 2, 1, 0
#: The Kinect v1 joint names, in the order of the simulated arrays (digest §1.6).
KINECT20_NAMES: tuple[str, ...] = (
    "HipCenter",
    "Spine",
    "ShoulderCenter",
    "Head",
    "ShoulderLeft",
    "ElbowLeft",
    "WristLeft",
    "HandLeft",
    "ShoulderRight",
    "ElbowRight",
    "WristRight",
    "HandRight",
    "HipLeft",
    "KneeLeft",
    "AnkleLeft",
    "FootLeft",
    "HipRight",
    "KneeRight",
    "AnkleRight",
    "FootRight",
)
NUM_JOINTS = len(LANDMARK_NAMES)
#: The ``real_sensor`` preset's jitter σ as a share of the default's (docs/decisions.md#real-sensor-simulator-preset).
REAL_SENSOR_JITTER_SCALE = 0.3
#: Named calibrations of :meth:`KinectNoiseConfig.preset` (the first is the default config).
NOISE_PRESETS: tuple[str, ...] = ("mean_error", "msr_steadiness", "real_sensor")
#: The error components :class:`KinectNoiseConfig` switches (b–g of the module docstring).
COMPONENTS: tuple[str, ...] = (
    "surface_bias",
    "joint_offsets",
    "occlusion",
    "depth_noise",
    "jitter",
    "bone_jitter",
    "swaps",
)

_INDEX = {name: k for k, name in enumerate(LANDMARK_NAMES)}
#: Body part of each landmark (left and right share one value in the config tables).
_PART = tuple(name[2:] if name[:2] in ("l_", "r_") else name for name in LANDMARK_NAMES)
#: +1 for left landmarks, −1 for right ones, 0 on the midline.
_SIDE = np.array([1.0 if n.startswith("l_") else -1.0 if n.startswith("r_") else 0.0 for n in LANDMARK_NAMES])
_LEG_PAIRS = tuple((_INDEX[f"l_{p}"], _INDEX[f"r_{p}"]) for p in ("knee", "ankle", "foot"))
_ARM_PAIRS = tuple((_INDEX[f"l_{p}"], _INDEX[f"r_{p}"]) for p in ("elbow", "wrist", "hand"))
_ALL_PAIRS = tuple(
    (_INDEX[f"l_{p}"], _INDEX[f"r_{p}"]) for p in ("shoulder", "elbow", "wrist", "hand", "hip", "knee", "ankle", "foot")
)
#: Limb joints (elbows, wrists, hands, knees, ankles, feet): the ones that touching another body part hides.
_LIMB_JOINT = np.array([part in ("elbow", "wrist", "hand", "knee", "ankle", "foot") for part in _PART])
_PELVIS, _NECK, _L_HIP, _R_HIP = _INDEX["pelvis"], _INDEX["neck"], _INDEX["l_hip"], _INDEX["r_hip"]
_FEET = [_INDEX[n] for n in ("l_ankle", "l_foot", "r_ankle", "r_foot")]
_PARENTS = np.array(LANDMARK_PARENTS)

#: Body capsules for self-occlusion: name → (landmark, landmark); radii are in the config.
CAPSULES: dict[str, tuple[str, str]] = {
    "torso": ("pelvis", "spine"),
    "upper_torso": ("spine", "neck"),
    "chest": ("l_shoulder", "r_shoulder"),
    "pelvis": ("l_hip", "r_hip"),
    "head": ("neck", "head"),
    "l_upper_arm": ("l_shoulder", "l_elbow"),
    "l_forearm": ("l_elbow", "l_wrist"),
    "l_hand": ("l_wrist", "l_hand"),
    "r_upper_arm": ("r_shoulder", "r_elbow"),
    "r_forearm": ("r_elbow", "r_wrist"),
    "r_hand": ("r_wrist", "r_hand"),
    "l_thigh": ("l_hip", "l_knee"),
    "l_shin": ("l_knee", "l_ankle"),
    "l_foot": ("l_ankle", "l_foot"),
    "r_thigh": ("r_hip", "r_knee"),
    "r_shin": ("r_knee", "r_ankle"),
    "r_foot": ("r_ankle", "r_foot"),
}
_CAP_A = np.array([_INDEX[a] for a, _ in CAPSULES.values()])
_CAP_B = np.array([_INDEX[b] for _, b in CAPSULES.values()])
_TRUNK = ("torso", "upper_torso", "chest", "pelvis")
#: [joints, capsules]: capsules that never hide the joint: those with the joint as an end, and the solid a joint sits
#: in (HipCenter: trunk and thigh tops; Spine: trunk; ShoulderCenter: trunk and head; hips: lower trunk).
_CAP_IGNORED = (np.arange(NUM_JOINTS)[:, None] == _CAP_A[None]) | (np.arange(NUM_JOINTS)[:, None] == _CAP_B[None])
for _joint, _names in (
    ("pelvis", _TRUNK + ("l_thigh", "r_thigh")),
    ("spine", _TRUNK),
    ("neck", _TRUNK + ("head",)),
    ("l_hip", ("torso", "pelvis")),
    ("r_hip", ("torso", "pelvis")),
):
    _CAP_IGNORED[_INDEX[_joint], [list(CAPSULES).index(name) for name in _names]] = True

_BODY_PARTS = ("pelvis", "spine", "neck", "head", "shoulder", "elbow", "wrist", "hand", "hip", "knee", "ankle", "foot")


def _default_surface_radius() -> dict[str, float]:
    # metres between the joint centre and the body surface the depth camera sees
    return {
        "pelvis": 0.08,
        "spine": 0.08,
        "neck": 0.08,
        "head": 0.06,
        "shoulder": 0.05,
        "elbow": 0.045,
        "wrist": 0.04,
        "hand": 0.04,
        "hip": 0.06,
        "knee": 0.055,
        "ankle": 0.045,
        "foot": 0.04,
    }


def _default_joint_offset() -> dict[str, tuple[float, float, float]]:
    # metres, (outward from the midline, up along the torso, forward), in the per-frame torso frame
    return {
        "pelvis": (0.0, 0.04, 0.0),
        "spine": (0.0, -0.03, 0.01),
        "neck": (0.0, -0.05, 0.01),
        "head": (0.0, 0.04, 0.01),
        "shoulder": (0.02, 0.01, 0.0),
        "elbow": (0.0, -0.01, 0.0),
        "wrist": (0.0, 0.0, 0.01),
        "hand": (0.01, 0.0, 0.03),
        "hip": (0.03, 0.05, 0.01),
        "knee": (0.0, 0.0, 0.01),
        "ankle": (0.0, 0.03, 0.01),
        "foot": (0.0, 0.02, 0.04),
    }


def _default_capsule_radius() -> dict[str, float]:
    # metres
    radius = {"torso": 0.13, "upper_torso": 0.10, "chest": 0.07, "pelvis": 0.09, "head": 0.09}
    for side in ("l_", "r_"):
        radius.update(
            {
                f"{side}upper_arm": 0.05,
                f"{side}forearm": 0.04,
                f"{side}hand": 0.045,
                f"{side}thigh": 0.075,
                f"{side}shin": 0.055,
                f"{side}foot": 0.045,
            }
        )
    return radius


def _default_visible_radius() -> dict[str, float]:
    # metres, radius of the body part around the joint that the tracker needs to see
    return {
        "pelvis": 0.12,
        "spine": 0.12,
        "neck": 0.10,
        "head": 0.09,
        "shoulder": 0.06,
        "elbow": 0.05,
        "wrist": 0.04,
        "hand": 0.05,
        "hip": 0.08,
        "knee": 0.06,
        "ankle": 0.05,
        "foot": 0.05,
    }


def _default_jitter_sigma() -> dict[str, float]:
    # metres, standard deviation of the low-pass jitter of a tracked joint
    return {
        "pelvis": 0.006,
        "spine": 0.006,
        "neck": 0.007,
        "head": 0.008,
        "shoulder": 0.010,
        "elbow": 0.015,
        "wrist": 0.022,
        "hand": 0.030,
        "hip": 0.008,
        "knee": 0.015,
        "ankle": 0.022,
        "foot": 0.030,
    }


@dataclass(frozen=True)
class KinectNoiseConfig:
    """Parameters of :func:`simulate_kinect`; the defaults are the calibrated Kinect v1 level
    (docs/decisions.md#kinect-simulator-calibration).

    Per-joint tables are keyed by body part (``pelvis``, ``spine``, ``neck``, ``head``, ``shoulder``, ``elbow``,
    ``wrist``, ``hand``, ``hip``, ``knee``, ``ankle``, ``foot``); left and right share a value.
    """

    # --- switches of the error components (COMPONENTS); all False returns the input exactly
    surface_bias: bool = True
    joint_offsets: bool = True
    occlusion: bool = True
    depth_noise: bool = True
    jitter: bool = True
    bone_jitter: bool = True
    swaps: bool = True
    # --- a. virtual camera
    camera_height_m: float = 0.8  # m above the clip's floor (lowest ankle/foot)
    camera_distance_m: tuple[float, float] = (2.0, 3.5)  # m, horizontal, drawn uniformly per clip
    facing_yaw_deg: tuple[float, float] = (-45.0, 45.0)  # degrees, subject's mean facing vs. the camera
    min_subject_distance_m: float = 1.5  # m, pelvis never nearer (camera steps back)
    max_camera_distance_m: float = 4.5  # m, how far the camera may step back
    max_out_of_view_share: float = 0.02  # share of joint entries out of view before it does
    field_of_view_deg: tuple[float, float] = (57.0, 43.0)  # degrees, horizontal and vertical (Kinect v1)
    # --- b. surface bias
    surface_radius_m: dict[str, float] = field(default_factory=_default_surface_radius)  # m, per body part
    # --- c. joint-definition offsets
    joint_offset_m: dict[str, tuple[float, float, float]] = field(default_factory=_default_joint_offset)  # m
    # --- d. self-occlusion and inference
    capsule_radius_m: dict[str, float] = field(default_factory=_default_capsule_radius)  # m, per CAPSULES name
    visible_radius_m: dict[str, float] = field(default_factory=_default_visible_radius)  # m, per body part
    hidden_coverage: float = 0.4  # 0..1, share of a joint's visible disc (of 7 samples) that occluders
    #                                          must cover to hide it
    contact_margin_m: float = 0.03  # m; a limb joint nearer than this to another body part's surface is
    #                                          INFERRED too (depth segmentation merges touching parts)
    snap_weight: float = 0.6  # 0..1, share of the occluder-surface snap in an inferred position
    inferred_drift_m: float = 0.08  # m, σ per axis of an inferred joint's drift (low-pass noise)
    inferred_drift_time_constant_s: float = 1.0  # s, the drift's low-pass and fade-in time from the occlusion start
    upright_limit_deg: float | None = 60.0  # degrees of trunk tilt from vertical beyond which the limbs are
    #                                          INFERRED (the tracker is trained on upright people); None: never
    not_tracked_after_s: float = 0.5  # s of continuous occlusion before NOT_TRACKED may start
    not_tracked_probability: float = 0.4  # chance that such a long occlusion turns NOT_TRACKED
    # --- e. depth noise and jitter
    depth_sigma_at_1m_m: float = 0.002  # m at 1 m depth; σ = this · depth², along the camera ray, white
    jitter_sigma_m: dict[str, float] = field(default_factory=_default_jitter_sigma)  # m, per body part
    jitter_time_constant_s: float = 0.1  # s, first-order low-pass of the jitter
    speed_jitter_s: float = 0.01  # s; extra jitter σ (m) = this · joint speed (m/s): blur and tracking lag
    inferred_jitter_factor: float = 3.0  # jitter multiplier on INFERRED / NOT_TRACKED joints
    # --- f. bone-length jitter
    bone_length_sigma: float = 0.03  # relative (1 = 100 %) standard deviation of every bone length
    bone_length_time_constant_s: float = 0.3  # s, low-pass of the bone-length noise
    # --- g. left/right swaps
    leg_swap_rate_facing_hz: float = 0.1  # 1/s, leg swaps started per second when facing the camera
    leg_swap_rate_side_hz: float = 1.5  # 1/s, ... when side-on (interpolated by sin² of the angle)
    arm_swap_rate_facing_hz: float = 0.0  # 1/s, arm swaps (off by default)
    arm_swap_rate_side_hz: float = 0.0  # 1/s
    swap_duration_s: tuple[float, float] = (0.1, 0.5)  # s, length of one swap run, drawn uniformly
    back_facing_mirror_deg: float | None = 120.0  # degrees between facing and camera beyond which all l/r mirror

    def __post_init__(self) -> None:
        for name, table in (
            ("surface_radius_m", self.surface_radius_m),
            ("joint_offset_m", self.joint_offset_m),
            ("visible_radius_m", self.visible_radius_m),
            ("jitter_sigma_m", self.jitter_sigma_m),
        ):
            missing = set(_BODY_PARTS) - set(table)
            unknown = set(table) - set(_BODY_PARTS)
            if missing or unknown:
                raise ValueError(
                    f"KinectNoiseConfig.{name}: missing {sorted(missing)}, unknown {sorted(unknown)}; "
                    f"keys are {_BODY_PARTS}"
                )
        if set(self.capsule_radius_m) != set(CAPSULES):
            raise ValueError(f"KinectNoiseConfig.capsule_radius_m must have the keys {sorted(CAPSULES)}")
        for name in ("camera_distance_m", "facing_yaw_deg", "swap_duration_s"):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ValueError(f"KinectNoiseConfig.{name}: range ({lo}, {hi}) has low > high")
        for name in ("snap_weight", "not_tracked_probability", "hidden_coverage"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"KinectNoiseConfig.{name} must be in [0, 1], got {getattr(self, name)}")
        if min(self.visible_radius_m.values()) <= 0:
            raise ValueError("KinectNoiseConfig.visible_radius_m must be positive")
        if self.camera_distance_m[0] <= 0 or self.max_camera_distance_m <= 0:
            raise ValueError("KinectNoiseConfig: camera distances must be positive")

    @classmethod
    def off(cls, **changes) -> KinectNoiseConfig:
        """Every error component switched off (the simulator returns its input, all TRACKED), then ``changes``."""
        return cls(**{**{name: False for name in COMPONENTS}, **changes})

    def without(self, *components: str) -> KinectNoiseConfig:
        """This config with the named :data:`COMPONENTS` switched off."""
        unknown = set(components) - set(COMPONENTS)
        if unknown:
            raise ValueError(f"unknown noise components {sorted(unknown)}; known: {COMPONENTS}")
        return replace(self, **{name: False for name in components})

    def scaled(self, factor: float) -> KinectNoiseConfig:
        """Every error magnitude times ``factor`` (surface radii, joint offsets, snap weight (at most 1), drift,
        depth noise, jitter, bone-length noise, swap rates); the camera and the body capsules are kept."""
        f = float(factor)
        return replace(
            self.sensor_noise_scaled(f),
            surface_radius_m={k: v * f for k, v in self.surface_radius_m.items()},
            joint_offset_m={k: tuple(x * f for x in v) for k, v in self.joint_offset_m.items()},
            snap_weight=min(1.0, self.snap_weight * f),
            inferred_drift_m=self.inferred_drift_m * f,
            leg_swap_rate_facing_hz=self.leg_swap_rate_facing_hz * f,
            leg_swap_rate_side_hz=self.leg_swap_rate_side_hz * f,
            arm_swap_rate_facing_hz=self.arm_swap_rate_facing_hz * f,
            arm_swap_rate_side_hz=self.arm_swap_rate_side_hz * f,
        )

    def sensor_noise_scaled(self, factor: float) -> KinectNoiseConfig:
        """This config with the frame-to-frame sensor noise times ``factor``: the jitter σ (and its speed term), the
        depth noise and the bone-length noise. The systematic errors (surface bias, joint offsets), occlusion and
        swaps are kept."""
        f = float(factor)
        if f < 0:
            raise ValueError(f"scale factor must be non-negative, got {factor}")
        return replace(
            self,
            jitter_sigma_m={k: v * f for k, v in self.jitter_sigma_m.items()},
            speed_jitter_s=self.speed_jitter_s * f,
            depth_sigma_at_1m_m=self.depth_sigma_at_1m_m * f,
            bone_length_sigma=self.bone_length_sigma * f,
        )

    @classmethod
    def preset(cls, name: str) -> KinectNoiseConfig:
        """A named calibration (:data:`NOISE_PRESETS`; how each was measured:
        docs/decisions.md#kinect-simulator-calibration):

        - ``"mean_error"``: the defaults, calibrated on the raw error only (12.5–14.5 cm on HDM05);
        - ``"msr_steadiness"``: the same raw-error level, with the frame-to-frame sensor noise (jitter, depth and
          bone-length noise) cut to a tenth so that tracked joints are as steady as the real Kinect skeletons of MSR
          Action3D, and the surface bias 15 % larger to keep the raw error in the thesis's range.
        - ``"real_sensor"``: the frame-to-frame statistics of real Kinect skeletons (MSR Action3D, the NTU samples'
          tracking states; docs/decisions.md#real-sensor-simulator-preset): white jitter
          (``REAL_SENSOR_JITTER_SCALE`` of the default σ, no low-pass, no speed term, as large on inferred joints),
          bone-length noise 0.3 %, inferred joints that snap and drift less (``snap_weight`` 0.2, drift 2 cm) and
          a higher ``hidden_coverage`` (0.5), no NOT_TRACKED runs, and leg swaps 50 times rarer; the surface bias
          and joint offsets are the default's, so the raw error is lower (about 9 cm on HDM05).
        """
        if name == "mean_error":
            return cls()
        if name == "msr_steadiness":
            base = cls().sensor_noise_scaled(0.1)
            return replace(base, surface_radius_m={k: v * 1.15 for k, v in base.surface_radius_m.items()})
        if name == "real_sensor":
            return replace(
                cls().sensor_noise_scaled(REAL_SENSOR_JITTER_SCALE),
                jitter_time_constant_s=0.0,
                speed_jitter_s=0.0,
                inferred_jitter_factor=1.0,
                bone_length_sigma=0.003,
                hidden_coverage=0.5,
                snap_weight=0.2,
                inferred_drift_m=0.02,
                not_tracked_probability=0.0,
                leg_swap_rate_facing_hz=0.002,
                leg_swap_rate_side_hz=0.03,
            )
        raise ValueError(f"unknown Kinect noise preset {name!r}; known: {NOISE_PRESETS}")

    def per_joint(self, table: str) -> np.ndarray:
        """The body-part table ``table`` (e.g. ``"surface_radius_m"``) spread over the 20 joints: ``[20]`` or
        ``[20, 3]``."""
        values = getattr(self, table)
        return np.array([values[part] for part in _PART], dtype=np.float64)


class KinectInputError(ValueError):
    """A motion that cannot be turned into a Kinect-20 skeleton; the message names the file."""


# ---------------------------------------------------------------------------------------------------- input


def _label(motion: Motion) -> str:
    return str(motion.source or motion.name or "motion")


def kinect20_from_motion(motion: Motion, fps: float | None = 30.0) -> np.ndarray:
    """The Kinect v1 20-joint skeleton of ``motion``: float32 ``[T, 20, 3]``, metres, y up, at ``fps`` (None keeps the
    motion's rate), joints in :data:`KINECT20_NAMES` order (body landmarks of
    :func:`~mocapkit.motion.geometry.landmark_positions`, so any layout it knows works).

    Raises:
        KinectInputError (a ValueError): no body landmarks, a landmark missing or unobserved in some frame,
            non-finite values, or no frame; the message names the file.
    """
    if fps is not None and float(fps) != motion.fps:
        motion = motion.resample(float(fps))
    label = _label(motion)
    if motion.num_frames == 0:
        raise KinectInputError(f"{label}: no frames")
    try:
        positions, observed = landmark_positions(motion)
    except ValueError as exc:  # SkeletonInputError names the file already
        raise KinectInputError(str(exc) if label in str(exc) else f"{label}: {exc}") from exc
    if not observed.all():
        unseen = [LANDMARK_NAMES[k] for k in np.flatnonzero(~observed.all(axis=0))]
        frames = int((~observed).any(axis=1).sum())
        raise KinectInputError(
            f"{label}: landmarks {unseen} are missing or unobserved in {frames} of "
            f"{motion.num_frames} frames; the Kinect simulator needs every landmark in every frame"
        )
    if not np.isfinite(positions).all():
        raise KinectInputError(f"{label}: non-finite landmark positions")
    return to_y_up(positions, motion.up_axis).astype(np.float32)


def _check_positions(positions: np.ndarray) -> np.ndarray:
    p = np.asarray(positions)
    if p.ndim != 3 or p.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"positions must be [frames, {NUM_JOINTS}, 3] (Kinect-20, metres, y up), got {list(p.shape)}")
    if len(p) == 0:
        raise ValueError("positions have no frames")
    if not np.isfinite(p).all():
        raise ValueError("positions must be finite")
    return p.astype(np.float64)


# ---------------------------------------------------------------------------------------------------- geometry


def _unit(v: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps)


def _torso_frames(clean: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame torso frame of clean y-up landmarks ``[T, 20, 3]``: ``(right, up, forward)``, each ``[T, 3]`` unit.

    ``up`` is pelvis → neck, ``right`` the hip line (left → right) made orthogonal to it, ``forward = up × right``
    (a body facing +z with y up has right = −x)."""
    up = _unit(clean[:, _NECK] - clean[:, _PELVIS])
    hips = clean[:, _R_HIP] - clean[:, _L_HIP]
    right = hips - (hips * up).sum(-1, keepdims=True) * up
    degenerate = np.linalg.norm(right, axis=-1) < 1e-6
    right[degenerate] = np.array([-1.0, 0.0, 0.0])
    right = _unit(right)
    return right, up, np.cross(up, right)


@dataclass(frozen=True)
class VirtualCamera:
    """A pinhole depth camera in the world frame (metres, y up).

    Attributes:
        position: ``[3]`` camera centre.
        look_at: ``[3]`` point on the optical axis.
        field_of_view_deg: horizontal and vertical field of view, degrees.
    """

    position: np.ndarray
    look_at: np.ndarray
    field_of_view_deg: tuple[float, float] = (57.0, 43.0)

    @property
    def axes(self) -> np.ndarray:
        """``[3, 3]`` rows: camera right, up, forward (optical axis), unit vectors in world coordinates."""
        forward = _unit(np.asarray(self.look_at, float) - np.asarray(self.position, float))
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right = _unit(right) if np.linalg.norm(right) > 1e-9 else np.array([1.0, 0.0, 0.0])
        return np.stack([right, np.cross(right, forward), forward])

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points ``[..., 3]`` → camera coordinates ``[..., 3]`` (x right, y up, z depth along the axis)."""
        return (np.asarray(points, float) - self.position) @ self.axes.T

    def in_view(self, points: np.ndarray) -> np.ndarray:
        """bool ``[...]``: the world points lie in front of the camera and inside its field of view."""
        c = self.to_camera(points)
        half_w, half_h = (math.tan(math.radians(a) / 2) for a in self.field_of_view_deg)
        z = c[..., 2]
        return (z > 0.05) & (np.abs(c[..., 0]) <= z * half_w) & (np.abs(c[..., 1]) <= z * half_h)


def place_camera(
    positions: np.ndarray, config: KinectNoiseConfig | None = None, seed: int | np.random.SeedSequence | None = 0
) -> VirtualCamera:
    """The per-clip :class:`VirtualCamera` for clean Kinect-20 ``positions`` ``[T, 20, 3]`` (m, y up): distance and
    facing yaw drawn from ``config``'s ranges, stepping back until the pelvis stays far enough and in view. It is the
    camera ``simulate_kinect(positions, config, seed)`` uses for the same int or SeedSequence ``seed``."""
    return _draw_camera(_check_positions(positions), config or KinectNoiseConfig(), _component_streams(seed)[0])


def _draw_camera(clean: np.ndarray, cfg: KinectNoiseConfig, rng: np.random.Generator) -> VirtualCamera:
    distance = rng.uniform(*cfg.camera_distance_m)
    yaw = math.radians(rng.uniform(*cfg.facing_yaw_deg))
    return _camera(clean, cfg, distance, yaw)


def _camera(clean: np.ndarray, cfg: KinectNoiseConfig, distance: float, yaw: float) -> VirtualCamera:
    centre = clean[:, _PELVIS].mean(axis=0)
    floor = clean[:, _FEET, 1].min()
    look_at = np.array([centre[0], 0.5 * (floor + np.percentile(clean[..., 1].max(axis=1), 95)), centre[2]])
    mean_facing = facing_direction(clean, _L_HIP, _R_HIP).mean(axis=0)
    heading = float(direction_yaw(mean_facing)) if np.linalg.norm(mean_facing) > 1e-6 else 0.0
    direction = np.array([math.sin(heading + yaw), 0.0, math.cos(heading + yaw)])  # subject → camera
    pelvis = clean[:, _PELVIS]
    half_width = math.tan(math.radians(cfg.field_of_view_deg[0]) / 2)
    while True:
        position = centre + distance * direction
        position[1] = floor + cfg.camera_height_m
        camera = VirtualCamera(position, look_at, tuple(cfg.field_of_view_deg))
        c = camera.to_camera(pelvis)
        too_near = np.hypot(c[:, 0], c[:, 2]).min() < cfg.min_subject_distance_m
        pelvis_out = (np.abs(c[:, 0]) > c[:, 2] * half_width * 0.95).any()
        body_out = (~camera.in_view(clean)).mean() > cfg.max_out_of_view_share
        if not (too_near or pelvis_out or body_out) or distance >= cfg.max_camera_distance_m:
            return camera
        distance = min(distance + 0.1, cfg.max_camera_distance_m)


def _segment_closest(
    p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray, eps: float = 1e-12
) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segments ``p1q1`` and ``p2q2`` (broadcast ``[..., 3]``): ``(s, t)`` parameters in [0, 1]
    along each (Ericson, Real-Time Collision Detection §5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = (d1 * d1).sum(-1)
    e = (d2 * d2).sum(-1)
    f = (d2 * r).sum(-1)
    c = (d1 * r).sum(-1)
    b = (d1 * d2).sum(-1)
    a, e, f, c, b = np.broadcast_arrays(a, e, f, c, b)
    a_safe, e_safe = np.maximum(a, eps), np.maximum(e, eps)
    denom = a * e - b * b
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.maximum(denom, eps), 0.0, 1.0), 0.0)
    t = (b * s + f) / e_safe
    s = np.where(t < 0, np.clip(-c / a_safe, 0.0, 1.0), np.where(t > 1, np.clip((b - c) / a_safe, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments (points)
    t = np.where(e <= eps, 0.0, t)
    s = np.where(e <= eps, np.clip(-c / a_safe, 0.0, 1.0), s)
    s = np.where(a <= eps, 0.0, s)
    t = np.where(a <= eps, np.clip(f / e_safe, 0.0, 1.0), t)
    return s, t


def _point_segment_distance(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(((point - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(point - (a + t[..., None] * ab), axis=-1)


#: Sample points of a joint's visible disc, in units of its radius: the centre and a ring of six at 0.7
#: (about equal areas), ``[S, 2]``.
_DISC_SAMPLES = np.concatenate(
    [[[0.0, 0.0]], 0.7 * np.stack([np.cos(np.arange(6) * np.pi / 3), np.sin(np.arange(6) * np.pi / 3)], axis=-1)]
)


def self_occlusion(
    positions: np.ndarray, camera: VirtualCamera, config: KinectNoiseConfig | None = None, chunk_frames: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """Which joints the depth camera cannot see, and where the view ray meets the occluder.

    Each joint's body part is a disc of ``visible_radius_m`` facing the camera at the joint's visible surface (the
    joint moved towards the camera by its ``surface_radius_m``), sampled at 7 points. A sample is covered when the
    camera ray to it passes through a body capsule that neither ends at the joint nor contains it (for the trunk
    joints, the trunk never hides them). A joint is hidden when at least ``hidden_coverage`` of its samples are
    covered (a thin forearm in front of the trunk does not hide the Spine; the trunk in front of a hand does), when a
    limb joint (elbow, wrist, hand, knee, ankle, foot) is within ``contact_margin_m`` of such a capsule's surface
    (touching parts merge in the depth image), or when the joint is outside the field of view.

    Args:
        positions: clean Kinect-20 landmarks ``[T, 20, 3]``, metres, y up.
        camera: the virtual camera.
        config: capsule radii, joint surface and visible radii, coverage threshold, field of view.
        chunk_frames: frames per vectorised block (memory bound).

    Returns:
        ``(hidden [T, 20] bool, hit_distance [T, 20] float64 m)``: hit_distance = distance from the camera to the
        nearest covering occluder's surface along a covered sample's ray (inf where no sample is covered).
    """
    cfg = config or KinectNoiseConfig()
    clean = _check_positions(positions)
    cam = np.asarray(camera.position, float)
    radius = np.array([cfg.capsule_radius_m[name] for name in CAPSULES])  # [C]
    surface_radius = cfg.per_joint("surface_radius_m")
    visible_radius = cfg.per_joint("visible_radius_m")
    hidden = np.zeros(clean.shape[:2], dtype=bool)
    hit_distance = np.full(clean.shape[:2], np.inf)
    for lo in range(0, len(clean), chunk_frames):
        p = clean[lo : lo + chunk_frames]  # [t, J, 3]
        ray_length = np.linalg.norm(p - cam, axis=-1)
        ray_dir = (p - cam) / np.maximum(ray_length, 1e-9)[..., None]
        across = np.cross(ray_dir, [0.0, 1.0, 0.0])
        across = np.where(np.linalg.norm(across, axis=-1, keepdims=True) > 1e-6, across, [1.0, 0.0, 0.0])
        across = _unit(across)
        upward = np.cross(across, ray_dir)
        surface = p - ray_dir * np.minimum(surface_radius, 0.5 * ray_length)[..., None]
        offsets = visible_radius[:, None, None] * (
            _DISC_SAMPLES[None, None, :, :1] * across[:, :, None]
            + _DISC_SAMPLES[None, None, :, 1:] * upward[:, :, None]
        )
        samples = surface[:, :, None] + offsets  # [t, J, S, 3]
        cap_a = p[:, _CAP_A][:, None, None]  # [t, 1, 1, C, 3]
        cap_b = p[:, _CAP_B][:, None, None]
        ends = samples[..., None, :]  # [t, J, S, 1, 3]
        s, t = _segment_closest(cam, ends, cap_a, cap_b)  # [t, J, S, C]
        on_ray = cam + (ends - cam) * s[..., None]
        gap = np.linalg.norm(on_ray - (cap_a + (cap_b - cap_a) * t[..., None]), axis=-1)
        contains = _point_segment_distance(p[:, :, None], p[:, None, _CAP_A], p[:, None, _CAP_B]) < radius
        candidate = (~contains & ~_CAP_IGNORED[None])[:, :, None, :]  # [t, J, 1, C]
        blocked = candidate & (gap < radius)  # [t, J, S, C]
        covered = blocked.any(axis=-1)  # [t, J, S]
        clearance = _point_segment_distance(p[:, :, None], p[:, None, _CAP_A], p[:, None, _CAP_B]) - radius
        touching = (candidate[:, :, 0] & (clearance < cfg.contact_margin_m)).any(axis=-1) & _LIMB_JOINT
        hidden[lo : lo + len(p)] = (covered.mean(axis=-1) >= cfg.hidden_coverage - 1e-9) | touching
        along = s * np.linalg.norm(ends - cam, axis=-1)
        entry = np.maximum(along - np.sqrt(np.maximum(radius**2 - gap**2, 0.0)), 0.0)
        hit_distance[lo : lo + len(p)] = np.where(blocked, entry, np.inf).min(axis=(-1, -2))
    hidden |= ~camera.in_view(clean)
    return hidden, hit_distance


# ---------------------------------------------------------------------------------------------------- noise


def _component_streams(seed: int | np.random.Generator | np.random.SeedSequence | None) -> list[np.random.Generator]:
    """One independent generator per random part (camera, occlusion, swaps, bones, depth, jitter)."""
    if isinstance(seed, np.random.Generator):
        seed = int(seed.integers(2**63))
    sequence = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return [np.random.default_rng(child) for child in sequence.spawn(6)]


def _lowpass_noise(rng: np.random.Generator, shape: tuple[int, ...], fps: float, time_constant_s: float) -> np.ndarray:
    """Stationary unit-variance first-order low-pass (AR(1)) Gaussian noise along axis 0 of ``shape``."""
    white = rng.standard_normal(shape)
    if time_constant_s <= 0 or shape[0] < 2:
        return white
    a = math.exp(-1.0 / (fps * time_constant_s))
    b = math.sqrt(1.0 - a * a)
    return lfilter([b], [1.0, -a], white, axis=0, zi=(1.0 - b) * white[:1])[0]


def _infer_hidden(
    est: np.ndarray,
    hidden: np.ndarray,
    hit_distance: np.ndarray,
    clean: np.ndarray,
    camera: VirtualCamera,
    cfg: KinectNoiseConfig,
    fps: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Replace hidden joints of ``est`` by the Kinect's guess; states INFERRED / NOT_TRACKED (module docstring d)."""
    T = len(est)
    drift_noise = cfg.inferred_drift_m * _lowpass_noise(
        rng, (T, NUM_JOINTS, 3), fps, cfg.inferred_drift_time_constant_s
    )
    run_draws = rng.random((T, NUM_JOINTS))
    state = np.where(hidden, INFERRED, TRACKED).astype(np.int8)
    if not hidden.any():
        return est, state
    out = est.copy()
    cam = np.asarray(camera.position, float)
    ray_dir = _unit(clean - cam)
    frames = np.arange(T)
    after = max(int(np.rint(cfg.not_tracked_after_s * fps)), 1)
    for j in range(NUM_JOINTS):  # parents come first, so a hidden parent is already replaced
        h = hidden[:, j]
        if not h.any():
            continue
        last_seen = np.maximum.accumulate(np.where(h, -1, frames))
        reference = np.maximum(last_seen, 0)
        parent = _PARENTS[j]
        if parent < 0:
            hold = est[reference, j]
        else:
            hold = out[:, parent] + (est[reference, j] - out[reference, parent])
        hidden_for = (frames - last_seen) / (fps * max(cfg.inferred_drift_time_constant_s, 1e-9))  # in time constants
        drift = drift_noise[:, j] * -np.expm1(-hidden_for)[:, None]
        snapped = np.isfinite(hit_distance[:, j])
        snap = cam + ray_dir[:, j] * np.where(snapped, hit_distance[:, j], 0.0)[:, None]
        weight = np.where(snapped, cfg.snap_weight, 0.0)[:, None]
        guess = weight * snap + (1.0 - weight) * hold + drift
        out[h, j] = guess[h]
        for start, stop in true_runs(h):
            if stop - start > after and run_draws[start, j] < cfg.not_tracked_probability:
                state[start + after : stop, j] = NOT_TRACKED
    return out, state


def _swap_runs(
    rate_hz: np.ndarray, fps: float, duration_s: tuple[float, float], draws: np.ndarray, lengths_s: np.ndarray
) -> np.ndarray:
    """bool ``[T]``: frames inside a swap run; runs start with probability ``1 − exp(−rate/fps)`` per frame."""
    start = draws < -np.expm1(-rate_hz / fps)
    swapped = np.zeros(len(rate_hz), dtype=bool)
    for t in np.flatnonzero(start):
        swapped[t : t + max(int(np.rint(lengths_s[t] * fps)), 1)] = True
    return swapped


def _swap_sides(
    est: np.ndarray,
    state: np.ndarray,
    clean: np.ndarray,
    camera: VirtualCamera,
    cfg: KinectNoiseConfig,
    fps: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Left/right confusions (module docstring g)."""
    T = len(est)
    draws = rng.random((T, 2))
    lengths = rng.uniform(*cfg.swap_duration_s, size=(T, 2))
    to_camera = np.asarray(camera.position, float) - clean[:, _PELVIS]
    to_camera[:, 1] = 0.0
    cos_angle = (facing_direction(clean, _L_HIP, _R_HIP) * _unit(to_camera)).sum(-1).clip(-1.0, 1.0)
    side_on = 1.0 - cos_angle**2  # sin² of the angle
    leg_rate = cfg.leg_swap_rate_facing_hz + (cfg.leg_swap_rate_side_hz - cfg.leg_swap_rate_facing_hz) * side_on
    arm_rate = cfg.arm_swap_rate_facing_hz + (cfg.arm_swap_rate_side_hz - cfg.arm_swap_rate_facing_hz) * side_on
    legs = _swap_runs(leg_rate, fps, cfg.swap_duration_s, draws[:, 0], lengths[:, 0])
    arms = _swap_runs(arm_rate, fps, cfg.swap_duration_s, draws[:, 1], lengths[:, 1])
    mirrored = np.zeros(T, dtype=bool)
    if cfg.back_facing_mirror_deg is not None:
        mirrored = np.degrees(np.arccos(cos_angle)) > cfg.back_facing_mirror_deg
    swap = np.zeros((T, NUM_JOINTS), dtype=bool)  # swap[t, left joint] flips the pair
    for left, _ in _LEG_PAIRS:
        swap[:, left] ^= legs
    for left, _ in _ARM_PAIRS:
        swap[:, left] ^= arms
    for left, _ in _ALL_PAIRS:
        swap[:, left] ^= mirrored
    out, new_state = est.copy(), state.copy()
    for left, right in _ALL_PAIRS:
        f = swap[:, left]
        out[f, left], out[f, right] = est[f, right], est[f, left]
        new_state[f, left], new_state[f, right] = state[f, right], state[f, left]
    return out, new_state


def _jitter_bone_lengths(est: np.ndarray, cfg: KinectNoiseConfig, fps: float, rng: np.random.Generator) -> np.ndarray:
    """Every bone length times ``1 + σ·n(t)`` (low-pass n), children carried along (module docstring f)."""
    scale = 1.0 + cfg.bone_length_sigma * _lowpass_noise(
        rng, (len(est), NUM_JOINTS), fps, cfg.bone_length_time_constant_s
    )
    out = est.copy()
    for j, parent in enumerate(LANDMARK_PARENTS):
        if parent >= 0:
            out[:, j] = out[:, parent] + (est[:, j] - est[:, parent]) * scale[:, j, None]
    return out


def simulate_kinect(
    positions: np.ndarray,
    config: KinectNoiseConfig | None = None,
    seed: int | np.random.Generator | np.random.SeedSequence | None = 0,
    fps: float = 30.0,
    camera: VirtualCamera | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Kinect v1 view of clean Kinect-20 landmarks (module docstring a–g).

    Args:
        positions: ``[T, 20, 3]`` clean landmarks in :data:`KINECT20_NAMES` order, metres, y up (e.g. from
            :func:`kinect20_from_motion`).
        config: the error model (default: the calibrated Kinect v1 level).
        seed: everything random derives from it (an int, a SeedSequence, or a Generator that is drawn from once).
        fps: frame rate of ``positions`` (time constants, rates and drift are per second).
        camera: a given camera instead of the per-clip random one of :func:`place_camera`.

    Returns:
        ``(noisy, state)``: float32 ``[T, 20, 3]`` metres, y up, in the input's world frame; int8 ``[T, 20]`` with
        :data:`TRACKED` / :data:`INFERRED` / :data:`NOT_TRACKED`.
    """
    cfg = config or KinectNoiseConfig()
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    clean = _check_positions(positions)
    T = len(clean)
    camera_rng, occlusion_rng, swap_rng, bone_rng, depth_rng, jitter_rng = _component_streams(seed)
    if camera is None:
        camera = _draw_camera(clean, cfg, camera_rng)
    est = clean.copy()
    state = np.full((T, NUM_JOINTS), TRACKED, dtype=np.int8)
    if cfg.joint_offsets:
        right, up, forward = _torso_frames(clean)
        offset = cfg.per_joint("joint_offset_m")  # [J, 3]
        outward = offset[:, 0] * np.where(_SIDE == 0, 0.0, -_SIDE)  # left joints: −right
        est += (
            outward[None, :, None] * right[:, None]
            + offset[None, :, 1, None] * up[:, None]
            + offset[None, :, 2, None] * forward[:, None]
        )
    if cfg.surface_bias:
        est += cfg.per_joint("surface_radius_m")[None, :, None] * _unit(camera.position - est)
    if cfg.occlusion:
        hidden, hit_distance = self_occlusion(clean, camera, cfg)
        if cfg.upright_limit_deg is not None:
            tilt = np.degrees(np.arccos(np.clip(_torso_frames(clean)[1][:, 1], -1.0, 1.0)))  # [T]
            hidden |= (tilt > cfg.upright_limit_deg)[:, None] & _LIMB_JOINT[None]
        est, state = _infer_hidden(est, hidden, hit_distance, clean, camera, cfg, fps, occlusion_rng)
    if cfg.swaps:
        est, state = _swap_sides(est, state, clean, camera, cfg, fps, swap_rng)
    if cfg.bone_jitter and cfg.bone_length_sigma > 0:
        est = _jitter_bone_lengths(est, cfg, fps, bone_rng)
    if cfg.depth_noise and cfg.depth_sigma_at_1m_m > 0:
        depth = camera.to_camera(est)[..., 2]
        ray = _unit(est - camera.position)
        est = est + (cfg.depth_sigma_at_1m_m * depth**2 * depth_rng.standard_normal((T, NUM_JOINTS)))[..., None] * ray
    if cfg.jitter:
        sigma = cfg.per_joint("jitter_sigma_m")[None, :] * np.where(state == TRACKED, 1.0, cfg.inferred_jitter_factor)
        if T > 1 and cfg.speed_jitter_s > 0:
            sigma = sigma + cfg.speed_jitter_s * np.linalg.norm(np.gradient(clean, axis=0), axis=-1) * fps
        est = est + sigma[..., None] * _lowpass_noise(jitter_rng, (T, NUM_JOINTS, 3), fps, cfg.jitter_time_constant_s)
    return est.astype(np.float32), state


# ---------------------------------------------------------------------------------------------------- batches


def file_seed(seed: int, path: str | os.PathLike) -> np.random.SeedSequence:
    """The seed of one file in :func:`simulate_pairs`: from ``seed`` and the file name, so it does not depend on
    which other files are simulated or in what order."""
    return np.random.SeedSequence([int(seed), zlib.crc32(Path(path).name.encode())])


@dataclass(frozen=True)
class KinectPair:
    """One simulated clip: ``clean`` and ``noisy`` float32 ``[T, 20, 3]`` (m, y up), ``state`` int8 ``[T, 20]``."""

    path: Path
    clean: np.ndarray
    noisy: np.ndarray
    state: np.ndarray

    def __iter__(self):
        """Unpacks as ``clean, noisy, state``."""
        return iter((self.clean, self.noisy, self.state))


def simulate_pairs(
    paths: Iterable[str | os.PathLike],
    config: KinectNoiseConfig | None = None,
    seed: int = 0,
    fps: float = 30.0,
    skip_bad: bool = False,
    progress: bool | None = None,
) -> tuple[list[KinectPair], list[tuple[Path, str]]]:
    """(mocap, simulated Kinect) pairs of motion files: read, :func:`kinect20_from_motion`, :func:`simulate_kinect`
    with :func:`file_seed`.

    Args:
        paths: motion files :func:`~mocapkit.datasets.formats.motion_io.read_motion` reads.
        config: the error model (default: calibrated).
        seed: base seed.
        fps: output frame rate.
        skip_bad: skip unreadable or unusable files (each reported: returned and warned) instead of raising.
        progress: tqdm bar (default: when more than 20 files).

    Returns:
        ``(pairs, skipped)``: one :class:`KinectPair` per good file, in order; ``(path, reason)`` per skipped file.

    Raises:
        KinectInputError: a file that cannot be read or used, naming it (unless ``skip_bad``).
    """
    from mocapkit.datasets.formats.motion_io import read_motion

    paths = [Path(p) for p in paths]
    iterator: Sequence[Path] = paths
    if progress if progress is not None else len(paths) > 20:
        from tqdm import tqdm

        iterator = tqdm(paths, desc="kinect noise", unit="file")
    pairs: list[KinectPair] = []
    skipped: list[tuple[Path, str]] = []
    for path in iterator:
        try:
            clean = kinect20_from_motion(read_motion(path), fps=fps)
        except (OSError, ValueError) as exc:
            reason = str(exc) if str(path) in str(exc) else f"{path}: {exc}"
            if not skip_bad:
                raise KinectInputError(reason) from exc
            warnings.warn(f"simulate_pairs skipped {reason}", stacklevel=2)
            skipped.append((path, reason))
            continue
        noisy, state = simulate_kinect(clean, config, seed=file_seed(seed, path), fps=fps)
        pairs.append(KinectPair(path, clean, noisy, state))
    return pairs, skipped


__all__ = [
    "CAPSULES",
    "COMPONENTS",
    "INFERRED",
    "KINECT20_NAMES",
    "NOT_TRACKED",
    "TRACKED",
    "KinectInputError",
    "KinectNoiseConfig",
    "KinectPair",
    "VirtualCamera",
    "file_seed",
    "kinect20_from_motion",
    "place_camera",
    "self_occlusion",
    "simulate_kinect",
    "simulate_pairs",
]
