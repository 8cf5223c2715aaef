"""Clustering metrics: accuracy under the best one-to-one label map (Hungarian), NMI and ARI.

* **ACC** = ``max over one-to-one maps m of (1/n) Σ 1[y_i = m(c_i)]``, solved with
  ``scipy.optimize.linear_sum_assignment`` on the contingency table. The table may be
  rectangular (``k_pred ≠ k_true``): with more clusters than classes the extra clusters match
  no class and count as errors, which is the standard, strict definition.
* **NMI** = ``sklearn.metrics.normalized_mutual_info_score(..., average_method="arithmetic")``,
  i.e. ``I(Y; C) / ((H(Y) + H(C)) / 2)`` (scikit-learn's default). Older papers (Cai et al. 2011)
  divide by ``max(H(Y), H(C))`` (``average_method="max"``), which gives smaller values;
  reports carry ``"nmi_normalisation"`` so numbers are never compared across the two by mistake.
* **ARI** = ``sklearn.metrics.adjusted_rand_score``: about 0 for random labels, 1 for identical partitions.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from sklearn.metrics import adjusted_rand_score, normalized_mutual_info_score
from sklearn.metrics.cluster import contingency_matrix

NMI_NORMALISATION = "arithmetic"


def _labels(labels_true, labels_pred) -> tuple[np.ndarray, np.ndarray]:
    labels_true, labels_pred = np.asarray(labels_true), np.asarray(labels_pred)
    if labels_true.ndim != 1 or labels_pred.ndim != 1:
        raise ValueError(f"labels must be 1-D, got shapes {labels_true.shape} and {labels_pred.shape}")
    if len(labels_true) != len(labels_pred):
        raise ValueError(f"labels_true and labels_pred differ in length: {len(labels_true)} vs {len(labels_pred)}")
    if len(labels_true) == 0:
        raise ValueError("no labels: clustering metrics need at least one sample")
    return labels_true, labels_pred


def clustering_accuracy(labels_true, labels_pred) -> float:
    """Fraction of samples whose cluster maps to their class under the best one-to-one map (Hungarian).

    Any label values are allowed (not necessarily 0..k-1); the numbers of classes and clusters may differ.
    """
    labels_true, labels_pred = _labels(labels_true, labels_pred)
    table = contingency_matrix(labels_true, labels_pred)  # [classes, clusters]
    rows, cols = linear_sum_assignment(-table)
    return float(table[rows, cols].sum() / len(labels_true))


def clustering_report(labels_true, labels_pred) -> dict:
    """``{"acc", "nmi", "ari", "nmi_normalisation": "arithmetic", "n_samples", "n_classes", "n_clusters"}``."""
    labels_true, labels_pred = _labels(labels_true, labels_pred)
    return {
        "acc": clustering_accuracy(labels_true, labels_pred),
        "nmi": float(normalized_mutual_info_score(labels_true, labels_pred, average_method=NMI_NORMALISATION)),
        "ari": float(adjusted_rand_score(labels_true, labels_pred)),
        "nmi_normalisation": NMI_NORMALISATION,
        "n_samples": int(len(labels_true)),
        "n_classes": int(len(np.unique(labels_true))),
        "n_clusters": int(len(np.unique(labels_pred))),
    }
