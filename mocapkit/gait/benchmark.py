"""The CASIA-B gait benchmark of the comparison runner: a GEI cache under the closed-set and cross-subject protocols.

Samples are the GEIs of a :class:`~mocapkit.datasets.casia_b.cache.GEICache`; the split of a protocol is
:func:`~mocapkit.datasets.casia_b.splits.protocol_split` (the same function the CNN's data module calls), drawn
with the benchmark's ``holdout_seed``, not the cell seed: every seed scores the same held-out sequences and
test subjects, and the seed moves validation and initialisation (as the gait report did).

Scoring, for learned runs (``evaluate_gait`` of ``mocapkit eval``) and estimators alike:

* ``closed_set``: :func:`~mocapkit.gait.metrics.closed_set_report` of the subject scores (an estimator's
  ``decision_function`` ``[n_test, n_subjects]``, a CNN's logits); metrics ``subject_accuracy`` (per test GEI),
  ``subject_accuracy_nm`` / ``_bg`` / ``_cl``, ``subject_accuracy_per_sequence`` (vote over a sequence's
  cycles), and ``view_accuracy`` / ``condition_accuracy`` for a multi-task CNN;
* ``cross_subject``: :func:`~mocapkit.gait.metrics.cross_view_rank1` of the test subjects' embeddings (an
  estimator's ``transform``, a CNN's shared FC-512); metrics ``rank1_nm`` / ``rank1_bg`` / ``rank1_cl``
  (identical view excluded).

An estimator gets ``fit(geis [n, H, W] float32 in [0, 1], subject IDs [n])`` on the whole training side.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.datasets.casia_b.cache import GEICache
from mocapkit.datasets.casia_b.splits import PROTOCOLS, protocol_split
from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split
from mocapkit.gait.metrics import (
    TABLE_6_2_ROWS,
    TASK_TITLES,
    THESIS_TABLE_6_2,
    closed_set_report,
    cross_view_rank1,
    plot_per_view_panels,
    table_6_2_cell,
)

#: Published cross-view rank-1 (%) on real CASIA-B (NM, BG, CL), for orientation only: other data, other nets.
LITERATURE_RANK1: dict[str, tuple[float, float, float]] = {
    "CNN-LB, GEI (Wu et al. TPAMI'17, LT protocol)": (89.9, 72.4, 54.0),
    "GaitSet (OpenGait model zoo)": (95.8, 90.0, 75.4),
}
#: Thesis Table 6.3, GEI+PCA+LDA (nm / bg / cl): a mostly-90° protocol, not the cross-view one.
THESIS_TABLE_6_3_PCA_LDA = (90.5, 3.6, 3.6)


def _percent(value) -> str:
    return "–" if value is None or (isinstance(value, float) and np.isnan(value)) else f"{100 * value:.2f}"


class GaitBenchmark(Benchmark):
    """CASIA-B-layout GEI cache, protocols ``closed_set`` and ``cross_subject``.

    Args:
        root: the GEI cache folder (``mocapkit prepare casia-b --out ROOT``).
        holdout_seed: the draw of the closed-set held-out sequences (fixed across cells).
        num_train_subjects: cross-subject training subjects (None: 74 of 124, or the same share).
        metric: ``"euc"`` or ``"cos"`` for rank-1 (estimators and, through ``eval.metric``, learned runs).
        aggregate: ``"sequence"`` or ``"gei"``: rank-1 items (``eval.aggregate`` for learned runs).
    """

    title = "CASIA-B gait recognition (GEIs)"
    protocols = PROTOCOLS

    def __init__(
        self,
        root: str,
        holdout_seed: int = 0,
        num_train_subjects: int | None = None,
        metric: str = "euc",
        aggregate: str = "sequence",
    ):
        if root is None:
            raise ComparisonError("benchmark.root is not set: give the GEI cache of `mocapkit prepare casia-b`")
        self.root = Path(root)
        self.cache = GEICache(self.root)  # fails early, naming the folder, before any training
        if len(self.cache) == 0:
            raise ComparisonError(f"{self.root}: the GEI cache is empty")
        self.holdout_seed = int(holdout_seed)
        self.num_train_subjects = None if num_train_subjects is None else int(num_train_subjects)
        self.metric, self.aggregate = metric, aggregate

    # -------------------------------------------------------------- data and splits
    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "num_geis": len(self.cache),
            "per": self.cache.meta.get("per"),
            "gei_size": [self.cache.height, self.cache.width],
            "holdout_seed": self.holdout_seed,
            "num_train_subjects": self.num_train_subjects,
            "metric": self.metric,
            "aggregate": self.aggregate,
        }

    def split(self, protocol: str, seed: int) -> Split:
        parts = protocol_split(
            self.cache, protocol, self.holdout_seed, self.num_train_subjects if protocol == "cross_subject" else None
        )
        if protocol == "closed_set":
            unseen = np.setdiff1d(self.cache.subjects[parts.test_idx], self.cache.subjects[parts.train_idx])
            if len(unseen):
                raise ComparisonError(f"{self.root}: closed-set test subjects {unseen.tolist()} have no training GEIs")
        return Split(
            protocol,
            seed,
            parts.train_idx,
            parts.test_idx,
            {"train_subjects": parts.train_subjects.tolist(), "test_subjects": parts.test_subjects.tolist()},
        )

    def data(self, indices: np.ndarray):
        """GEIs float32 ``[n, H, W]`` in [0, 1] and subject IDs ``[n]`` of GEIs ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        geis = self.cache.all_geis[indices].astype(np.float32) / np.float32(255)
        return geis, np.asarray(self.cache.subjects[indices], dtype=np.int64)

    # -------------------------------------------------------------- scoring
    def _score(self, protocol: str, indices: np.ndarray, scores=None, classes=None, embeddings=None) -> dict:
        cache = self.cache
        if protocol == "closed_set":
            subjects = cache.subjects[indices].astype(np.int64)
            detail = closed_set_report(
                {
                    "subject_logits": scores,
                    "subjects": np.searchsorted(classes, subjects),
                    "subject_ids": subjects,
                    "views": np.searchsorted(np.asarray(VIEWS), cache.views[indices]),
                    "conditions": cache.conditions[indices],
                    "sequences": cache.sequences[indices],
                }
            )
            return {"metrics": closed_set_metrics(detail), "detail": {"closed_set": detail}}
        detail = cross_view_rank1(
            embeddings,
            cache.subjects[indices],
            cache.conditions[indices],
            cache.sequences[indices],
            cache.views[indices],
            metric=self.metric,
            aggregate=self.aggregate,
        )
        return {"metrics": cross_view_metrics(detail), "detail": {"cross_view": detail}}

    def evaluate_estimator(self, estimator, split: Split) -> dict:
        """Fit on the whole training side; closed set: ``decision_function``, cross subject: ``transform``."""
        X, y = self.data(split.train)
        estimator.fit(X, y)
        X_test, _ = self.data(split.test)
        if split.protocol == "closed_set":
            result = self._score(
                "closed_set",
                split.test,
                scores=estimator.decision_function(X_test),
                classes=np.asarray(estimator.classes_),
            )
        else:
            result = self._score("cross_subject", split.test, embeddings=estimator.transform(X_test))
        fitted = {k: int(getattr(estimator, k)) for k in ("n_pca_", "n_lda_") if hasattr(estimator, k)}
        result["detail"].update(fitted)
        return result

    def learned_overrides(self, protocol: str, seed: int) -> list[str]:
        overrides = [
            f"data.root={self.root}",
            f"data.protocol={protocol}",
            f"data.holdout_seed={self.holdout_seed}",
            f"eval.metric={self.metric}",
            f"eval.aggregate={self.aggregate}",
        ]
        if protocol == "cross_subject" and self.num_train_subjects is not None:
            overrides.append(f"data.num_train_subjects={self.num_train_subjects}")
        return overrides

    def check_learned_config(self, cfg, method: str) -> None:
        if cfg.get("task") != "gait":
            raise ComparisonError(
                f"methods.{method}: experiment has task={cfg.get('task')!r}; the gait benchmark needs task: gait"
            )

    def evaluate_learned(self, report: dict, run_dir: Path, split: Split) -> dict:
        if "closed_set" in report:
            return {"metrics": closed_set_metrics(report["closed_set"]), "detail": report}
        if "cross_view" in report:
            return {"metrics": cross_view_metrics(report["cross_view"]), "detail": report}
        raise ComparisonError(f"{run_dir}: the evaluation report has neither closed_set nor cross_view")

    # -------------------------------------------------------------- presentation
    def headline(self, protocol: str) -> list[str]:
        if protocol == "closed_set":
            return [
                "subject_accuracy",
                "subject_accuracy_nm",
                "subject_accuracy_bg",
                "subject_accuracy_cl",
                "subject_accuracy_per_sequence",
                "view_accuracy",
                "condition_accuracy",
            ]
        return ["rank1_nm", "rank1_bg", "rank1_cl"]

    def markdown(self, results: dict) -> str:
        """Closed set laid out as thesis Table 6.2 and cross-subject rank-1 tables, for the first seed."""
        seed = results["seeds"][0]
        lines = [
            f"## Detail tables (seed {seed})",
            "",
            (
                "Thesis and literature columns are results on the **real CASIA-B** (124 subjects), a different "
                "data set from this cache unless it was prepared from CASIA-B itself: there for scale, not as a "
                "like-for-like comparison. Averages are over test samples."
            ),
            "",
        ]
        for protocol in results["protocols"]:
            cells = {
                c["label"]: c["detail"] for c in results["cells"] if c["protocol"] == protocol and c["seed"] == seed
            }
            if not cells:
                continue
            if protocol == "closed_set":
                reports = {label: d["closed_set"] for label, d in cells.items()}
                lines += [
                    "### Closed set (thesis Table 6.2 protocol): accuracy (%) per test GEI",
                    "",
                    closed_set_table(reports, "gei"),
                ]
                if any(r.get("per") == "cycle" for r in reports.values()):
                    lines += [
                        "### Closed set, per test sequence (vote: summed scores of its cycles)",
                        "",
                        closed_set_table(reports, "sequence"),
                    ]
            else:
                reports = {label: d["cross_view"] for label, d in cells.items()}
                lines += [
                    "### Cross subject (OpenGait protocol): mean rank-1 (%)",
                    "",
                    (
                        "Gallery nm-01..04, probes nm-05/06, bg-01/02, cl-01/02 of unseen subjects; per (probe "
                        "view, gallery view), identical view excluded, mean over probe views."
                    ),
                    "",
                    cross_subject_tables(reports),
                ]
        return "\n".join(lines)

    def plots(self, results: dict, out_dir: Path) -> list[Path]:
        """``per_view.png``: closed-set subject accuracy and cross-subject NM rank-1 per view (mean over seeds)."""
        panels = per_view_panels(results)
        if not panels:
            return []
        return [
            plot_per_view_panels(
                panels, Path(out_dir) / "per_view.png", f"{self.root.name}: per-view accuracy (mean over seeds)"
            )
        ]


# ------------------------------------------------------------------------------------------ metrics
def closed_set_metrics(report: dict) -> dict:
    """Flat metrics of a :func:`closed_set_report`: ``<task>_accuracy``, ``subject_accuracy_<condition>``,
    ``subject_accuracy_per_sequence`` (fractions)."""
    metrics = {}
    for task, entry in report["tasks"].items():
        metrics[f"{task}_accuracy"] = entry["accuracy"]
        if task == "subject":
            metrics.update({f"subject_accuracy_{c}": a for c, a in entry["per_condition"].items()})
            if "per_sequence" in entry:
                metrics["subject_accuracy_per_sequence"] = entry["per_sequence"]["accuracy"]
    return metrics


def cross_view_metrics(report: dict) -> dict:
    """``rank1_<condition>``: mean rank-1 over probe views, identical view excluded (fractions; None if no probe)."""
    return {f"rank1_{c}": entry["mean"] for c, entry in report["conditions"].items()}


# ------------------------------------------------------------------------------------------ tables
def closed_set_table(reports: dict[str, dict], level: str = "gei") -> str:
    """Rows 0°..180°, nm, bg, cl, average; columns every method's tasks, then thesis Table 6.2.

    ``reports``: method label → :func:`closed_set_report`. ``level``: ``"gei"`` or ``"sequence"`` (vote).
    """
    columns = []
    for label, report in reports.items():
        for task, entry in report["tasks"].items():
            if level == "sequence":
                entry = entry.get("per_sequence", entry)
            columns.append((f"{label}: {TASK_TITLES[task].lower()}", entry))
    header = (
        ["Probe"] + [title for title, _ in columns] + [f"thesis: {TASK_TITLES[t].lower()}" for t in THESIS_TABLE_6_2]
    )
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, row in TABLE_6_2_ROWS:
        cells = [_percent(table_6_2_cell(entry, row)) for _, entry in columns]
        cells += [f"{THESIS_TABLE_6_2[t][row]:.2f}" for t in THESIS_TABLE_6_2]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def cross_subject_tables(reports: dict[str, dict]) -> str:
    """Mean rank-1 per probe condition × method with literature references; then rank-1 per probe view.

    ``reports``: method label → :func:`cross_view_rank1` report.
    """
    names = list(reports)
    header = (
        ["Probe"]
        + names
        + [f"{n} (incl. identical view)" for n in names]
        + list(LITERATURE_RANK1)
        + ["thesis Table 6.3 GEI+PCA+LDA (90° protocol)"]
    )
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for c, condition in enumerate(CONDITIONS):
        cells = [_percent(r["conditions"][condition]["mean"]) for r in reports.values()]
        cells += [_percent(r["conditions"][condition]["mean_including_identical"]) for r in reports.values()]
        cells += [f"{ref[c]:.1f}" for ref in LITERATURE_RANK1.values()] + [f"{THESIS_TABLE_6_3_PCA_LDA[c]:.1f}"]
        lines.append(f"| {condition.upper()} | " + " | ".join(cells) + " |")
    lines += ["", "Rank-1 (%) per probe view (mean over the other gallery views):", ""]
    header = ["Method", "Probe"] + [f"{v}°" for v in VIEWS] + ["mean", "missing cells"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, report in reports.items():
        for condition, entry in report["conditions"].items():
            cells = [_percent(entry["per_probe_view"].get(str(v))) for v in VIEWS]
            cells += [_percent(entry["mean"]), f"{len(entry['missing_cells'])}/{len(VIEWS) ** 2}"]
            lines.append(f"| {label} | {condition.upper()} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def per_view_panels(results: dict) -> dict:
    """Plot data: per method, closed-set subject accuracy per view and cross-subject NM rank-1 per probe view,
    each the mean over the seeds (``{panel title: {method label: {view: accuracy}}}``)."""

    def mean_series(protocol: str, get) -> dict:
        series: dict[str, dict[str, list]] = {}
        for cell in results["cells"]:
            if cell["protocol"] != protocol:
                continue
            per_view = get(cell["detail"])
            if per_view is None:
                continue
            for view, value in per_view.items():
                if value is not None:
                    series.setdefault(cell["label"], {}).setdefault(view, []).append(value)
        return {label: {v: float(np.mean(a)) for v, a in views.items()} for label, views in series.items()}

    panels = {}
    if "closed_set" in results["protocols"]:
        panels["closed set: subject accuracy per view"] = mean_series(
            "closed_set", lambda d: d["closed_set"]["tasks"].get("subject", {}).get("per_view")
        )
    if "cross_subject" in results["protocols"]:
        panels["cross subject: NM rank-1 per probe view (identical view excluded)"] = mean_series(
            "cross_subject", lambda d: d["cross_view"]["conditions"]["nm"]["per_probe_view"]
        )
    return {title: series for title, series in panels.items() if series}


def gait_report(
    data_root,
    out_dir,
    protocols=("closed_set", "cross_subject"),
    experiments=("casiab_multitask", "casiab_single_subject"),
    overrides=(),
    seed: int = 0,
    include_pca_lda: bool = True,
) -> dict:
    """``mocapkit gait-report``: ``compare gait`` with the old options (a thin alias).

    ``overrides`` go to every learned run (``learned_overrides``); ``data.holdout_seed=`` /
    ``data.num_train_subjects=`` among them also set the benchmark's split, as they did for the baseline.
    Experiments that ``configs/compare/gait.yaml`` does not list are added as learned methods.
    """
    from omegaconf import OmegaConf, open_dict

    from mocapkit.evaluation.compare import compose, run_comparison

    cfg = compose(["gait", f"out={Path(out_dir)}", f"benchmark.root={Path(data_root)}", f"seeds=[{int(seed)}]"])
    with open_dict(cfg):
        cfg.protocols = list(protocols)
        cfg.learned_overrides = list(overrides)
        for item in overrides:
            key, _, value = item.lstrip("+").partition("=")
            if key in ("data.holdout_seed", "data.num_train_subjects"):
                OmegaConf.update(cfg, f"benchmark.{key.split('.', 1)[1]}", None if value == "null" else int(value))
        by_experiment = {}  # experiment → its first method (gait.yaml lists the plain recipe before variants)
        for k, m in cfg.methods.items():
            if m.get("learned"):
                by_experiment.setdefault(m.learned.experiment, k)
        only = []
        for experiment in experiments:
            if experiment not in by_experiment:
                cfg.methods[experiment] = {"label": experiment, "learned": {"experiment": experiment}}
                by_experiment[experiment] = experiment
            only.append(by_experiment[experiment])
        only += [k for k, m in cfg.methods.items() if m.get("estimator")] if include_pca_lda else []
        cfg.only = only
    return run_comparison(cfg)
