"""``mocapkit depth-track``: full-body tracking of depth videos (Lou 2012 ch. 3) from files to files.

``track_depth_files(inputs, prior, out=DIR)``
    every depth sequence of ``inputs`` (``.npz`` files and folders of PNGs,
    :func:`~mocapkit.datasets.formats.depth_images.read_depth_sequence`; a folder of sequences is expanded) is
    tracked by a ``depth_tracking`` method of the registry (default ``tracker``,
    :class:`~mocapkit.depth_tracking.tracker.DepthTracker`; ``--set`` Hydra overrides of its parameters) whose
    motion prior is built from the mocap files of ``prior`` (any format ``read_motion`` reads, folders
    recursively, each turned into the 16 :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS` at 30 fps). Without
    ``prior`` the method runs with ``prior=none`` and the report says so.

Per input ``<stem>``, in ``out``:

- ``<stem>.c3d`` (or ``.bvh``): the 16 tracked joints (names :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS`,
  metres, y up, the sequence's frame rate). Where the sequence knows its ``camera_to_world`` the joints are in
  that world frame; otherwise in camera coordinates turned half a turn about x, ``(x, −y, −z)``, so y is up and
  the frame stays right-handed. ``read_motion`` reads the file back to the same positions; ``mocapkit render``
  draws it (a C3D as points: its 16 labels are no layout of :data:`~mocapkit.motion.layouts.LAYOUTS`, so it
  carries no bones; the BVH has them, with position channels on every joint, as the tracker's joint positions
  come without joint rotations).
- ``<stem>_frames.png``: ``pictures`` evenly spaced frames, the depth image in grey with the sensor's skeleton
  ("before", blue, when the sequence has one) and the tracked skeleton ("after", red) projected into it.
- ``report.json`` (all inputs): per file the frames, seconds, frames/s, method, its parameters and, when the
  sequence carries ground-truth ``joints``, the mean joint error in mm of the tracker and of the sensor skeleton
  (:func:`~mocapkit.depth_tracking.base.joint_error_mm`); the prior's takes; every skipped file with its reason.

Errors name the file (and the frame): an unreadable sequence, a folder of bare PNGs without a camera, a frame of
all background, images that do not match the camera's resolution
(:class:`~mocapkit.datasets.formats.depth_images.DepthFormatError`,
:class:`~mocapkit.depth_tracking.base.DepthInputError`), a sequence without the sensor skeleton the method's
``start``/``skeleton`` need (the message names the flags that do without it), an unusable prior or performer file
(:class:`DepthTrackError`). With ``skip_bad`` a bad input or prior file is skipped and listed in the report, never
silently.
"""

from __future__ import annotations

import io
import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.depth_tracking.base import TRACKED_JOINTS, DepthInputError, check_sequence, joint_error_mm

#: The registry task whose methods ``depth-track`` runs.
TASK = "depth_tracking"
DEFAULT_METHOD = "tracker"
#: Frame rate of the prior's mocap takes: the camera's, which the LPCA prior's successors assume.
PRIOR_FPS = 30.0
FORMATS = ("c3d", "bvh")
#: Colours of the pictures: the sensor's skeleton (before) and the tracker's (after).
BEFORE_COLOUR, AFTER_COLOUR = "tab:blue", "tab:red"


class DepthTrackError(ValueError):
    """Input ``mocapkit depth-track`` cannot use (a prior or performer file, a method, an input folder); the message
    names it."""


def tracked_parents() -> tuple[int, ...]:
    """Parent of each of the 16 :data:`TRACKED_JOINTS` (−1: HipCenter, the root), from the tracker's bones."""
    from mocapkit.depth_tracking.body_model import BONES

    parents = [-1] * len(TRACKED_JOINTS)
    for bone in BONES:
        parents[bone.end] = bone.start
    return tuple(parents)


# ------------------------------------------------------------------------------------------------ inputs


def _is_sequence_folder(folder: Path) -> bool:
    """A folder that is one depth sequence: ``depth/``, ``camera.yaml`` or PNGs directly in it."""
    if (folder / "depth").is_dir() or (folder / "camera.yaml").is_file():
        return True
    return any(p.suffix.lower() == ".png" and p.is_file() for p in folder.iterdir())


def _sequences_under(folder: Path) -> list[Path]:
    found: list[Path] = []
    for child in sorted(folder.iterdir()):
        if child.name.startswith("."):
            continue
        if child.is_dir():
            found += [child] if _is_sequence_folder(child) else _sequences_under(child)
        elif child.suffix.lower() == ".npz" and child.is_file():
            found.append(child)
    return found


def find_depth_sequences(paths) -> list[Path]:
    """Depth-sequence paths of files and folders, in order: a ``.npz`` or any other file is one input (the reader
    judges it), a folder that is a sequence (``depth/``, ``camera.yaml`` or PNGs in it) is one, any other folder is
    searched recursively for ``.npz`` files and sequence folders.

    Raises:
        FileNotFoundError: a path that does not exist. DepthTrackError: a folder without sequences, or two inputs
            with the same name (their outputs would collide).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    found: list[Path] = []
    for path in map(Path, paths):
        if not path.exists():
            raise FileNotFoundError(f"input {path}: no such file or folder")
        if path.is_dir() and not _is_sequence_folder(path):
            under = _sequences_under(path)
            if not under:
                raise DepthTrackError(
                    f"input {path}: no depth sequences in this folder (looked for .npz files and folders of depth PNGs)"
                )
            found += under
        else:
            found.append(path)
    seen: dict[str, Path] = {}
    for path in found:
        if _stem(path) in seen:
            raise DepthTrackError(f"{path} and {seen[_stem(path)]}: same name, their outputs would collide")
        seen[_stem(path)] = path
    return found


def _stem(path: Path) -> str:
    return path.stem if path.is_file() else path.name


def _reason(path, exc: BaseException) -> str:
    return str(exc) if str(path) in str(exc) else f"{path}: {exc}"


def prior_clips(paths, skip_bad: bool = False, progress: bool = True) -> tuple[list[np.ndarray], list, list]:
    """The 16 tracked joints of every mocap file under ``paths`` at :data:`PRIOR_FPS`.

    Returns:
        ``(clips, files, skipped)``: float32 ``[T, 16, 3]`` metres (y up) per usable file, those files, and
        ``[path, reason]`` per skipped one.

    Raises:
        DepthTrackError: a file that cannot be read or has no full Kinect landmarks, naming it (unless
            ``skip_bad``); no usable file at all.
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths, read_motion
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion
    from mocapkit.depth_tracking.base import tracked_joints

    files = expand_motion_paths(paths, "--prior", empty_error=DepthTrackError)
    iterator = files
    if progress and len(files) > 20:
        from tqdm import tqdm

        iterator = tqdm(files, desc="depth-track prior", unit="file")
    clips, used, skipped = [], [], []
    for path in iterator:
        try:
            clips.append(tracked_joints(kinect20_from_motion(read_motion(path), fps=PRIOR_FPS)))
            used.append(path)
        except (OSError, ValueError) as exc:
            if not skip_bad:
                raise DepthTrackError(f"--prior {_reason(path, exc)}") from exc
            skipped.append([str(path), _reason(path, exc)])
    if not clips:
        raise DepthTrackError(f"--prior {', '.join(map(str, paths))}: no usable mocap file ({len(skipped)} skipped)")
    return clips, used, skipped


def performer_joints(path: str | os.PathLike) -> np.ndarray:
    """The 16 tracked joints ``[T, 16, 3]`` (metres) of a mocap file of the performer, for their bone lengths."""
    from mocapkit.datasets.formats.motion_io import read_motion
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion
    from mocapkit.depth_tracking.base import tracked_joints

    try:
        return tracked_joints(kinect20_from_motion(read_motion(path), fps=None))
    except (OSError, ValueError) as exc:
        raise DepthTrackError(f"--performer {_reason(path, exc)}") from exc


# ------------------------------------------------------------------------------------------------ method


def build_tracker(method: str = DEFAULT_METHOD, overrides: Sequence[str] = ()):
    """The ``depth_tracking`` method ``method`` of the registry with the Hydra ``overrides`` (unfitted).

    Raises:
        DepthTrackError: a method that does not build its prior from mocap (no ``fit_mocap``: the regressor and the
            sensor baselines learn from depth sequences). ConfigError: an unknown method or parameter.
    """
    from mocapkit.train.registry import build_method

    tracker = build_method(TASK, method, overrides)
    if not hasattr(tracker, "fit_mocap"):
        raise DepthTrackError(
            f"--method {method}: {type(tracker).__name__} learns from depth sequences, not from mocap; depth-track "
            f"runs the {TASK} methods with a mocap motion prior (fit_mocap), e.g. {DEFAULT_METHOD}"
        )
    return tracker


def _override_keys(overrides: Sequence[str]) -> set[str]:
    return {item.split("=", 1)[0].strip().lstrip("+~") for item in overrides}


def _plain(value):
    """A parameter value as JSON data (anything else as its repr)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return repr(value)


def check_needs(sequence, params: dict, performer: bool = False) -> None:
    """Refuse a sequence no method can track (:func:`check_sequence`: an all-background frame, the wrong resolution)
    or this method's ``start``/``skeleton`` cannot: a missing sensor skeleton or ground truth (the message names the
    file and the flags that do without it), non-finite joints (naming the frame).

    Raises:
        DepthInputError: naming the file.
    """
    check_sequence(sequence, what="depth-track")  # an empty frame or the wrong resolution first: no flag helps
    path = sequence.source or "depth sequence"
    start, skeleton = params.get("start"), params.get("skeleton")
    uses_skeleton = not performer  # a performer's mocap gives the bone lengths instead
    needs = []
    if start == "sensor" or (uses_skeleton and skeleton == "sensor"):
        needs.append("sensor_joints")
    if start == "ground_truth" or (uses_skeleton and skeleton == "ground_truth"):
        needs.append("joints")
    if "sensor_joints" in needs and sequence.sensor_joints is None:
        what = [f"start={start}"] if start == "sensor" else []
        fixes = ["--start standing"] if start == "sensor" else []
        if uses_skeleton and skeleton == "sensor":
            what.append(f"skeleton={skeleton}")
            fixes.append("--skeleton template (or --performer MOCAP_FILE)")
        raise DepthInputError(
            f"{path}: the sequence has no sensor skeleton (sensor_joints), which the tracker's {' and '.join(what)} "
            f"need; pass {' and '.join(fixes)} to track it without one"
        )
    if "joints" in needs and sequence.joints is None:
        raise DepthInputError(
            f"{path}: the sequence has no ground-truth joints, which start/skeleton=ground_truth need; pass "
            "--start sensor|standing and --skeleton sensor|template"
        )
    if needs:
        check_sequence(sequence, tuple(needs), what="depth-track")


# ------------------------------------------------------------------------------------------------ outputs


def to_y_up(joints: np.ndarray, camera_to_world: np.ndarray | None) -> np.ndarray:
    """Camera-coordinate joints ``[T, J, 3]`` (metres, y down, z forward) → y up: the world frame of
    ``camera_to_world`` (``[4, 4]``) when known, else a half turn about x, ``(x, −y, −z)`` (right-handed)."""
    joints = np.asarray(joints, dtype=np.float64)
    if camera_to_world is not None:
        matrix = np.asarray(camera_to_world, dtype=np.float64)
        return joints @ matrix[:3, :3].T + matrix[:3, 3]
    return joints * np.array([1.0, -1.0, -1.0])


def tracked_motion(positions: np.ndarray, fps: float, name: str = "", source: str = ""):
    """The 16 tracked joints ``[T, 16, 3]`` (metres, y up) as a :class:`~mocapkit.motion.container.Motion` with the
    tracker's hierarchy; identity joint rotations, so a BVH writes them as position channels."""
    from mocapkit.motion.container import Motion

    positions = np.asarray(positions, dtype=np.float32)
    rotations = np.broadcast_to(np.eye(3, dtype=np.float32), (*positions.shape[:2], 3, 3)).copy()
    return Motion(
        positions=positions,
        joint_names=TRACKED_JOINTS,
        parents=tracked_parents(),
        fps=float(fps),
        rotations=rotations,
        up_axis="y",
        name=name,
        source=source,
    )


def _sixteen(joints: np.ndarray | None) -> np.ndarray | None:
    """Kinect-20 (or already 16) joints ``[T, J, 3]`` → the 16 tracked ones; None for any other skeleton."""
    from mocapkit.depth_tracking.base import tracked_joints

    if joints is None:
        return None
    if joints.shape[1] == 20:
        return tracked_joints(joints)
    return joints if joints.shape[1] == len(TRACKED_JOINTS) else None


def draw_frames(sequence, tracked: np.ndarray, path: Path, pictures: int = 4) -> Path:
    """``pictures`` evenly spaced frames of ``sequence`` side by side: depth in grey, the sensor's skeleton
    (before, blue) and ``tracked`` ``[T, 16, 3]`` (after, red; camera coordinates) projected with the intrinsics.
    Written atomically as PNG to ``path``."""
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from mocapkit.depth_tracking.body_model import BONES
    from mocapkit.io_atomic import atomic_write_bytes

    k = sequence.intrinsics
    count = max(1, min(int(pictures), sequence.num_frames))
    frames = np.unique(np.linspace(0, sequence.num_frames - 1, count).round().astype(int))
    sensor = _sixteen(sequence.sensor_joints)
    skeletons = [
        (joints, colour) for joints, colour in ((sensor, BEFORE_COLOUR), (tracked, AFTER_COLOUR)) if joints is not None
    ]
    # one box for every panel, around the body and both skeletons: a person fills a small part of the image
    v, u = np.nonzero((sequence.depth_mm[frames] > 0).any(axis=0))
    corners = [np.array([[u.min(), v.min()], [u.max(), v.max()]], dtype=np.float64)] if len(u) else []
    for joints, _ in skeletons:
        points = np.asarray(joints[frames], dtype=np.float64).reshape(-1, 3)
        uv = k.project(points[points[:, 2] > 1e-6])
        corners.append(uv[np.isfinite(uv).all(axis=1)])
    corners = np.concatenate(corners) if corners else np.zeros((0, 2))
    if len(corners):
        (u0, v0), (u1, v1) = corners.min(axis=0), corners.max(axis=0)
        pad = 0.08 * max(u1 - u0, v1 - v0) + 4
        u0, u1 = max(u0 - pad, -0.5), min(u1 + pad, k.width - 0.5)
        v0, v1 = max(v0 - pad, -0.5), min(v1 + pad, k.height - 0.5)
    if not len(corners) or u1 <= u0 or v1 <= v0:
        u0, u1, v0, v1 = -0.5, k.width - 0.5, -0.5, k.height - 0.5
    panel = 2.5
    aspect = min(max((v1 - v0) / (u1 - u0), 0.5), 3.0)
    fig = Figure(figsize=(panel * len(frames), panel * aspect + 0.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(frames), squeeze=False)[0]
    cmap = colormaps["gray_r"].with_extremes(bad="black")  # near is light, no measurement black
    for ax, t in zip(axes, frames):
        depth = sequence.depth_m(t)
        seen = depth[depth > 0]
        low, high = np.percentile(seen, [1, 99]) if seen.size else (0.0, 1.0)
        image = np.ma.masked_equal(depth, 0)
        ax.imshow(image, cmap=cmap, vmin=low, vmax=max(high, low + 1e-3), interpolation="nearest")
        for joints, colour in skeletons:
            points = np.asarray(joints[t], dtype=np.float64)
            uv = k.project(np.where(points[:, 2:3] > 1e-6, points, np.nan))
            for bone in BONES:
                a, b = uv[bone.start], uv[bone.end]
                ax.plot([a[0], b[0]], [a[1], b[1]], color=colour, linewidth=1.5)
            ax.plot(uv[:, 0], uv[:, 1], "o", color=colour, markersize=2.5)
        ax.set_xlim(u0, u1)
        ax.set_ylim(v1, v0)
        ax.set_title(f"frame {t}", fontsize=9)
        ax.set_axis_off()
    handles = [Line2D([], [], color=AFTER_COLOUR, label="tracked (after)")]
    if sensor is not None:
        handles.insert(0, Line2D([], [], color=BEFORE_COLOUR, label="sensor skeleton (before)"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.suptitle(Path(sequence.source).name or "depth sequence", fontsize=10)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    return atomic_write_bytes(path, buffer.getvalue())


# ------------------------------------------------------------------------------------------------ report


@dataclass
class DepthTrackReport:
    """What :func:`track_depth_files` did: one entry per tracked file, ``[path, reason]`` per skipped one."""

    method: str
    parameters: dict
    out: str
    prior: dict
    performer: str | None = None
    tracked: list[dict] = field(default_factory=list)
    skipped: list[list[str]] = field(default_factory=list)
    frames_per_s: float = float("nan")

    def to_dict(self) -> dict:
        return {
            "method": self.method,
            "parameters": self.parameters,
            "prior": self.prior,
            "performer": self.performer,
            "frames_per_s": _plain(self.frames_per_s),
            "files": self.tracked,
            "skipped": self.skipped,
        }

    def to_text(self) -> str:
        prior = self.prior
        if self.parameters.get("prior") == "none":
            prior_text = "no motion prior: prior=none" + ("" if prior.get("takes") else ", no --prior given")
        else:
            prior_text = f"prior: {prior['takes']} mocap take(s), {prior['frames']} frames"
        speed = f", {self.frames_per_s:.2f} frames/s" if math.isfinite(self.frames_per_s) else ""
        lines = [
            f"[depth-track] tracked {len(self.tracked)} file(s) with {self.method} ({prior_text}) into {self.out}{speed}"
        ]
        for entry in self.tracked:
            error = entry.get("joint_error_mm")
            truth = ""
            if error:
                truth = f", error vs truth {error['tracker']:.0f} mm"
                if error.get("sensor") is not None:
                    truth += f" (sensor skeleton {error['sensor']:.0f} mm)"
            speed = f", {entry['frames_per_s']:.2f} frames/s" if entry["frames_per_s"] else ""
            lines.append(f"  {entry['input']}: {entry['frames']} frames{speed}{truth} -> {entry['output']}")
        for path, reason in prior.get("skipped", []):
            lines.append(f"  skipped prior {path}: {reason}")
        for path, reason in self.skipped:
            lines.append(f"  skipped {path}: {reason}")
        return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ the command


def track_depth_files(
    inputs,
    prior=None,
    *,
    out: str | os.PathLike,
    method: str = DEFAULT_METHOD,
    overrides: Sequence[str] = (),
    camera=None,
    fps: float | None = None,
    performer: str | os.PathLike | None = None,
    format: str = "c3d",
    pictures: int = 4,
    skip_bad: bool = False,
    progress: bool = True,
) -> DepthTrackReport:
    """Track depth sequences and write the joints, pictures and a report (module docstring).

    Args:
        inputs: depth sequences (``.npz`` files, sequence folders) and folders of them.
        prior: mocap files and folders for the motion prior; None or empty: the method with ``prior=none``.
        out: output folder (created).
        method: a ``depth_tracking`` method of the registry that builds its prior from mocap (``fit_mocap``).
        overrides: Hydra overrides of its parameters (``iterations=5``, ``start=standing``, ``device=cuda``...).
        camera: intrinsics for every input (a preset name, a ``camera.yaml``, or
            :class:`~mocapkit.datasets.formats.depth_images.CameraIntrinsics`); needed for bare PNG folders,
            overrides a file's own.
        fps: frame rate for every input (overrides the file's own).
        performer: a mocap file of the performer: the body's bone lengths (instead of the ``skeleton`` parameter's
            source).
        format: ``"c3d"`` or ``"bvh"``.
        pictures: frames in each ``<stem>_frames.png`` (0: none).
        skip_bad: skip (and report) unusable inputs and prior files instead of raising.
        progress: progress bars (the tracker's per sequence, the prior's for many files).

    Returns:
        the :class:`DepthTrackReport` (also ``out/report.json``).

    Raises:
        DepthFormatError, DepthInputError, FileNotFoundError: a bad input, naming the file (and the frame), unless
            ``skip_bad``. DepthTrackError: a bad prior or performer file, a method without a mocap prior, a
            folder without sequences. ConfigError: an unknown method or parameter.
    """
    from mocapkit.datasets.formats.depth_images import camera_from_argument, read_depth_sequence
    from mocapkit.datasets.formats.motion_io import write_motion
    from mocapkit.io_atomic import atomic_path, atomic_write_text

    if format not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {format!r}")
    if int(pictures) < 0:
        raise ValueError(f"pictures must be 0 or more, got {pictures}")
    if fps is not None and not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    intrinsics = camera_from_argument(camera) if camera is not None else None  # a bad --camera once, not per file
    files = find_depth_sequences(inputs)
    prior_paths = [prior] if isinstance(prior, (str, os.PathLike)) else list(prior or [])

    tracker = build_tracker(method, overrides)
    body = performer_joints(performer) if performer is not None else None
    given = _override_keys(overrides)
    params = tracker.get_params(deep=False)
    if "progress" in params and "progress" not in given:
        tracker.set_params(progress=bool(progress))
    if prior_paths:
        if params.get("prior") == "none":
            if "prior" in given:
                raise DepthTrackError("--prior MOCAP ... builds a motion prior, but --set prior=none turns it off")
            tracker.set_params(prior="lpca")  # the registry's default tracks without a prior until one is given
        clips, used, skipped_prior = prior_clips(prior_paths, skip_bad=skip_bad, progress=progress)
        prior_info = {
            "files": [str(p) for p in used],
            "takes": len(clips),
            "frames": int(sum(len(c) for c in clips)),
            "skipped": skipped_prior,
        }
    else:
        clips = []
        if params.get("prior", "none") != "none":
            if "prior" in given:
                raise DepthTrackError(f"--set prior={params['prior']} needs mocap takes: give --prior MOCAP ...")
            tracker.set_params(prior="none")
        prior_info = {
            "files": [],
            "takes": 0,
            "frames": 0,
            "skipped": [],
            "note": "no --prior given: tracked without a motion prior (prior=none)",
        }
    started = time.perf_counter()
    tracker.fit_mocap(clips)
    prior_info["fit_seconds"] = round(time.perf_counter() - started, 2)
    params = {k: _plain(v) for k, v in tracker.get_params(deep=False).items()}

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    report = DepthTrackReport(
        method=method,
        parameters=params,
        out=str(out),
        prior=prior_info,
        performer=None if performer is None else str(performer),
    )
    total_frames, total_seconds = 0, 0.0
    for path in files:
        try:
            sequence = read_depth_sequence(path, intrinsics=intrinsics, fps=fps)
            check_needs(sequence, params, performer=body is not None)
        except (OSError, ValueError) as exc:
            if not skip_bad:
                raise
            report.skipped.append([str(path), _reason(path, exc)])
            continue
        start = time.perf_counter()
        joints = tracker.predict(sequence, performer=body) if body is not None else tracker.predict(sequence)
        seconds = time.perf_counter() - start
        total_frames += sequence.num_frames
        total_seconds += seconds
        stem = _stem(path)
        target = out / f"{stem}.{format}"
        motion = tracked_motion(to_y_up(joints, sequence.camera_to_world), sequence.fps, stem, str(path))
        with atomic_path(target, f".{format}") as tmp:  # the BVH writer writes in place
            write_motion(tmp, motion)
        entry = {
            "input": str(path),
            "output": str(target),
            "frames": sequence.num_frames,
            "fps": sequence.fps,
            "seconds": round(seconds, 3),
            "frames_per_s": sequence.num_frames / seconds if seconds > 0 else None,
            "coordinates": "world (camera_to_world)"
            if sequence.camera_to_world is not None
            else "camera turned y-up: (x, -y, -z)",
            "method": method,
            "parameters": params,
        }
        truth = _sixteen(sequence.joints)
        if truth is not None:
            sensor = _sixteen(sequence.sensor_joints)
            entry["joint_error_mm"] = {
                "tracker": float(joint_error_mm(joints, truth).mean()),
                "sensor": None if sensor is None else float(joint_error_mm(sensor, truth).mean()),
            }
        if pictures:
            entry["picture"] = str(draw_frames(sequence, joints, out / f"{stem}_frames.png", pictures))
        report.tracked.append(entry)
    report.frames_per_s = total_frames / total_seconds if total_seconds > 0 else float("nan")
    atomic_write_text(out / "report.json", json.dumps(report.to_dict(), indent=1))
    return report


__all__ = [
    "DEFAULT_METHOD",
    "DepthTrackError",
    "DepthTrackReport",
    "build_tracker",
    "check_needs",
    "draw_frames",
    "find_depth_sequences",
    "performer_joints",
    "prior_clips",
    "to_y_up",
    "track_depth_files",
    "tracked_motion",
    "tracked_parents",
]
