"""Clustering metrics: Hungarian accuracy (rectangular too), NMI normalisation, ARI."""

import numpy as np
import pytest
from sklearn.metrics import normalized_mutual_info_score

from mocapkit.evaluation.clustering import clustering_accuracy, clustering_report


def test_permuted_labels_give_perfect_scores():
    truth = np.repeat([0, 1, 2, 3], 5)
    permuted = np.array([2, 0, 3, 1])[truth] + 10  # renamed clusters, arbitrary values
    report = clustering_report(truth, permuted)
    assert report["acc"] == 1.0 and report["nmi"] == pytest.approx(1.0) and report["ari"] == pytest.approx(1.0)


def test_hand_computed_accuracy():
    truth = [0, 0, 0, 1, 1, 1]
    pred = [1, 1, 0, 0, 0, 0]
    # best map: cluster 1 -> class 0 (2 right), cluster 0 -> class 1 (3 right) = 5/6
    assert clustering_accuracy(truth, pred) == pytest.approx(5 / 6)
    assert clustering_accuracy([0, 1, 2], [0, 0, 0]) == pytest.approx(1 / 3)


def test_rectangular_more_clusters_than_classes():
    truth = [0, 0, 0, 0, 1, 1, 1, 1]
    pred = [0, 0, 1, 1, 2, 2, 2, 3]
    # one-to-one: class 0 <- cluster 0 or 1 (2), class 1 <- cluster 2 (3): 5/8; extra clusters are errors
    assert clustering_accuracy(truth, pred) == pytest.approx(5 / 8)


def test_rectangular_fewer_clusters_than_classes():
    truth = [0, 0, 1, 1, 2, 2]
    pred = [5, 5, 5, 5, 7, 7]
    assert clustering_accuracy(truth, pred) == pytest.approx(4 / 6)


def test_nmi_normalisation_is_arithmetic_and_stated():
    truth = [0, 0, 0, 1, 1, 1, 2, 2, 2]
    pred = [0, 0, 1, 1, 1, 1, 2, 2, 0]
    report = clustering_report(truth, pred)
    assert report["nmi_normalisation"] == "arithmetic"
    assert report["nmi"] == pytest.approx(normalized_mutual_info_score(truth, pred, average_method="arithmetic"))
    unequal = [0, 0, 0, 0, 0, 0, 1, 1, 2]
    arith = clustering_report(truth, unequal)["nmi"]
    assert arith != pytest.approx(normalized_mutual_info_score(truth, unequal, average_method="max"))


def test_random_labels_have_ari_near_zero():
    rng = np.random.default_rng(0)
    truth, pred = rng.integers(0, 5, 2000), rng.integers(0, 5, 2000)
    report = clustering_report(truth, pred)
    assert abs(report["ari"]) < 0.02 and report["acc"] < 0.3
    assert report["n_samples"] == 2000 and report["n_classes"] == 5 and report["n_clusters"] == 5


def test_bad_labels_are_clear_errors():
    with pytest.raises(ValueError, match="differ in length"):
        clustering_accuracy([0, 1], [0])
    with pytest.raises(ValueError, match="1-D"):
        clustering_report(np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="no labels"):
        clustering_report([], [])
