"""Search inside long takes: subsequence DTW over every frame, and ``mocapkit search --within``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli import main as cli
from mocapkit.retrieval import RetrievalIndexError, build_index
from mocapkit.retrieval.subsequence import (
    search_within,
    segment_iou,
    subsequence_candidates,
    subsequence_profile,
)
from tests.shared_data import synthetic_hdm05_folder


def _shape(frames: int) -> np.ndarray:
    """A 3-d curve over one cycle, ``[frames, 3]``: the pattern planted in the takes."""
    t = np.linspace(0, 2 * np.pi, frames)
    return np.stack([np.sin(t), np.cos(2 * t), t / 6], axis=1)


def _walk(frames: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=0.3, size=(frames, 3)).cumsum(axis=0) * 0.05


def test_segment_iou():
    assert segment_iou((0, 10), (5, 15)) == pytest.approx(5 / 15)
    assert segment_iou((0, 10), (10, 20)) == 0.0
    assert segment_iou((3, 3), (3, 3)) == 0.0  # empty intervals overlap nothing


def test_subsequence_profile_is_dtaidistance_open_ended_dtw(monkeypatch):
    """Every end frame's cost equals dtaidistance's subsequence DTW (psi relaxation on the series' both ends), and
    its start is where that cheapest path begins; blocks of columns give the same profile as one block."""
    from dtaidistance import dtw_ndim

    rng = np.random.default_rng(0)
    query, series = rng.normal(size=(17, 3)), rng.normal(size=(90, 3))
    cost, start = subsequence_profile(query, series)
    _, paths = dtw_ndim.warping_paths_fast(query, series, psi=(0, 0, 90, 90), compact=False, psi_neg=False)
    np.testing.assert_allclose(cost, paths[17, 1:] ** 2, rtol=1e-9)
    for end in (20, 55, 89):  # the path's start: a brute-force minimum over the segments ending at `end`
        segments = [dtw_ndim.distance(query, series[s : end + 1]) ** 2 for s in range(end + 1)]
        assert cost[end] == pytest.approx(min(segments), rel=1e-9)
        assert segments[start[end]] == pytest.approx(cost[end], rel=1e-9)
    monkeypatch.setattr("mocapkit.retrieval.subsequence.BLOCK", 7)
    blocked = subsequence_profile(query, series)
    np.testing.assert_allclose(blocked[0], cost, rtol=1e-9)
    assert np.array_equal(blocked[1], start)


def test_subsequence_dtw_finds_a_time_warped_copy():
    take = _walk(400, 0)
    take[150:240] = _shape(90)  # the 60-frame query, played 1.5 times slower
    start, end, distance = min(subsequence_candidates(_shape(60), take, 30, 120, 15), key=lambda c: c[2])
    assert abs(start - 150) <= 2 and abs(end - 240) <= 2 and distance < 0.05
    # the length limits hold: no candidate segment is longer than max_length
    assert all(30 <= e - s <= 70 for s, e, _ in subsequence_candidates(_shape(60), take, 30, 70, 15))


def test_search_within_ranks_planted_copies_over_takes(monkeypatch):
    takes = [_walk(3000, 1), _walk(2000, 2), _walk(2500, 3)]
    truth = [(0, 700, 760), (2, 1900, 1980), (1, 100, 150)]  # same speed, slower, faster
    for t, s, e in truth:
        takes[t][s:e] = _shape(e - s)
    matches = search_within(_shape(60), takes, k=3)
    assert len(matches) == 3
    assert [m.distance for m in matches] == sorted(m.distance for m in matches)
    hits = {
        (t, s, e) for t, s, e in truth for m in matches if m.take == t and segment_iou((m.start, m.end), (s, e)) >= 0.5
    }
    assert hits == set(truth)
    monkeypatch.setattr("mocapkit.retrieval.subsequence.PROGRESS_FRAMES", 0)  # the progress bar's path (a terminal's)
    assert search_within(_shape(60), takes, k=3) == matches
    with pytest.raises(ValueError, match="the query has 3 features per frame, the takes \\[4\\]"):
        search_within(_shape(60), [np.zeros((100, 4))])
    broken = [take.copy() for take in takes]
    broken[2][50] = np.nan
    with pytest.raises(ValueError, match="take\\(s\\) \\[2\\] hold NaN"):
        search_within(_shape(60), broken)
    with pytest.raises(ValueError, match="the query's features hold NaN"):
        search_within(np.full((60, 3), np.nan), takes)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return synthetic_hdm05_folder(
        tmp_path_factory, ("hopBothLegs1hops", "squat1Reps"), clips_per_actor=2, max_frames=240
    )


def test_search_within_cli(folder, tmp_path, capsys):
    out = tmp_path / "index"
    assert cli(["index", str(folder / "bd"), "--out", str(out), "--method", "dtw_takes"]) == 0
    query = min((folder / "mm").glob("*squat1Reps*.amc"))
    capsys.readouterr()
    assert cli(["search", "--index", str(out), str(query), "--within", "-k", "2", "--json"]) == 0
    results = json.loads(capsys.readouterr().out)
    hits = results[0]["results"]
    assert results[0]["query"] == str(query) and 1 <= len(hits) <= 2
    manifest = json.loads((out / "manifest.json").read_text())
    duration = {f["path"]: f["frames"] / f["fps"] for f in manifest["files"]}
    for hit in hits:
        assert 0.0 <= hit["start"] < hit["end"] <= duration[hit["path"]] + 1e-6
    assert "squat1Reps" in Path(hits[0]["path"]).name
    assert [h["distance"] for h in hits] == sorted(h["distance"] for h in hits)
    # an indexed query's own file is not searched
    own = min((folder / "bd").glob("*squat1Reps*.amc"))
    assert cli(["search", "--index", str(out), str(own), "--within", "-k", "0", "--json"]) == 0
    assert all(h["path"] != str(own.resolve()) for h in json.loads(capsys.readouterr().out)[0]["results"])
    # plain text: file, seconds
    assert cli(["search", "--index", str(out), str(query), "--within", "-k", "1"]) == 0
    assert " s - " in capsys.readouterr().out


def test_search_within_needs_a_dtw_index(folder, tmp_path):
    index = build_index(
        folder / "bd", tmp_path / "hod", method="hod", overrides=["n_words=8", "n_features=20"], quiet=True
    )
    with pytest.raises(RetrievalIndexError, match="--within needs an index of a DTW method.*built with hod"):
        index.search_within([str(min((folder / "mm").glob("*.amc")))])
