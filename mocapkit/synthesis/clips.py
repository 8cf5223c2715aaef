"""The clips a synthesiser learns from: the checks every ``fit`` runs (AMC clips, one hierarchy, enough clips, long
enough clips), the packing of AMC values into one matrix (:func:`dof_matrix`, :func:`dof_values`), its resampling
and smoothing in time (:func:`time_warp`, :func:`resample_clip`, :func:`smooth_values`) and BVH → AMC conversion
(:func:`as_amc_clips`). The contract that uses them is :mod:`mocapkit.synthesis.base`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit.datasets.formats.asf_amc import AsfSkeleton, amc_motion
from mocapkit.motion.container import Motion

#: Default ``smoothing_seconds`` of every generator (:class:`MotionSynthesizer`, *Smoothing*): a Gaussian of two
#: frames at 30 fps (67 ms) on each variant's joint-angle curves. Chosen on training clips only
#: (``scripts/selection/select_synthesis_defaults.py --param smoothing_seconds``); the rule and the numbers:
#: docs/decisions.md#synthesis-smoothing.
SMOOTHING_SECONDS = 2 / 30


class SynthesisInputError(ValueError):
    """Training clips a synthesiser cannot learn from; the message names the clip (file) and what is wrong."""


def clip_label(motion: Motion) -> str:
    """The file of a clip, else its name: what error messages name."""
    return str(motion.source or motion.name or "<unnamed clip>")


@dataclass(frozen=True)
class DofLayout:
    """Which AMC channel is which column of a :func:`dof_matrix`.

    Attributes:
        bones: the bones with dofs, root first, in the skeleton's AMC order.
        dofs: per bone, its channel names (root: ``AsfSkeleton.root_order``, e.g. ``("TX", ..., "RZ")``; other
            bones: their ``dof``, e.g. ``("rx", "ry", "rz")``).
    """

    bones: tuple[str, ...]
    dofs: tuple[tuple[str, ...], ...]

    @classmethod
    def of(cls, skeleton: AsfSkeleton) -> DofLayout:
        dof = {b.name: tuple(b.dof) for b in skeleton.bones}
        bones = tuple(skeleton.amc_bones)
        return cls(bones=bones, dofs=tuple(tuple(skeleton.root_order) if b == "root" else dof[b] for b in bones))

    @property
    def width(self) -> int:
        """Number of columns (channels) of the matrix."""
        return sum(len(d) for d in self.dofs)

    def columns(self, bone: str) -> slice:
        """The columns of ``bone`` in the matrix."""
        start = 0
        for b, d in zip(self.bones, self.dofs):
            if b == bone:
                return slice(start, start + len(d))
            start += len(d)
        raise KeyError(bone)


def dof_matrix(motion: Motion) -> tuple[np.ndarray, DofLayout]:
    """A clip's AMC values as one float64 ``[frames, channels]`` matrix (angles in degrees, root TX/TY/TZ in ASF
    length units) and the :class:`DofLayout` of its columns."""
    skeleton = motion.metadata["asf"]
    layout = DofLayout.of(skeleton)
    values = motion.metadata["amc_values"]
    scale = np.degrees(1.0) if motion.metadata.get("amc_angle_unit", "deg") == "rad" else 1.0
    columns = []
    for bone, dofs in zip(layout.bones, layout.dofs):
        v = np.asarray(values[bone], dtype=np.float64).reshape(len(motion.positions), len(dofs)).copy()
        for k, name in enumerate(dofs):
            if name.lower().startswith("r"):
                v[:, k] *= scale
        columns.append(v)
    return np.concatenate(columns, axis=1), layout


def dof_values(matrix: np.ndarray, layout: DofLayout) -> dict[str, np.ndarray]:
    """The inverse of :func:`dof_matrix`: bone → ``[frames, len(dof)]`` AMC values (degrees, ASF units)."""
    matrix = np.asarray(matrix, dtype=np.float64)
    if matrix.ndim != 2 or matrix.shape[1] != layout.width:
        raise ValueError(f"a DOF matrix must be [frames, {layout.width}], got {list(matrix.shape)}")
    return {bone: matrix[:, layout.columns(bone)].copy() for bone in layout.bones}


def rotation_columns(layout: DofLayout) -> np.ndarray:
    """bool ``[channels]``: which columns of a :func:`dof_matrix` are angles (degrees)."""
    return np.array([name.lower().startswith("r") for dofs in layout.dofs for name in dofs])


def time_warp(matrix: np.ndarray, n_frames: int, angles: np.ndarray | None = None, kind: str = "linear") -> np.ndarray:
    """Resample a ``[T, channels]`` matrix to ``[n_frames, channels]`` at evenly spaced times (first and last frames
    kept), by ``kind`` = ``"linear"`` interpolation or a ``"cubic"`` spline (scipy ``CubicSpline``, not-a-knot;
    continuous velocity and acceleration, so upsampling adds no jerk at the source frames).

    ``angles`` (bool ``[channels]``) marks the columns in degrees: they are unwrapped (period 360°) first, so the
    result may leave ``[-180, 180]`` (AMC takes any angle).
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    if angles is not None and angles.any():
        matrix = matrix.copy()
        matrix[:, angles] = np.unwrap(matrix[:, angles], period=360.0, axis=0)
    if len(matrix) == n_frames:
        return matrix.copy()
    source = np.linspace(0.0, 1.0, len(matrix))
    target = np.linspace(0.0, 1.0, n_frames)
    if kind == "cubic" and len(matrix) >= 4:
        from scipy.interpolate import CubicSpline

        return CubicSpline(source, matrix, axis=0)(target)
    if kind not in ("linear", "cubic"):
        raise ValueError(f"time_warp: kind={kind!r}, expected 'linear' or 'cubic'")
    return np.stack([np.interp(target, source, column) for column in matrix.T], axis=1)


def smooth_values(
    values: dict[str, np.ndarray], layout: DofLayout, fps: float, seconds: float
) -> dict[str, np.ndarray]:
    """One variant's AMC values (bone → ``[T, len(dof)]``, degrees and ASF units) low-passed in time by a Gaussian of
    standard deviation ``seconds`` (``seconds · fps`` frames; scipy ``gaussian_filter1d``, ``mode="nearest"``, so
    the ends are not pulled towards zero). Angle columns are unwrapped (period 360°) first, so a turn through
    ±180° is not smeared into a spin. ``seconds <= 0`` returns a copy."""
    matrix = np.concatenate(
        [
            np.asarray(values[bone], dtype=np.float64).reshape(-1, len(dofs))
            for bone, dofs in zip(layout.bones, layout.dofs)
        ],
        axis=1,
    )
    sigma = float(seconds) * float(fps)
    if sigma > 0 and len(matrix) > 1:
        from scipy.ndimage import gaussian_filter1d

        angles = rotation_columns(layout)
        matrix[:, angles] = np.unwrap(matrix[:, angles], period=360.0, axis=0)
        matrix = gaussian_filter1d(matrix, sigma, axis=0, mode="nearest")
    return dof_values(matrix, layout)


def model_frames(frames: int, fps: float, model_fps: float) -> int:
    """Frames at ``model_fps`` that span ``frames`` frames at ``fps`` (first and last frames kept)."""
    return round((frames - 1) * model_fps / fps) + 1


def resample_clip(clip: Motion, fps: float) -> Motion:
    """An AMC clip at another frame rate, its AMC values time-warped linearly over the same duration (the
    synthesisers that model a lower rate than the data's train on these)."""
    if float(fps) == clip.fps:
        return clip
    matrix, layout = dof_matrix(clip)
    values = dof_values(time_warp(matrix, model_frames(len(matrix), clip.fps, fps), rotation_columns(layout)), layout)
    return amc_motion(
        clip.metadata["asf"], values, fps=float(fps), angle_unit="deg", name=clip.name, source=clip.source
    )


def clip_segment(clip: Motion, start: int, stop: int) -> Motion:
    """Frames ``start`` … ``stop - 1`` of an AMC clip, as an AMC motion on the same skeleton and frame rate (its
    name and source gain ``[start:stop]``; the skeleton file, ``metadata["asf_path"]``, and a converted BVH's
    rig, ``metadata["bvh_rig"]``, are kept)."""
    values = {bone: np.asarray(v)[start:stop] for bone, v in clip.metadata["amc_values"].items()}
    suffix = f"[{start}:{stop}]"
    kept = {key: clip.metadata[key] for key in ("asf_path", "bvh_rig") if clip.metadata.get(key) is not None}
    return amc_motion(
        clip.metadata["asf"],
        values,
        fps=clip.fps,
        angle_unit=clip.metadata.get("amc_angle_unit", "deg"),
        name=f"{clip.name}{suffix}",
        source=f"{clip.source}{suffix}" if clip.source else None,
        metadata=kept,
    )


def clip_windows(clip: Motion, seconds: float) -> list[Motion]:
    """A long take cut into consecutive, non-overlapping windows of ``round(seconds · fps)`` frames each
    (:func:`clip_segment`, names ``<name>[start:stop]``), for takes that hold many repetitions of one motion
    (CMU's minute-long walks) where the synthesisers want about ten short example clips. The last
    ``len % window`` frames are left out; a clip shorter than one window gives no window (callers report both).

    Raises:
        ValueError: ``seconds`` not positive, or shorter than 4 frames at the clip's frame rate.
    """
    frames = round(float(seconds) * clip.fps)
    if not seconds > 0 or frames < 4:
        raise ValueError(f"window of {seconds} s = {frames} frames at {clip.fps:g} fps; give at least 4 frames")
    return [clip_segment(clip, start, start + frames) for start in range(0, len(clip.positions) - frames + 1, frames)]


def on_skeleton(clip: Motion, skeleton: AsfSkeleton) -> Motion:
    """An AMC clip posed on another ``skeleton`` by its own AMC values (same frame rate), so that clips of
    different performers compare without their body sizes."""
    return amc_motion(
        skeleton,
        clip.metadata["amc_values"],
        fps=clip.fps,
        angle_unit=clip.metadata.get("amc_angle_unit", "deg"),
        name=clip.name,
        source=clip.source,
    )


def as_amc_clips(motions: Sequence[Motion], reference: Motion | None = None, reference_frame: int = 0) -> list[Motion]:
    """Training clips as AMC motions: ASF/AMC clips as they are, BVH clips
    (:func:`~mocapkit.datasets.formats.bvh.read_bvh`) converted exactly to ASF/AMC
    (:func:`~mocapkit.datasets.formats.bvh_to_amc.bvh_to_amc`) on **one** rig, whose rest pose is the posture of
    ``reference`` (default: the first BVH clip) at ``reference_frame`` straightened into a T-pose, so that every
    clip's angles are measured from the same rest. Anything else is passed on for :func:`check_clips` to refuse.

    Raises:
        mocapkit.datasets.formats.bvh_to_amc.BvhConversionError: a BVH clip that cannot be converted (names it).
    """
    motions = list(motions)
    bvh = [m for m in motions if isinstance(m, Motion) and "bvh" in m.metadata and "amc_values" not in m.metadata]
    if not bvh:
        return motions
    from mocapkit.datasets.formats.bvh_to_amc import bvh_rig, bvh_to_amc

    rig = bvh_rig(bvh[0] if reference is None else reference, reference_frame)
    return [bvh_to_amc(m, rig) if any(m is b for b in bvh) else m for m in motions]


def check_clips(clips: Sequence[Motion], min_clips: int = 2, min_frames: int = 4, what: str = "fit") -> DofLayout:
    """Reject what no synthesiser can learn from, naming the clip; returns the shared :class:`DofLayout`.

    Raises:
        SynthesisInputError: fewer than ``min_clips`` clips; a clip that is not an AMC motion (no
            ``metadata["amc_values"]``/``["asf"]``); a clip shorter than ``min_frames`` frames; a clip whose bones or
            dofs differ from the first clip's; non-finite angles.
    """
    clips = list(clips)
    if len(clips) < min_clips:
        raise SynthesisInputError(
            f"{what}: {len(clips)} training clip(s); this synthesiser needs at least {min_clips} of one motion type"
        )
    layout = None
    for clip in clips:
        if not isinstance(clip, Motion) or "amc_values" not in clip.metadata or "asf" not in clip.metadata:
            raise SynthesisInputError(
                f"{what}: {clip_label(clip) if isinstance(clip, Motion) else type(clip).__name__}"
                f" is not an ASF/AMC motion (read it with mocapkit.datasets.formats.asf_amc."
                f"read_amc, or convert a BVH with mocapkit.synthesis.base.as_amc_clips); "
                f"synthesis works on joint angles"
            )
        if len(clip.positions) < min_frames:
            raise SynthesisInputError(
                f"{what}: {clip_label(clip)} has {len(clip.positions)} frames; this synthesiser "
                f"needs at least {min_frames}"
            )
        this = DofLayout.of(clip.metadata["asf"])
        if layout is None:
            layout, first = this, clip
        elif this != layout:
            diff = sorted(set(zip(this.bones, this.dofs)) ^ set(zip(layout.bones, layout.dofs)))
            raise SynthesisInputError(
                f"{what}: {clip_label(clip)} has a different skeleton from {clip_label(first)} "
                f"(bones/dofs that differ: {diff[:6]})"
            )
        matrix, _ = dof_matrix(clip)
        bad = ~np.isfinite(matrix)
        if bad.any():
            frame, column = np.argwhere(bad)[0]
            raise SynthesisInputError(
                f"{what}: {clip_label(clip)} has a non-finite AMC value at frame {frame + 1} (column {column})"
            )
    return layout


def check_flag(estimator, name: str) -> bool:
    """``estimator.<name>`` as a bool; a ValueError naming the class and parameter when it is not True or False
    (a bad parameter value, as scikit-learn's checks raise)."""
    value = getattr(estimator, name)
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{type(estimator).__name__}: {name} must be True or False, got {value!r}")  # noqa: TRY004
    return bool(value)
