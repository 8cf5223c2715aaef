"""DTW's prefiltered search (``prefilter=K``): a FAISS prefilter on fixed-length descriptors, then the method's own
distance on the ``K`` clips it returns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets import read_motion
from mocapkit.retrieval import MotionIndex, build_index, search_index
from mocapkit.retrieval.base import top_k
from mocapkit.retrieval.dtw import DTWRetrieval
from tests.shared_data import synthetic_hdm05_folder


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> tuple[Path, list]:
    """3 classes × 2 actors × 3 takes, HDM05 layout; the folder and its 18 motions."""
    folder = synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", "hopBothLegs1hops", "squat1Reps"), clips_per_actor=3, max_frames=160
    )
    return folder, [read_motion(p) for p in sorted(folder.glob("*/*.amc"))]


@pytest.mark.parametrize("hubness", [None, "mutual_proximity"])
def test_a_prefilter_as_large_as_the_library_is_exact_search(clips, hubness):
    _, motions = clips
    exact = DTWRetrieval(features=["positions", "relational"], hubness=hubness).fit(motions[:12])
    wide = DTWRetrieval(features=["positions", "relational"], hubness=hubness, prefilter=12).fit(motions[:12])
    a, b = exact.search(motions[12:], 5), wide.search(motions[12:], 5)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_allclose(a[1], b[1])


def test_prefiltered_search_ranks_its_candidates_by_exact_dtw(clips):
    """Without mutual proximity the distances returned are the exact ones of the clips returned, in order; every
    database clip finds itself first; the prefilter returns the clips its descriptors put nearest."""
    _, motions = clips
    method = DTWRetrieval(features=["positions", "relational"], prefilter=4).fit(motions)
    found, d = method.search(motions, 3)
    exact = method.distances(motions)
    # the frame costs come from matrix products summed in another order: a clip's distance to itself is rounding
    np.testing.assert_allclose(d, np.take_along_axis(exact, found, axis=1), rtol=1e-6, atol=1e-6)
    assert (found[:, 0] == np.arange(len(motions))).all()
    assert (np.diff(d, axis=1) >= 0).all()
    descriptors = method._project(method._descriptors(method.encode(motions[:1])))
    nearest = top_k(((method._project(method._descriptors(method.database_)) - descriptors) ** 2).sum(1)[None], 4)[0]
    assert set(found[0]) <= set(nearest[0])


def test_mutual_proximity_on_candidates_keeps_most_of_the_exact_top_five(clips):
    _, motions = clips
    method = DTWRetrieval(features=["positions", "relational"], hubness="mutual_proximity", prefilter=8)
    method.fit(motions[:14])
    exact = top_k(method.distances(motions[14:]), 5)[0]
    found = method.search(motions[14:], 5)[0]
    assert np.mean([len(set(a) & set(b)) / 5 for a, b in zip(exact, found)]) >= 0.8


def test_an_index_keeps_its_prefilter_and_adds_to_it(clips, tmp_path):
    folder, motions = clips
    out = tmp_path / "idx"
    index = build_index(folder / "bd", out, method="dtw_world_frame", overrides=["prefilter=3"], quiet=True)
    query = str(min((folder / "mm").glob("*squat*.amc")))
    before = index.search([query], k=3)
    after = search_index(out, [query], k=3)
    assert [r["path"] for r in before[0]["results"]] == [r["path"] for r in after[0]["results"]]
    loaded = MotionIndex.load(out)
    assert loaded.method.prefilter == 3 and loaded.method.prefilter_kind_ == "flat"
    loaded.method.add([read_motion(query)])  # the added clip is in the prefilter's index: it finds itself
    assert loaded.method.search([read_motion(query)], 1)[0][0, 0] == loaded.method.n_database_ - 1
    with pytest.raises(ValueError, match="prefilter must be None or a positive number"):
        DTWRetrieval(prefilter=0).fit(motions[:4])


def test_a_c3d_file_is_written_after_a_faiss_index_was_built(tmp_path):
    """faiss and ezc3d are both SWIG builds; faiss loaded first broke ezc3d's writer (TypeError in Parameter_set).
    In a fresh process: build a FAISS index through mocapkit, then write a C3D file."""
    import subprocess
    import sys

    code = (
        "import numpy as np\n"
        "from mocapkit.retrieval import ann\n"
        "ann.build(np.eye(4, dtype=np.float32), 'flat', metric='l2')\n"
        "from mocapkit.motion.container import Motion\n"
        "from mocapkit.datasets import write_motion, read_motion\n"
        "m = Motion(np.random.default_rng(0).normal(size=(10, 3, 3)), ['A', 'B', 'C'], 100.0, name='m')\n"
        f"write_motion({str(tmp_path / 'm.c3d')!r}, m)\n"
        f"assert read_motion({str(tmp_path / 'm.c3d')!r}).num_frames == 10\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    # faiss imported directly, first: the writer names the file and the cure instead of ezc3d's overload list
    direct = code.replace("from mocapkit.retrieval import ann\n", "import faiss\nfrom mocapkit.retrieval import ann\n")
    result = subprocess.run([sys.executable, "-c", direct], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "m.c3d: ezc3d could not write the file" in result.stderr
    assert "import ezc3d first" in result.stderr


@pytest.mark.parametrize("hubness", [None, "mutual_proximity"])
def test_lower_bound_pruning_ranks_candidates_as_computing_every_distance(clips, hubness, monkeypatch):
    """DTW on the candidates in their lower bounds' order, stopping when the next bound passes the k-th distance
    found, returns the ranking that DTW on every candidate gives (exact search's, without mutual proximity), having
    computed fewer distances."""
    import mocapkit.retrieval.dtw as dtw_module
    from mocapkit.retrieval.frames import CandidateCosts

    _, motions = clips
    method = DTWRetrieval(features=["positions", "relational"], hubness=hubness, n_reference=6, prefilter=4)
    method.fit(motions[:14])  # 6 reference clips of 14: the query's statistics are a sample of its distances
    encoded = method.encode(motions[14:15])
    query = {name: encoded[name][0] for name in method.features_}
    everything = np.arange(14)
    monkeypatch.setattr(dtw_module, "PRUNE_BATCH", 100)
    full = method._rank_candidates(query, everything, 5)
    computed = []
    distances = CandidateCosts.distances

    def counted(self, which=None):  # the candidates' DTW (not the query's, to mutual proximity's reference clips)
        computed.append(0 if which is None else len(which))
        return distances(self, which)

    monkeypatch.setattr(CandidateCosts, "distances", counted)
    monkeypatch.setattr(dtw_module, "PRUNE_BATCH", 1)
    pruned = method._rank_candidates(query, everything, 5)
    np.testing.assert_array_equal(pruned[0], full[0])
    np.testing.assert_allclose(pruned[1], full[1])
    assert 5 <= sum(computed) / len(method.features_) < 14
    # mutual proximity takes the query's statistics from the reference clips in exact search too: the same ranking
    exact = top_k(method.distances(motions[14:15]), 5)
    np.testing.assert_array_equal(pruned[0], exact[0][0])
    np.testing.assert_allclose(pruned[1], exact[1][0], rtol=1e-6, atol=1e-6)


def test_a_library_grown_past_the_hnsw_size_by_additions_is_searched_by_hnsw(clips, monkeypatch):
    """Added clips join the prefilter's FAISS index without a rebuild once the scales are fixed (past
    ``n_reference`` clips with mutual proximity); when the library grows past ``AUTO_HNSW_MIN_CLIPS`` the flat index
    becomes HNSW over every clip. While the scales still follow the clips, every descriptor is indexed again."""
    from mocapkit.retrieval import ann

    _, motions = clips
    monkeypatch.setattr(ann, "AUTO_HNSW_MIN_CLIPS", 10)
    params = {"features": ["positions", "relational"], "hubness": "mutual_proximity", "n_reference": 4}
    grown = DTWRetrieval(**params, prefilter=4).fit(motions[:6])
    index = grown.prefilter_index_
    assert grown.prefilter_kind_ == "flat"
    grown.add(motions[6:9])
    assert grown.prefilter_index_ is index and grown.prefilter_index_.ntotal == 9  # the same index, grown
    grown.add(motions[9:])
    assert grown.prefilter_kind_ == "hnsw" and grown.prefilter_index_.ntotal == 18
    whole = DTWRetrieval(**params, prefilter=4).fit(motions[:6])
    whole.add(motions[6:])  # one addition past the size: the same vectors, in the same order
    np.testing.assert_allclose(
        grown.prefilter_index_.reconstruct_n(0, 18), whole.prefilter_index_.reconstruct_n(0, 18), rtol=1e-6, atol=1e-6
    )
    found = grown.search(motions, 1)[0]
    assert (found[:, 0] == np.arange(len(motions))).all()  # every clip, old or added, finds itself
    # frame scales without mutual proximity follow the union: the index holds every clip's descriptor at today's
    small = DTWRetrieval(features=["positions", "relational"], prefilter=4).fit(motions[:6])
    small.add(motions[6:9])
    assert not np.array_equal(
        small.scales_, DTWRetrieval(features=["positions", "relational"]).fit(motions[:6]).scales_
    )
    np.testing.assert_allclose(
        small.prefilter_index_.reconstruct_n(0, 9),
        small._project(small._descriptors(small.database_)),
        rtol=1e-5,
        atol=1e-6,
    )
