"""Classification metrics against hand-computed values."""
import numpy as np
import pytest

from mocapkit.evaluation import classification_report, plot_confusion_matrix, topk_accuracy


def test_report_matches_hand_computed_values(tmp_path):
    # 3 classes; class 0: 2/2 right, class 1: 1/2 right, class 2: 0/1 right (predicted 0, true class is 2nd best)
    scores = np.array([[0.9, 0.1, 0.0], [0.8, 0.2, 0.0], [0.1, 0.7, 0.2], [0.6, 0.3, 0.1], [0.5, 0.1, 0.4]])
    labels = np.array([0, 0, 1, 1, 2])
    subjects = np.array([1, 2, 1, 2, 2])
    r = classification_report(scores, labels, groups={"subject": subjects}, class_names=["a", "b", "c"])
    assert r["top1"] == pytest.approx(3 / 5)
    assert r["mean_class_accuracy"] == pytest.approx((1 + 0.5 + 0) / 3)
    assert r["per_class"]["b"] == {"accuracy": 0.5, "support": 2}
    assert r["per_subject"]["1"]["accuracy"] == 1.0 and r["per_subject"]["2"]["accuracy"] == pytest.approx(1 / 3)
    assert r["confusion_matrix"] == [[2, 0, 0], [1, 1, 0], [1, 0, 0]]
    assert topk_accuracy(scores, labels, 2) == pytest.approx(5 / 5)
    assert r["top5"] == 1.0  # k is capped at the number of classes
    png = plot_confusion_matrix(np.array(r["confusion_matrix"]), r["class_names"], tmp_path / "cm.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_shapes_and_empty_input_are_errors():
    with pytest.raises(ValueError, match="scores must be"):
        classification_report(np.zeros((3, 2)), np.zeros(4, dtype=int))
    with pytest.raises(ValueError, match="no samples"):
        classification_report(np.zeros((0, 2)), np.zeros(0, dtype=int))
