"""A synthetic stand-in for CASIA-B: binary walking silhouettes in CASIA-B's folder layout and file names.

The map, from one sequence ``<subject>/<condition>-<nn>/<view>`` to its PNGs:

1. **Subject** (:func:`draw_subject`, keyed by the seed and the subject number): body shape
   (height, leg / arm / thigh proportions, shoulder and hip width, girth, limb thickness,
   head size) and gait (stride length, cycle period in frames at 25 fps, arm swing, elbow
   bend, knee flexion, forward lean, pelvis sway) plus the bag the subject carries in ``bg``
   and the length of the coat worn in ``cl``. Subject ``k`` looks the same in every sequence.
2. **Walk** (:func:`draw_walk`, keyed by subject, condition and repetition): small per-walk
   variation (speed, start phase, start position, lateral offset, arm swing, lean). Like
   CASIA-B, whose 11 cameras film every walk at the same time, all views share the walk.
3. **Body** (:func:`body_capsules`): an articulated 3-D body made of tapered capsules
   (segment ``a -> b`` with radii ``ra -> rb``, metres) posed per frame by sinusoidal hip /
   knee / shoulder / elbow curves; world axes ``x`` forward (the walking direction), ``y``
   left, ``z`` up; feet kept on the ground (``z = 0``), so the pelvis bobs. ``bg`` adds a
   bag (shoulder bag at a hip, backpack, or a bag in one hand), ``cl`` thickens torso and arms
   and adds a skirt-like flare from the waist to mid-thigh.
4. **Camera** (:func:`project_capsules`): azimuth = view angle (0° the walker comes towards
   the camera, 90° side view walking left to right, 180° walks away), weak perspective from
   8 m: the walker crosses the frame in lateral views and grows / shrinks in frontal ones.
5. **Raster** (:func:`rasterize_capsules`): numpy, one pass per capsule over all frames (and,
   in :func:`render_views`, all views) at once: distance from each pixel to the 2-D segment
   against the interpolated radius, in a window around the capsule, giving a signed "inside
   depth" field in pixels. (``bench/bench_casia_b_render.py``: PIL's C polygon fill is faster
   at these sizes; the field is kept because the edge noise needs it.)
6. **Segmentation noise** (:func:`apply_segmentation_noise`): ragged edges (smooth noise
   added to the field before thresholding), holes, a foot shadow blob, and now and then an
   empty frame or a partial one (lower half missing, or cut off by a frame edge).

Every random draw comes from a numpy ``SeedSequence`` keyed by the seed and the sequence's
fields, so the PNGs are byte-identical for any ``workers`` and any subset of the views.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.casia_b import (
    CONDITIONS,
    SEQUENCES_PER_CONDITION,
    VIEWS,
    GaitSequenceKey,
)
from mocapkit.datasets.parallel import write_all
from mocapkit.datasets.synthetic.config import FieldCheck, SynthConfig

FPS = 25.0
#: Camera distance in metres (weak perspective: one scale per frame, from the pelvis depth).
CAMERA_DISTANCE_M = 8.0
#: Weak-perspective depth floor, metres (a very long frontal walk does not come closer than this).
MIN_DEPTH_M = 2.0
#: Camera height in metres; the image's vertical centre.
CAMERA_HEIGHT_M = 0.9
#: Downward tilt of every camera (degrees). CASIA-B's cameras look slightly down on the walkway; the tilt
#: is what tells view θ from 180° − θ in a silhouette: without it (level orthographic cameras) the two
#: silhouettes are mirror images of a left-right symmetric walker, and their GEIs coincide.
CAMERA_TILT_DEG = 15.0
#: A 1.75 m person is this fraction of the image height at the track centre.
PERSON_HEIGHT_FRACTION = 0.62
#: The raster's field is clipped below at minus this many pixels (outside the body).
FIELD_FLOOR_PX = 4.0
BAG_STYLES = ("shoulder bag", "backpack", "hand bag")


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class SegmentationNoise:
    """Background-subtraction artefacts added to a clean rendering (see :func:`apply_segmentation_noise`)."""

    hole_rate: float = 0.001
    edge_noise: float = 0.6
    shadow_prob: float = 0.2
    empty_frame_prob: float = 0.01
    partial_frame_prob: float = 0.01

    def validate(self) -> None:
        for name in ("hole_rate", "shadow_prob", "empty_frame_prob", "partial_frame_prob"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} = {value!r}: must be a probability in [0, 1]")
        if not (np.isfinite(self.edge_noise) and 0.0 <= self.edge_noise <= 3.0):
            raise ValueError(f"edge_noise = {self.edge_noise!r}: must be in [0, 3] pixels")
        if self.empty_frame_prob + self.partial_frame_prob > 0.5:
            raise ValueError("empty_frame_prob + partial_frame_prob must be at most 0.5 (most frames must be usable)")


@dataclass
class CasiaBSynthConfig(SynthConfig):
    """What :func:`synthesize_casia_b` generates: every (subject, condition-nn, view), ``frames`` PNGs each.

    Data set shape:
        num_subjects: subjects ``001..``; each has its own body and gait.
        frames: silhouettes per sequence (at 25 fps; a gait cycle is 22–30 frames).
        height: image height in pixels; the width is ``height * 4 // 3`` (CASIA-B is 320x240).
        views: camera azimuths in degrees, a subset of :data:`~mocapkit.datasets.formats.casia_b.VIEWS`.
        conditions: sequences per condition, e.g. ``{"nm": 6, "bg": 2, "cl": 2}`` (CASIA-B's);
            ``bg`` walks carry a bag, ``cl`` walks wear a coat; leave a condition out to skip it.
        seed: everything random derives from it.

    Segmentation noise (per view; see :class:`SegmentationNoise`):
        hole_rate: probability per foreground pixel of seeding a 3x3 hole.
        edge_noise: std of the smooth noise added to the silhouette boundary, pixels.
        shadow_prob: probability per sequence of a foot shadow blob.
        empty_frame_prob: probability per frame that the segmentation returns nothing.
        partial_frame_prob: probability per frame that the lower half is missing or the body is cut at a side.
    """

    num_subjects: int = 8
    frames: int = 40
    height: int = 64
    views: tuple[int, ...] = VIEWS
    conditions: dict[str, int] = field(default_factory=lambda: dict(SEQUENCES_PER_CONDITION))
    seed: int = 0
    hole_rate: float = SegmentationNoise.hole_rate
    edge_noise: float = SegmentationNoise.edge_noise
    shadow_prob: float = SegmentationNoise.shadow_prob
    empty_frame_prob: float = SegmentationNoise.empty_frame_prob
    partial_frame_prob: float = SegmentationNoise.partial_frame_prob

    def __post_init__(self) -> None:
        self.views = tuple(int(v) for v in self.views)
        self.conditions = dict(self.conditions)
        self.validate()

    @property
    def width(self) -> int:
        return self.height * 4 // 3

    @property
    def noise(self) -> SegmentationNoise:
        return SegmentationNoise(
            self.hole_rate, self.edge_noise, self.shadow_prob, self.empty_frame_prob, self.partial_frame_prob
        )

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first bad field."""
        check = FieldCheck(self)
        check.integer("num_subjects", 1, 999)
        check.integer("frames", 1, 10000)
        check.integer("height", 16, 1024, " pixels")
        check.distinct("views", lambda v: v in VIEWS, f"must be a non-empty tuple of distinct values from {VIEWS}")
        check.require(
            bool(self.conditions)
            and set(self.conditions) <= set(CONDITIONS)
            and all(isinstance(n, (int, np.integer)) and 1 <= n <= 99 for n in self.conditions.values()),
            "conditions",
            f"must map conditions from {CONDITIONS} to counts in 1..99",
        )
        check.seed()
        self.noise.validate()

    def sequence_keys(self) -> list[GaitSequenceKey]:
        """Every sequence the configuration describes, sorted."""
        return sorted(
            GaitSequenceKey(s, c, n, v)
            for s in range(1, self.num_subjects + 1)
            for c in CONDITIONS
            if c in self.conditions
            for n in range(1, self.conditions[c] + 1)
            for v in self.views
        )


# --------------------------------------------------------------------------- subjects and walks

_SUBJECT, _WALK, _VIEW = 1, 2, 3  # stream kinds of _rng


def _rng(seed: int, *key: int) -> np.random.Generator:
    """A generator keyed by the seed and integers (stream kind first, then the sequence's fields)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *map(int, key)]))


@dataclass(frozen=True)
class SubjectParams:
    """One walker's persistent body and gait. Lengths in metres, angles in degrees.

    Attributes:
        height: standing height.
        leg_ratio: hip joint to sole / height.
        thigh_share: thigh / (thigh + shank).
        arm_ratio: shoulder to wrist / height.
        shoulder_ratio, hip_ratio: shoulder joint spacing and hip joint spacing / height.
        girth: torso width and depth factor (1 = average).
        limb_thickness: limb radius factor.
        head_size: head radius factor.
        stride_ratio: stride (two steps) / height.
        period: frames per gait cycle (two steps) at 25 fps.
        arm_swing: shoulder flexion amplitude.
        elbow_bend: mean elbow flexion.
        knee_peak: peak knee flexion in swing.
        lean: forward lean of the trunk.
        sway: lateral pelvis sway amplitude, metres.
        bag_style: index into :data:`BAG_STYLES` (``bg`` walks).
        bag_side: +1 left, -1 right.
        coat_length: coat hem height as a fraction of the thigh (``cl`` walks; 0 = hip, 1 = knee).
    """

    height: float
    leg_ratio: float
    thigh_share: float
    arm_ratio: float
    shoulder_ratio: float
    hip_ratio: float
    girth: float
    limb_thickness: float
    head_size: float
    stride_ratio: float
    period: float
    arm_swing: float
    elbow_bend: float
    knee_peak: float
    lean: float
    sway: float
    bag_style: int
    bag_side: int
    coat_length: float


def draw_subject(seed: int, subject: int) -> SubjectParams:
    """The body and gait of ``subject`` (1-based), the same for every call with the same seed."""
    rng = _rng(seed, _SUBJECT, subject)
    u = rng.uniform
    return SubjectParams(
        height=u(1.55, 1.92),
        leg_ratio=u(0.46, 0.54),
        thigh_share=u(0.48, 0.56),
        arm_ratio=u(0.40, 0.46),
        shoulder_ratio=u(0.20, 0.26),
        hip_ratio=u(0.09, 0.12),
        girth=u(0.8, 1.3),
        limb_thickness=u(0.8, 1.25),
        head_size=u(0.88, 1.15),
        stride_ratio=u(0.68, 0.86),
        period=u(23.0, 30.0),
        arm_swing=u(8.0, 40.0),
        elbow_bend=u(8.0, 35.0),
        knee_peak=u(48.0, 68.0),
        lean=u(-2.0, 9.0),
        sway=u(0.0, 0.035),
        bag_style=int(rng.integers(len(BAG_STYLES))),
        bag_side=int(rng.choice([-1, 1])),
        coat_length=u(0.35, 0.9),
    )


@dataclass(frozen=True)
class WalkVariation:
    """Per-walk deviations from the subject's gait (shared by all views of one walk).

    Attributes:
        speed: multiplies the cadence (and so the speed).
        phase: gait phase at frame 0, radians.
        start: track centre offset along the walking direction, metres.
        lateral: offset of the walking line, metres.
        arm_scale: multiplies the arm swing.
        lean: added to the lean, degrees.
    """

    speed: float = 1.0
    phase: float = 0.0
    start: float = 0.0
    lateral: float = 0.0
    arm_scale: float = 1.0
    lean: float = 0.0


def draw_walk(rng: np.random.Generator) -> WalkVariation:
    """Small random per-walk variation."""
    return WalkVariation(
        speed=float(rng.uniform(0.95, 1.05)),
        phase=float(rng.uniform(0, 2 * np.pi)),
        start=float(rng.uniform(-0.3, 0.3)),
        lateral=float(rng.uniform(-0.2, 0.2)),
        arm_scale=float(rng.uniform(0.85, 1.15)),
        lean=float(rng.normal(0.0, 1.0)),
    )


# --------------------------------------------------------------------------- body


@dataclass
class Capsules:
    """Tapered capsules over time: segment ``a[t, i] -> b[t, i]`` with radius ``ra[i] -> rb[i]``.

    Attributes:
        a, b: float64 ``[T, N, 3]`` world points (metres; x forward, y left, z up).
        ra, rb: float64 ``[N]`` radii at ``a`` and ``b``, metres.
        pelvis: float64 ``[T, 3]`` the pelvis centre (weak-perspective depth reference).
        feet: float64 ``[T, 3]`` the midpoint of the ankles on the ground (shadow anchor).
    """

    a: np.ndarray
    b: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    pelvis: np.ndarray
    feet: np.ndarray


def _direction(pitch: np.ndarray) -> np.ndarray:
    """Unit vectors ``[T, 3]`` pointing down, rotated forward (towards +x) by ``pitch`` radians."""
    return np.stack([np.sin(pitch), np.zeros_like(pitch), -np.cos(pitch)], axis=-1)


def body_capsules(
    subject: SubjectParams, condition: str, frames: int, walk: WalkVariation = WalkVariation(), fps: float = FPS
) -> Capsules:
    """Pose the subject's capsule body for ``frames`` frames of walking along +x.

    Joint angle curves over the gait phase ``phi`` (one cycle = two steps; left leg half a cycle
    behind the right): hip flexion ``A cos(phi) + 4°`` with ``A`` from the stride, knee flexion a
    swing peak (``knee_peak``) plus a small loading bump, arms swinging against the legs; the
    pelvis rises and falls so that the lower foot touches the ground.
    """
    if condition not in CONDITIONS:
        raise ValueError(f"condition {condition!r} is not one of {CONDITIONS}")
    s = subject
    h = s.height
    t = np.arange(frames, dtype=np.float64)
    period = s.period / walk.speed
    phi = 2 * np.pi * t / period + walk.phase
    ankle_h = 0.045 * h
    leg = s.leg_ratio * h - ankle_h
    thigh, shank = leg * s.thigh_share, leg * (1 - s.thigh_share)
    head_r = 0.062 * h * s.head_size
    neck_len = 0.045 * h
    torso_len = h - s.leg_ratio * h - neck_len - 2 * head_r - 0.02 * h
    upper_arm, forearm = s.arm_ratio * h * 0.55, s.arm_ratio * h * 0.45
    stride = s.stride_ratio * h
    hip_amp = np.arcsin(np.clip(stride / (4 * s.leg_ratio * h), 0.05, 0.7))
    speed = stride / (period / fps)  # metres per second
    thick = s.limb_thickness * h / 1.75
    coat = condition == "cl"

    # legs, relative to the pelvis centre at height 0; right leg phase phi, left leg phi + pi
    hip_half = 0.5 * s.hip_ratio * h
    yaw = np.radians(4.0) * np.cos(phi)  # pelvis rotation, right hip forward at phi = 0
    parts_a, parts_b, radii = [], [], []

    def add(a, b, ra, rb):
        parts_a.append(a)
        parts_b.append(b)
        radii.append((ra, rb))

    joints = {}
    for side, offset in (("r", 0.0), ("l", np.pi)):
        sign = -1.0 if side == "r" else 1.0
        p = phi + offset
        hip_flex = hip_amp * np.cos(p) + np.radians(4.0)
        knee_flex = np.radians(
            4.0
            + (s.knee_peak - 4.0) * ((1 + np.cos(p - 1.45 * np.pi)) / 2) ** 4
            + 12.0 * ((1 + np.cos(p - 0.15 * np.pi)) / 2) ** 8
        )
        ankle_pitch = np.radians(8.0) * np.sin(p)
        hip = np.stack([-sign * hip_half * np.sin(yaw), sign * hip_half * np.cos(yaw), np.zeros_like(p)], axis=-1)
        knee = hip + thigh * _direction(hip_flex)
        ankle = knee + shank * _direction(hip_flex - knee_flex)
        foot_dir = np.stack([np.cos(ankle_pitch), np.zeros_like(p), np.sin(ankle_pitch)], axis=-1)
        heel = ankle + np.array([0.0, 0.0, -0.5 * ankle_h]) - 0.025 * h * foot_dir
        toe = ankle + np.array([0.0, 0.0, -0.5 * ankle_h]) + 0.095 * h * foot_dir
        joints[side] = {"hip": hip, "knee": knee, "ankle": ankle, "heel": heel, "toe": toe, "phase": p}
        add(hip, knee, 0.085 * thick, 0.055 * thick)
        add(knee, ankle, 0.05 * thick, 0.035 * thick)
        add(heel, toe, 0.034 * thick, 0.026 * thick)
    foot_radius = 0.034 * thick
    lowest = np.minimum.reduce([np.minimum(j["heel"][:, 2], j["toe"][:, 2]) for j in joints.values()]) - foot_radius
    pelvis = np.stack(
        [walk.start + speed * (t - (frames - 1) / 2) / fps, walk.lateral + s.sway * np.sin(phi), -lowest], axis=-1
    )

    # trunk: two side-by-side tapered capsules (wide from the front, thinner from the side)
    lean = np.radians(s.lean + walk.lean + 1.5 * np.sin(2 * phi))
    up = np.stack([np.sin(lean), np.zeros_like(lean), np.cos(lean)], axis=-1)  # leaning forward: towards +x
    girth = s.girth * (1.3 if coat else 1.0)
    depth_r = 0.1 * girth * h / 1.75
    half_w = 0.06 * girth * h / 1.75
    neck = up * torso_len
    lateral = np.array([0.0, 1.0, 0.0])
    for sign in (-1.0, 1.0):
        add(
            sign * half_w * lateral,
            neck - 0.05 * h * up + sign * half_w * lateral,
            depth_r * 0.95,
            depth_r * (1.05 if coat else 1.0),
        )
    add(
        -hip_half * lateral + 0.02 * h * up,
        hip_half * lateral + 0.02 * h * up,
        0.085 * girth * h / 1.75,
        0.085 * girth * h / 1.75,
    )
    shoulder_half = 0.5 * s.shoulder_ratio * h
    shoulder_yaw = -0.6 * yaw
    shoulders = {}
    for side in ("r", "l"):
        sign = -1.0 if side == "r" else 1.0
        shoulders[side] = (
            neck
            - 0.04 * h * up
            + np.stack(
                [
                    -sign * shoulder_half * np.sin(shoulder_yaw),
                    sign * shoulder_half * np.cos(shoulder_yaw),
                    np.zeros_like(phi),
                ],
                axis=-1,
            )
        )
    add(shoulders["r"], shoulders["l"], 0.05 * girth * h / 1.75, 0.05 * girth * h / 1.75)
    head_centre = neck + neck_len * up + np.array([0.012 * h, 0.0, head_r * 0.9])
    add(neck, neck + neck_len * up, 0.045 * h / 1.75 * s.girth**0.5, 0.042 * h / 1.75 * s.girth**0.5)
    add(
        head_centre - np.array([0.0, 0.0, 0.25 * head_r]),
        head_centre + np.array([0.0, 0.0, 0.2 * head_r]),
        head_r * 0.92,
        head_r * 0.85,
    )

    # arms swing against the same-side leg; the bag hand swings less
    bag = condition == "bg"
    hand_bag_side = "l" if s.bag_side > 0 else "r"
    hands = {}
    for side in ("r", "l"):
        sign = -1.0 if side == "r" else 1.0
        swing = np.radians(s.arm_swing * walk.arm_scale) * -np.cos(joints[side]["phase"])
        if bag and BAG_STYLES[s.bag_style] == "hand bag" and side == hand_bag_side:
            swing = 0.3 * swing
        elbow = np.radians(s.elbow_bend) + 0.5 * np.maximum(swing, 0.0)
        abduction = np.array([0.0, sign * (0.025 * h + (0.03 if coat else 0.0)), 0.0])
        shoulder = shoulders[side]
        # a forward swing and a bent elbow both take the forearm towards +x
        elbow_p = shoulder + upper_arm * _direction(swing) + abduction * 0.5
        wrist = elbow_p + forearm * _direction(swing + elbow) + abduction * 0.5
        hands[side] = wrist
        arm_r = 0.045 * thick * (1.35 if coat else 1.0)
        add(shoulder, elbow_p, arm_r, 0.038 * thick * (1.3 if coat else 1.0))
        add(elbow_p, wrist, 0.035 * thick * (1.15 if coat else 1.0), 0.028 * thick)

    if coat:  # skirt-like flare from the waist to the hem, following the mean thigh angle
        hem_down = 0.05 * h + thigh * s.coat_length
        knees_x = 0.5 * (joints["r"]["knee"][:, 0] + joints["l"]["knee"][:, 0])
        hem = np.stack([0.6 * s.coat_length * knees_x, np.zeros_like(phi), np.full_like(phi, -hem_down)], axis=-1)
        flare = 0.17 * h / 1.75 * s.girth**0.5 + 0.05 * s.coat_length
        add(0.15 * torso_len * up, hem, depth_r * 1.1, flare)
    if bag:
        style = BAG_STYLES[s.bag_style]
        side_y = np.array([0.0, s.bag_side, 0.0])
        if style == "shoulder bag":  # a box hanging at the hip, outside the trunk
            centre = side_y * (half_w + depth_r + 0.1) + np.array([0.03, 0.0, -0.04])
            centre = centre + 0.04 * np.sin(phi)[:, None] * np.array([1.0, 0.0, 0.0])
            for dx in (-0.09, 0.09):
                add(centre + [dx, 0.0, -0.07], centre + [dx, 0.0, 0.07], 0.075, 0.075)
        elif style == "backpack":  # a box behind the upper trunk
            centre = 0.62 * torso_len * up - (depth_r + 0.09) * np.stack(
                [np.cos(lean), np.zeros_like(lean), -np.sin(lean)], axis=-1
            )
            for dy in (-0.1, 0.1):
                add(centre + [0.0, dy, -0.15], centre + [0.0, dy, 0.15], 0.1, 0.09)
        else:  # a bag hanging from one hand
            hand = hands[hand_bag_side]
            add(hand + [0.0, 0.0, -0.08], hand + [0.0, 0.0, -0.22], 0.09, 0.11)

    ra, rb = (np.array(r, dtype=np.float64) for r in zip(*radii))
    a = np.stack([np.broadcast_to(x, (frames, 3)) for x in parts_a], axis=1) + pelvis[:, None, :]
    b = np.stack([np.broadcast_to(x, (frames, 3)) for x in parts_b], axis=1) + pelvis[:, None, :]
    feet = 0.5 * (joints["r"]["ankle"] + joints["l"]["ankle"]) + pelvis
    feet[:, 2] = 0.0
    return Capsules(a, b, ra, rb, pelvis, feet)


# --------------------------------------------------------------------------- camera and raster


def camera_axes(view: float) -> tuple[np.ndarray, np.ndarray]:
    """``(right, forward)`` unit vectors of the camera at azimuth ``view`` degrees.

    ``forward`` is the viewing direction: at 0° the camera looks along -x (the walker comes
    towards it), at 90° along +y (the walker goes left to right), at 180° along +x.
    """
    theta = np.radians(view)
    return np.array([np.sin(theta), np.cos(theta), 0.0]), np.array([-np.cos(theta), np.sin(theta), 0.0])


def pixels_per_metre(height: int) -> float:
    """Image scale at the track centre: a 1.75 m walker is :data:`PERSON_HEIGHT_FRACTION` of ``height``."""
    return PERSON_HEIGHT_FRACTION * height / 1.75


def project(points: np.ndarray, scale: np.ndarray, view: float, height: int, width: int) -> np.ndarray:
    """World points ``[T, ..., 3]`` to pixel coordinates ``[T, ..., 2]`` (x right, y down) with per-frame ``scale``.

    The camera is tilted down by :data:`CAMERA_TILT_DEG`: its up axis is ``cos(tilt)·z + sin(tilt)·forward``,
    so of two points at the same height the one farther along the viewing direction is drawn higher.
    """
    right, forward = camera_axes(view)
    s = scale.reshape((-1,) + (1,) * (points.ndim - 2))
    u = points @ right
    tilt = np.radians(CAMERA_TILT_DEG)
    up = (points[..., 2] - CAMERA_HEIGHT_M) * np.cos(tilt) + (points @ forward) * np.sin(tilt)
    return np.stack([width / 2 + s * u, height / 2 - s * up], axis=-1)


def project_capsules(
    capsules: Capsules, view: float, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weak-perspective projection of capsules.

    Returns:
        ``(a, b, ra, rb, scale)``: endpoints float64 ``[T, N, 2]`` in pixels, radii ``[T, N]`` in pixels,
        and the per-frame scale ``[T]`` in pixels per metre (larger when the walker is closer).
    """
    _, forward = camera_axes(view)
    depth = CAMERA_DISTANCE_M + capsules.pelvis @ forward
    scale = pixels_per_metre(height) * CAMERA_DISTANCE_M / np.maximum(depth, MIN_DEPTH_M)
    a = project(capsules.a, scale, view, height, width)
    b = project(capsules.b, scale, view, height, width)
    return a, b, scale[:, None] * capsules.ra, scale[:, None] * capsules.rb, scale


def _window_indices(
    lo: np.ndarray, hi: np.ndarray, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Flat indices of one common-size window per frame covering the boxes ``lo..hi`` (int ``[T, 2]``, x y).

    Windows are clipped to the image and shifted back inside where they would stick out.
    Returns ``(index int64 [T, h, w] into a [T, H, W] array, x0 [T], y0 [T])``, or None when empty.
    """
    lo = np.clip(lo, 0, [width, height])
    hi = np.clip(hi, 0, [width, height])
    win_w, win_h = (int(v) for v in np.maximum(hi - lo, 0).max(axis=0))
    if win_w == 0 or win_h == 0:
        return None
    x0 = np.clip(lo[:, 0], 0, width - win_w)
    y0 = np.clip(lo[:, 1], 0, height - win_h)
    frame_base = (np.arange(len(lo), dtype=np.int64) * (height * width))[:, None, None]
    rows = (y0[:, None] + np.arange(win_h))[:, :, None]
    cols = (x0[:, None] + np.arange(win_w))[:, None, :]
    index = frame_base + rows * width + cols
    return index, x0, y0


def rasterize_capsules(
    a: np.ndarray, b: np.ndarray, ra: np.ndarray, rb: np.ndarray, height: int, width: int
) -> np.ndarray:
    """Signed inside-depth field of the union of 2-D tapered capsules, vectorised over frames and pixels.

    For each pixel centre ``p`` and capsule ``i``: ``u`` = projection parameter of ``p`` on the
    segment ``a -> b`` clipped to [0, 1], ``d`` = distance from ``p`` to ``a + u (b - a)``,
    ``r = ra + u (rb - ra)``; the field is ``max_i (r - d)`` (> 0 inside), clipped below at
    ``-FIELD_FLOOR_PX``. One numpy pass per capsule (~25) covers all frames at once, each frame in a
    window around that capsule (one window size per capsule, its largest over the frames); this is
    about 3x faster than evaluating every capsule on a common body window.

    Args:
        a, b: float ``[T, N, 2]`` endpoints in pixels (x right, y down).
        ra, rb: float ``[T, N]`` radii in pixels.
    Returns:
        float32 ``[T, H, W]``, pixels.
    """
    T, N = a.shape[:2]
    out = np.full((T, height, width), -FIELD_FLOOR_PX, dtype=np.float32)
    flat = out.reshape(-1)
    a, b = a.astype(np.float32), b.astype(np.float32)
    ra, rb = ra.astype(np.float32), rb.astype(np.float32)
    margin = FIELD_FLOOR_PX + 1
    for i in range(N):
        ai, bi, rai, rbi = a[:, i], b[:, i], ra[:, i, None, None], rb[:, i, None, None]
        reach = np.maximum(ra[:, i], rb[:, i])[:, None] + margin
        window = _window_indices(
            np.floor(np.minimum(ai, bi) - reach).astype(np.int64),
            np.ceil(np.maximum(ai, bi) + reach).astype(np.int64),
            height,
            width,
        )
        if window is None:
            continue
        index, x0, y0 = window
        win_h, win_w = index.shape[1:]
        px = (x0[:, None] + np.arange(win_w, dtype=np.float32) + 0.5 - ai[:, 0:1])[:, None, :]  # [T, 1, w]
        py = (y0[:, None] + np.arange(win_h, dtype=np.float32) + 0.5 - ai[:, 1:2])[:, :, None]  # [T, h, 1]
        ab = bi - ai
        abx, aby = ab[:, 0, None, None], ab[:, 1, None, None]
        len2 = np.maximum(abx * abx + aby * aby, 1e-12)
        u = np.clip((px * abx + py * aby) / len2, 0.0, 1.0)  # [T, h, w]
        inside = rai + u * (rbi - rai) - np.sqrt((px - u * abx) ** 2 + (py - u * aby) ** 2)
        flat[index] = np.maximum(flat[index], inside)
    return out


# --------------------------------------------------------------------------- segmentation noise


def apply_segmentation_noise(
    field: np.ndarray,
    noise: SegmentationNoise | None,
    rng: np.random.Generator,
    shadow_anchor: np.ndarray | None = None,
    scale: np.ndarray | None = None,
) -> np.ndarray:
    """Threshold a signed field ``[T, H, W]`` (pixels, > 0 inside) into a noisy binary silhouette.

    In order: smooth noise of std ``edge_noise`` pixels is added to the field (ragged edges);
    with probability ``shadow_prob`` an elongated ground shadow is added under ``shadow_anchor``
    (``[T, 2]`` pixels, the feet; ``scale`` ``[T]`` pixels per metre); threshold at 0; 3x3 holes
    seeded with probability ``hole_rate`` per foreground pixel; then per frame, with probability
    ``empty_frame_prob`` nothing, and with ``partial_frame_prob`` the lower half of the silhouette
    removed or everything beyond a column inside the silhouette cut away (body at a frame edge).

    Returns:
        uint8 ``[T, H, W]`` with values 0 / 255. ``noise=None``: just the threshold.
    """
    from scipy import ndimage

    if noise is None:
        return np.where(field > 0, np.uint8(255), np.uint8(0))
    T, H, W = field.shape
    field = field.astype(np.float32, copy=True)
    if shadow_anchor is not None and scale is not None and rng.random() < noise.shadow_prob:
        direction = rng.choice([-1.0, 1.0])
        half_len = rng.uniform(0.3, 0.5) * scale
        half_thick = np.maximum(0.035 * scale, 1.0)
        cx = shadow_anchor[:, 0] + direction * 0.6 * half_len
        cy = shadow_anchor[:, 1]
        xs = np.arange(W, dtype=np.float32) + 0.5
        ys = np.arange(H, dtype=np.float32) + 0.5
        du = (xs[None, None, :] - cx[:, None, None]) / half_len[:, None, None]
        dv = (ys[None, :, None] - cy[:, None, None]) / half_thick[:, None, None]
        field = np.maximum(field, (half_thick[:, None, None] * (1 - np.sqrt(du**2 + dv**2))).astype(np.float32))
    # edges and holes only matter near the body: work in one window per frame around field > floor
    near = field > -FIELD_FLOOR_PX + 1e-3
    rows, cols = near.any(axis=2), near.any(axis=1)
    lo = np.stack([cols.argmax(axis=1), rows.argmax(axis=1)], axis=1)
    hi = np.stack([W - cols[:, ::-1].argmax(axis=1), H - rows[:, ::-1].argmax(axis=1)], axis=1)
    hi[~rows.any(axis=1)] = lo[~rows.any(axis=1)]  # frames with nothing near the body
    window = _window_indices(lo, hi, H, W)
    mask = np.zeros((T, H, W), dtype=bool)
    if window is not None:
        index = window[0]
        local = field.reshape(-1)[index]  # [T, h, w]
        if noise.edge_noise > 0:
            white = rng.standard_normal(local.shape, dtype=np.float32)
            smooth = ndimage.gaussian_filter(white, sigma=(0, 1.0, 1.0), mode="wrap")
            local += noise.edge_noise / 0.2821 * smooth  # 0.2821 = std of white noise smoothed with sigma 1 (2-D)
        inside = local > 0
        if noise.hole_rate > 0:
            seeds = (rng.random(inside.shape, dtype=np.float32) < noise.hole_rate) & inside
            inside &= ~ndimage.binary_dilation(seeds, structure=np.ones((1, 3, 3), dtype=bool))
        mask.reshape(-1)[index] = inside
    fate = rng.random(T)
    empty = fate < noise.empty_frame_prob
    partial = (fate >= noise.empty_frame_prob) & (fate < noise.empty_frame_prob + noise.partial_frame_prob)
    mask[empty] = False
    for t in np.flatnonzero(partial):
        rows, cols = np.flatnonzero(mask[t].any(axis=1)), np.flatnonzero(mask[t].any(axis=0))
        if len(rows) == 0:
            continue
        if rng.random() < 0.5:
            mask[t, (rows[0] + rows[-1]) // 2 :] = False  # lower half missing
        else:
            cut = int(rng.integers(cols[0], cols[-1] + 1))
            if rng.random() < 0.5:
                mask[t, :, cut:] = False
            else:
                mask[t, :, :cut] = False
    return np.where(mask, np.uint8(255), np.uint8(0))


# --------------------------------------------------------------------------- one walk


def render_walk(
    subject_params: SubjectParams,
    view: float,
    condition: str,
    frames: int,
    height: int,
    rng: np.random.Generator,
    walk: WalkVariation | None = None,
    noise: SegmentationNoise | None = SegmentationNoise(),
) -> np.ndarray:
    """Render one walk as CASIA-B-like binary silhouettes.

    Args:
        subject_params: the walker (:func:`draw_subject`).
        view: camera azimuth, degrees (0 towards the camera, 90 side view, 180 away).
        condition: ``"nm"``, ``"bg"`` (with the subject's bag) or ``"cl"`` (in a coat).
        frames: number of frames ``T`` (25 fps).
        height: image height ``H`` in pixels; the width is ``height * 4 // 3``.
        rng: draws the walk variation (when ``walk`` is None) and then the noise.
        walk: per-walk variation; None = drawn from ``rng``.
        noise: segmentation artefacts; None = a clean silhouette.

    Returns:
        uint8 ``[T, H, W]``, values 0 / 255.
    """
    if walk is None:
        walk = draw_walk(rng)
    return render_views(subject_params, [view], condition, frames, height, [rng], walk, noise)[0]


def render_views(
    subject_params: SubjectParams,
    views,
    condition: str,
    frames: int,
    height: int,
    rngs,
    walk: WalkVariation = WalkVariation(),
    noise: SegmentationNoise | None = SegmentationNoise(),
) -> list[np.ndarray]:
    """One walk seen by several cameras at once (CASIA-B films each walk with all 11).

    The body is posed once, all views are rasterised in one call, and each view gets its own
    noise from its own generator in ``rngs``; view ``k`` equals
    ``render_walk(subject_params, views[k], condition, frames, height, rngs[k], walk, noise)``.

    Returns:
        one uint8 ``[T, H, W]`` array per view.
    """
    if not isinstance(frames, (int, np.integer)) or frames < 1:
        raise ValueError(f"frames must be a positive integer, got {frames!r}")
    if not isinstance(height, (int, np.integer)) or height < 8:
        raise ValueError(f"height must be an integer >= 8 pixels, got {height!r}")
    views = [float(v) for v in views]
    if not views or not all(np.isfinite(views)):
        raise ValueError(f"views must be finite angles in degrees, got {views!r}")
    if len(rngs) != len(views):
        raise ValueError(f"one generator per view: {len(views)} views, {len(rngs)} generators")
    width = height * 4 // 3
    capsules = body_capsules(subject_params, condition, frames, walk)
    projected = [project_capsules(capsules, view, height, width) for view in views]
    a, b, ra, rb = (np.concatenate([p[k] for p in projected]) for k in range(4))
    fields = rasterize_capsules(a, b, ra, rb, height, width).reshape(len(views), frames, height, width)
    out = []
    for view, depth, (*_, scale), rng in zip(views, fields, projected, rngs):
        feet = project(capsules.feet, scale, view, height, width)
        out.append(apply_segmentation_noise(depth, noise, rng, shadow_anchor=feet, scale=scale))
    return out


# --------------------------------------------------------------------------- the data set


def _write_walk(job) -> list[str]:
    """Render and write every view of one walk (worker entry point). ``job = (out, config, subject, cond, number)``."""
    from PIL import Image

    out, config, subject, condition, number = job
    params = draw_subject(config.seed, subject)
    cond_index = CONDITIONS.index(condition)
    walk = draw_walk(_rng(config.seed, _WALK, subject, cond_index, number))
    rngs = [_rng(config.seed, _VIEW, subject, cond_index, number, view) for view in config.views]
    views = render_views(params, config.views, condition, config.frames, config.height, rngs, walk, config.noise)
    folders = []
    for view, silhouettes in zip(config.views, views):
        key = GaitSequenceKey(subject, condition, number, view)
        folder = Path(out) / key.name
        folder.mkdir(parents=True, exist_ok=True)
        for t, mask in enumerate(silhouettes, start=1):
            Image.fromarray(mask, mode="L").save(folder / key.frame_name(t), format="PNG")
        folders.append(str(folder))
    return folders


def synthesize_casia_b(
    out: str | os.PathLike, config: CasiaBSynthConfig | None = None, progress: bool = True, workers: int = 1
) -> list[Path]:
    """Write the synthetic data set in CASIA-B's layout.

    Writes ``out/<subject>/<condition>-<nn>/<view>/<SSS-cc-nn-VVV-FFF>.png`` (8-bit gray, 0 / 255,
    frames 1-based) for every sequence of :meth:`CasiaBSynthConfig.sequence_keys`, and
    ``out/README.txt`` saying the data is synthetic, with the configuration as JSON.

    Args:
        config: what to generate; None = ``CasiaBSynthConfig()`` (8 subjects, 40 frames, height 64).
        workers: processes (one job per walk, all its views); the PNGs are byte-identical for any value.
        progress: show a tqdm bar.

    Returns:
        the sequence (view) folders, sorted by key.
    """
    config = CasiaBSynthConfig() if config is None else config
    config.validate()
    if not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "README.txt").write_text(
        "SYNTHETIC data in the CASIA-B silhouette layout, written by mocapkit.datasets.synthetic.casia_b.\n"
        "These are rendered capsule-body walkers, not recordings of people; do not report results on them\n"
        "as CASIA-B results.\n\nconfig:\n" + json.dumps(config.to_dict(), indent=2) + "\n",
        encoding="utf-8",
    )
    jobs = [
        (str(out), config, s, c, n)
        for s in range(1, config.num_subjects + 1)
        for c in CONDITIONS
        if c in config.conditions
        for n in range(1, config.conditions[c] + 1)
    ]
    write_all(
        _write_walk,
        jobs,
        workers,
        total=len(jobs) * len(config.views),
        desc="synthesizing CASIA-B",
        unit="seq",
        progress=progress,
    )
    return [out / key.name for key in config.sequence_keys()]
