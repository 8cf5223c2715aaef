"""Metrics, tables and plots: classification, clustering and gait (closed-set tables, cross-view rank-1)."""
from mocapkit.evaluation.classification import classification_report, plot_confusion_matrix, topk_accuracy
from mocapkit.evaluation.clustering import clustering_accuracy, clustering_report
from mocapkit.evaluation.gait import closed_set_report, cross_view_rank1

__all__ = ["classification_report", "closed_set_report", "clustering_accuracy", "clustering_report",
           "cross_view_rank1", "plot_confusion_matrix", "topk_accuracy"]
