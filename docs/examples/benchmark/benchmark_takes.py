"""Action recognition on a folder of takes, every performer held out in turn: a benchmark of the comparison runner
(docs/extending.md#add-a-benchmark).

Samples are the takes of :class:`~mocapkit.datasets.takes.datamodule.TakesDataModule`; protocols are
``test_<performer>``. Estimators get ``X`` = a list of ``[T_i, J, 3]`` float32 sequences (metres) and ``y`` =
0-based actions, and are scored by the default :meth:`~mocapkit.evaluation.compare.base.Benchmark.evaluate_estimator`
(fit on the training side, accuracy of ``predict`` on the test side).
"""

from __future__ import annotations

import numpy as np

from mocapkit.datasets.takes.datamodule import TakesDataModule
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split


class TakesBenchmark(Benchmark):
    """A folder of takes, one protocol per held-out performer, recognition accuracy.

    Args:
        root: the folder of takes. layout: the skeleton the takes are put on. fps: their frame rate.
    """

    title = "action recognition on a folder of takes (leave one performer out)"
    percent_metrics = ("accuracy",)

    def __init__(self, root: str, layout: str = "cmu31", fps: float = 30.0):
        self.root = root
        self.takes = TakesDataModule(root, layout=layout, fps=fps, val_fraction=0)
        self.performers = list(self.takes.performers)
        if len(self.performers) < 2:
            raise ComparisonError(
                f"benchmark.root={root}: leaving a performer out needs 2 performers or more, "
                f"the folder has {self.performers}"
            )
        self.protocols = tuple(f"test_{performer}" for performer in self.performers)

    def split(self, protocol: str, seed: int) -> Split:
        if protocol not in self.protocols:
            raise ComparisonError(f"protocol {protocol!r}: one of {list(self.protocols)}")
        held_out = self.performers.index(protocol.removeprefix("test_"))
        test = self.takes.subjects == held_out
        return Split(
            protocol, seed, np.flatnonzero(~test), np.flatnonzero(test), {"test_performer": self.performers[held_out]}
        )

    def data(self, indices: np.ndarray):
        """Sequences (a list of ``[T_i, J, 3]`` float32 arrays, metres) and labels ``[n]`` of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.takes.sequences[i].numpy() for i in indices], self.takes.labels[indices]

    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "n_takes": len(self.takes.sequences),
            "performers": self.performers,
            "class_names": self.takes.class_names,
        }
