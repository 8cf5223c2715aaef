"""``mocapkit kinect-fix``: train a Kinect posture corrector (Zhou 2014 ch. 5's task) on simulated pairs of real
mocap, then correct real Kinect skeletons with it.

``train_kinect_model(mocap, out, method=None, noise=None)``
    every motion file under ``mocap`` (HDM05/CMU ASF/AMC, BVH, C3D with body landmarks, ...) becomes a (Kinect,
    mocap) pair through the calibrated Kinect v1 simulator
    (:func:`~mocapkit.datasets.synthetic.kinect_noise.simulate_pairs`, 30 fps; :data:`DEFAULT_NOISE`, the
    ``real_sensor`` calibration, by default); the registry's default method (``configs/kinect/method.yaml``:
    ``bigru_steady``, docs/decisions.md#kinect-default) is fitted on them and saved. With ``method="gp"`` or
    ``"zhou_thesis"`` a :class:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor` is saved as one
    ``.npz`` (:meth:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor.save`), with
    ``method="bigru"`` / ``"transformer"`` / ``"bigru_steady"`` (the registry's kinect methods, ``configs/kinect/method/NAME.yaml``; ``--set``
    Hydra overrides of their parameters) a learned refiner network retrained as a corrector
    (:class:`~mocapkit.kinect.learned.LearnedKinectCorrector`, one ``torch.save`` file read back with
    ``weights_only=True``).
``export_kinect_model(model, out)``
    a learned corrector as ONNX (normalisation inside the graph, parity with PyTorch checked); ``apply`` runs the
    ``.onnx`` with onnxruntime.
``fix_kinect_files(model, inputs, out_dir)``
    every input (MSR Action3D skeleton text, NTU ``.skeleton``, C3D or any file with the 20 Kinect landmarks) is
    resampled to the model's 30 fps when it differs (MSR Action3D is 15 fps), read as Kinect-20 joints
    (:func:`kinect_clip`), reconstructed, and written as ``OUT/<name>.c3d`` (MSR-20 joint names, y up, metres
    stored as mm, at the model's rate): ``read_motion`` reads it back and ``mocapkit render`` draws it.
    ``report.json`` lists every file: frames, filled entries, the joints the sensor did not track (NTU files carry
    the SDK's states, :func:`ntu_tracking_state`), and without ground truth the real-data proxies before/after
    (:func:`~mocapkit.kinect.metrics.steadiness`: bone-length sd, jitter, joint-angle violations, swap events),
    summarised over files (:func:`~mocapkit.kinect.metrics.steadiness_summary`);
    ``--plot N`` draws the first N as before/after strips (raw blue, corrected red).

Wild input: a landmark missing in some frames (MSR's all-zero frames, NTU's lost tracks, C3D gaps) is filled by
linear interpolation over time and marked NOT_TRACKED, so the reconstructor's reliability term gives it weight 0
there and the GP prior and temporal term decide; the count is reported per file. A landmark missing in every
frame, a skeleton without the 20 landmarks or an unreadable file is an error naming the file, or with
``skip_bad`` a skipped file listed in the report. Nothing is dropped silently.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.synthetic.kinect_noise import TRACKED
from mocapkit.motion.container import Motion, all_coordinates
from mocapkit.motion.layouts import LANDMARK_NAMES, MSR20, find_landmarks

MODEL_FPS = 30.0
#: The simulator calibration ``train_kinect_model`` trains on without ``noise`` (docs/decisions.md#kinect-default).
DEFAULT_NOISE = "real_sensor"


class KinectFixError(ValueError):
    """Input ``mocapkit kinect-fix`` cannot use; the message names the file (and the joints)."""


def kinect_clip(motion: Motion) -> tuple[np.ndarray, np.ndarray, int]:
    """A motion's 20 Kinect landmarks, gaps filled, with tracking states.

    Returns:
        ``(positions, state, filled)``: float64 ``[T, 20, 3]`` metres, y up, in
        :data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order; int8 ``[T, 20]`` tracking states
        (TRACKED 2 where observed, NOT_TRACKED 0 where filled); the number of filled (frame, joint) entries.

    Raises:
        KinectFixError: no frame, a skeleton without the body landmarks, or a landmark never observed.
    """
    from mocapkit.kinect.reconstruction import NOT_TRACKED, TRACKED
    from mocapkit.motion.geometry import landmark_positions, to_y_up

    label = motion.source or motion.name or "<motion>"
    if motion.num_frames == 0:
        raise KinectFixError(f"{label}: no frames")
    try:
        positions, observed = landmark_positions(motion)
    except ValueError as exc:
        raise KinectFixError(str(exc) if str(label) in str(exc) else f"{label}: {exc}") from exc
    observed &= all_coordinates(np.isfinite(positions))
    if not observed.any():
        raise KinectFixError(
            f"{label}: no landmark is observed in any of its {motion.num_frames} frames (all-zero "
            f"or missing frames only)"
        )
    never = [LANDMARK_NAMES[k] for k in np.flatnonzero(~observed.any(axis=0))]
    if never:
        raise KinectFixError(
            f"{label}: the Kinect landmarks {never} are missing in every frame (a Kinect-20 "
            f"skeleton is needed: MSR Action3D, NTU RGB+D or a rig with those joints)"
        )
    positions = to_y_up(positions, motion.up_axis).astype(np.float64)
    frames = np.arange(motion.num_frames)
    for k in np.flatnonzero(~observed.all(axis=0)):
        seen = observed[:, k]
        for axis in range(3):
            positions[~seen, k, axis] = np.interp(frames[~seen], frames[seen], positions[seen, k, axis])
    state = np.where(observed, TRACKED, NOT_TRACKED).astype(np.int8)
    return positions, state, int((~observed).sum())


def ntu_tracking_state(path: str | os.PathLike, motion: Motion) -> np.ndarray:
    """The Kinect SDK's own per-joint tracking states of an NTU ``.skeleton`` file's main body (the body
    ``read_motion`` chose, ``motion.metadata["kept_tracks"][0]``), on the 20 Kinect landmarks: int8 ``[T, 20]``
    (2 tracked, 1 inferred, 0 not tracked; 0 in the frames without that body)."""
    from mocapkit.datasets.formats.ntu_skeleton import read_skeleton
    from mocapkit.motion.layouts import NTU25

    seq = read_skeleton(path)
    tracks = motion.metadata.get("kept_tracks") or []
    if not tracks:
        return np.zeros((seq.num_frames, len(LANDMARK_NAMES)), dtype=np.int8)
    found = find_landmarks(NTU25.joint_names, NTU25.name)
    states = seq.joint_tracking_state[tracks[0]]  # [T, 25]
    out = states[:, [found[name] for name in LANDMARK_NAMES]].astype(np.int8)
    out[~seq.present[tracks[0]]] = 0
    return out


def read_kinect_file(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, int, float]:
    """One real Kinect file as the models see it: resampled to :data:`MODEL_FPS`, the 20 landmarks, gaps filled
    (:func:`kinect_clip`), and for an NTU ``.skeleton`` the SDK's own tracking states (:func:`ntu_tracking_state`;
    a filled entry stays NOT_TRACKED). Returns ``(positions [T, 20, 3] m, state [T, 20] int8, filled entries,
    the file's own frame rate)``; the reader's errors and :class:`KinectFixError` name the file."""
    from mocapkit.datasets.formats.motion_io import read_motion

    motion = read_motion(path)
    source_fps = float(motion.fps)
    resampled = motion.resample(MODEL_FPS)
    raw, state, filled = kinect_clip(resampled)
    if motion.metadata.get("format") == "ntu" and resampled.num_frames == motion.num_frames:
        state = np.minimum(state, ntu_tracking_state(path, motion))
    return raw, state, filled, source_fps


def swap_lag(source_fps: float) -> int:
    """Frames at :data:`MODEL_FPS` over which a jump of a file recorded at ``source_fps`` is spread (2 for MSR
    Action3D's 15 fps): the ``lag`` of :func:`~mocapkit.kinect.metrics.swap_events`."""
    return max(1, round(MODEL_FPS / float(source_fps)))


def _as_msr_motion(positions: np.ndarray, fps: float, name: str, source: str) -> Motion:
    """Kinect-20 landmarks ``[T, 20, 3]`` (y up, m) as an MSR-20 Motion (its joint names and parents)."""
    found = find_landmarks(MSR20.joint_names, MSR20.name)
    out = np.zeros((len(positions), len(MSR20.joint_names), 3), dtype=np.float32)
    for k, landmark in enumerate(LANDMARK_NAMES):
        out[:, found[landmark]] = positions[:, k]
    return Motion(
        positions=out,
        joint_names=MSR20.joint_names,
        parents=MSR20.parents,
        fps=fps,
        up_axis="y",
        name=name,
        source=source,
        layout_name=MSR20.name,
    )


def train_kinect_model(
    mocap,
    out: str | os.PathLike,
    seed: int = 0,
    skip_bad: bool = False,
    noise: str | None = None,
    method: str | None = None,
    overrides: Sequence[str] = (),
) -> dict:
    """Fit a Kinect corrector on simulated pairs of the motion files in ``mocap`` (files or folders, searched
    recursively) and save it to ``out``: with ``method="gp"`` or ``"zhou_thesis"``
    :class:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor` (``.npz``), with ``"bigru"`` or
    ``"transformer"`` or ``"bigru_steady"`` (the default) :class:`~mocapkit.kinect.learned.LearnedKinectCorrector`
    (a ``torch.save`` file, ``.pt`` by convention).

    Args:
        seed: the simulation seed and the model's ``random_state``.
        method: a kinect method of the registry that can be saved (``bigru_steady``, ``gp``, ``zhou_thesis``, ``bigru``, ``transformer``;
            ``mocapkit methods kinect``); None: the registry's default (``configs/kinect/method.yaml``).
        noise: the simulator's calibration (:meth:`~mocapkit.datasets.synthetic.kinect_noise.KinectNoiseConfig.preset`:
            ``real_sensor``, ``mean_error`` or ``msr_steadiness``); None: :data:`DEFAULT_NOISE`.
        skip_bad: skip (and report) unreadable or unusable files instead of failing.
        overrides: ``--set`` Hydra overrides of the model's parameters (the GP's ``max_train_frames=5000``,
            ``gp_iterations``, weights, ...; the learned corrector's ``steps``, ``window``, ``network={hidden: 16}``).

    Returns:
        ``{"model", "method", "noise", "files", "frames", "skipped": [[path, reason], ...], "fit_seconds"}`` (also
        printed by the CLI).
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths
    from mocapkit.datasets.synthetic.kinect_noise import (
        KinectNoiseConfig,
        simulate_pairs,
    )
    from mocapkit.train.registry import build_method, default_method, method_parameters

    method = method or default_method("kinect")
    noise = DEFAULT_NOISE if noise is None else noise
    try:
        config = KinectNoiseConfig.preset(noise)
    except ValueError as exc:
        raise KinectFixError(f"--noise {noise}: {exc}") from None
    seeded = [f"random_state={int(seed)}"] if "random_state" in method_parameters("kinect", method) else []
    model = build_method("kinect", method, [*seeded, *overrides])
    if not hasattr(model, "save"):
        raise KinectFixError(
            f"--method {method}: {type(model).__name__} has no model file to save; kinect-fix "
            f"trains the methods that save one (bigru_steady, gp, zhou_thesis, bigru, transformer)"
        )
    files = expand_motion_paths(mocap, "--mocap", empty_error=KinectFixError)
    pairs, skipped = simulate_pairs(files, config, seed=seed, fps=MODEL_FPS, skip_bad=skip_bad, progress=True)
    if not pairs:
        raise KinectFixError(f"--mocap {', '.join(map(str, mocap))}: no usable motion file ({len(skipped)} skipped)")
    what = f"{type(model).__name__} ({method})"
    print(
        f"[kinect-fix] fitting {what} on {len(pairs)} simulated clips ({sum(len(p.clean) for p in pairs)} frames)...",
        file=sys.stderr,
        flush=True,
    )
    start = time.perf_counter()
    model.fit([p.noisy for p in pairs], [p.clean for p in pairs], [p.state for p in pairs])
    seconds = time.perf_counter() - start
    path = model.save(out)
    return {
        "model": str(path),
        "method": method,
        "noise": noise,
        "files": len(pairs),
        "frames": int(sum(len(p.clean) for p in pairs)),
        "skipped": [[str(p), r] for p, r in skipped],
        "fit_seconds": round(seconds, 1),
    }


def load_model(path: str | os.PathLike):
    """A saved Kinect model: a ``.npz`` is Zhou's GP reconstructor
    (:meth:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor.load`), an ``.onnx`` an exported
    learned corrector (:class:`~mocapkit.kinect.learned.OnnxKinectCorrector`, the network in
    onnxruntime), a ``.ckpt`` a run of ``mocapkit train experiment=kinect_corrector_*``
    (:meth:`~mocapkit.kinect.learned.LearnedKinectCorrector.from_checkpoint`), any other file a learned corrector
    (:meth:`~mocapkit.kinect.learned.LearnedKinectCorrector.load`);
    a :class:`KinectFixError` names the file when it is none of them."""
    from mocapkit.kinect.learned import (
        LearnedKinectCorrector,
        OnnxKinectCorrector,
    )
    from mocapkit.kinect.reconstruction import KinectPostureReconstructor

    if not Path(path).is_file():
        raise KinectFixError(f"--model {path}: no such file")
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".onnx":
            return OnnxKinectCorrector(str(path)).fit()
        if suffix == ".ckpt":  # a run of `mocapkit train experiment=kinect_corrector_*`
            return LearnedKinectCorrector.from_checkpoint(path)
        return (KinectPostureReconstructor if suffix == ".npz" else LearnedKinectCorrector).load(path)
    except ValueError as exc:
        raise KinectFixError(str(exc)) from None


def export_kinect_model(model: str | os.PathLike, out: str | os.PathLike) -> dict:
    """Export a learned corrector written by :func:`train_kinect_model` (``--method bigru|transformer``) as ONNX
    (:meth:`~mocapkit.kinect.learned.LearnedKinectCorrector.export_onnx`); ``kinect-fix apply --model
    OUT`` then runs it with onnxruntime. Zhou's GP model (``.npz``) has no network to export: a
    :class:`KinectFixError` says so. Returns the export's figures (parity with PyTorch included)."""
    from mocapkit.kinect.learned import LearnedKinectCorrector

    if Path(model).suffix.lower() == ".npz":
        raise KinectFixError(
            f"--model {model}: a GP reconstructor (.npz) has no network to export to ONNX; only the "
            f"learned correctors do (kinect-fix train --method bigru|transformer)"
        )
    corrector = load_model(model)
    if not isinstance(corrector, LearnedKinectCorrector):
        raise KinectFixError(f"--model {model}: already an ONNX export")
    return corrector.export_onnx(out)


@dataclass
class KinectFixReport:
    """What :func:`fix_kinect_files` did: one entry per written file, one per skipped file."""

    model: str
    fixed: list[dict] = field(default_factory=list)
    skipped: list[list[str]] = field(default_factory=list)
    frames_per_s: float = float("nan")
    summary: dict = field(default_factory=dict)

    def to_text(self) -> str:
        lines = [
            (f"[kinect-fix] corrected {len(self.fixed)} file(s) with {self.model} ({self.frames_per_s:,.0f} frames/s)")
        ]
        if self.summary:
            s = self.summary
            lines.append(
                "  means over files, before → after (share of files not worse): "
                + ", ".join(
                    f"{label} {s[k + '_before']:.2f} → {s[k + '_after']:.2f}{unit} ({100 * s[k + '_not_worse']:.0f} %)"
                    for k, label, unit in (
                        ("bone_sd_cm", "bone-length sd", " cm"),
                        ("jitter_cm", "jitter", " cm"),
                        ("angle_violations_pct", "joint-angle violations", " %"),
                        ("swap_events", "swap events", ""),
                    )
                )
                + f"; new swap events {s['new_swap_events']:.0f}"
            )
            filled = [f for f in self.fixed if f["filled_entries"]]
            if filled:
                lines.append(
                    f"  {len(filled)} file(s) had missing joints, filled and marked not tracked: "
                    + ", ".join(f"{Path(f['input']).name} ({f['filled_entries']})" for f in filled[:10])
                    + (" ..." if len(filled) > 10 else "")
                )
        for path, reason in self.skipped:
            lines.append(f"  skipped {path}: {reason}")
        return "\n".join(lines)


def fix_kinect_files(
    model, inputs, out_dir: str | os.PathLike, skip_bad: bool = False, plot: int = 0, overrides: Sequence[str] = ()
) -> KinectFixReport:
    """Correct Kinect skeleton files with a saved model (see the module docstring).

    Args:
        model: a file from :func:`train_kinect_model` (a GP ``.npz``, else a learned corrector; :func:`load_model`)
            or a fitted model.
        inputs: files or folders (searched recursively for files ``read_motion`` reads).
        out_dir: where ``<name>.c3d``, ``report.json`` and the ``<name>_before_after.png`` plots go.
        skip_bad: skip (and report) files that cannot be read or used instead of failing.
        plot: draw the first ``plot`` files before/after.
        overrides: ``--set`` prediction parameters set on the model, Hydra's grammar (the GP's ``w_spatial``,
            ``w_temporal``, ``w_reliability``, ``energy_unit=0.1``, ...; the learned corrector's ``inference_window``,
            ``overlap``); a key the model does not have fails naming it and listing the model's parameters.
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths, write_motion
    from mocapkit.io_atomic import atomic_write_text
    from mocapkit.kinect.metrics import steadiness, steadiness_summary

    name = str(model)
    if isinstance(model, (str, os.PathLike)):
        model = load_model(model)
    if overrides:
        from mocapkit.train.registry import override_values

        # a saved model is not a registry entry: its parameters are the ones it was trained with
        model.set_params(
            **override_values(overrides, list(model.get_params(deep=False)), f"{type(model).__name__} ({name})")
        )
    files = expand_motion_paths(inputs, "input", empty_error=KinectFixError)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    report = KinectFixReport(model=name)
    total_frames, total_seconds = 0, 0.0
    for path in files:
        try:
            raw, state, filled, source_fps = read_kinect_file(path)
        except (OSError, ValueError) as exc:
            reason = str(exc) if str(path) in str(exc) else f"{path}: {exc}"
            if not skip_bad:
                raise KinectFixError(reason) from exc
            report.skipped.append([str(path), reason])
            continue
        start = time.perf_counter()
        fixed = model.predict(raw, state=state)
        total_seconds += time.perf_counter() - start
        total_frames += len(raw)
        target = out_dir / f"{path.stem}.c3d"
        write_motion(target, _as_msr_motion(fixed, MODEL_FPS, path.stem, str(path)))
        before, after = steadiness(raw, swap_lag(source_fps)), steadiness(fixed, swap_lag(source_fps))
        entry = {
            "input": str(path),
            "output": str(target),
            "frames": len(raw),
            "fps": MODEL_FPS,
            "source_fps": source_fps,
            "filled_entries": filled,
            "untracked_entries": int((state != TRACKED).sum()),
            "bone_sd_raw_cm": before["bone_sd_cm"],
            "bone_sd_fixed_cm": after["bone_sd_cm"],
            "jitter_raw_cm": before["jitter_cm"],
            "jitter_fixed_cm": after["jitter_cm"],
            "before": before,
            "after": after,
        }
        if len(report.fixed) < plot:
            entry["plot"] = str(_plot_before_after(raw, fixed, path, out_dir))
        report.fixed.append(entry)
    if not report.fixed and not report.skipped:
        raise KinectFixError(f"input {', '.join(map(str, inputs))}: no motion files")
    report.frames_per_s = total_frames / total_seconds if total_seconds > 0 else float("nan")
    if report.fixed:
        report.summary = steadiness_summary([f["before"] for f in report.fixed], [f["after"] for f in report.fixed])
    atomic_write_text(
        out_dir / "report.json",
        json.dumps(
            {
                "model": report.model,
                "frames_per_s": report.frames_per_s,
                "summary": report.summary,
                "fixed": report.fixed,
                "skipped": report.skipped,
            },
            indent=1,
        ),
    )
    return report


def _plot_before_after(raw: np.ndarray, fixed: np.ndarray, path: Path, out_dir: Path) -> Path:
    from mocapkit.visualization.render import render_strip

    before = _as_msr_motion(raw, MODEL_FPS, f"{path.stem} raw", str(path))
    after = _as_msr_motion(fixed, MODEL_FPS, f"{path.stem} corrected", str(path))
    return render_strip(
        [before, after],
        out_dir / f"{path.stem}_before_after.png",
        n=8,
        view="front",
        title=f"{path.name}: raw Kinect (blue) and corrected (red)",
    )
