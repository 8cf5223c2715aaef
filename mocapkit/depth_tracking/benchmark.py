"""The depth-tracking benchmark of the comparison runner (Lou 2012 ch. 3 on depth rendered from real mocap).

No depth recording with ground truth is available here, so, as the thesis did for its ablations, every mocap take
(HDM05 cuts by default) is rendered by a virtual depth camera with a sensor-noise model
(:func:`~mocapkit.datasets.synthetic.depth.render_depth_sequence`: capsule body, Kinect v1 camera and noise, the
sensor-style skeleton of the Kinect simulator from the same camera; a take whose performer leaves the view is cut to
its longest run of frames in view, :func:`in_view`). **The cell's seed is the render seed** (camera
placement, body girth, depth noise, sensor skeleton).

Protocols are held-out performers: protocol ``mm`` fits on the other performers' sequences and scores ``mm``'s.
To keep a CPU run within reach, each performer contributes a seeded subset of takes (``clips_per_class`` per motion
class) cut to ``max_frames`` frames (2 s at 30 fps by default); the tracker's prior database is the training
sequences' ground-truth joints, the regressor trains on their depth, the GP on their sensor skeletons.

Estimators follow :mod:`mocapkit.depth_tracking.base`. Metrics per cell, pooled over every test frame: ``error_mm``
(per-frame mean error over the 16 joints), ``sensor_mm`` (the sensor-style skeleton's on the same frames),
``reduction`` (1 − error / sensor), ``frames_per_s`` (``predict`` over the test sequences, one process) and
``fit_seconds``; the detail holds the error per motion class and per joint, and the per-frame errors of the first
test take for the plot.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np

from mocapkit.depth_tracking.base import TRACKED_JOINTS, joint_error_mm, tracked_joints
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split, mean_sd

HEADLINE = ["error_mm", "reduction", "frames_per_s"]


def motion_class(path: Path) -> str:
    """The motion class of an HDM05 cut (``HDM_bd_grabHighR_001_120.amc`` → ``grabHighR``), else the file stem
    without a trailing take number."""
    stem = Path(path).stem
    match = re.match(r"HDM_[a-z]{2}_(.+?)_\d+_\d+$", stem)
    return match.group(1) if match else re.sub(r"[_-]?\d+$", "", stem)


def in_view(sequence):
    """``sequence`` cut to its longest run of frames with some depth (a performer who walks out of the camera's
    view or range leaves empty frames, which no estimator takes); ``metadata["in_view"]`` records the frames kept."""
    from dataclasses import replace

    seen = sequence.depth_mm.reshape(sequence.num_frames, -1).any(axis=1)
    if seen.all() or not seen.any():
        return sequence
    length, first, start = 0, 0, None
    for t, ok in enumerate([*seen.tolist(), False]):
        if ok and start is None:
            start = t
        elif not ok and start is not None:
            if t - start > length:  # the first of equally long runs
                length, first = t - start, start
            start = None
    cut = slice(first, first + length)

    def part(array):
        return None if array is None else array[cut]

    metadata = {**sequence.metadata, "in_view": [first, first + length]}
    return replace(
        sequence,
        depth_mm=sequence.depth_mm[cut],
        colour=part(sequence.colour),
        parts=part(sequence.parts),
        joints=part(sequence.joints),
        sensor_joints=part(sequence.sensor_joints),
        sensor_state=part(sequence.sensor_state),
        metadata=metadata,
    )


class DepthTrackingBenchmark(Benchmark):
    """Held-out-performer tracking from rendered depth (module docstring).

    Args:
        root: a folder of motion files, one sub-folder per performer (``../shared/data/hdm05_cuts11``).
        protocols: the held-out performers; default: all.
        camera: the depth camera preset (``kinect_v1`` or ``azure_kinect``).
        noise: the depth-noise preset (None: the camera's).
        fps: frame rate of the rendered video.
        clips_per_class: takes per performer and motion class (a seeded choice); None: all.
        max_frames: frames per take at most (from the start); None: all.
        clip_seed: the seed of the take subset.
    """

    title = "Full-body tracking from depth (Kinect v1 depth rendered from real mocap, held-out performers)"
    percent_metrics = ("reduction",)
    selection_cv = "validation on training performers held out in turn (the first `cv` in name order; mm, negated)"

    def __init__(
        self,
        root: str,
        protocols: list[str] | None = None,
        camera: str = "kinect_v1",
        noise: str | None = None,
        fps: float = 30.0,
        clips_per_class: int | None = 1,
        max_frames: int | None = 60,
        clip_seed: int = 0,
    ):
        from mocapkit.datasets.formats.motion_io import find_motion_files

        self.root = Path(root)
        if not self.root.is_dir():
            raise ComparisonError(f"benchmark.root={root}: not a folder")
        files = [f for f in find_motion_files(self.root) if f.parent != self.root]
        if not files:
            raise ComparisonError(f"benchmark.root={root}: no motion files in per-performer sub-folders")
        groups = sorted({f.parent.name for f in files})
        if clips_per_class is not None:
            rng = np.random.default_rng(clip_seed)
            kept = []
            for group in groups:
                by_class: dict[str, list[Path]] = {}
                for f in sorted(f for f in files if f.parent.name == group):
                    by_class.setdefault(motion_class(f), []).append(f)
                for mine in by_class.values():
                    chosen = rng.choice(len(mine), min(int(clips_per_class), len(mine)), replace=False)
                    kept += [mine[i] for i in sorted(chosen)]
            files = kept
        self.files = sorted(files)
        self.groups = np.array([f.parent.name for f in self.files])
        self.classes = np.array([motion_class(f) for f in self.files])
        self.protocols = tuple(protocols) if protocols else tuple(groups)
        unknown = [p for p in self.protocols if p not in groups]
        if unknown:
            raise ComparisonError(f"benchmark.protocols: {unknown} are not performer folders of {root} ({groups})")
        self.camera, self.noise, self.fps = camera, noise, float(fps)
        self.clips_per_class, self.max_frames, self.clip_seed = clips_per_class, max_frames, clip_seed
        self._joints: list[np.ndarray] | None = None
        self._sequences: dict[tuple[int, int], object] = {}

    # ------------------------------------------------------------------ data
    def joints(self) -> list[np.ndarray]:
        """The Kinect-20 world landmarks ``[T, 20, 3]`` of every take (read once)."""
        if self._joints is None:
            from mocapkit.datasets.formats.motion_io import read_motion
            from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion

            self._joints = []
            for path in self.files:
                clip = kinect20_from_motion(read_motion(path), fps=self.fps)
                self._joints.append(clip[: self.max_frames] if self.max_frames else clip)
        return self._joints

    def sequence(self, index: int, seed: int):
        """The rendered :class:`~mocapkit.datasets.formats.depth_images.DepthSequence` of take ``index``."""
        key = (int(index), int(seed))
        if key not in self._sequences:
            from mocapkit.datasets.synthetic.depth import render_depth_sequence
            from mocapkit.datasets.synthetic.kinect_noise import file_seed

            path = self.files[index]
            sequence = render_depth_sequence(
                self.joints()[index],
                self.fps,
                camera=self.camera,
                noise=self.noise,
                seed=file_seed(seed, path),
                source=str(path),
            )
            self._sequences[key] = in_view(sequence)
        return self._sequences[key]

    def data(self, indices: np.ndarray, seed: int = 0) -> list:
        """The rendered sequences of takes ``indices``."""
        return [self.sequence(i, seed) for i in indices]

    def split(self, protocol: str, seed: int) -> Split:
        if protocol not in self.protocols:
            raise ComparisonError(f"unknown protocol {protocol!r}: this benchmark has {list(self.protocols)}")
        test = np.flatnonzero(self.groups == protocol)
        train = np.flatnonzero(self.groups != protocol)
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "held_out": protocol,
                "train_groups": sorted(set(self.groups[train].tolist())),
                "render_seed": seed,
            },
        )

    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "n_takes": len(self.files),
            "groups": {g: int((self.groups == g).sum()) for g in sorted(set(self.groups.tolist()))},
            "classes": sorted(set(self.classes.tolist())),
            "camera": self.camera,
            "noise": self.noise,
            "fps": self.fps,
            "clips_per_class": self.clips_per_class,
            "max_frames": self.max_frames,
            "clip_seed": self.clip_seed,
        }

    # ------------------------------------------------------------------ scoring
    def _score(self, fitted, test: np.ndarray, seed: int) -> dict:
        sequences = self.data(test, seed)
        start = time.perf_counter()
        predicted = [fitted.predict(s) for s in sequences]
        seconds = time.perf_counter() - start
        truth = [tracked_joints(s.joints) for s in sequences]
        errors = [joint_error_mm(p, t) for p, t in zip(predicted, truth)]
        sensor = [joint_error_mm(tracked_joints(s.sensor_joints), t) for s, t in zip(sequences, truth)]
        per_joint = np.concatenate([1000 * np.linalg.norm(p - t, axis=-1) for p, t in zip(predicted, truth)]).mean(0)
        frames = int(sum(len(e) for e in errors))
        by_class: dict[str, list[float]] = {}
        for k, e in zip(test, errors):
            by_class.setdefault(str(self.classes[k]), []).extend(e.tolist())
        return {
            "error_mm": float(np.concatenate(errors).mean()),
            "sensor_mm": float(np.concatenate(sensor).mean()),
            "frames_per_s": frames / max(seconds, 1e-9),
            "n_frames": frames,
            "per_class_mm": {c: float(np.mean(v)) for c, v in sorted(by_class.items())},
            "per_joint_mm": per_joint.round(2).tolist(),
            "first_take": {
                "file": str(self.files[test[0]]),
                "error_mm": errors[0].round(2).tolist(),
                "sensor_mm": sensor[0].round(2).tolist(),
            },
        }

    def evaluate_estimator(self, estimator, split: Split) -> dict:
        from sklearn.base import clone

        fitted = clone(estimator)
        start = time.perf_counter()
        fitted.fit(self.data(split.train, split.seed))
        fit_seconds = time.perf_counter() - start
        scores = self._score(fitted, split.test, split.seed)
        metrics = {
            "error_mm": scores["error_mm"],
            "sensor_mm": scores["sensor_mm"],
            "reduction": 1.0 - scores["error_mm"] / scores["sensor_mm"],
            "frames_per_s": scores["frames_per_s"],
            "fit_seconds": fit_seconds,
        }
        detail = {k: scores[k] for k in ("n_frames", "per_class_mm", "per_joint_mm", "first_take")}
        return {"metrics": metrics, "detail": detail}

    def cross_validate(self, estimator, train: np.ndarray, folds: int, seed: int) -> float:
        """``−error_mm`` over each training performer held out in turn (the first ``folds`` in name order)."""
        from sklearn.base import clone

        groups = sorted(set(self.groups[train].tolist()))
        if len(groups) < 2:
            raise ComparisonError(f"selection needs at least 2 training performers, got {groups}")
        weighted, frames = 0.0, 0
        for group in groups[: max(1, int(folds))]:
            fitted = clone(estimator).fit(self.data(train[self.groups[train] != group], seed))
            scores = self._score(fitted, train[self.groups[train] == group], seed)
            weighted += scores["error_mm"] * scores["n_frames"]
            frames += scores["n_frames"]
        return -weighted / frames

    # ------------------------------------------------------------------ presentation
    def headline(self, protocol: str) -> list[str]:
        return HEADLINE

    def markdown(self, results: dict) -> str:
        cells = [c for c in results.get("cells", []) if "metrics" in c]
        if not cells:
            return ""
        keys = list(dict.fromkeys(c["method"] for c in cells))
        lines = [
            "## Over all held-out performers",
            "",
            "Frame-weighted mean error over the 16 joints (mm), per seed; mean ± sd over seeds. `sensor` is the "
            "sensor-style skeleton on the same frames.",
            "",
            "| method | error (mm) | sensor (mm) | reduction | frames/s |",
            "|---|---|---|---|---|",
        ]
        for key in keys:
            mine = [c for c in cells if c["method"] == key]
            errors, sensors, speeds = [], [], []
            for seed in sorted({c["seed"] for c in mine}):
                seed_cells = [c for c in mine if c["seed"] == seed]
                n = np.array([c["detail"]["n_frames"] for c in seed_cells], dtype=np.float64)
                errors.append(np.array([c["metrics"]["error_mm"] for c in seed_cells]) @ n / n.sum())
                sensors.append(np.array([c["metrics"]["sensor_mm"] for c in seed_cells]) @ n / n.sum())
                speeds += [c["metrics"]["frames_per_s"] for c in seed_cells]
            reduction = [100 * (1 - e / s) for e, s in zip(errors, sensors)]
            lines.append(
                f"| {mine[0]['label']} | {mean_sd(errors, 1)} | {mean_sd(sensors, 1)} | "
                f"{mean_sd(reduction, 1)} % | {np.median(speeds):,.1f} |"
            )
        classes = sorted({k for c in cells for k in c["detail"]["per_class_mm"]})
        lines += [
            "",
            "## Per motion class",
            "",
            "Mean error (mm) over the held-out performers' frames of each class (first seed).",
            "",
            "| method | " + " | ".join(classes) + " |",
            "|---|" + "---|" * len(classes),
        ]
        first = min(c["seed"] for c in cells)
        for key in keys:
            mine = [c for c in cells if c["method"] == key and c["seed"] == first]
            row = []
            for cls in classes:
                values = [c["detail"]["per_class_mm"][cls] for c in mine if cls in c["detail"]["per_class_mm"]]
                row.append(f"{np.mean(values):.0f}" if values else "–")
            lines.append(f"| {mine[0]['label'] if mine else key} | " + " | ".join(row) + " |")
        return "\n".join(lines) + "\n"

    def plots(self, results: dict, out_dir: Path) -> list[Path]:
        """``per_joint_error.png`` (each method's error per joint, first seed) and ``per_frame_error.png`` (the
        first test take's error per frame, each method beside the sensor skeleton)."""
        from mocapkit.evaluation.plots import pyplot, save_figure

        cells = [c for c in results.get("cells", []) if "metrics" in c]
        if not cells:
            return []
        seed = min(c["seed"] for c in cells)
        cells = [c for c in cells if c["seed"] == seed]
        keys = list(dict.fromkeys(c["method"] for c in cells))
        plt = pyplot()
        out = []
        fig, ax = plt.subplots(figsize=(10, 4))
        x = np.arange(len(TRACKED_JOINTS))
        for key in keys:
            mine = [c for c in cells if c["method"] == key]
            n = np.array([c["detail"]["n_frames"] for c in mine], dtype=np.float64)
            ax.plot(
                x,
                np.array([c["detail"]["per_joint_mm"] for c in mine]).T @ n / n.sum(),
                marker="o",
                ms=3,
                label=mine[0]["label"],
            )
        ax.set_xticks(x, TRACKED_JOINTS, rotation=60, ha="right", fontsize=8)
        ax.set_ylabel("mean joint error (mm)")
        ax.set_title(f"Per-joint error over the held-out performers (seed {seed})")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        out.append(save_figure(fig, Path(out_dir) / "per_joint_error.png"))
        first = [c for c in cells if c["protocol"] == cells[0]["protocol"]]
        fig, ax = plt.subplots(figsize=(10, 4))
        ax.plot(first[0]["detail"]["first_take"]["sensor_mm"], "k--", label="sensor skeleton")
        for c in first:
            ax.plot(c["detail"]["first_take"]["error_mm"], label=c["label"])
        ax.set_xlabel("frame")
        ax.set_ylabel("mean joint error (mm)")
        ax.set_title(Path(first[0]["detail"]["first_take"]["file"]).name)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        out.append(save_figure(fig, Path(out_dir) / "per_frame_error.png"))
        return out


__all__ = ["DepthTrackingBenchmark", "in_view", "motion_class"]
