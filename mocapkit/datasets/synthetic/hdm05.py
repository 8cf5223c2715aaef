"""Synthetic HDM05-style data: a 31-joint ASF per actor and AMC clips of HDM05 classes.

:func:`synthesize_hdm05` writes, into ``out_dir``:

- ``HDM_<actor>.asf`` for each actor: the CMU/HDM05 31-joint skeleton (the same bone
  names, ASF order, dofs, axes and ``:units length 0.45``), with per-actor proportions
  (height, leg and arm ratios);
- ``<class>_<actor>_<nnn>.amc``: joint-angle trajectories at 120 Hz for each class,
  actor and take ``nnn`` (1-based), readable by :func:`mocapkit.datasets.formats.asf_amc.read_amc`
  (which finds ``HDM_<actor>.asf`` beside the clip);
- ``classes.txt``: the synthesised 130-class names, one per line, in the config's order.

Motions are built from the class name (parsed with the HDM05 merge rules): the stem
picks a motion primitive (gait, hop, kick, punch, squat, jumping jack, clap, arm
rotation, elbow-to-knee; any other of the 130 classes gets a stem-seeded periodic
pattern), the count (``2Reps``, ``3hops``, ``4Steps``) sets the number of cycles,
the acting limb (``L``/``R``/``Both``) and start side (``Lstart``/``RStart``) choose
the limbs and phase, directions (``Front``/``Side``, ``Forward``/``Backward``,
``Circle``, ``OnPlace``) shape the trajectory. Actors differ in proportions,
amplitude, tempo and posture; every clip adds its own amplitude/tempo jitter and
smooth angle noise. Everything is deterministic given ``config.seed``.

Angle conventions used here (measured on the CMU/HDM05 skeleton with
:func:`~mocapkit.datasets.formats.asf_amc.forward_kinematics`; y up, the person faces +z,
left = +x): humerus ``(rx, rz) = (f - 30·(1 - a/90), ±90·(1 - a/90))`` for shoulder
flexion ``f`` and abduction ``a`` (``+`` left, ``-`` right; ``f = 0`` hangs down,
``f = 90`` points forward); radius ``rx`` = elbow flexion; femur ``rx = -hip flexion``
and ``rz = ±abduction``; tibia ``rx`` = knee flexion; lowerback ``rx`` = forward bend;
root ``ry`` = heading (yaw).
"""

from __future__ import annotations

import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.asf_amc import (
    AsfBone,
    AsfSkeleton,
    forward_kinematics,
    write_amc,
    write_asf,
)
from mocapkit.datasets.mocap.hdm05_classes import ACTORS, class_names, merge_25_stem, merge_65

#: Default classes: several variants per stem, so that the 130 → 65 → 25 merges all
#: collapse something (counts, L/R limb, L/R start, front/side, circle vs straight).
DEFAULT_CLASSES = (
    "punchLFront1Reps",
    "punchLFront2Reps",
    "punchRFront1Reps",
    "punchRSide1Reps",
    "kickLFront1Reps",
    "kickRFront2Reps",
    "kickRSide1Reps",
    "walk2StepsLstart",
    "walk2StepsRstart",
    "walk4StepsRstart",
    "walkLeftCircle4StepsRstart",
    "hopBothLegs1hops",
    "hopLLeg2hops",
    "hopRLeg1hops",
    "jumpingJack1Reps",
    "jumpingJack3Reps",
    "squat1Reps",
    "squat3Reps",
    "clap1Reps",
    "clapAboveHead1Reps",
    "rotateArmsLForward1Reps",
    "rotateArmsBothBackward1Reps",
    "elbowToKnee1RepsLelbowStart",
    "elbowToKnee1RepsRelbowStart",
)

UNIT = 0.0254 / 0.45  #: metres per ASF length unit of the written skeletons (CMU/HDM05 convention)


@dataclass
class HDM05SynthConfig:
    """What :func:`synthesize_hdm05` writes.

    Attributes:
        classes: 130-class names to synthesise (``mocapkit synth hdm05 --classes``).
        actors: actors, a subset of :data:`~mocapkit.datasets.mocap.hdm05_classes.ACTORS` (``--actors``).
        clips_per_actor: takes per class and actor (``nnn`` = 001 …).
        seed: master seed (``--seed``); the output is a pure function of the config.
        fps: frame rate of the motions (Hz).
        noise_deg: standard deviation of the smooth per-dof angle noise (degrees).
        variation: relative per-clip jitter of amplitude and tempo.
        max_frames: clips are cut to at most this many frames.
        digits: significant digits of the AMC values.
    """

    classes: tuple[str, ...] = DEFAULT_CLASSES
    actors: tuple[str, ...] = ACTORS
    clips_per_actor: int = 2
    seed: int = 0
    fps: float = 120.0
    noise_deg: float = 1.5
    variation: float = 0.12
    max_frames: int = 900
    digits: int = 6

    def __post_init__(self) -> None:
        self.classes = tuple(self.classes)
        self.actors = tuple(self.actors)
        known = set(class_names(130))
        bad = [c for c in self.classes if c not in known]
        if bad:
            raise ValueError(f"not HDM05 classes: {bad}; see mocapkit.datasets.mocap.hdm05_classes.class_names(130)")
        bad = [a for a in self.actors if a not in ACTORS]
        if bad:
            raise ValueError(f"unknown HDM05 actors {bad}; known: {ACTORS}")
        if not self.classes or not self.actors:
            raise ValueError("need at least one class and one actor")
        if self.clips_per_actor < 1:
            raise ValueError(f"clips_per_actor must be >= 1, got {self.clips_per_actor}")
        if self.fps <= 0:
            raise ValueError(f"fps must be positive, got {self.fps}")


@dataclass(frozen=True)
class ActorStyle:
    """Body proportions and movement style of one synthetic actor."""

    height: float  #: approximate standing height (m)
    legs: float  #: leg-length factor
    arms: float  #: arm-length factor
    amplitude: float  #: joint-angle amplitude factor
    tempo: float  #: speed factor (>1 = faster)
    lean: float  #: forward trunk lean (deg)
    arm_carry: float  #: elbow flexion while idle (deg)


ACTOR_STYLES = {
    "bd": ActorStyle(1.80, 1.00, 1.00, 1.10, 1.00, 3.0, 10.0),
    "bk": ActorStyle(1.72, 1.04, 0.96, 0.90, 0.88, -1.0, 20.0),
    "dg": ActorStyle(1.76, 0.98, 1.03, 1.00, 1.10, 5.0, 5.0),
    "mm": ActorStyle(1.64, 0.96, 1.01, 1.20, 1.18, 1.0, 15.0),
    "tr": ActorStyle(1.86, 1.03, 1.05, 0.85, 0.95, 7.0, 25.0),
}

# name, direction, length (units, ~1.76 m person), axis, dof — the CMU/HDM05 template (left side;
# the right side mirrors x and the sign of the axis' y and z angles).
_LEFT = (
    ("hipjoint", (0.63, -0.69, 0.36), 2.5, (0, 0, 0), ()),
    ("femur", (0.342, -0.94, 0.0), 6.8, (0, 0, 20), ("rx", "ry", "rz")),
    ("tibia", (0.342, -0.94, 0.0), 7.3, (0, 0, 20), ("rx",)),
    ("foot", (0.18, -0.49, 0.85), 2.6, (-90, 0, 20), ("rx", "rz")),
    ("toes", (0.0, 0.0, 1.0), 1.3, (-90, 0, 20), ("rx",)),
)
_SPINE = (
    ("lowerback", (0.0, 1.0, -0.1), 2.4, (0, 0, 0), ("rx", "ry", "rz")),
    ("upperback", (0.0, 1.0, 0.0), 2.4, (0, 0, 0), ("rx", "ry", "rz")),
    ("thorax", (0.0, 1.0, 0.03), 2.4, (0, 0, 0), ("rx", "ry", "rz")),
    ("lowerneck", (0.0, 1.0, -0.06), 1.55, (0, 0, 0), ("rx", "ry", "rz")),
    ("upperneck", (0.0, 1.0, -0.1), 1.55, (0, 0, 0), ("rx", "ry", "rz")),
    ("head", (0.0, 1.0, -0.03), 1.6, (0, 0, 0), ("rx", "ry", "rz")),
)
_LEFT_ARM = (
    ("clavicle", (0.99, 0.04, -0.07), 3.4, (0, 0, 0), ("ry", "rz")),
    ("humerus", (1.0, 0.0, 0.0), 5.0, (180, -30, -90), ("rx", "ry", "rz")),
    ("radius", (1.0, 0.0, 0.0), 3.4, (180, -30, -90), ("rx",)),
    ("wrist", (1.0, 0.0, 0.0), 1.7, (0, 90, 90), ("ry",)),
    ("hand", (1.0, 0.0, 0.0), 1.1, (0, 90, 90), ("rx", "rz")),
    ("fingers", (1.0, 0.0, 0.0), 0.9, (0, 90, 90), ("rx",)),
    ("thumb", (0.707, 0.0, 0.707), 1.2, (-90, 45, 0), ("rx", "rz")),
)
_HIERARCHY = {
    "root": ["lhipjoint", "rhipjoint", "lowerback"],
    "lhipjoint": ["lfemur"],
    "lfemur": ["ltibia"],
    "ltibia": ["lfoot"],
    "lfoot": ["ltoes"],
    "rhipjoint": ["rfemur"],
    "rfemur": ["rtibia"],
    "rtibia": ["rfoot"],
    "rfoot": ["rtoes"],
    "lowerback": ["upperback"],
    "upperback": ["thorax"],
    "thorax": ["lowerneck", "lclavicle", "rclavicle"],
    "lowerneck": ["upperneck"],
    "upperneck": ["head"],
    "lclavicle": ["lhumerus"],
    "lhumerus": ["lradius"],
    "lradius": ["lwrist"],
    "lwrist": ["lhand", "lthumb"],
    "lhand": ["lfingers"],
    "rclavicle": ["rhumerus"],
    "rhumerus": ["rradius"],
    "rradius": ["rwrist"],
    "rwrist": ["rhand", "rthumb"],
    "rhand": ["rfingers"],
}
_TEMPLATE_HEIGHT = 1.76


def actor_skeleton(actor: str, style: ActorStyle | None = None) -> AsfSkeleton:
    """The CMU/HDM05-like 31-joint :class:`AsfSkeleton` of a synthetic actor (joint order = CMU31)."""
    style = style or ACTOR_STYLES[actor]
    s = style.height / _TEMPLATE_HEIGHT
    bones: list[AsfBone] = []

    def add(name, direction, length, axis, dof, factor, mirror):
        d = np.array(direction, float)
        ax = np.array(axis, float)
        if mirror:
            d[0] = -d[0]
            ax[1:] = -ax[1:]
        limits = [(-180.0, 180.0)] * len(dof)
        bones.append(
            AsfBone(
                id=len(bones) + 1,
                name=name,
                direction=d / np.linalg.norm(d),
                length=round(length * s * factor, 5),
                axis=ax,
                axis_order="XYZ",
                dof=tuple(dof),
                limits=limits,
            )
        )

    for side, mirror in (("l", False), ("r", True)):
        for name, d, ln, ax, dof in _LEFT:
            add(side + name, d, ln, ax, dof, style.legs if name != "hipjoint" else 1.0, mirror)
    for name, d, ln, ax, dof in _SPINE:
        add(name, d, ln, ax, dof, 1.0, False)
    for side, mirror in (("l", False), ("r", True)):
        for name, d, ln, ax, dof in _LEFT_ARM:
            add(side + name, d, ln, ax, dof, style.arms if name != "clavicle" else 1.0, mirror)
    return AsfSkeleton(
        name=f"HDM_{actor}_synthetic",
        version="1.10",
        units={"mass": 1.0, "length": 0.45, "angle": "deg"},
        documentation=f"synthetic HDM05-style skeleton of actor {actor} (mocapkit)",
        bones=bones,
        hierarchy={k: list(v) for k, v in _HIERARCHY.items()},
    )


# --------------------------------------------------------------------------- motion primitives


@dataclass
class _Pose:
    """Per-bone AMC angle arrays (degrees) plus root translation (metres) and heading, over T frames."""

    skel: AsfSkeleton
    T: int
    angles: dict = field(default_factory=dict)

    def __post_init__(self):
        for b in self.skel.bones:
            if b.dof:
                self.angles[b.name] = np.zeros((self.T, len(b.dof)))
        self.trans = np.zeros((self.T, 3))
        self.root_rot = np.zeros((self.T, 3))  # rx ry rz (deg)

    def add(self, bone: str, dof: str, values) -> None:
        self.angles[bone][:, self.skel.bone(bone).dof.index(dof)] += values

    def shoulder(self, side: str, flex, abd=0.0, twist=0.0) -> None:
        sign = 1.0 if side == "l" else -1.0
        k = 1.0 - np.asarray(abd, float) / 90.0
        self.add(side + "humerus", "rx", np.asarray(flex, float) - 30.0 * k)
        self.add(side + "humerus", "rz", sign * 90.0 * k)
        self.add(side + "humerus", "ry", twist)

    def elbow(self, side: str, flex) -> None:
        self.add(side + "radius", "rx", flex)

    def hip(self, side: str, flex, abd=0.0) -> None:
        self.add(side + "femur", "rx", -np.asarray(flex, float))
        self.add(side + "femur", "rz", (1.0 if side == "l" else -1.0) * np.asarray(abd, float))

    def knee(self, side: str, flex) -> None:
        self.add(side + "tibia", "rx", flex)

    def ankle(self, side: str, flex) -> None:
        self.add(side + "foot", "rx", flex)

    def bend(self, forward, twist=0.0, side_bend=0.0) -> None:
        for bone, w in (("lowerback", 0.4), ("upperback", 0.35), ("thorax", 0.25)):
            self.add(bone, "rx", w * np.asarray(forward, float))
            self.add(bone, "ry", w * np.asarray(twist, float))
            self.add(bone, "rz", w * np.asarray(side_bend, float))


def _parse(cls: str) -> dict:
    c65 = merge_65(cls)
    count = re.search(r"(\d+)(Reps|hops|Steps)", cls)
    n = int(count.group(1)) if count else 1
    start = re.search(r"([LR])(?:Hand|elbow)?[Ss]tart$", cls)
    limb = "both"  # the acting limb: an L/R right after a lower-case letter
    if "Both" not in c65:
        side = re.search(r"(?<=[a-z])([LR])(?=[A-Z]|$)", c65)
        limb = side.group(1).lower() if side else "both"
    return {
        "stem": merge_25_stem(cls),
        "c65": c65,
        "count": n,
        "start": (start.group(1).lower() if start else "l"),
        "limb": limb,
    }


_PERIOD = {
    "walk": 1.1,
    "jog": 0.75,
    "run": 0.65,
    "sneak": 1.6,
    "shuffle": 1.2,
    "hop": 0.65,
    "kick": 1.3,
    "punch": 0.9,
    "squat": 1.8,
    "jumping": 1.1,
    "clap": 0.55,
    "rotate": 1.1,
    "elbow": 1.6,
}


def _smooth_noise(rng: np.random.Generator, T: int, width: int, sd: float) -> np.ndarray:
    """[T] zero-mean noise smoothed over ~``width`` frames with standard deviation ~``sd``."""
    raw = rng.standard_normal(T + 2 * width)
    kernel = np.hanning(2 * width + 1)
    kernel /= np.sqrt((kernel**2).sum())
    return np.convolve(raw, kernel, mode="same")[width : width + T] * sd


def _clip(cls: str, skel: AsfSkeleton, style: ActorStyle, rng: np.random.Generator, cfg: HDM05SynthConfig) -> dict:
    info = _parse(cls)
    stem, c65, n = info["stem"], info["c65"], info["count"]
    amp = style.amplitude * (1.0 + cfg.variation * rng.uniform(-1, 1))
    tempo = style.tempo * (1.0 + cfg.variation * rng.uniform(-1, 1))
    period = _PERIOD.get(stem, 1.2) / tempo
    locomotion = stem in ("walk", "jog", "run", "sneak", "shuffle")
    cycles = n / 2.0 if locomotion else float(n)  # a gait cycle is two steps
    if locomotion and n == 1:
        cycles = 1.0
    pre, post = rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4)
    active = cycles * period
    T = int(min(cfg.max_frames, max(24, round((pre + active + post) * cfg.fps))))
    t = np.arange(T) / cfg.fps
    u = np.clip((t - pre) / period, 0.0, cycles)  # cycle phase, 0 … cycles
    on = ((t >= pre) & (t <= pre + active)).astype(float)
    env = np.clip(np.minimum((t - pre) / 0.25, (pre + active - t) / 0.25), 0.0, 1.0) ** 2
    pulse = np.sin(np.pi * (u % 1.0)) ** 2 * on  # one bump per cycle
    P = _Pose(skel, T)
    first, second = ("l", "r") if info["start"] == "l" else ("r", "l")
    limb = info["limb"]
    sides = ("l", "r") if limb == "both" else (limb,)

    # rest posture: arms hanging, elbows carried, small trunk lean
    for s in "lr":
        P.shoulder(s, 8.0, 6.0)
        P.elbow(s, style.arm_carry)
    P.bend(style.lean)
    lift = 0.0 * t  # airborne height (m); feet are put on the floor otherwise
    forward = 0.0 * t  # distance travelled along the heading (m)
    lateral = 0.0 * t
    yaw = 0.0 * t  # heading change (deg)

    if locomotion:
        theta = np.pi * u * 2.0  # gait cycle angle
        big = {"walk": 1.0, "jog": 1.4, "run": 1.6, "sneak": 0.8, "shuffle": 0.5}[stem] * amp
        swing = np.sin(theta) * env
        for s, sgn in ((first, 1.0), (second, -1.0)):
            P.hip(s, 25.0 * big * sgn * swing)
            P.knee(s, 50.0 * big * np.clip(sgn * np.sin(theta - 0.8), 0, None) * env)
            P.ankle(s, 10.0 * big * sgn * swing)
            P.shoulder(s, -20.0 * big * sgn * swing)
            P.elbow(s, 15.0 * big * (stem != "walk") * 4.0)
        speed = {"walk": 1.3, "jog": 2.2, "run": 2.8, "sneak": 0.7, "shuffle": 0.5}[stem] * tempo
        dist = np.cumsum(on) / cfg.fps * speed
        if stem in ("jog", "run"):
            lift = 0.05 * big * np.clip(np.sin(2 * theta), 0, None) * env
        if stem == "sneak":
            for s in "lr":
                P.hip(s, 25.0)
                P.knee(s, 40.0)
            P.bend(20.0)
        if "OnPlace" in c65:
            dist = dist * 0.0
        if "Backwards" in c65:
            forward = -dist
        elif c65.startswith("walkLeft") and "Circle" not in c65:
            lateral = dist * 0.5
        elif "CrossFront" in c65:
            lateral = -dist * 0.5
        else:
            forward = dist
        if "Circle" in c65:
            turn = 1.0 if "Left" in c65 else -1.0
            yaw = turn * 360.0 / max(cycles, 1.0) * 0.5 * u
    elif stem == "hop":
        hop = np.sin(np.pi * (u % 1.0)) * on
        lifted = {"l": "r", "r": "l"}.get(limb)
        for s in "lr":
            if s == lifted:
                P.hip(s, 35.0 * amp * env)
                P.knee(s, 70.0 * amp * env)
            else:
                P.knee(s, 35.0 * amp * (1 - hop) * env)
                P.hip(s, 20.0 * amp * (1 - hop) * env)
        lift = 0.18 * amp * hop
        forward = np.cumsum(on) / cfg.fps * 0.4
        for s in "lr":
            P.shoulder(s, 20.0 * env, 25.0 * env)
    elif stem == "kick":
        front = "Front" in c65
        for s in sides:
            if front:
                P.hip(s, 85.0 * amp * pulse)
            else:
                P.hip(s, 20.0 * amp * pulse, 60.0 * amp * pulse)
            P.knee(s, 70.0 * np.sin(np.pi * (u % 1.0)) ** 6 * on + 25.0 * pulse)
        other = "r" if sides == ("l",) else "l"
        P.knee(other, 12.0 * pulse)
        P.bend(-12.0 * pulse if front else 0.0, side_bend=(25.0 if sides == ("l",) else -25.0) * pulse * (not front))
        for s in "lr":
            P.shoulder(s, 50.0 * env, 10.0 * env)
            P.elbow(s, 90.0 * env)
    elif stem == "punch":
        front = "Front" in c65
        for s in "lr":  # guard
            P.shoulder(s, 45.0 * env, 10.0 * env)
            P.elbow(s, 100.0 * env)
        for s in sides:
            if front:
                P.shoulder(s, 45.0 * amp * pulse)
            else:
                P.shoulder(s, -20.0 * pulse, 80.0 * amp * pulse)
            P.elbow(s, -95.0 * amp * pulse)
            P.bend(0.0, twist=(15.0 if s == "l" else -15.0) * pulse * front)
    elif stem == "squat":
        for s in "lr":
            P.hip(s, 95.0 * amp * pulse)
            P.knee(s, 110.0 * amp * pulse)
            P.ankle(s, -25.0 * pulse)
            P.shoulder(s, 75.0 * pulse)
        P.bend(25.0 * pulse)
    elif stem == "jumping":
        for s in "lr":
            P.shoulder(s, 0.0, 150.0 * amp * pulse)
            P.elbow(s, -style.arm_carry * pulse)
            P.hip(s, 0.0, 20.0 * amp * pulse)
            P.knee(s, 20.0 * (1 - np.abs(np.cos(2 * np.pi * u))) * on)
        lift = 0.08 * np.abs(np.sin(2 * np.pi * u)) * on
    elif stem == "clap":
        high = "AboveHead" in c65
        raise_deg = (160.0 if high else 75.0) * env  # arm elevation (degrees), not the root's lift
        beat = np.sin(np.pi * (u % 1.0)) ** 2 * on
        for s in "lr":
            P.shoulder(s, raise_deg, 25.0 * (1 - beat) * env, twist=0.0)
            P.elbow(s, (20.0 if high else 45.0) * env)
            P.add(s + "humerus", "ry", (35.0 if s == "l" else -35.0) * beat)
    elif stem == "rotate":
        backward = "Backward" in c65
        angle = 360.0 * u * (-1.0 if backward else 1.0)
        for s in sides:
            P.shoulder(s, angle * on + 0.0, 10.0 * env)
            P.elbow(s, -style.arm_carry * env)
    elif stem == "elbow":
        for k in range(int(np.ceil(cycles * 2))):  # alternate sides each half cycle
            s_elbow = first if k % 2 == 0 else second
            s_knee = "r" if s_elbow == "l" else "l"
            half = ((u * 2 >= k) & (u * 2 < k + 1)).astype(float) * on
            bump = np.sin(np.pi * np.clip(u * 2 - k, 0, 1)) ** 2 * half
            P.hip(s_knee, 80.0 * amp * bump)
            P.knee(s_knee, 80.0 * bump)
            P.shoulder(s_elbow, 70.0 * bump, 40.0 * bump)
            P.elbow(s_elbow, 110.0 * bump)
            P.bend(25.0 * bump, twist=(30.0 if s_elbow == "l" else -30.0) * bump)
        for s in "lr":
            P.shoulder(s, 0.0, 60.0 * env)
            P.elbow(s, 100.0 * env)
    else:  # any other class: a stem-seeded periodic pattern
        srng = np.random.default_rng(zlib.crc32(c65.encode()))
        movable = [
            (b.name, d)
            for b in skel.bones
            if b.dof
            for d in b.dof
            if b.name[1:] in ("femur", "tibia", "humerus", "radius") or b.name == "lowerback"
        ]
        for i in srng.choice(len(movable), size=6, replace=False):
            bone, dof = movable[i]
            P.add(bone, dof, srng.uniform(15, 50) * amp * np.sin(2 * np.pi * u + srng.uniform(0, 2 * np.pi)) * env)

    # smooth noise on every dof
    for bone, arr in P.angles.items():
        for k in range(arr.shape[1]):
            arr[:, k] += _smooth_noise(rng, T, 12, cfg.noise_deg)
    heading0 = rng.uniform(-180.0, 180.0)
    head = np.deg2rad(heading0 + yaw)
    x0, z0 = rng.uniform(-1.0, 1.0, size=2)
    # integrate the travelled distance along the (turning) heading
    step_f = np.diff(forward, prepend=forward[:1])
    step_l = np.diff(lateral, prepend=lateral[:1])
    dx = np.sin(head) * step_f + np.cos(head) * step_l
    dz = np.cos(head) * step_f - np.sin(head) * step_l
    P.trans[:, 0] = x0 + np.cumsum(dx)
    P.trans[:, 2] = z0 + np.cumsum(dz)
    P.trans[:, 1] = lift
    P.root_rot[:, 1] = heading0 + yaw
    P.root_rot[:, 0] = _smooth_noise(rng, T, 20, 1.0)
    P.root_rot[:, 2] = _smooth_noise(rng, T, 20, 1.0)
    return {"pose": P}


def _amc_values(P: _Pose) -> dict:
    """AMC values of a pose, with the root raised so that the lowest foot joint is on the floor
    (y = 0) in every frame, plus the pose's airborne lift."""
    values = {b: a for b, a in P.angles.items()}
    root = np.zeros((P.T, 6))
    root[:, 0] = P.trans[:, 0] / UNIT
    root[:, 2] = P.trans[:, 2] / UNIT
    root[:, 3:] = P.root_rot
    values["root"] = root
    pos, _ = forward_kinematics(P.skel, values)
    feet = [P.skel.joint_names.index(n) for n in ("lfoot", "ltoes", "rfoot", "rtoes")]
    root[:, 1] = (P.trans[:, 1] - pos[:, feet, 1].min(axis=1)) / UNIT
    return values


def synthesize_hdm05(out_dir: str | Path, config: HDM05SynthConfig | None = None, progress: bool = True) -> list[Path]:
    """Write a synthetic HDM05-style ASF/AMC data set (see the module docstring).

    Args:
        out_dir: output folder (created).
        config: what to write (default :class:`HDM05SynthConfig`).
        progress: show a progress bar.

    Returns:
        The AMC clip paths, sorted (the ASFs and ``classes.txt`` are beside them).
    """
    cfg = config or HDM05SynthConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "classes.txt").write_text("\n".join(cfg.classes) + "\n", encoding="ascii")
    jobs = []
    skeletons = {}
    for actor in cfg.actors:
        skel = actor_skeleton(actor)
        write_asf(out / f"HDM_{actor}.asf", skel)
        skel.source = None  # the AMC header then does not name a local path
        skeletons[actor] = skel
        for cls in cfg.classes:
            for take in range(1, cfg.clips_per_actor + 1):
                jobs.append((cls, actor, take))
    iterator = jobs
    if progress:
        try:
            from tqdm import tqdm

            iterator = tqdm(jobs, desc="synth hdm05", unit="clip")
        except ImportError:  # pragma: no cover
            pass
    paths = []
    for cls, actor, take in iterator:
        skel = skeletons[actor]
        # one independent stream per clip, so a clip does not depend on which others are written
        key = [cfg.seed, ACTORS.index(actor), zlib.crc32(cls.encode()), take]
        rng = np.random.default_rng(key)
        clip = _clip(cls, skel, ACTOR_STYLES[actor], rng, cfg)
        path = out / f"{cls}_{actor}_{take:03d}.amc"
        write_amc(path, _amc_values(clip["pose"]), skel, digits=cfg.digits)
        paths.append(path)
    return sorted(paths)
