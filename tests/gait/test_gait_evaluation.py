"""Gait metrics on hand-made predictions and embeddings whose answers are known."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.datasets.formats.casia_b import VIEWS
from mocapkit.gait.metrics import (
    closed_set_markdown,
    closed_set_report,
    cross_view_markdown,
    cross_view_rank1,
    plot_per_view,
    plot_per_view_panels,
)

SEQUENCES = [(0, s) for s in range(1, 7)] + [(1, 1), (1, 2), (2, 1), (2, 2)]  # (condition, repetition) of CASIA-B


def _one_hot(labels: np.ndarray, classes: int, scale: float = 1.0) -> np.ndarray:
    return scale * np.eye(classes)[labels]


# ------------------------------------------------------------------------------------------ closed set
def test_closed_set_report_per_view_and_condition():
    rows = [(v, c, s) for v in range(11) for c in range(3) for s in (0, 1)]
    views, conditions, subjects = (np.array(col) for col in zip(*rows))
    # subject task: wrong for subject 1 in views 5..10; view task: wrong for every cl GEI
    predicted_subject = np.where((views >= 5) & (subjects == 1), 0, subjects)
    predicted_view = np.where(conditions == 2, (views + 1) % 11, views)
    report = closed_set_report(
        {
            "subject_logits": _one_hot(predicted_subject, 2),
            "subjects": subjects,
            "view_logits": _one_hot(predicted_view, 11),
            "views": views,
            "conditions": conditions,
            "subject_ids": subjects + 1,
            "sequences": np.ones_like(views),
        }
    )
    assert report["per"] == "sequence" and report["num_geis"] == report["num_sequences"] == 66
    assert set(report["tasks"]) == {"subject", "view"}  # no condition logits, no condition task
    subject = report["tasks"]["subject"]
    assert subject["per_view"] == {str(v): (1.0 if k < 5 else 0.5) for k, v in enumerate(VIEWS)}
    assert subject["per_condition"] == pytest.approx({"nm": 16 / 22, "bg": 16 / 22, "cl": 16 / 22})
    assert subject["accuracy"] == pytest.approx(48 / 66)
    assert subject["chance"] == 0.5
    view = report["tasks"]["view"]
    assert view["per_condition"] == {"nm": 1.0, "bg": 1.0, "cl": 0.0}
    assert view["accuracy"] == pytest.approx(2 / 3)
    assert all(a == pytest.approx(2 / 3) for a in view["per_view"].values())
    assert "per_sequence" not in subject
    assert json.loads(json.dumps(report)) == report  # JSON round trip keeps it as is

    table = closed_set_markdown(report, "test")
    lines = table.splitlines()
    assert lines[2].startswith("| Probe | Identify subject (per GEI) | Predict view (per GEI) |")
    assert "Identify subject (thesis, real CASIA-B)" in lines[2]
    assert lines[4].startswith("| 0° | 100.00 | 66.67 | 96.09 | 97.55 |")
    assert any(line.startswith("| condition cl | 72.73 | 0.00 | 93.82 | 97.79 |") for line in lines)
    assert any(line.startswith("| **average** | 72.73 | 66.67 | 95.88 | 98.67 |") for line in lines)
    assert "96.09" not in closed_set_markdown(report, "no reference", reference=False)


def test_closed_set_votes_over_a_sequences_cycles():
    # two test videos of three cycles each (subject label 0 of 2)
    logits = np.array(
        [
            [1, 0],
            [1, 0],
            [0, 5],  # video A: 2/3 cycles right, the summed logits pick subject 1
            [0, 1],
            [3, 0],
            [3, 0],
        ],  # video B: 2/3 cycles right, the sum picks subject 0
        dtype=float,
    )
    report = closed_set_report(
        {
            "subject_logits": logits,
            "subjects": np.zeros(6, int),
            "subject_ids": np.ones(6, int),
            "views": np.full(6, 5),
            "conditions": np.array([0, 0, 0, 1, 1, 1]),
            "sequences": np.array([5, 5, 5, 1, 1, 1]),
        }
    )
    subject = report["tasks"]["subject"]
    assert report["per"] == "cycle" and report["num_sequences"] == 2
    assert subject["accuracy"] == pytest.approx(4 / 6)
    assert subject["per_sequence"]["accuracy"] == 0.5
    assert subject["per_sequence"]["per_condition"] == {"nm": 0.0, "bg": 1.0}
    assert subject["per_sequence"]["per_view"] == {"90": 0.5}
    table = closed_set_markdown(report)
    assert "Identify subject (per sequence (vote))" in table
    assert "| 90° | 66.67 | 50.00 | 95.80 |" in table
    assert "| 0° | – | – | 96.09 |" in table


def test_closed_set_rejects_bad_input():
    base = {
        "subject_logits": np.zeros((2, 3)),
        "subjects": np.array([0, -1]),
        "views": np.zeros(2, int),
        "conditions": np.zeros(2, int),
    }
    with pytest.raises(ValueError, match="-1 marks a subject outside"):
        closed_set_report(base)
    with pytest.raises(KeyError, match="views"):
        closed_set_report({k: v for k, v in base.items() if k != "views"})
    with pytest.raises(ValueError, match="NaN"):
        closed_set_report({**base, "subjects": np.array([0, 1]), "subject_logits": np.full((2, 3), np.nan)})
    with pytest.raises(ValueError, match="has 3 rows"):
        closed_set_report({**base, "conditions": np.zeros(3, int)})
    with pytest.raises(KeyError, match="no logits"):
        closed_set_report({"views": np.zeros(2, int), "conditions": np.zeros(2, int)})


# ------------------------------------------------------------------------------------------ cross view
def _casia_layout(num_subjects: int):
    """Every (subject, condition, repetition, view) of a CASIA-B-shaped test set, one GEI each."""
    rows = [(s, c, q, v) for s in range(1, num_subjects + 1) for c, q in SEQUENCES for v in VIEWS]
    return [np.array(col) for col in zip(*rows)]


def test_identical_view_matches_are_excluded():
    # the subject code rotates with the view: a match is only right at the identical view (12 > 10 view steps)
    subjects, conditions, sequences, views = _casia_layout(12)
    view_index = np.searchsorted(VIEWS, views)
    embeddings = _one_hot((subjects + view_index) % 12, 12)
    report = cross_view_rank1(embeddings, subjects, conditions, sequences, views)
    for condition in ("nm", "bg", "cl"):
        entry = report["conditions"][condition]
        assert np.array_equal(np.array(entry["matrix"]), np.eye(11))
        assert entry["mean"] == 0.0
        assert entry["mean_including_identical"] == pytest.approx(1 / 11)
        assert entry["missing_cells"] == []
    assert report["conditions"]["nm"]["num_probes"] == 12 * 11 * 2
    assert report["num_gallery"] == 12 * 11 * 4


def test_cross_view_matches_count():
    # a shared view offset in other dimensions does not hide the subject: every cell is right
    subjects, conditions, sequences, views = _casia_layout(3)
    embeddings = np.hstack([_one_hot(subjects - 1, 3), _one_hot(np.searchsorted(VIEWS, views), 11, 5.0)])
    report = cross_view_rank1(embeddings, subjects, conditions, sequences, views)
    assert all(report["conditions"][c]["mean"] == 1.0 for c in ("nm", "bg", "cl"))
    table = cross_view_markdown(report, "t")
    assert "| NM | " + " | ".join(["100.00"] * 11) + " | 100.00 | 100.00 | 0/121 |" in table


def test_de_diag_divides_off_diagonal_by_ten():
    subjects, conditions, sequences, views = _casia_layout(5)
    embeddings = np.random.default_rng(0).normal(size=(len(subjects), 4)) + _one_hot(subjects - 1, 5)[:, :4]
    report = cross_view_rank1(embeddings, subjects, conditions, sequences, views)
    for condition in ("nm", "bg", "cl"):
        entry = report["conditions"][condition]
        matrix = np.array(entry["matrix"], dtype=float)
        expected = (matrix.sum(1) - np.diag(matrix)) / 10  # OpenGait de_diag
        assert [entry["per_probe_view"][str(v)] for v in VIEWS] == pytest.approx(expected.tolist())
        assert entry["mean"] == pytest.approx(expected.mean())
        assert entry["mean_including_identical"] == pytest.approx(matrix.mean())
    # one cell by brute force: bg probes at 36°, gallery at 144°
    probe = (conditions == 1) & (views == 36)
    gallery = (conditions == 0) & (sequences <= 4) & (views == 144)
    distance = ((embeddings[probe][:, None] - embeddings[gallery][None]) ** 2).sum(-1)
    right = (subjects[gallery][distance.argmin(1)] == subjects[probe]).mean()
    assert report["conditions"]["bg"]["matrix"][2][8] == pytest.approx(right)


def _two_subject_probe(probe_embedding):
    """Gallery nm-01 of subjects 1, 2 at 0°; one probe nm-05 of subject 1 at 18° (cycles = rows)."""
    probe_embedding = np.atleast_2d(probe_embedding)
    k = len(probe_embedding)
    return (
        np.vstack([[10.0, 0.0], [0.9, 0.5], probe_embedding]),
        np.array([1, 2] + [1] * k),
        np.zeros(2 + k, int),
        np.array([1, 1] + [5] * k),
        np.array([0, 0] + [18] * k),
    )


def test_euclidean_and_cosine_differ_and_missing_views_are_reported():
    embeddings, subjects, conditions, sequences, views = _two_subject_probe([1.0, 0.0])
    euc = cross_view_rank1(embeddings, subjects, conditions, sequences, views, metric="euc")
    cos = cross_view_rank1(embeddings, subjects, conditions, sequences, views, metric="cos")
    assert euc["conditions"]["nm"]["matrix"][1][0] == 0.0  # nearer in distance to subject 2
    assert cos["conditions"]["nm"]["matrix"][1][0] == 1.0  # same direction as subject 1
    assert euc["conditions"]["nm"]["mean"] == 0.0 and cos["conditions"]["nm"]["mean"] == 1.0
    assert cos["conditions"]["nm"]["per_probe_view"]["0"] is None
    missing = cos["conditions"]["nm"]["missing_cells"]
    assert len(missing) == 120 and [18, 0] not in missing and [0, 18] in missing
    assert cos["conditions"]["bg"]["mean"] is None and cos["conditions"]["bg"]["num_probes"] == 0
    assert "| BG | " + " | ".join(["–"] * 11) + " | – | – | 121/121 |" in cross_view_markdown(cos)
    with pytest.raises(ValueError, match="metric"):
        cross_view_rank1(embeddings, subjects, conditions, sequences, views, metric="l1")


def test_sequence_aggregation_averages_cycles():
    gallery = np.array([[0.0, 0.0], [4.0, 0.0]])
    probe_cycles = np.array([[3.0, 0.0], [-2.0, 0.0]])  # nearest: subject 2, subject 1; their mean: subject 1
    embeddings = np.vstack([gallery, probe_cycles])
    subjects, conditions = np.array([1, 2, 1, 1]), np.zeros(4, int)
    sequences, views = np.array([1, 1, 5, 5]), np.array([0, 0, 18, 18])
    per_gei = cross_view_rank1(embeddings, subjects, conditions, sequences, views, aggregate="gei")
    per_sequence = cross_view_rank1(embeddings, subjects, conditions, sequences, views)
    assert per_gei["conditions"]["nm"]["matrix"][1][0] == 0.5 and per_gei["conditions"]["nm"]["num_probes"] == 2
    assert per_sequence["aggregate"] == "sequence"
    assert per_sequence["conditions"]["nm"]["matrix"][1][0] == 1.0
    assert per_sequence["conditions"]["nm"]["num_probes"] == 1


def test_cross_view_rejects_view_labels_and_bad_shapes():
    embeddings, subjects, conditions, sequences, views = _two_subject_probe([1.0, 0.0])
    with pytest.raises(ValueError, match="views must be in degrees"):
        cross_view_rank1(embeddings, subjects, conditions, sequences, np.array([0, 0, 1]))
    with pytest.raises(ValueError, match="subject_ids must have shape"):
        cross_view_rank1(embeddings, subjects[:2], conditions, sequences, views)
    with pytest.raises(ValueError, match="NaN"):
        cross_view_rank1(np.full_like(embeddings, np.nan), subjects, conditions, sequences, views)


def test_per_view_plots(tmp_path):
    series = {"multi-task": {"0": 0.9, "90": 0.8}, "PCA+LDA": {str(v): 0.5 for v in VIEWS}}
    path = plot_per_view(series, tmp_path / "one.png", "closed set")
    assert path.stat().st_size > 1000
    both = plot_per_view_panels(
        {"closed set": series, "cross subject NM": {"x": {18: None, 36: 0.2}}}, tmp_path / "two.png"
    )
    assert both.stat().st_size > path.stat().st_size / 2
    with pytest.raises(ValueError, match="empty"):
        plot_per_view_panels({}, tmp_path / "none.png")
