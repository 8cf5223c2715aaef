"""NTU RGB+D-format action recognition as a benchmark of the comparison runner.

Samples are the sequences of a prepared cache (``mocapkit prepare ntu``); protocols are the NTU split
names (``ntu60_xsub``, ``ntu60_xview``, ``ntu120_xsub``, ``ntu120_xset``): the split does not depend on
the seed, which moves the training runs' initialisation, their validation hold-out and the estimators'
``random_state``. Estimators get the sequences (``[bodies, T, 25, 3]`` float32 metres, zeros where a
body is absent) and the 0-based labels; learned runs train on ``data.root=<cache> data.split=<protocol>``
and report ``mocapkit eval``'s top-1 on the same test samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.splits import SPLITS, split_indices
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split


class NTUBenchmark(Benchmark):
    """A prepared NTU-format cache, its subject / view / setup protocols, recognition accuracy.

    Args:
        root: the cache folder.
    """

    title = "NTU RGB+D-format action recognition (held-out subjects or views)"
    protocols = tuple(s for s in SPLITS if s != "custom")
    percent_metrics = ("accuracy", "top5", "mean_class_accuracy")

    def __init__(self, root: str):
        if root is None:
            raise ComparisonError("benchmark.root is not set: give a cache written by `mocapkit prepare ntu`")
        self.root = Path(root)
        self.cache = NTUCache(self.root)

    def describe(self) -> dict:
        return {"root": str(self.root), "n_sequences": len(self.cache), "num_classes": int(self.cache.labels.max()) + 1}

    def split(self, protocol: str, seed: int) -> Split:
        train, test = split_indices(self.cache, protocol)
        subjects = np.asarray(self.cache.subjects)
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "train_subjects": np.unique(subjects[train]).tolist(),
                "test_subjects": np.unique(subjects[test]).tolist(),
            },
        )

    def data(self, indices: np.ndarray):
        """Sequences (a list of ``[bodies, T_i, 25, 3]`` float32 arrays) and labels ``[n]`` of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.cache.positions(int(i)) for i in indices], np.asarray(self.cache.labels)[indices]

    def learned_overrides(self, protocol: str, seed: int) -> list[str]:
        return [f"data.root={self.root}", f"data.split={protocol}"]

    def check_learned_config(self, cfg, method: str) -> None:
        if cfg.get("task") != "action" or "ntu" not in str(cfg.data.get("_target_", "")):
            raise ComparisonError(
                f"method {method}: the NTU benchmark scores action runs on NTU data "
                f"(task={cfg.get('task')!r}, data={cfg.data.get('_target_')!r})"
            )

    def evaluate_learned(self, report: dict, run_dir: Path, split: Split) -> dict:
        metrics = {
            "accuracy": float(report["top1"]),
            "top5": float(report["top5"]),
            "mean_class_accuracy": float(report["mean_class_accuracy"]),
        }
        return {"metrics": metrics, "detail": {k: report[k] for k in ("split", "sample_counts") if k in report}}

    def headline(self, protocol: str) -> list[str]:
        return ["accuracy", "top5", "mean_class_accuracy"]
