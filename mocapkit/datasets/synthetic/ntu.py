"""A synthetic stand-in for NTU RGB+D: real ``.skeleton`` files of keyframed whole-body actions.

The map, from one sample name ``SsssCcccPpppRrrrAaaa`` to its file:

1. **Action** (``A``): a table entry of :data:`ACTIONS`, keyframed poses of named
   degrees of freedom (:data:`~mocapkit.datasets.synthetic.kinematics.DOF_NAMES`, degrees /
   metres) for one actor, plus a partner for the two-person interactions.
2. **Performance** (``S``, ``P``, ``R``, ``A``; shared by the three cameras, which
   film it at the same time, like NTU): the subject's body proportions, tempo,
   amplitude and persistent style (posture offsets, a time warp and a personal way
   of doing each action) plus per-sample noise perturb the keyframes; smooth cubic
   interpolation gives ``[T, DOF]`` trajectories; forward kinematics
   (:mod:`mocapkit.datasets.synthetic.kinematics`) gives ``[T, 25, 3]`` joint positions, feet
   kept on the floor (``y = 0``) and placed in the room.
3. **Camera** (``S``, ``C``): setups fix camera height and distance, cameras fix the
   azimuth (C001 in front, C002 / C003 at +45° / −45°); positions go to Kinect
   camera space (metres; ``x`` horizontal, ``y`` up, ``z`` depth away from the camera).
4. **Sensor** (per camera): Gaussian jitter, frames with no body, and sometimes a
   spurious extra body (a chair-like blob, wider than tall, or a passer-by seen
   for fewer than 12 frames).
5. :func:`~mocapkit.datasets.formats.ntu_skeleton.sequence_from_positions` +
   :func:`~mocapkit.datasets.formats.ntu_skeleton.write_skeleton` write the file.

Every random draw comes from a numpy ``SeedSequence`` keyed by the seed and the
sample's fields, so files are byte-identical for any ``workers`` and any subset
of the configuration lists.

Difficulty: the defaults are calibrated so a simple baseline (logistic
regression on root-centred, time-pooled joint statistics; see
``scripts/selection/calibrate_synth_ntu.py``) reaches roughly 55–85 % on held-out subjects
(chance is ``1 / num_classes``); ``difficulty`` scales all the human variation at once.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.ntu_skeleton import (
    NTUSampleName,
    SkeletonSequence,
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.datasets.parallel import write_all
from mocapkit.datasets.synthetic import kinematics as kin
from mocapkit.datasets.synthetic.config import FieldCheck, SynthConfig
from mocapkit.datasets.synthetic.kinematics import DOF_NAMES, J

FPS = 30.0
_DOF = {name: k for k, name in enumerate(DOF_NAMES)}
_JOINT_COLS = np.array([k for k, n in enumerate(DOF_NAMES) if n in kin.DOFS])
_KINECT_ID_BASE = 72057594037927936  # 2**56: real Kinect v2 tracking IDs are just above it


# --------------------------------------------------------------------------- configuration


@dataclass
class NTUSynthConfig(SynthConfig):
    """What :func:`synthesize_ntu` generates. One file per (setup, camera, subject, replication, action).

    Dataset shape:
        num_classes: actions ``A001..`` taken in order from :data:`ACTIONS` (1–20).
        num_subjects: subjects ``P001..P{S}``; each has its own body, tempo and style.
        setups: setup numbers; each fixes camera height and distance (see :func:`camera_rig`).
        cameras: subset of (1, 2, 3): C001 in front of the actor, C002 / C003 at +45° / −45°.
        replications: each replication is a new performance (new noise), facing
            slightly towards C002 (odd) or C003 (even), like NTU.
        seed: everything random derives from it.

    Human variation (degrees are joint angles):
        style_noise: std of each subject's persistent style, degrees: posture offsets
            on every joint angle and the subject's own way of doing each action
            (offsets to the keyframed angles). The main cross-subject difficulty knob.
        sample_noise: std of per-sample deviations of the keyframed angles, degrees;
            slow wobble of every joint angle has half this amplitude.
        tempo_spread: std of log tempo per subject (per sample: half of it).
        amplitude_spread: std of the motion amplitude factor per subject and again per
            (subject, action); per sample half of it.
        difficulty: multiplies the four knobs above and the personal time warp and
            keyframe timing shifts (0 = every subject moves like the template, with only
            body size, facing, view and sensor effects left). The strongest single knob.
        height_range_m: subjects' standing heights, uniform in this range, metres.
        facing_spread_deg: std of the actor's facing direction per sample, degrees
            (around ±15° towards C002 / C003 by replication; not scaled by ``difficulty``).
        length_scale: multiplies every action's duration (default lengths are about
            40–120 frames at 30 fps); tests use small values for speed.

    Sensor artefacts (per camera):
        jitter_m: std of Gaussian noise per joint per frame, metres (hand tips and
            thumbs get twice this, as Kinect tracks them worst).
        drop_frame_prob: expected fraction of frames in which the sensor loses every
            body (body count 0), in bursts of 1–3 frames.
        extra_body_prob: probability that a camera also reports a spurious body: half
            the time a static chair-like blob (wider than tall, so spread denoising
            drops it), otherwise a passer-by in the background seen for 6–11 frames
            (fewer than pyskl's 12, so ``min_frames=12`` drops it).
    """

    num_classes: int = 12
    num_subjects: int = 10
    setups: tuple[int, ...] = (1, 2)
    cameras: tuple[int, ...] = (1, 2, 3)
    replications: tuple[int, ...] = (1, 2)
    seed: int = 0
    style_noise: float = 25.0
    sample_noise: float = 12.0
    tempo_spread: float = 0.15
    amplitude_spread: float = 0.2
    difficulty: float = 1.0
    height_range_m: tuple[float, float] = (1.5, 1.9)
    facing_spread_deg: float = 12.0
    length_scale: float = 1.0
    jitter_m: float = 0.012
    drop_frame_prob: float = 0.02
    extra_body_prob: float = 0.1

    def __post_init__(self) -> None:
        for name in ("setups", "cameras", "replications", "height_range_m"):
            setattr(self, name, tuple(getattr(self, name)))
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad field."""
        check = FieldCheck(self)
        check.integer("num_classes", 1, len(ACTIONS))
        check.integer("num_subjects", 1, 999)
        for name in ("setups", "replications"):
            check.distinct(
                name,
                lambda v: isinstance(v, (int, np.integer)) and 1 <= v <= 999,
                "must be a non-empty tuple of distinct integers in 1..999",
            )
        check.distinct(
            "cameras", lambda v: v in (1, 2, 3), "must be a non-empty tuple of distinct values from (1, 2, 3)"
        )
        check.seed()
        check.non_negative(
            "style_noise",
            "sample_noise",
            "tempo_spread",
            "amplitude_spread",
            "difficulty",
            "jitter_m",
            "facing_spread_deg",
        )
        check.probability("drop_frame_prob", "extra_body_prob")
        check.require(
            self.drop_frame_prob <= 0.5, "drop_frame_prob", "must be at most 0.5 (the body must be seen in most frames)"
        )
        lo, hi = self.height_range_m if len(self.height_range_m) == 2 else (0, -1)
        check.require(
            1.0 <= lo <= hi <= 2.3, "height_range_m", "must be (low, high) with 1.0 <= low <= high <= 2.3 metres"
        )
        check.require(0.1 <= self.length_scale <= 5.0, "length_scale", "must be in [0.1, 5]")


# --------------------------------------------------------------------------- the actions

Pose = dict  # DOF name -> value (degrees for joint angles, metres / degrees for root DOFs); missing = rest (0)
Keyframe = tuple  # (u in [0, 1] of the action's duration, Pose)


@dataclass(frozen=True)
class ActionSpec:
    """One action class.

    Attributes:
        name: class name (``classes.txt``).
        frames: duration at tempo 1 at 30 fps, idle padding excluded.
        actor: keyframes of the main actor; each keyframe is a complete pose
            (DOFs it does not name are at rest). The first and last should be rest-like.
        partner: keyframes of the second person, for two-person interactions.
        plant: which foot stays where it is ("both" = midpoint of the ankles, "left",
            "right"); root DOFs move the body on top of that.
    """

    name: str
    frames: int
    actor: tuple
    partner: tuple | None = None
    plant: str = "both"

    @property
    def two_person(self) -> bool:
        return self.partner is not None


def _both(**pose) -> Pose:
    """Expand ``shoulder_flex=40`` into ``l_shoulder_flex=40, r_shoulder_flex=40`` (root/spine DOFs kept)."""
    out = {}
    for k, v in pose.items():
        if k in _DOF:
            out[k] = v
        else:
            out["l_" + k] = v
            out["r_" + k] = v
    return out


def _oscillate(u0: float, u1: float, n: int, a: Pose, b: Pose) -> list:
    """``n`` keyframes evenly spaced in ``[u0, u1]`` alternating between poses ``a`` and ``b``."""
    return [(u, dict(a if k % 2 == 0 else b)) for k, u in enumerate(np.linspace(u0, u1, n).tolist())]


REST: Pose = {}
_GUARD = _both(shoulder_flex=40, elbow=110, shoulder_abd=10)
_SEATED = {**_both(hip_flex=90, knee=90, shoulder_flex=25, elbow=45, hip_abd=6), "spine_bend": 8}
_SQUAT = {**_both(hip_flex=105, knee=125, ankle=-30, shoulder_flex=75, elbow=10), "spine_bend": 25}
_WAVE_UP = dict(r_shoulder_abd=85, r_shoulder_twist=80, r_elbow=85)
_SALUTE = dict(r_shoulder_abd=55, r_shoulder_flex=35, r_shoulder_twist=65, r_elbow=140, r_wrist=10)
_CLAP_OPEN = _both(shoulder_flex=50, shoulder_abd=10, elbow=80, shoulder_twist=-5)
_CLAP_SHUT = _both(shoulder_flex=50, shoulder_abd=10, elbow=80, shoulder_twist=-32)
_PUNCH = {
    **_both(shoulder_flex=40, elbow=110, shoulder_abd=10),
    "r_shoulder_flex": 85,
    "r_elbow": 5,
    "r_shoulder_abd": -5,
    "spine_twist": 18,
}
_REACH = dict(r_shoulder_flex=45, r_elbow=35, r_shoulder_abd=-28, spine_twist=8)
_HUG = _both(shoulder_flex=80, shoulder_abd=35, shoulder_twist=-30, elbow=70)


def _actions() -> tuple[ActionSpec, ...]:
    up = _both(shoulder_flex=170, elbow=5)
    walk_a = {
        **_both(knee=10),
        "r_hip_flex": 18,
        "l_hip_flex": -8,
        "l_knee": 25,
        "l_shoulder_flex": 15,
        "r_shoulder_flex": -10,
    }
    walk_b = {
        **_both(knee=10),
        "l_hip_flex": 18,
        "r_hip_flex": -8,
        "r_knee": 25,
        "r_shoulder_flex": 15,
        "l_shoulder_flex": -10,
    }
    return (
        ActionSpec(
            "wave right hand",
            75,
            (
                (0.0, REST),
                (0.2, _WAVE_UP),
                *_oscillate(0.28, 0.72, 5, {**_WAVE_UP, "r_elbow": 55}, {**_WAVE_UP, "r_elbow": 115}),
                (0.82, _WAVE_UP),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "both arms up",
            60,
            (
                (0.0, REST),
                (0.35, {**up, "spine_bend": -8}),
                (0.6, {**up, "spine_bend": -8, "head_nod": -10}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "clap",
            70,
            ((0.0, REST), (0.18, _CLAP_OPEN), *_oscillate(0.26, 0.78, 6, _CLAP_SHUT, _CLAP_OPEN), (1.0, REST)),
        ),
        ActionSpec(
            "punch forward",
            50,
            ((0.0, REST), (0.25, _GUARD), (0.42, _PUNCH), (0.55, _GUARD), (0.72, _GUARD), (1.0, REST)),
        ),
        ActionSpec(
            "point forward",
            60,
            (
                (0.0, REST),
                (0.3, dict(r_shoulder_flex=80, r_elbow=8, r_shoulder_abd=-5, spine_twist=5)),
                (0.7, dict(r_shoulder_flex=84, r_elbow=5, r_shoulder_abd=-8, spine_twist=6)),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "kick forward",
            55,
            (
                (0.0, REST),
                (0.3, {**_both(shoulder_abd=20), "r_hip_flex": 45, "r_knee": 80, "spine_bend": -5}),
                (0.48, {**_both(shoulder_abd=25), "r_hip_flex": 75, "r_knee": 5, "r_ankle": 20, "spine_bend": -12}),
                (0.66, {**_both(shoulder_abd=20), "r_hip_flex": 40, "r_knee": 80}),
                (1.0, REST),
            ),
            plant="left",
        ),
        ActionSpec("squat down", 80, ((0.0, REST), (0.35, _SQUAT), (0.65, {**_SQUAT, "spine_bend": 22}), (1.0, REST))),
        ActionSpec(
            "sit down",
            70,
            (
                (0.0, REST),
                (0.25, {**_both(hip_flex=45, knee=50, shoulder_flex=30), "spine_bend": 30}),
                (0.55, {**_SEATED, "spine_bend": 18}),
                (1.0, _SEATED),
            ),
        ),
        ActionSpec(
            "stand up",
            70,
            (
                (0.0, _SEATED),
                (0.3, {**_SEATED, "spine_bend": 35}),
                (0.6, {**_both(hip_flex=30, knee=35, shoulder_flex=20), "spine_bend": 20}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "handshake",
            75,
            (
                (0.0, REST),
                (0.3, {**_REACH, "root_fwd": 0.25}),
                *_oscillate(
                    0.38,
                    0.66,
                    5,
                    {**_REACH, "root_fwd": 0.25, "r_shoulder_flex": 48},
                    {**_REACH, "root_fwd": 0.25, "r_shoulder_flex": 33},
                ),
                (0.75, {**_REACH, "root_fwd": 0.25}),
                (1.0, REST),
            ),
            partner=(
                (0.0, REST),
                (0.32, {**_REACH, "root_fwd": 0.25}),
                *_oscillate(
                    0.38,
                    0.66,
                    5,
                    {**_REACH, "root_fwd": 0.25, "r_shoulder_flex": 48},
                    {**_REACH, "root_fwd": 0.25, "r_shoulder_flex": 33},
                ),
                (0.75, {**_REACH, "root_fwd": 0.25}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "push other person",
            55,
            (
                (0.0, REST),
                (0.3, {**_both(shoulder_flex=70, elbow=80), "root_fwd": 0.15}),
                (0.45, {**_both(shoulder_flex=80, elbow=10), "root_fwd": 0.35, "spine_bend": 12}),
                (0.65, {**_both(shoulder_flex=40, elbow=30), "root_fwd": 0.35}),
                (1.0, {"root_fwd": 0.25}),
            ),
            partner=(
                (0.0, REST),
                (0.43, REST),
                (
                    0.58,
                    {**_both(shoulder_abd=30, shoulder_flex=20), "root_fwd": -0.35, "spine_bend": -15, "head_nod": 15},
                ),
                (0.75, {**_both(shoulder_abd=10), "root_fwd": -0.45}),
                (1.0, {"root_fwd": -0.45}),
            ),
        ),
        ActionSpec(
            "hug",
            85,
            (
                (0.0, REST),
                (0.3, {**_HUG, "root_fwd": 0.35, "spine_bend": 8}),
                (0.7, {**_HUG, "root_fwd": 0.35, "spine_bend": 10, "r_shoulder_abd": 30}),
                (1.0, REST),
            ),
            partner=(
                (0.0, REST),
                (0.32, {**_HUG, "root_fwd": 0.35, "spine_bend": 8}),
                (0.7, {**_HUG, "root_fwd": 0.35, "spine_bend": 10}),
                (1.0, REST),
            ),
        ),
        # ---- beyond the default 12
        ActionSpec(
            "bow",
            60,
            (
                (0.0, REST),
                (0.4, {**_both(shoulder_flex=-5), "spine_bend": 50, "chest_bend": 12, "head_nod": 10}),
                (0.6, {**_both(shoulder_flex=-5), "spine_bend": 52, "chest_bend": 14, "head_nod": 12}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "jump up",
            45,
            (
                (0.0, REST),
                (0.3, {**_both(hip_flex=45, knee=70, ankle=-20, shoulder_flex=-35), "spine_bend": 20}),
                (0.45, {**_both(shoulder_flex=120, ankle=25), "root_up": 0.25}),
                (0.62, {**_both(hip_flex=40, knee=60, ankle=-15, shoulder_flex=20), "spine_bend": 15}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "turn around",
            80,
            (
                (0.0, REST),
                (0.25, {**walk_a, "root_yaw": 45}),
                (0.45, {**walk_b, "root_yaw": 95}),
                (0.65, {**walk_a, "root_yaw": 140}),
                (0.85, {"root_yaw": 180}),
                (1.0, {"root_yaw": 180}),
            ),
        ),
        ActionSpec(
            "throw",
            55,
            (
                (0.0, REST),
                (0.35, {**_WAVE_UP, "r_elbow": 95, "spine_twist": -25, "spine_bend": -8, "l_shoulder_flex": 40}),
                (
                    0.52,
                    {
                        "r_shoulder_flex": 110,
                        "r_elbow": 10,
                        "spine_twist": 25,
                        "spine_bend": 15,
                        "l_shoulder_flex": -15,
                    },
                ),
                (0.68, {"r_shoulder_flex": 30, "r_elbow": 20, "spine_twist": 20, "spine_bend": 20}),
                (1.0, REST),
            ),
            plant="left",
        ),
        ActionSpec(
            "punch other person",
            50,
            (
                (0.0, REST),
                (0.25, {**_GUARD, "root_fwd": 0.1}),
                (0.42, {**_PUNCH, "root_fwd": 0.25}),
                (0.55, {**_GUARD, "root_fwd": 0.2}),
                (1.0, {"root_fwd": 0.1}),
            ),
            partner=(
                (0.0, REST),
                (0.4, REST),
                (0.5, {"spine_bend": -20, "head_nod": -20, "root_fwd": -0.12, "spine_twist": 15}),
                (0.7, {"spine_bend": -5, "root_fwd": -0.18}),
                (1.0, {"root_fwd": -0.18}),
            ),
        ),
        ActionSpec("salute", 60, ((0.0, REST), (0.3, _SALUTE), (0.7, {**_SALUTE, "head_nod": -5}), (1.0, REST))),
        ActionSpec(
            "pat on back",
            70,
            (
                (0.0, REST),
                (0.3, {"root_fwd": 0.3, "r_shoulder_flex": 70, "r_elbow": 40, "r_shoulder_abd": -20}),
                *_oscillate(
                    0.38,
                    0.7,
                    5,
                    {"root_fwd": 0.3, "r_shoulder_flex": 72, "r_elbow": 25, "r_shoulder_abd": -20},
                    {"root_fwd": 0.3, "r_shoulder_flex": 70, "r_elbow": 60, "r_shoulder_abd": -20},
                ),
                (1.0, REST),
            ),
            partner=(
                (0.0, REST),
                (0.35, {"root_yaw": 30, "root_fwd": 0.1}),
                (0.7, {"root_yaw": 30, "root_fwd": 0.1, "head_nod": 15}),
                (1.0, REST),
            ),
        ),
        ActionSpec(
            "jumping jacks",
            70,
            (
                (0.0, REST),
                *_oscillate(
                    0.15,
                    0.85,
                    4,
                    {**_both(shoulder_abd=165, hip_abd=22, elbow=10), "root_up": 0.08},
                    {**_both(shoulder_abd=15, hip_abd=3), "root_up": 0.0},
                ),
                (1.0, REST),
            ),
        ),
    )


ACTIONS: tuple[ActionSpec, ...] = _actions()


def class_names(num_classes: int) -> list[str]:
    """Names of actions ``A001..A{num_classes}`` (index k = action k+1)."""
    if not isinstance(num_classes, (int, np.integer)) or not 1 <= num_classes <= len(ACTIONS):
        raise ValueError(f"num_classes must be an integer in 1..{len(ACTIONS)}, got {num_classes!r}")
    return [a.name for a in ACTIONS[:num_classes]]


# --------------------------------------------------------------------------- randomness


def _rng(config: NTUSynthConfig, *key: int) -> np.random.Generator:
    """A generator keyed by the seed and integers (stream kind first, then sample fields)."""
    return np.random.default_rng(np.random.SeedSequence([int(config.seed), *map(int, key)]))


# Stream kinds for _rng: which part of the generator a draw belongs to.
_SUBJECT, _SUBJECT_ACTION, _PERFORMANCE, _CAMERA, _PARTNER = 1, 2, 3, 4, 5


@dataclass
class PersonStyle:
    """One person's persistent traits (drawn once per subject).

    Attributes:
        body: segment lengths. tempo: duration multiplier. amplitude: motion multiplier.
        warp: time-warp strength in (-0.6, 0.6); posture: ``[DOF]`` degree offsets added to every frame.
    """

    body: kin.BodyProportions
    tempo: float
    amplitude: float
    warp: float
    posture: np.ndarray


def person_style(config: NTUSynthConfig, rng: np.random.Generator) -> PersonStyle:
    """Draw a person's body and style (see :class:`PersonStyle`)."""
    d = config.difficulty
    height = rng.uniform(*config.height_range_m)
    ratios = 1.0 + np.clip(0.05 * rng.standard_normal(4), -0.12, 0.12)
    body = kin.BodyProportions.from_height(height, ratios)
    tempo = float(np.exp(np.clip(d * config.tempo_spread * rng.standard_normal(), -0.5, 0.5)))
    amplitude = float(np.clip(1.0 + d * config.amplitude_spread * rng.standard_normal(), 0.6, 1.4))
    warp = float(np.clip(0.3 * d * rng.standard_normal(), -0.6, 0.6))
    posture = np.zeros(len(DOF_NAMES))
    posture[_JOINT_COLS] = 0.5 * d * config.style_noise * rng.standard_normal(len(_JOINT_COLS))
    return PersonStyle(body, tempo, amplitude, warp, posture)


# --------------------------------------------------------------------------- trajectories


def keyframe_matrix(keyframes) -> tuple[np.ndarray, np.ndarray]:
    """Keyframes → times ``[K]`` in [0, 1] and values ``[K, DOF]`` (columns in :data:`DOF_NAMES` order)."""
    times = np.array([u for u, _ in keyframes], dtype=float)
    values = np.zeros((len(keyframes), len(DOF_NAMES)))
    for k, (_, pose) in enumerate(keyframes):
        for name, v in pose.items():
            if name not in _DOF:
                raise KeyError(f"unknown DOF {name!r} in a keyframe")
            values[k, _DOF[name]] = v
    if times[0] != 0.0 or times[-1] != 1.0 or np.any(np.diff(times) <= 0):
        raise ValueError(f"keyframe times must increase from 0 to 1, got {times.tolist()}")
    return times, values


def interpolate(times: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Smooth cubic (Catmull-Rom-style Hermite) interpolation through keyframes.

    Args:
        times: ``[K]`` increasing keyframe times; values: ``[K, D]``; u: ``[T]`` query times.
    Returns:
        ``[T, D]``; zero slope at the first and last keyframe, so motions start and end at rest.
    """
    K = len(times)
    slope = np.zeros_like(values)
    if K > 2:
        slope[1:-1] = (values[2:] - values[:-2]) / (times[2:] - times[:-2])[:, None]
    u = np.clip(u, times[0], times[-1])
    k = np.clip(np.searchsorted(times, u, side="right") - 1, 0, K - 2)
    h = times[k + 1] - times[k]
    s = ((u - times[k]) / h)[:, None]
    h = h[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * values[k] + h10 * h * slope[k] + h01 * values[k + 1] + h11 * h * slope[k + 1]


def _perturb_keyframes(values: np.ndarray, sd: float, rng: np.random.Generator) -> np.ndarray:
    """Add ``N(0, sd)`` degrees to the interior keyframes of the joint DOFs the action uses."""
    out = values.copy()
    active = np.flatnonzero(np.any(values != 0, axis=0))
    active = np.intersect1d(active, _JOINT_COLS)
    noise = sd * rng.standard_normal((len(values), len(active)))
    out[1:-1, active] += noise[1:-1]
    return out


def dof_trajectory(
    keyframes,
    style: PersonStyle,
    personal_rng: np.random.Generator,
    sample_rng: np.random.Generator,
    config: NTUSynthConfig,
    num_frames: int,
    pad: tuple[int, int],
) -> np.ndarray:
    """DOF values ``[pad0 + num_frames + pad1, DOF]`` (degrees / metres) for one person.

    ``personal_rng`` gives the subject's persistent way of doing this action (the
    same for every replication); ``sample_rng`` the per-performance noise.
    """
    d = config.difficulty
    times, values = keyframe_matrix(keyframes)
    values = _perturb_keyframes(values, 0.8 * d * config.style_noise, personal_rng)
    amp_personal = 1.0 + d * config.amplitude_spread * personal_rng.standard_normal()
    shift_personal = 0.03 * d * personal_rng.standard_normal(len(times))
    values = _perturb_keyframes(values, d * config.sample_noise, sample_rng)
    amp = style.amplitude * amp_personal * (1.0 + 0.5 * d * config.amplitude_spread * sample_rng.standard_normal())
    values[:, _JOINT_COLS] *= np.clip(amp, 0.5, 1.5)
    # Move the interior keyframes in time a little (personal + per sample), keeping their order.
    shift = shift_personal + 0.02 * d * sample_rng.standard_normal(len(times))
    times = times.copy()
    times[1:-1] = np.sort(np.clip(times[1:-1] + shift[1:-1], 0.02, 0.98))
    times[1:-1] += np.arange(1, len(times) - 1) * 1e-4  # strictly increasing even after clipping
    u = np.linspace(0.0, 1.0, num_frames)
    u = u + style.warp * np.sin(np.pi * u) / np.pi  # monotone for |warp| < 1
    traj = interpolate(times, values, u)
    traj = np.concatenate([np.repeat(traj[:1], pad[0], 0), traj, np.repeat(traj[-1:], pad[1], 0)])
    # Persistent posture and a slow wobble of every joint angle.
    T = len(traj)
    t = np.arange(T)[:, None] / FPS
    n = len(_JOINT_COLS)
    freq = sample_rng.uniform(0.2, 0.8, n)
    phase = sample_rng.uniform(0, 2 * np.pi, n)
    wob = 0.5 * d * config.sample_noise * sample_rng.standard_normal(n)
    traj[:, _JOINT_COLS] += style.posture[_JOINT_COLS] + wob * np.sin(2 * np.pi * freq * t + phase)
    return traj


def pose_person(
    traj: np.ndarray, body: kin.BodyProportions, plant: str, facing_deg: float, location_xz: tuple[float, float]
) -> np.ndarray:
    """DOF trajectory → world positions ``[T, 25, 3]`` metres (floor at ``y = 0``).

    Steps: FK in the body frame (root yaw included); shift horizontally so the planted
    foot (or the ankles' midpoint) stays put and vertically so the lowest foot joint
    touches the floor, plus ``root_up``; move by ``root_fwd`` / ``root_side`` along the
    initial facing; turn to ``facing_deg`` (about +y, 0 = facing C001) and place at
    ``location_xz``.
    """
    local = kin.euler_to_matrix(kin.dofs_to_euler(traj))
    yaw = np.deg2rad(traj[:, _DOF["root_yaw"]])
    pos = kin.forward_kinematics(kin.rest_offsets(body), local, root_rot=kin.rot_y(yaw))
    if plant == "both":
        anchor = 0.5 * (pos[:, J["AnkleLeft"]] + pos[:, J["AnkleRight"]])
    else:
        anchor = pos[:, J["Ankle" + plant.capitalize()]]
    pos[..., [0, 2]] -= (anchor - anchor[:1])[:, None, [0, 2]]
    feet = [J["AnkleLeft"], J["AnkleRight"], J["FootLeft"], J["FootRight"]]
    pos[..., 1] -= pos[:, feet, 1].min(axis=1)[:, None]
    pos[..., 1] += traj[:, _DOF["root_up"], None]
    # Body frame: forward is -z, right is +x.
    pos[..., 2] -= traj[:, _DOF["root_fwd"], None]
    pos[..., 0] += traj[:, _DOF["root_side"], None]
    world = pos @ kin.rot_y(np.deg2rad(facing_deg)).T
    world[..., 0] += location_xz[0]
    world[..., 2] += location_xz[1]
    return world


# --------------------------------------------------------------------------- cameras

#: Camera azimuth around the scene centre, degrees (C001 in front of the actor).
CAMERA_AZIMUTH_DEG = {1: 0.0, 2: 45.0, 3: -45.0}


def camera_rig(setup: int) -> tuple[float, float]:
    """(height above the floor, horizontal distance to the scene centre) in metres for a setup.

    A fixed low-discrepancy sequence over setups: heights 0.6–1.4 m, distances 2.5–3.5 m.
    """
    frac_h = ((setup - 1) * 0.6180339887 + 0.25) % 1.0
    frac_d = ((setup - 1) * 0.3819660113 + 0.55) % 1.0
    return 0.6 + 0.8 * frac_h, 2.5 + 1.0 * frac_d


def camera_pose(setup: int, camera: int) -> tuple[np.ndarray, np.ndarray]:
    """World → Kinect camera transform: ``p_cam = R @ (p_world - c)``.

    The camera stands at azimuth :data:`CAMERA_AZIMUTH_DEG` around the scene centre
    (the world origin) and looks at the point 0.9 m above it. Rows of ``R`` are the
    camera's x (its left), y (up) and z (viewing direction) axes, as Kinect reports them.

    Returns:
        ``R`` ``[3, 3]`` and the camera position ``c`` ``[3]`` (metres).
    """
    height, dist = camera_rig(setup)
    az = np.deg2rad(CAMERA_AZIMUTH_DEG[camera])
    c = np.array([-dist * np.sin(az), height, -dist * np.cos(az)])
    forward = np.array([0.0, 0.9, 0.0]) - c
    forward /= np.linalg.norm(forward)
    left = np.cross([0.0, 1.0, 0.0], forward)
    left /= np.linalg.norm(left)
    up = np.cross(forward, left)
    return np.stack([left, up, forward]), c


# --------------------------------------------------------------------------- one sample


def sample_names(config: NTUSynthConfig) -> list[NTUSampleName]:
    """Every sample of ``config``, in file-name order."""
    return [
        NTUSampleName(s, c, p, r, a)
        for s in sorted(config.setups)
        for c in sorted(config.cameras)
        for p in range(1, config.num_subjects + 1)
        for r in sorted(config.replications)
        for a in range(1, config.num_classes + 1)
    ]


def perform(config: NTUSynthConfig, setup: int, subject: int, replication: int, action: int) -> list[np.ndarray]:
    """World positions of the people in one performance (shared by all cameras).

    Returns:
        one ``[T, 25, 3]`` array per person (actor first), metres, floor at ``y = 0``.
    """
    spec = ACTIONS[action - 1]
    d = config.difficulty
    rng = _rng(config, _PERFORMANCE, setup, subject, replication, action)
    actor = person_style(config, _rng(config, _SUBJECT, subject))
    tempo = actor.tempo * float(np.exp(np.clip(0.5 * d * config.tempo_spread * rng.standard_normal(), -0.3, 0.3)))
    num_frames = max(int(round(spec.frames * config.length_scale * tempo)), 8)
    pad = (int(rng.integers(3, 16) * config.length_scale) + 1, int(rng.integers(3, 16) * config.length_scale) + 1)
    facing = (15.0 if replication % 2 else -15.0) + config.facing_spread_deg * rng.standard_normal()
    centre = 0.15 * rng.standard_normal(2)

    traj = dof_trajectory(
        spec.actor, actor, _rng(config, _SUBJECT_ACTION, subject, action, 0), rng, config, num_frames, pad
    )
    if not spec.two_person:
        return [pose_person(traj, actor.body, spec.plant, facing, tuple(centre))]
    # Two people face each other across the scene centre, ~1.15 m apart; the partner is
    # the subject's fixed partner (own body and style).
    partner = person_style(config, _rng(config, _PARTNER, subject))
    traj_b = dof_trajectory(
        spec.partner, partner, _rng(config, _SUBJECT_ACTION, subject, action, 1), rng, config, num_frames, pad
    )
    gap = 0.5 * rng.uniform(1.05, 1.25)
    turn = kin.rot_y(np.deg2rad(facing))
    a_xz = centre + (turn @ np.array([-gap, 0.0, 0.0]))[[0, 2]]
    b_xz = centre + (turn @ np.array([gap, 0.0, 0.0]))[[0, 2]]
    return [
        pose_person(traj, actor.body, spec.plant, facing - 90.0, tuple(a_xz)),
        pose_person(traj_b, partner.body, "both", facing + 90.0, tuple(b_xz)),
    ]


def _chair_blob(T: int, rng: np.random.Generator) -> np.ndarray:
    """A static non-human "body": 25 points in a box ~0.6 m wide and deep, ~0.3 m tall. ``[T, 25, 3]`` world."""
    side = rng.choice([-1.0, 1.0])
    centre = np.array([side * rng.uniform(0.9, 1.4), rng.uniform(0.35, 0.55), rng.uniform(-0.2, 0.6)])
    size = np.array([rng.uniform(0.55, 0.7), rng.uniform(0.25, 0.32), rng.uniform(0.55, 0.7)])
    points = centre + (rng.uniform(-0.5, 0.5, (25, 3)) * size)
    return np.repeat(points[None], T, axis=0)


def _passer_by(T: int, config: NTUSynthConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Someone walking across the background. Returns world positions ``[T, 25, 3]`` and ``present [T]``."""
    style = person_style(config, rng)
    cycle = 1.1  # seconds per stride
    t = np.arange(T) / FPS
    phase = 2 * np.pi * t / cycle + rng.uniform(0, 2 * np.pi)
    traj = np.zeros((T, len(DOF_NAMES)))
    for s, sign in (("r", 1.0), ("l", -1.0)):
        traj[:, _DOF[f"{s}_hip_flex"]] = sign * 22 * np.sin(phase)
        traj[:, _DOF[f"{s}_knee"]] = 30 * np.clip(np.sin(phase + sign * np.pi / 2), 0, None) + 5
        traj[:, _DOF[f"{s}_shoulder_flex"]] = -sign * 18 * np.sin(phase)
        traj[:, _DOF[f"{s}_elbow"]] = 15
    direction = rng.choice([-1.0, 1.0])
    traj[:, _DOF["root_fwd"]] = 1.2 * t
    world = pose_person(
        traj, style.body, "both", -direction * 90.0, (-direction * rng.uniform(0.8, 1.5), rng.uniform(1.2, 1.6))
    )
    present = np.zeros(T, dtype=bool)
    length = int(rng.integers(6, 12))
    start = int(rng.integers(0, max(T - length, 1)))
    present[start : start + length] = True
    return world, present


def _dropped_frames(T: int, prob: float, rng: np.random.Generator) -> np.ndarray:
    """bool ``[T]``: frames where the sensor loses every body, in bursts of 1–3 frames (~``prob`` of all)."""
    lost = np.zeros(T, dtype=bool)
    if prob <= 0:
        return lost
    starts = rng.random(T) < prob / 2.0  # mean burst length is 2
    lengths = rng.integers(1, 4, T)
    for t in np.flatnonzero(starts):
        lost[t : t + lengths[t]] = True
    return lost


def synthesize_sample(
    name: NTUSampleName, config: NTUSynthConfig = NTUSynthConfig(), performance: list[np.ndarray] | None = None
) -> SkeletonSequence:
    """Generate one sample as a :class:`SkeletonSequence` (what :func:`synthesize_ntu` writes).

    Args:
        name: which sample (its action must be <= ``config.num_classes`` and so on).
        performance: the output of :func:`perform` for this sample's setup, subject,
            replication and action, if already computed (the cameras share it).
    """
    if performance is None:
        performance = perform(config, name.setup, name.subject, name.replication, name.action)
    rng = _rng(config, _CAMERA, name.setup, name.camera, name.subject, name.replication, name.action)
    R, c = camera_pose(name.setup, name.camera)
    T = performance[0].shape[0]
    tracks = list(performance)
    present = [np.ones(T, dtype=bool) for _ in tracks]
    if rng.random() < config.extra_body_prob:
        if rng.random() < 0.5:
            span = int(rng.uniform(0.75, 1.0) * T)
            start = int(rng.integers(0, T - span + 1))
            extra, extra_present = _chair_blob(T, rng), np.zeros(T, dtype=bool)
            extra_present[start : start + span] = True
        else:
            extra, extra_present = _passer_by(T, config, rng)
        at = int(rng.integers(0, len(tracks) + 1))  # the spurious body is not always listed last
        tracks.insert(at, extra)
        present.insert(at, extra_present)
    positions = (np.stack(tracks) - c) @ R.T  # [B, T, 25, 3] camera space
    noise_scale = np.full(25, float(config.jitter_m))
    noise_scale[[J["HandTipLeft"], J["ThumbLeft"], J["HandTipRight"], J["ThumbRight"]]] *= 2.0
    positions = positions + rng.standard_normal(positions.shape) * noise_scale[:, None]
    lost = _dropped_frames(T, config.drop_frame_prob, rng)
    present = np.stack(present) & ~lost[None]
    ids = _KINECT_ID_BASE + rng.choice(np.arange(1000, 60000), size=len(tracks), replace=False)
    return sequence_from_positions(str(name), positions, [int(i) for i in ids], present)


# --------------------------------------------------------------------------- the data set


def _write_group(job) -> list[str]:
    """Write all cameras of one performance (worker entry point). ``job = (out_dir, config, names)``."""
    out_dir, config, names = job
    first = names[0]
    performance = perform(config, first.setup, first.subject, first.replication, first.action)
    paths = []
    for name in names:
        path = os.path.join(out_dir, f"{name}.skeleton")
        write_skeleton(path, synthesize_sample(name, config, performance))
        paths.append(path)
    return paths


def synthesize_ntu(
    out_dir: str | os.PathLike, config: NTUSynthConfig = NTUSynthConfig(), workers: int = 1, progress: bool = True
) -> list[Path]:
    """Write the synthetic data set to ``out_dir``.

    Writes one ``SsssCcccPpppRrrrAaaa.skeleton`` per (setup, camera, subject,
    replication, action), ``classes.txt`` (line k = name of action k+1) and
    ``synth_config.json`` (``config.to_dict()``).

    Args:
        workers: processes; output is byte-identical for any value.
        progress: show a tqdm bar.

    Returns:
        the ``.skeleton`` paths in file-name order.
    """
    config.validate()
    if not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "classes.txt").write_text("".join(n + "\n" for n in class_names(config.num_classes)), encoding="utf-8")
    (out / "synth_config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n", encoding="utf-8")

    # One job per performance: its cameras share the motion, computed once.
    groups: dict[tuple, list[NTUSampleName]] = {}
    for n in sample_names(config):
        groups.setdefault((n.setup, n.subject, n.replication, n.action), []).append(n)
    jobs = [(str(out), config, names) for names in groups.values()]
    total = sum(len(names) for names in groups.values())
    write_all(
        _write_group, jobs, workers, total=total, desc="synthesizing NTU", unit="file", progress=progress, chunksize=4
    )
    return [out / f"{n}.skeleton" for n in sample_names(config)]
