"""Classification metrics against hand-computed values and an independent computation (torchmetrics, loops)."""

import numpy as np
import pytest
import torch
from torchmetrics.functional.classification import multiclass_accuracy

from mocapkit.evaluation import (
    classification_report,
    plot_confusion_matrix,
    topk_accuracy,
)


def test_report_matches_hand_computed_values(tmp_path):
    # 3 classes; class 0: 2/2 right, class 1: 1/2 right, class 2: 0/1 right (predicted 0, true class is 2nd best)
    scores = np.array([[0.9, 0.1, 0.0], [0.8, 0.2, 0.0], [0.1, 0.7, 0.2], [0.6, 0.3, 0.1], [0.5, 0.1, 0.4]])
    labels = np.array([0, 0, 1, 1, 2])
    subjects = np.array([1, 2, 1, 2, 2])
    r = classification_report(scores, labels, groups={"subject": subjects}, class_names=["a", "b", "c"])
    assert r["top1"] == pytest.approx(3 / 5)
    assert r["mean_class_accuracy"] == pytest.approx((1 + 0.5 + 0) / 3)
    assert r["chance"] == pytest.approx(1 / 3)
    assert r["per_class"]["b"] == {"accuracy": 0.5, "support": 2}
    assert r["per_subject"]["1"]["accuracy"] == 1.0 and r["per_subject"]["2"]["accuracy"] == pytest.approx(1 / 3)
    assert r["confusion_matrix"] == [[2, 0, 0], [1, 1, 0], [1, 0, 0]]
    assert topk_accuracy(scores, labels, 2) == pytest.approx(5 / 5)
    assert r["top5"] == 1.0  # k is capped at the number of classes
    png = plot_confusion_matrix(np.array(r["confusion_matrix"]), r["class_names"], tmp_path / "cm.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _rank_of_label(scores: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """0-based rank of each true class, ties going to the lower class index (as argmax)."""
    true = scores[np.arange(len(labels)), labels][:, None]
    lower_index = np.arange(scores.shape[1])[None, :] < labels[:, None]
    return ((scores > true) | ((scores == true) & lower_index)).sum(1)


@pytest.mark.parametrize("num_classes", [2, 3, 7, 12])
def test_accuracies_match_an_independent_computation(num_classes):
    rng = np.random.default_rng(num_classes)
    n = 200
    labels = rng.integers(0, num_classes, n)
    labels[labels == num_classes - 1] = 0  # the last class never occurs: mean-class and chance ignore it
    scores = rng.normal(size=(n, num_classes)) + 1.5 * np.eye(num_classes)[labels] * rng.random((n, 1))
    r = classification_report(scores, labels, groups={"subject": labels % 3})
    rank = _rank_of_label(scores, labels)
    for k in range(1, num_classes + 3):
        expected = float((rank < k).mean())
        assert topk_accuracy(scores, labels, k) == pytest.approx(expected, abs=1e-12), k
        if k < num_classes:  # torchmetrics, a second library (no ties in random scores)
            tm = multiclass_accuracy(
                torch.from_numpy(scores), torch.from_numpy(labels), num_classes=num_classes, top_k=k, average="micro"
            )
            assert float(tm) == pytest.approx(expected, abs=1e-6), k
    assert r["top1"] == pytest.approx(float((scores.argmax(1) == labels).mean()), abs=1e-12)
    assert r["top5"] == pytest.approx(float((rank < 5).mean()), abs=1e-12)
    present = np.unique(labels)
    per_class = [(scores.argmax(1)[labels == c] == c).mean() for c in present]
    assert r["mean_class_accuracy"] == pytest.approx(float(np.mean(per_class)), abs=1e-12)
    assert r["chance"] == pytest.approx(1 / len(present))
    assert set(r["per_class"]) == {f"class_{c}" for c in present}
    for g in range(3):
        hits = scores.argmax(1)[labels % 3 == g] == labels[labels % 3 == g]
        if len(hits):
            assert r["per_subject"][str(g)]["accuracy"] == pytest.approx(float(hits.mean()), abs=1e-12)


def test_ties_go_to_the_lower_class_as_argmax():
    scores = np.array([[1.0, 1.0, 1.0, 0.0], [0.0, 2.0, 2.0, 2.0], [0.5, 0.5, 0.5, 0.5]])
    labels = np.array([2, 1, 3])
    assert topk_accuracy(scores, labels, 1) == pytest.approx(1 / 3)  # only the second sample (argmax 1)
    assert topk_accuracy(scores, labels, 2) == pytest.approx(1 / 3)
    assert topk_accuracy(scores, labels, 3) == pytest.approx(2 / 3)
    assert topk_accuracy(scores, labels, 4) == 1.0
    expected = [float((_rank_of_label(scores, labels) < k).mean()) for k in (1, 2, 3, 4)]
    assert expected == [topk_accuracy(scores, labels, k) for k in (1, 2, 3, 4)]


def test_bad_shapes_and_empty_input_are_errors():
    with pytest.raises(ValueError, match="scores must be"):
        classification_report(np.zeros((3, 2)), np.zeros(4, dtype=int))
    with pytest.raises(ValueError, match="no samples"):
        classification_report(np.zeros((0, 2)), np.zeros(0, dtype=int))
