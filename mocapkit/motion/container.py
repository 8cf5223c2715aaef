"""The one motion container every reader returns and every method consumes.

``read_motion(path)`` (in :mod:`mocapkit.datasets.formats.motion_io`) returns a
:class:`Motion` for ASF/AMC, BVH, C3D and MSR Action3D files alike:

- ``positions``: float32 ``[frames, joints, 3]`` in **metres**; NaN where missing;
- ``missing``: bool ``[frames, joints]``, True where the file has no valid value
  (C3D gaps, MSR all-zero frames); always consistent with the NaNs. One rule for arrays: a
  joint with any non-finite coordinate (NaN or Inf) when the Motion is built is missing, and
  its position becomes NaN;
- ``joint_names`` and ``parents`` (``-1`` for the root; ``None`` for marker sets
  with no hierarchy, such as C3D);
- ``rotations``: optional float32 ``[frames, joints, 3, 3]`` local joint rotations
  (for the forward-kinematics formats);
- ``fps``, ``source_units`` (what the file used, e.g. ``"mm"`` or
  ``"inch/0.45 (CMU)"``), ``up_axis`` (``"y"`` or ``"z"``), ``name``, ``source``,
  ``metadata``.

Views: :meth:`Motion.resample`, :meth:`Motion.root_centered`,
:meth:`Motion.torso_aligned`, :meth:`Motion.map_layout` (between NTU-25, MSR-20
and CMU/HDM05-31 through shared body landmarks) and :meth:`Motion.select`.
Every view returns a new Motion; the original is never modified.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from mocapkit.motion.geometry import AXES, hip_line_heading, horizontal_axes, turn_about_up
from mocapkit.motion.layouts import LANDMARKS, SkeletonLayout, mirror_joints


# Per-joint tests of ``[..., 3]`` coordinate arrays. numpy reduces over a trailing axis of 3 about ten times slower
# than it combines the three coordinate slices (170-210 µs against 13-34 µs on a [300, 31, 3] array; a refiner pays
# several of them per take: bench/RESULTS.md#onnx-runtime-costs), so these read the
# coordinates one at a time.
def any_coordinate(mask: np.ndarray) -> np.ndarray:
    """``mask [..., 3]`` bool → ``[...]``: True where any of the three coordinates is (``mask.any(-1)``)."""
    return mask[..., 0] | mask[..., 1] | mask[..., 2]


def all_coordinates(mask: np.ndarray) -> np.ndarray:
    """``mask [..., 3]`` bool → ``[...]``: True where all three coordinates are (``mask.all(-1)``)."""
    return mask[..., 0] & mask[..., 1] & mask[..., 2]


def point_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance of ``[..., 3]`` points ``a`` and ``b`` → ``[...]`` (``np.linalg.norm(a - b, axis=-1)``)."""
    d = a - b
    return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])


@dataclass
class Motion:
    """A motion clip: joint (or marker) positions over time, in metres. See the module docstring."""

    positions: np.ndarray
    joint_names: tuple[str, ...]
    fps: float
    parents: tuple[int, ...] | None = None
    missing: np.ndarray | None = None
    rotations: np.ndarray | None = None
    source_units: str = "m"
    up_axis: str = "y"
    name: str = ""
    source: str | None = None
    layout_name: str | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.positions = np.asarray(self.positions, dtype=np.float32)
        self.joint_names = tuple(self.joint_names)
        if self.positions.ndim != 3 or self.positions.shape[2] != 3:
            raise ValueError(
                f"{self._label()}: positions must be [frames, joints, 3], got {list(self.positions.shape)}"
            )
        frames, joints = self.positions.shape[:2]
        if len(self.joint_names) != joints:
            raise ValueError(f"{self._label()}: {len(self.joint_names)} joint names for {joints} joints")
        if self.parents is not None:
            self.parents = tuple(int(p) for p in self.parents)
            if len(self.parents) != joints or any(p >= joints or p < -1 for p in self.parents):
                raise ValueError(f"{self._label()}: parents must give one index in [-1, {joints}) per joint")
        if not (self.fps > 0):  # also rejects NaN
            raise ValueError(f"{self._label()}: frame rate must be positive, got {self.fps}")
        if self.up_axis not in AXES:
            raise ValueError(f"{self._label()}: up_axis must be x, y or z, got {self.up_axis!r}")
        nan = any_coordinate(~np.isfinite(self.positions))  # NaN or Inf: not observed
        if self.missing is None:
            self.missing = nan
        else:
            missing = np.asarray(self.missing, dtype=bool)
            if missing.shape != (frames, joints):
                raise ValueError(f"{self._label()}: missing must be [{frames}, {joints}], got {list(missing.shape)}")
            self.missing = missing | nan
        if self.missing.any():  # a missing joint is NaN in all three coordinates
            self.positions = self.positions.copy()  # never write NaN into the caller's array
            self.positions[self.missing] = np.nan
        if self.rotations is not None:
            self.rotations = np.asarray(self.rotations, dtype=np.float32)
            if self.rotations.shape != (frames, joints, 3, 3):
                raise ValueError(f"{self._label()}: rotations must be [{frames}, {joints}, 3, 3]")

    def _label(self) -> str:
        return self.source or self.name or "motion"

    # ------------------------------------------------------------------ basics

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def num_joints(self) -> int:
        return int(self.positions.shape[1])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.num_frames - 1) / self.fps

    @property
    def layout(self) -> SkeletonLayout:
        """The skeleton topology (needs ``parents``)."""
        if self.parents is None:
            raise ValueError(f"{self._label()} has no joint hierarchy (a marker set)")
        return SkeletonLayout(self.layout_name or self.name or "custom", self.joint_names, self.parents)

    def filled(self, value: float = 0.0) -> np.ndarray:
        """``positions`` with missing entries replaced by ``value`` (a copy)."""
        return np.where(self.missing[..., None], np.float32(value), self.positions)

    def index(self, joint: str) -> int:
        try:
            return self.joint_names.index(joint)
        except ValueError:
            raise KeyError(f"{self._label()} has no joint {joint!r}") from None

    # ------------------------------------------------------------------ views

    def select(self, joints: list[str] | list[int]) -> Motion:
        """Only ``joints`` (names or indices), in that order; parents are kept where they are selected."""
        idx = [self.index(j) if isinstance(j, str) else int(j) % self.num_joints for j in joints]
        parents = None
        if self.parents is not None:
            where = {old: new for new, old in enumerate(idx)}
            parents = tuple(where.get(self.parents[i], -1) for i in idx)
            if sum(p < 0 for p in parents) != 1:
                parents = None  # the selection is not a tree any more
        return replace(
            self,
            positions=self.positions[:, idx],
            joint_names=tuple(self.joint_names[i] for i in idx),
            parents=parents,
            missing=self.missing[:, idx],
            rotations=None if self.rotations is None else self.rotations[:, idx],
            layout_name=None,
            metadata=dict(self.metadata),
        )

    def resample(self, fps: float) -> Motion:
        """Linear interpolation in time to ``fps`` frames per second (over the same duration).

        A resampled frame is missing where either neighbouring source frame is.
        Local rotations are dropped (interpolating matrices linearly is wrong).
        """
        if fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        if self.num_frames < 2 or fps == self.fps:
            same = fps == self.fps
            return replace(
                self,
                positions=self.positions.copy(),
                missing=self.missing.copy(),
                rotations=self.rotations if same else None,
                fps=self.fps if same else float(fps),
                metadata=dict(self.metadata),
            )
        count = int(np.floor(self.duration * fps + 1e-6)) + 1
        return self.sample_at(np.arange(count) * (self.fps / fps), fps)

    def sample_at(self, t: np.ndarray, fps: float) -> Motion:
        """The motion at the times ``t`` (``[N]``, in this motion's frames, clipped to its first and last frame),
        linearly interpolated, as a Motion at ``fps``. A sample is missing where either neighbouring source frame
        is (the one it lies on, when it lies on a frame). Local rotations are dropped."""
        t = np.clip(np.asarray(t, dtype=np.float64), 0, self.num_frames - 1)
        lo = np.floor(t).astype(np.int64)
        hi = np.minimum(lo + 1, self.num_frames - 1)
        w = (t - lo).astype(np.float32)[:, None, None]
        positions = self.filled()[lo] * (1 - w) + self.filled()[hi] * w
        missing = self.missing[lo] | (self.missing[hi] & (w[:, :, 0] > 0))
        return replace(
            self, positions=positions, missing=missing, fps=float(fps), rotations=None, metadata=dict(self.metadata)
        )

    def root_centered(self, root: str | int | None = None) -> Motion:
        """Positions relative to the root joint (default: the hierarchy's root, else joint 0) in every frame."""
        r = self._joint(root, default=self.parents.index(-1) if self.parents else 0)
        return replace(self, positions=self.positions - self.positions[:, r : r + 1], metadata=dict(self.metadata))

    def torso_aligned(self, left_hip: str | int, right_hip: str | int, root: str | int | None = None) -> Motion:
        """Root-centred and turned about the up axis so that, in every frame, the hip line
        (left → right) lies along the first horizontal axis (x, or x for z-up data)."""
        centred = self.root_centered(root)
        angle = hip_line_heading(centred.positions, self._joint(left_hip), self._joint(right_hip), self.up_axis)
        return replace(centred, positions=turn_about_up(centred.positions, angle, self.up_axis), rotations=None)

    def mirrored(self) -> Motion:
        """The motion's mirror image: the first horizontal axis negated (x, for y-up and z-up data alike) and every
        left joint's trajectory given to its right counterpart and back (:func:`~mocapkit.motion.layouts.
        mirror_joints`). A left-handed wave becomes a right-handed one; bone lengths and speeds are unchanged.
        Local rotations are dropped. Raises ``ValueError`` for a skeleton whose sides cannot be paired by name or
        whose hierarchy is not left-right symmetric."""
        swap = mirror_joints(self.joint_names)
        if self.parents is not None and any(
            (self.parents[j] < 0) != (self.parents[swap[j]] < 0)
            or (self.parents[j] >= 0 and swap[self.parents[j]] != self.parents[swap[j]])
            for j in range(self.num_joints)
        ):
            raise ValueError(f"{self._label()}: the joint hierarchy is not left-right symmetric; cannot mirror it")
        axis = horizontal_axes(self.up_axis)[0]
        positions = self.positions[:, swap].copy()
        positions[..., axis] *= -1
        return replace(
            self,
            positions=positions,
            missing=self.missing[:, swap].copy(),
            rotations=None,
            metadata=dict(self.metadata),
        )

    def map_layout(self, target: SkeletonLayout) -> Motion:
        """The same motion on another layout, joint by joint through shared body landmarks.

        Target joints without a corresponding source joint are missing (NaN).
        """
        source_name = self.layout_name
        if source_name not in LANDMARKS or target.name not in LANDMARKS:
            raise ValueError(
                f"no landmark table for layout {source_name!r} -> {target.name!r}; known: {sorted(LANDMARKS)}"
            )
        by_landmark = {lm: self.index(joint) for lm, joint in LANDMARKS[source_name].items()}
        source_of = {target.index(joint): by_landmark.get(lm) for lm, joint in LANDMARKS[target.name].items()}
        positions = np.full((self.num_frames, target.num_joints, 3), np.nan, dtype=np.float32)
        for j, src in source_of.items():
            if src is not None:
                positions[:, j] = self.positions[:, src]
        return Motion(
            positions=positions,
            joint_names=target.joint_names,
            parents=target.parents,
            fps=self.fps,
            source_units=self.source_units,
            up_axis=self.up_axis,
            name=self.name,
            source=self.source,
            layout_name=target.name,
            metadata=dict(self.metadata, mapped_from=source_name),
        )

    def _joint(self, joint: str | int | None, default: int | None = None) -> int:
        if joint is None:
            if default is None:
                raise ValueError("a joint is required")
            return default
        return self.index(joint) if isinstance(joint, str) else int(joint)
