"""Gait recognition metrics on CASIA-B: the thesis's closed-set accuracies and OpenGait's cross-view rank-1.

Everything takes plain numpy arrays (from the CNN's ``predict_step``, from ONNX Runtime or from the
GEI+PCA+LDA baseline), so every method is reported the same way.

Closed set (thesis §6.1, Table 6.2)
    :func:`closed_set_report`: per task (identify subject / predict view / predict condition), the
    accuracy of ``argmax(logits)`` overall, per probe view (0°..180°) and per condition (nm/bg/cl),
    averaged over test GEIs; with one GEI per gait cycle, also per test sequence (video) by summing
    the logits of its cycles. :func:`closed_set_markdown` lays it out like Table 6.2.

Cross subject (OpenGait's CASIA-B protocol, ``single_view_gallery_evaluation``)
    :func:`cross_view_rank1`: gallery ``nm-01..04``, probes ``nm-05/06``, ``bg-01/02``, ``cl-01/02``
    of subjects never seen in training; for each probe condition an 11×11 matrix of rank-1 accuracy
    [probe view, gallery view]; per probe view the mean over the 10 *other* gallery views (OpenGait's
    ``de_diag``), then the mean over probe views. :func:`cross_view_markdown` prints OpenGait's rows.

Per-view keys are the view in degrees as a string (``"0"``, ``"18"``, ... ``"180"``), so a report
survives a JSON round trip unchanged; accuracies are fractions in [0, 1].
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from sklearn.metrics import pairwise_distances

from mocapkit.datasets.casia_b.splits import gallery_probe_masks
from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.evaluation.plots import pyplot, save_figure

#: The classification tasks of the multi-task network: name → (logits key, label key).
TASKS: dict[str, tuple[str, str]] = {
    "subject": ("subject_logits", "subjects"),
    "view": ("view_logits", "views"),
    "condition": ("condition_logits", "conditions"),
}
#: Column titles of thesis Table 6.2.
TASK_TITLES = {"subject": "Identify subject", "view": "Predict view", "condition": "Predict condition"}
#: Thesis Table 6.2 (real CASIA-B, 124 subjects, the thesis's own hold-out), accuracy in %.
#: Keys: views in degrees, the conditions, and ``"average"`` (as printed; the thesis's averages are inconsistent, see closed_set_report).
THESIS_TABLE_6_2: dict[str, dict[str, float]] = {
    "subject": {
        "0": 96.09,
        "18": 98.68,
        "36": 97.82,
        "54": 94.94,
        "72": 95.80,
        "90": 95.80,
        "108": 95.23,
        "126": 95.80,
        "144": 94.08,
        "162": 94.37,
        "180": 96.09,
        "nm": 99.35,
        "bg": 91.47,
        "cl": 93.82,
        "average": 95.88,
    },
    "view": {
        "0": 97.55,
        "18": 98.99,
        "36": 98.70,
        "54": 99.01,
        "72": 98.41,
        "90": 99.63,
        "108": 94.68,
        "126": 99.23,
        "144": 98.70,
        "162": 99.85,
        "180": 99.11,
        "nm": 99.29,
        "bg": 98.37,
        "cl": 97.79,
        "average": 98.67,
    },
    "condition": {
        "0": 91.08,
        "18": 95.10,
        "36": 95.68,
        "54": 97.69,
        "72": 97.98,
        "90": 97.11,
        "108": 95.97,
        "126": 98.55,
        "144": 97.98,
        "162": 96.25,
        "180": 95.39,
        "nm": 99.51,
        "bg": 94.19,
        "cl": 95.05,
        "average": 96.31,
    },
}
#: Table 6.2's rows as (label, key): the views 0°..180°, the conditions, the average.
TABLE_6_2_ROWS: tuple[tuple[str, str], ...] = (
    *((f"{v}°", str(v)) for v in VIEWS),
    *((f"condition {c}", c) for c in CONDITIONS),
    ("**average**", "average"),
)
METRICS = ("euc", "cos")
AGGREGATES = ("sequence", "gei")


# --------------------------------------------------------------------------------------------- closed set
def _column(predictions: dict[str, np.ndarray], key: str, n: int | None) -> np.ndarray:
    if key not in predictions:
        raise KeyError(f"predictions[{key!r}] is missing (keys: {sorted(predictions)})")
    values = np.asarray(predictions[key])
    if n is not None and len(values) != n:
        raise ValueError(f"predictions[{key!r}] has {len(values)} rows, expected {n}")
    return values


def _accuracy_table(correct: np.ndarray, views: np.ndarray, conditions: np.ndarray) -> dict:
    """Overall, per-view (degrees) and per-condition accuracy of a boolean ``correct`` vector."""
    per_view = {str(VIEWS[v]): float(correct[views == v].mean()) for v in range(len(VIEWS)) if (views == v).any()}
    per_condition = {
        name: float(correct[conditions == c].mean()) for c, name in enumerate(CONDITIONS) if (conditions == c).any()
    }
    return {
        "accuracy": float(correct.mean()),
        "num_samples": len(correct),
        "per_view": per_view,
        "per_condition": per_condition,
    }


def closed_set_report(predictions: dict[str, np.ndarray]) -> dict:
    """Closed-set accuracies per task, per probe view and per condition (thesis Table 6.2).

    Args:
        predictions: arrays of length N (one row per test GEI), as concatenated from
            ``GaitRecognitionModule.predict_step``: ``"views"`` (label 0..10), ``"conditions"``
            (0 nm, 1 bg, 2 cl), ``"subjects"`` (label index); the logits ``"subject_logits"`` ``[N, S]``,
            ``"view_logits"`` ``[N, 11]``, ``"condition_logits"`` ``[N, 3]`` of the tasks the model has;
            optionally ``"subject_ids"`` (1-based) and ``"sequences"`` (1-based) to identify test videos.

    Returns:
        ``{"num_geis", "num_sequences", "per", "tasks": {task: {"accuracy", "num_samples", "per_view",
        "per_condition", "chance", ["per_sequence": {same fields, by vote}]}}}``.
        ``per`` is ``"cycle"`` when some test sequence has several GEIs; then ``per_sequence`` holds
        the accuracy by voting over a sequence's cycles (the sum of their logits), since the thesis tests on videos.

    Averages are over test GEIs (and over test videos for ``per_sequence``). The thesis's printed
    averages are not consistent with its own rows (the subject average 95.88 is the mean
    over views, the mean over nm/bg/cl is 94.88); we do not reproduce either convention and report the
    plain mean over test samples, so "average" = the overall accuracy.
    """
    tasks = [task for task, (logits_key, _) in TASKS.items() if logits_key in predictions]
    if not tasks:
        raise KeyError(
            f"predictions hold no logits (expected one of {[k for k, _ in TASKS.values()]}; "
            f"keys: {sorted(predictions)})"
        )
    views = _column(predictions, "views", None).astype(np.int64)
    n = len(views)
    if n == 0:
        raise ValueError("predictions are empty: no test GEIs to evaluate")
    conditions = _column(predictions, "conditions", n).astype(np.int64)
    if views.min() < 0 or views.max() >= len(VIEWS):
        raise ValueError(
            f"predictions['views'] must be view labels 0..{len(VIEWS) - 1}, got {views.min()}..{views.max()}"
        )
    if conditions.min() < 0 or conditions.max() >= len(CONDITIONS):
        raise ValueError(
            f"predictions['conditions'] must be 0..{len(CONDITIONS) - 1}, got {conditions.min()}..{conditions.max()}"
        )
    # A test video is one (subject, condition, repetition, view); several rows of one video = per-cycle GEIs.
    identity = _column(predictions, "subject_ids" if "subject_ids" in predictions else "subjects", n)
    sequences = _column(predictions, "sequences", n) if "sequences" in predictions else np.arange(n)
    keys = np.stack([np.asarray(identity, np.int64), conditions, np.asarray(sequences, np.int64), views], axis=1)
    _, video, video_counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    video = video.reshape(-1)
    per_cycle = bool((video_counts > 1).any())
    report: dict = {
        "num_geis": n,
        "num_sequences": len(video_counts),
        "per": "cycle" if per_cycle else "sequence",
        "tasks": {},
    }
    for task in tasks:
        logits_key, label_key = TASKS[task]
        logits = np.asarray(_column(predictions, logits_key, n), dtype=np.float64)
        labels = _column(predictions, label_key, n).astype(np.int64)
        if logits.ndim != 2:
            raise ValueError(f"predictions[{logits_key!r}] must be [N, classes], got shape {logits.shape}")
        if not np.isfinite(logits).all():
            raise ValueError(f"predictions[{logits_key!r}] contains NaN or infinite values")
        if labels.min() < 0 or labels.max() >= logits.shape[1]:
            raise ValueError(
                f"predictions[{label_key!r}] must be labels 0..{logits.shape[1] - 1} for the closed set "
                f"(got {labels.min()}..{labels.max()}; -1 marks a subject outside the training label "
                "space, which only the cross-subject protocol has)"
            )
        entry = _accuracy_table(logits.argmax(1) == labels, views, conditions)
        entry["chance"] = 1.0 / logits.shape[1]
        if per_cycle:
            video_logits = np.zeros((len(video_counts), logits.shape[1]))
            np.add.at(video_logits, video, logits)
            first = np.unique(video, return_index=True)[1]  # one row per video, in video order
            entry["per_sequence"] = _accuracy_table(
                video_logits.argmax(1) == labels[first], views[first], conditions[first]
            )
        report["tasks"][task] = entry
    return report


def _percent(value) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{100 * value:.2f}"


def table_6_2_cell(entry: dict | None, row: str) -> float | None:
    """The accuracy of one task's report ``entry`` in a :data:`TABLE_6_2_ROWS` row (None: no such samples)."""
    if entry is None:
        return None
    if row == "average":
        return entry["accuracy"]
    return entry["per_view"].get(row, entry["per_condition"].get(row))


def closed_set_markdown(report: dict, title: str = "Closed-set accuracy (%)", reference: bool = True) -> str:
    """A markdown table laid out like thesis Table 6.2.

    Rows 0°..180°, then nm, bg, cl, then the average (over test GEIs; see :func:`closed_set_report`);
    columns Identify subject / Predict view / Predict condition for the tasks present, per GEI and,
    when GEIs are per cycle, per sequence by vote; with ``reference`` the thesis's Table 6.2 numbers
    (real CASIA-B, a different data set from a synthetic cache) as a last column block.
    """
    tasks = list(report["tasks"])
    blocks = [("per GEI", lambda t: report["tasks"][t])]
    if report.get("per") == "cycle":
        blocks.append(("per sequence (vote)", lambda t: report["tasks"][t].get("per_sequence")))
    header = ["Probe"] + [f"{TASK_TITLES[t]} ({name})" for name, _ in blocks for t in tasks]
    if reference:
        header += [f"{TASK_TITLES[t]} (thesis, real CASIA-B)" for t in tasks]
    lines = [f"**{title}**", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, row in TABLE_6_2_ROWS:
        cells = [_percent(table_6_2_cell(get(t), row)) for _, get in blocks for t in tasks]
        if reference:
            cells += [f"{THESIS_TABLE_6_2[t][row]:.2f}" for t in tasks]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        f"{report['num_geis']} test GEIs in {report['num_sequences']} test sequences "
        f"(GEIs per {report['per']}); averages are over test samples "
        "(the thesis's printed averages are inconsistent with its rows)."
    )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------- cross view
def _nan_to_none(value):
    if isinstance(value, list):
        return [_nan_to_none(v) for v in value]
    return None if value is None or (isinstance(value, float) and math.isnan(value)) else value


def _mean_or_nan(values: np.ndarray) -> float:
    values = values[~np.isnan(values)]
    return float(values.mean()) if len(values) else float("nan")


def cross_view_rank1(
    embeddings: np.ndarray,
    subject_ids: np.ndarray,
    conditions: np.ndarray,
    sequences: np.ndarray,
    views: np.ndarray,
    metric: str = "euc",
    aggregate: str = "sequence",
) -> dict:
    """OpenGait's CASIA-B rank-1 per (probe view, gallery view), identical views excluded.

    Args:
        embeddings: ``[N, D]`` features of the test subjects' GEIs (e.g. the CNN's shared FC-512).
        subject_ids: ``[N]`` subject IDs (any integers; a match is a gallery sample of the same ID).
        conditions: ``[N]`` 0 nm, 1 bg, 2 cl. sequences: ``[N]`` 1-based repetition (``nm-05`` → 5).
        views: ``[N]`` camera azimuth **in degrees** (0, 18, ..., 180), not the 0..10 view label.
        metric: ``"euc"`` (Euclidean distance, OpenGait's default) or ``"cos"`` (1 − cosine similarity).
        aggregate: ``"sequence"`` (default): average the embeddings of a sequence's GEIs (one per
            gait cycle) first, so each (subject, condition, repetition, view) is one probe or gallery
            item, as in OpenGait, which embeds a whole sequence; ``"gei"``: every GEI is its own probe
            and gallery item (rank-1 per probe GEI). With one GEI per sequence both are the same.

    Returns:
        ``{"metric", "aggregate", "num_gallery", "conditions": {"nm"|"bg"|"cl": {"matrix" (11×11, rows probe
        views, columns gallery views, None where a view has no probe or gallery item), "per_probe_view",
        "mean", "per_probe_view_including_identical", "mean_including_identical", "num_probes",
        "missing_cells" ([probe view, gallery view] in degrees)}}, "views"}``.
        ``per_probe_view[v]`` is the mean of row v without its diagonal cell; with a full matrix that is
        the row's off-diagonal sum / 10, as OpenGait's ``de_diag``. Missing cells (tiny data sets) are
        left out of every mean and listed, never counted as 0.
    """
    if metric not in METRICS:
        raise ValueError(f"metric={metric!r}: expected one of {METRICS}")
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate={aggregate!r}: expected one of {AGGREGATES}")
    embeddings = np.asarray(embeddings, dtype=np.float64)
    if embeddings.ndim != 2 or len(embeddings) == 0:
        raise ValueError(f"embeddings must be a non-empty [N, D] array, got shape {embeddings.shape}")
    if not np.isfinite(embeddings).all():
        raise ValueError("embeddings contain NaN or infinite values")
    n = len(embeddings)
    columns = {}
    for name, values in (
        ("subject_ids", subject_ids),
        ("conditions", conditions),
        ("sequences", sequences),
        ("views", views),
    ):
        values = np.asarray(values, dtype=np.int64)
        if values.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},) like embeddings, got {values.shape}")
        columns[name] = values
    bad_views = sorted(set(np.unique(columns["views"]).tolist()) - set(VIEWS))
    if bad_views:
        raise ValueError(f"views must be in degrees {VIEWS}; got {bad_views} (convert 0..10 labels with VIEWS[label])")
    if aggregate == "sequence":
        keys = np.stack([columns[k] for k in ("subject_ids", "conditions", "sequences", "views")], axis=1)
        keys, item = np.unique(keys, axis=0, return_inverse=True)
        item = item.reshape(-1)
        summed = np.zeros((len(keys), embeddings.shape[1]))
        np.add.at(summed, item, embeddings)
        embeddings = summed / np.bincount(item)[:, None]
        columns = dict(zip(("subject_ids", "conditions", "sequences", "views"), keys.T))
    ids, view_deg = columns["subject_ids"], columns["views"]
    gallery, probes = gallery_probe_masks(columns["conditions"], columns["sequences"])
    distance_metric = "euclidean" if metric == "euc" else "cosine"
    report: dict = {
        "metric": metric,
        "aggregate": aggregate,
        "views": list(VIEWS),
        "num_gallery": int(gallery.sum()),
        "conditions": {},
    }
    for condition, probe in probes.items():
        matrix = np.full((len(VIEWS), len(VIEWS)), np.nan)
        for p, probe_view in enumerate(VIEWS):
            probe_rows = np.flatnonzero(probe & (view_deg == probe_view))
            if not len(probe_rows):
                continue
            for g, gallery_view in enumerate(VIEWS):
                gallery_rows = np.flatnonzero(gallery & (view_deg == gallery_view))
                if not len(gallery_rows):
                    continue
                distance = pairwise_distances(embeddings[probe_rows], embeddings[gallery_rows], metric=distance_metric)
                nearest = gallery_rows[distance.argmin(1)]
                matrix[p, g] = float((ids[nearest] == ids[probe_rows]).mean())
        off_diagonal = matrix.copy()
        np.fill_diagonal(off_diagonal, np.nan)
        per_view = {str(v): _mean_or_nan(off_diagonal[p]) for p, v in enumerate(VIEWS)}
        per_view_all = {str(v): _mean_or_nan(matrix[p]) for p, v in enumerate(VIEWS)}
        missing = [[VIEWS[p], VIEWS[g]] for p, g in zip(*np.nonzero(np.isnan(matrix)))]
        report["conditions"][condition] = {
            "matrix": _nan_to_none(matrix.tolist()),
            "per_probe_view": {v: _nan_to_none(a) for v, a in per_view.items()},
            "mean": _nan_to_none(_mean_or_nan(np.array(list(per_view.values())))),
            "per_probe_view_including_identical": {v: _nan_to_none(a) for v, a in per_view_all.items()},
            "mean_including_identical": _nan_to_none(_mean_or_nan(np.array(list(per_view_all.values())))),
            "num_probes": int(probe.sum()),
            "missing_cells": missing,
        }
    return report


def cross_view_markdown(report: dict, title: str = "Cross-view rank-1 (%), identical view excluded") -> str:
    """OpenGait-style table: rows NM/BG/CL, columns the 11 probe views and their mean; then the
    means including the identical view and the count of missing (view without data) cells."""
    header = ["Probe"] + [f"{v}°" for v in VIEWS] + ["mean", "mean incl. identical", "missing cells"]
    lines = [f"**{title}**", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for condition, entry in report["conditions"].items():
        cells = [_percent(entry["per_probe_view"].get(str(v))) for v in VIEWS]
        cells += [
            _percent(entry["mean"]),
            _percent(entry["mean_including_identical"]),
            f"{len(entry['missing_cells'])}/{len(VIEWS) ** 2}",
        ]
        lines.append(f"| {condition.upper()} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        f"metric {report['metric']}, one item per {report['aggregate']}, "
        f"{report['num_gallery']} gallery items (nm-01..04); probes nm-05/06, bg-01/02, cl-01/02. "
        "Per probe view: mean over the other gallery views "
        "(OpenGait de_diag, /10 when all views are present)."
    )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------- plots
def plot_per_view_panels(
    panels: dict[str, dict[str, dict]], path: str | Path, title: str | None = None, ylabel: str = "accuracy (%)"
) -> Path:
    """Save side-by-side per-view line plots as PNG.

    Args:
        panels: ``{panel title: {method name: {view (degrees, str or int): accuracy in [0, 1] or None}}}``;
            one subplot per panel, one line per method; missing/None points are gaps.
        path: the PNG to write.
    """
    plt = pyplot()

    if not panels:
        raise ValueError("panels is empty: nothing to plot")
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.2), squeeze=False)
    for ax, (panel_title, series) in zip(axes[0], panels.items()):
        for method, per_view in series.items():
            values = {int(v): a for v, a in per_view.items()}
            y = [np.nan if values.get(v) is None else 100 * values[v] for v in VIEWS]
            ax.plot(VIEWS, y, marker="o", label=method)
        ax.set_xticks(VIEWS)
        ax.set_xlabel("probe view (degrees)")
        ax.set_ylabel(ylabel)
        ax.set_ylim(0, 102)
        ax.set_title(panel_title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi=110)


def plot_per_view(series: dict[str, dict], path: str | Path, title: str = "Accuracy per view") -> Path:
    """One per-view line plot, one line per method (``{method: {view degrees: accuracy in [0, 1]}}``)."""
    return plot_per_view_panels({title: series}, path)
