"""``bench/bench_retrieval.py --fresh-query``: a fitted method is saved as an index (its frame files left where a
streamed build put them) and a new process loads it and times its queries (that a loaded index ranks as the method
it was saved from: tests/retrieval/test_index_add.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from mocapkit.datasets import read_motion
from mocapkit.train.registry import build_method
from tests.scripts import load_script
from tests.shared_data import synthetic_hdm05_folder


@pytest.fixture(scope="module")
def motions(tmp_path_factory):
    folder = synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", "squat1Reps"), clips_per_actor=2, max_frames=120
    )
    return [read_motion(p) for p in sorted(Path(folder).glob("*/*.amc"))]


def test_recall_over_real_clips_counts_each_real_clip_behind_the_exact_top_k_once():
    """``source_recall``: the share of the distinct real clips behind the exact top k that the found top k returns
    a copy of, whichever copies."""
    import numpy as np

    bench = load_script("bench/bench_retrieval.py")
    sources = np.array(["a", "a", "a", "b", "b", "c"])
    exact = np.array([[0, 1, 3], [3, 4, 5]])  # real clips {a, b} and {b, c}
    found = np.array([[2, 0, 5], [0, 1, 2]])  # {a, c}: a found; {a}: neither
    assert bench.source_recall(found, exact, sources) == pytest.approx((1 / 2 + 0) / 2)
    assert bench.source_recall(exact, exact, sources) == 1.0


def test_a_new_process_loads_the_saved_index_and_times_its_queries(motions, tmp_path):
    bench = load_script("bench/bench_retrieval.py")
    method = build_method("retrieval", "dtw_large", ["prefilter=3", "n_reference=4"]).fit(motions[:6])
    method.store_frames(tmp_path / "index")  # as a streamed build leaves them: the index keeps these files
    # cold: the new process drops the frame files from the page cache before each query of its first pass
    report = bench.fresh_query(method, "dtw_large:prefilter=3", motions[6:], str(tmp_path / "index"), cold=True)
    assert (tmp_path / "index" / "manifest.json").is_file()
    for key in ("first_p50_ms", "second_p95_ms", "load_s"):
        assert report[key] > 0
    assert 0 < report["private_after_load_mb"] <= report["private_mb"] <= report["peak_mb"]
