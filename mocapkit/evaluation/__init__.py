"""Shared evaluation: classification and clustering metrics, result plots, ``mocapkit eval`` and the comparison
engine (:mod:`mocapkit.evaluation.compare`). Each task's own metrics live in its package (``mocapkit.<task>.metrics``)."""

from mocapkit.evaluation.classification import classification_report, plot_confusion_matrix, topk_accuracy
from mocapkit.evaluation.clustering import clustering_accuracy, clustering_report

__all__ = [
    "classification_report",
    "clustering_accuracy",
    "clustering_report",
    "plot_confusion_matrix",
    "topk_accuracy",
]
