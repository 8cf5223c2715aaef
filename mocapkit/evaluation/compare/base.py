"""The benchmark interface of the comparison runner (see :mod:`mocapkit.evaluation.compare` for the contract).

:class:`Benchmark` is the base class: a data set with named protocols, the split of a protocol for a seed,
and the metric code that scores a method on it. Subclasses implement :meth:`Benchmark.split`,
:meth:`Benchmark.data` and, where the default does not fit, :meth:`Benchmark.evaluate_estimator`; benchmarks
with learned methods also implement :meth:`Benchmark.learned_overrides` and :meth:`Benchmark.evaluate_learned`.
Everything else is optional presentation (headline metrics, detail sections, plots).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.train.config import ConfigError


class ComparisonError(ConfigError):
    """A comparison that cannot run as configured; the message names the key, method, protocol or benchmark."""


@dataclass
class Split:
    """The two sides of one protocol for one seed.

    Attributes:
        protocol: the protocol name. seed: the seed the split was drawn for (it may not depend on it).
        train: int64 ``[n_train]`` sorted sample indices fitted on (a learned method may keep part for validation).
        test: int64 ``[n_test]`` sorted sample indices scored; every method of a cell sees exactly these.
        info: JSON-able description (subjects on each side, counts, ...), written to ``results.json``.
    """

    protocol: str
    seed: int
    train: np.ndarray
    test: np.ndarray
    info: dict = field(default_factory=dict)

    def describe(self) -> dict:
        """``{"n_train", "n_test", "test_sha1", "test_indices", **info}`` for ``results.json``."""
        return {
            "n_train": len(self.train),
            "n_test": len(self.test),
            "test_sha1": indices_sha1(self.test),
            "test_indices": np.asarray(self.test).tolist(),
            **self.info,
        }


def mean_sd(values, digits: int) -> str:
    """``"41.7 ± 5.4"``: mean ± sample sd of ``values`` with ``digits`` decimals (the value alone for one), for the
    benchmarks' tables of means over seeds."""
    values = [float(v) for v in values]
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{np.mean(values):.{digits}f} ± {np.std(values, ddof=1):.{digits}f}"


def indices_sha1(indices) -> str:
    """SHA-1 of sorted int64 sample indices: equal for two methods exactly when they scored the same samples."""
    return hashlib.sha1(np.sort(np.asarray(indices, dtype=np.int64)).tobytes()).hexdigest()


class Benchmark:
    """A data set, its protocols and its metrics; subclass it to plug a new benchmark into the runner.

    Class attributes:
        title: a human-readable name for the report.
        protocols: the protocol names :meth:`split` knows.
        percent_metrics: metric names (or ``"*"``) printed as percentages; the others with 3 decimals.
    """

    title = "benchmark"
    #: How :meth:`cross_validate` splits the training side, for the report.
    selection_cv = "stratified k-fold CV"
    protocols: tuple[str, ...] = ()
    percent_metrics: tuple[str, ...] = ("*",)

    # ------------------------------------------------------------------ required
    def split(self, protocol: str, seed: int) -> Split:
        """The train / test samples of ``protocol`` for ``seed`` (the same object for every method)."""
        raise NotImplementedError

    def data(self, indices: np.ndarray):
        """``(X, y)`` of samples ``indices``: what an estimator's ``fit`` / ``predict`` take (array or list, ``[n]``).

        The default :meth:`evaluate_estimator` and the runner's CV selection use it.
        """
        raise NotImplementedError

    # ------------------------------------------------------------------ estimators
    def evaluate_estimator(self, estimator, split: Split) -> dict:
        """Fit ``estimator`` on ``split.train``, score it on ``split.test``.

        Returns ``{"metrics": {name: float}, "detail": JSON-able}``. The default: ``fit(X, y)``, then the
        accuracy of ``predict`` against ``y`` of the test side.
        """
        X, y = self.data(split.train)
        estimator.fit(X, y)
        X_test, y_test = self.data(split.test)
        predicted = np.asarray(estimator.predict(X_test))
        return {"metrics": {"accuracy": float((predicted == np.asarray(y_test)).mean())}, "detail": {}}

    def cross_validate(self, estimator, train: np.ndarray, folds: int, seed: int) -> float:
        """Mean validation score (higher is better) of ``estimator`` over ``folds`` folds of the training samples
        ``train``: what the runner's ``select`` maximises. The default: stratified ``folds``-fold
        ``cross_val_score`` on :meth:`data` (the estimator's own ``score``); a benchmark whose folds must keep
        groups apart (performers, subjects) or whose score is not the estimator's overrides it."""
        from sklearn.model_selection import StratifiedKFold, cross_val_score

        X, y = self.data(train)
        cv = StratifiedKFold(folds, shuffle=True, random_state=seed)
        return float(np.mean(cross_val_score(estimator, X, y, cv=cv, error_score="raise")))

    # ------------------------------------------------------------------ learned runs
    def learned_overrides(self, protocol: str, seed: int) -> list[str]:
        """Hydra overrides that make a training run use this benchmark's data and ``split(protocol, seed)``."""
        raise ComparisonError(f"benchmark {type(self).__name__} has no learned methods (no learned_overrides)")

    def check_learned_config(self, cfg, method: str) -> None:
        """Reject a composed run config this benchmark cannot score (e.g. the wrong task); a no-op by default."""

    def evaluate_learned(self, report: dict, run_dir: Path, split: Split) -> dict:
        """``{"metrics", "detail"}`` of a trained run from its :func:`~mocapkit.evaluation.evaluate.evaluate` report."""
        raise ComparisonError(f"benchmark {type(self).__name__} cannot score learned runs (no evaluate_learned)")

    def learned_test_indices(self, run_dir: Path) -> np.ndarray:
        """The test sample indices the run's data module scored (rebuilt from ``run_dir/config.yaml``)."""
        from omegaconf import OmegaConf

        from mocapkit.train.training import build_datamodule

        datamodule = build_datamodule(OmegaConf.load(Path(run_dir) / "config.yaml"))
        return np.asarray(datamodule.test_idx, dtype=np.int64)

    # ------------------------------------------------------------------ presentation
    def describe(self) -> dict:
        """JSON-able description of the data (root, sample counts, ...) for ``results.json``."""
        return {}

    def headline(self, protocol: str) -> list[str]:
        """Metric names of the summary table under ``protocol``, the first one plotted (default: all, sorted)."""
        return []

    def markdown(self, results: dict) -> str:
        """Extra ``results.md`` sections (detail tables) from the whole ``results`` dict; ``""`` for none."""
        return ""

    def plots(self, results: dict, out_dir: Path) -> list[Path]:
        """Extra PNG plots written into ``out_dir``; their paths."""
        return []

    def format_metric(self, name: str, mean: float | None, sd: float | None = None) -> str:
        """``"93.30 %"``, ``"85.70 ± 1.50 %"`` (percent metrics) or ``"0.662 ± 0.010"``; ``"–"`` for missing."""
        if mean is None or (isinstance(mean, float) and math.isnan(mean)):
            return "–"
        percent = "*" in self.percent_metrics or name in self.percent_metrics
        scale, digits, unit = (100.0, 2, " %") if percent else (1.0, 3, "")
        text = f"{scale * mean:.{digits}f}"
        if sd is not None:
            text += f" ± {scale * sd:.{digits}f}"
        return text + unit
