"""HDM05 action recognition across performers as a benchmark of the comparison runner.

Samples are the clips of an HDM05 folder (:class:`~mocapkit.datasets.hdm05.datamodule.HDM05ActionDataModule`:
the real cuts' layout or the synthetic generator's); protocols are the leave-one-performer-out folds,
``test_<actor>`` for every performer of the folder. Estimators get ``X`` = a list of ``[T_i, 31, 3]`` float32
sequences (metres, y up, resampled to ``fps``) and ``y`` = 0-based classes; learned runs train on
``data.root=<folder> data.test_actors=[<actor>]`` (validation from the training performers only) and report
``mocapkit eval``'s top-1 on the same clips.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.datasets.hdm05.datamodule import HDM05ActionDataModule
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split


class HDM05ActionBenchmark(Benchmark):
    """An HDM05 folder, one protocol per held-out performer, recognition accuracy.

    Args:
        root: the folder of clips. labels: ``file``, ``65`` or ``25`` (the data module's label sets).
        fps: the frame rate clips are resampled to (the learned runs get the same as ``data.fps``).
    """

    title = "HDM05 action recognition (leave one performer out)"
    percent_metrics = ("accuracy", "mean_class_accuracy")

    def __init__(self, root: str, labels: str = "file", fps: float = 30.0):
        if root is None:
            raise ComparisonError("benchmark.root is not set: give a folder of HDM05 clips")
        self.root, self.labels_from, self.fps = Path(root), labels, float(fps)
        self.data_module = HDM05ActionDataModule(str(self.root), labels=labels, fps=fps, val_fraction=0)
        self.performers = list(self.data_module.performers)
        if len(self.performers) < 2:
            raise ComparisonError(
                f"benchmark.root={self.root}: leaving a performer out needs at least 2 "
                f"performers, the folder has {self.performers}"
            )
        self.protocols = tuple(f"test_{actor}" for actor in self.performers)
        self.sequences = [s.numpy() for s in self.data_module.sequences]
        self.labels = np.asarray(self.data_module.labels)

    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "n_clips": len(self.sequences),
            "performers": self.performers,
            "labels": self.labels_from,
            "fps": self.fps,
            "class_names": self.data_module.class_names,
        }

    def split(self, protocol: str, seed: int) -> Split:
        actor = protocol.removeprefix("test_")
        subjects = np.asarray(self.data_module.subjects)
        test_mask = subjects == self.performers.index(actor)
        train, test = np.flatnonzero(~test_mask), np.flatnonzero(test_mask)
        return Split(
            protocol,
            seed,
            train,
            test,
            {"train_actors": [a for a in self.performers if a != actor], "test_actors": [actor]},
        )

    def data(self, indices: np.ndarray):
        """Sequences (a list of ``[T_i, 31, 3]`` float32 arrays) and labels ``[n]`` of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.sequences[i] for i in indices], self.labels[indices]

    def learned_overrides(self, protocol: str, seed: int) -> list[str]:
        return [
            f"data.root={self.root}",
            f"data.test_actors=[{protocol.removeprefix('test_')}]",
            "data.train_actors=null",
            f"data.labels={self.labels_from}",
            f"data.fps={self.fps}",
        ]

    def check_learned_config(self, cfg, method: str) -> None:
        if cfg.get("task") != "action" or "hdm05" not in str(cfg.data.get("_target_", "")):
            raise ComparisonError(
                f"method {method}: the HDM05 benchmark scores action runs on HDM05 data "
                f"(task={cfg.get('task')!r}, data={cfg.data.get('_target_')!r})"
            )

    def evaluate_learned(self, report: dict, run_dir: Path, split: Split) -> dict:
        metrics = {"accuracy": float(report["top1"]), "mean_class_accuracy": float(report["mean_class_accuracy"])}
        return {"metrics": metrics, "detail": {k: report[k] for k in ("split", "sample_counts") if k in report}}

    def headline(self, protocol: str) -> list[str]:
        return ["accuracy", "mean_class_accuracy"]
