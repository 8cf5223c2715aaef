"""Classification metrics, confusion matrices and their plots.

Everything takes plain arrays, so any model's predictions (PyTorch, ONNX
Runtime or a classical method) are reported the same way. The accuracies come from
scikit-learn (``accuracy_score``, ``top_k_accuracy_score``, ``balanced_accuracy_score``,
``confusion_matrix``); the per-class and per-group tables are read off them.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from sklearn.metrics import (
    accuracy_score,
    balanced_accuracy_score,
    confusion_matrix,
    top_k_accuracy_score,
)

from mocapkit.evaluation.plots import pyplot, save_figure


def topk_accuracy(scores: np.ndarray, labels: np.ndarray, k: int) -> float:
    """Fraction of samples whose label is among the ``k`` highest scores. ``scores``: ``[N, C]``.

    ``k`` is capped at ``C`` (top-``C`` is 1). Ties go to the lower class index, as ``argmax`` does,
    so top-1 is the accuracy of ``scores.argmax(1)`` and top-k never falls below it.
    """
    scores, labels = np.asarray(scores), np.asarray(labels)
    num_classes = scores.shape[1]
    k = min(k, num_classes)
    if k == num_classes:
        return 1.0
    if k == 1:  # also the two-class case, which top_k_accuracy_score only takes as one score column
        return float(accuracy_score(labels, scores.argmax(1)))
    # scikit-learn ranks tied scores by descending class index; on reversed columns (and labels) that
    # is ascending original index, the argmax order
    return float(top_k_accuracy_score(num_classes - 1 - labels, scores[:, ::-1], k=k, labels=np.arange(num_classes)))


def classification_report(
    scores: np.ndarray,
    labels: np.ndarray,
    groups: dict[str, np.ndarray] | None = None,
    class_names: list[str] | None = None,
) -> dict:
    """Top-1, top-5, mean-class accuracy, per-class accuracy, per-group accuracy and the confusion matrix.

    Mean-class accuracy is the mean of the per-class accuracies (recalls) over the classes present in
    ``labels`` (scikit-learn's balanced accuracy); ``chance`` is 1 / the number of those classes.

    Args:
        scores: ``[N, C]`` logits or probabilities.
        labels: ``[N]`` 0-based true classes.
        groups: optional ``{"subject": [N] ids, ...}``; each gives a ``per_<name>`` accuracy table.
        class_names: ``C`` names (default ``"class_<k>"``).
    """
    scores = np.asarray(scores, dtype=np.float64)
    labels = np.asarray(labels, dtype=np.int64)
    if scores.ndim != 2 or len(scores) != len(labels):
        raise ValueError(f"scores must be [N, C] and labels [N], got {scores.shape} and {labels.shape}")
    if len(labels) == 0:
        raise ValueError("no samples to evaluate")
    num_classes = scores.shape[1]
    names = list(class_names) if class_names else [f"class_{k}" for k in range(num_classes)]
    predictions = scores.argmax(1)
    confusion = confusion_matrix(labels, predictions, labels=np.arange(num_classes))
    support = confusion.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        recall = np.diag(confusion) / support
    present = support > 0
    with warnings.catch_warnings():  # classes predicted but absent from labels are left out, as meant
        warnings.filterwarnings("ignore", message="y_pred contains classes not in y_true")
        mean_class = balanced_accuracy_score(labels, predictions)
    report = {
        "num_samples": len(labels),
        "num_classes": int(num_classes),
        "top1": float(accuracy_score(labels, predictions)),
        "top5": topk_accuracy(scores, labels, 5),
        "mean_class_accuracy": float(mean_class),
        "chance": float(1.0 / max(1, present.sum())),
        "per_class": {
            names[k]: {"accuracy": float(recall[k]), "support": int(support[k])}
            for k in range(num_classes)
            if present[k]
        },
        "confusion_matrix": confusion.tolist(),
        "class_names": names,
    }
    for group_name, ids in (groups or {}).items():
        ids = np.asarray(ids)
        report[f"per_{group_name}"] = {
            str(g): {
                "accuracy": float(accuracy_score(labels[ids == g], predictions[ids == g])),
                "support": int((ids == g).sum()),
            }
            for g in np.unique(ids)
        }
    return report


def plot_confusion_matrix(
    confusion: np.ndarray,
    class_names: list[str],
    path: str | Path,
    title: str = "Confusion matrix",
    normalize: bool = True,
) -> Path:
    """Save a confusion-matrix heat map (rows = true class, normalised per row by default) as PNG."""
    plt = pyplot()

    confusion = np.asarray(confusion, dtype=np.float64)
    shown = confusion / np.maximum(confusion.sum(1, keepdims=True), 1) if normalize else confusion
    n = len(class_names)
    side = min(24, max(5, 0.35 * n + 2))
    fig, ax = plt.subplots(figsize=(side, side * 0.9))
    im = ax.imshow(shown, cmap="Blues", vmin=0, vmax=1 if normalize else None)
    ax.set_xticks(range(n), class_names, rotation=90, fontsize=8)
    ax.set_yticks(range(n), class_names, fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(title)
    if n <= 30:
        for i in range(n):
            for j in range(n):
                if confusion[i, j]:
                    ax.text(
                        j,
                        i,
                        f"{shown[i, j]:.2f}" if normalize else int(confusion[i, j]),
                        ha="center",
                        va="center",
                        fontsize=6,
                        color="white" if shown[i, j] > 0.5 else "black",
                    )
    fig.colorbar(im, ax=ax, fraction=0.046)
    return save_figure(fig, path, dpi=120)
