"""scripts/results/retrieval_self_supervised.py: its runs hold out exactly the query groups of the folds of
``mocapkit compare retrieval_*``, so its figures are the compare rows' (real Bandai listing; skipped without it)."""

from types import SimpleNamespace

import numpy as np
import pytest

from tests.scripts import ROOT, load_script

BANDAI = ROOT.parent / "shared" / "data" / "bandai_motion_1"


def test_hdm05_and_msr_folds_are_the_benchmark_protocols():
    script = load_script("scripts/results/retrieval_self_supervised.py")
    assert [held for _, held, _ in script.folds("hdm05")] == [["bd"], ["bk"], ["dg"], ["mm"]]
    ((_, held, data),) = script.folds("msr")
    assert held == ["2", "4", "6", "8", "10"] and "data.label=action" in data


@pytest.mark.skipif(not BANDAI.is_dir(), reason="no Bandai data in ../shared/data")
@pytest.mark.parametrize("label", ["content", "style"])
def test_bandai_folds_hold_out_the_compare_folds_query_groups(monkeypatch, label):
    from mocapkit.datasets.mocap.folders import list_clips
    from mocapkit.retrieval.benchmark import RetrievalBenchmark

    clips = list_clips("bandai", BANDAI)
    fields = {"content": np.array([c["class"] for c in clips]), "style": np.array([c["group"] for c in clips])}
    # the clips' listing only: folds read the fields, never the motions
    no_motions = [SimpleNamespace(name=str(c["path"])) for c in clips]
    monkeypatch.setattr(RetrievalBenchmark, "_read", lambda self: (no_motions, fields))
    benchmark = RetrievalBenchmark("bandai", str(BANDAI), [label], n_folds=3)
    group = "style" if label == "content" else "content"  # what a fold holds out
    expected = [sorted(set(fields[group][queries].tolist())) for _, queries in benchmark.folds(label).values()]
    script = load_script("scripts/results/retrieval_self_supervised.py")
    monkeypatch.setitem(script.ROOTS, "bandai", str(BANDAI))
    found = script.folds(f"bandai_{label}")
    assert [sorted(held) for _, held, _ in found] == expected
    assert all(f"data.label={label}" in data for _, _, data in found)
