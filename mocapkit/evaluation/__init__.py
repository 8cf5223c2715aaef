"""Metrics, tables and plots."""
from mocapkit.evaluation.classification import classification_report, plot_confusion_matrix, topk_accuracy

__all__ = ["classification_report", "plot_confusion_matrix", "topk_accuracy"]
