"""The bag-of-clip-words pipeline (mocapkit.classical.bag_of_words) and the MSR Action3D NMF benchmark script."""
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from sklearn.cluster import KMeans
from sklearn.decomposition import NMF as SklearnNMF

from mocapkit.classical.bag_of_words import BagOfWordsClassifier, assign_words, fit_words, word_histograms
from tests.shared_data import SHARED, needs

MSR_ROOT = SHARED / "data" / "msr_action3d"
SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "msr3d_nmf_benchmark.py"


def _load_script():
    spec = importlib.util.spec_from_file_location("msr3d_nmf_benchmark", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_word_histograms_are_l1_normalised_per_sequence():
    hist = word_histograms([0, 2, 2, 1, 1], [0, 0, 0, 2, 2], n_sequences=3, n_words=3)
    np.testing.assert_allclose(hist, [[1 / 3, 0, 2 / 3], [0, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match=r"words must lie in \[0, 3\)"):
        word_histograms([3], [0], 1, 3)


def _clip_data(seed: int, sequences_per_class: int = 8, classes: int = 3, clips: int = 4):
    """Each class draws its clips from its own two of six non-negative prototypes."""
    rng = np.random.default_rng(seed)
    prototypes = np.random.default_rng(99).uniform(0, 1, size=(6, 12)) ** 4 * 3
    X, owner, y = [], [], []
    for c in range(classes):
        for _ in range(sequences_per_class):
            s = len(y)
            y.append(c)
            for _ in range(clips):
                X.append(prototypes[2 * c + rng.integers(2)] + rng.uniform(0, 0.05, 12))
                owner.append(s)
    return np.array(X), np.array(owner), np.array(y)


@pytest.mark.parametrize("clusterer", [KMeans(6, n_init=4, random_state=0),
                                       SklearnNMF(6, init="nndsvda", max_iter=500, random_state=0)])
def test_bag_of_words_classifier_recognises_separable_sequences(clusterer):
    X, owner, y = _clip_data(0)
    X_test, owner_test, y_test = _clip_data(1)
    model = BagOfWordsClassifier(clusterer).fit(X, owner, y)
    assert model.n_words_ == 6 and len(model.train_words_) == len(X)
    assert model.best_C_ in model.Cs
    assert model.score(X_test, owner_test, y_test) == 1.0
    hist = model.histograms(X_test, owner_test, len(y_test))
    np.testing.assert_allclose(hist.sum(1), 1.0)


def test_words_of_kmeans_and_nmf_follow_their_conventions():
    X, _, _ = _clip_data(0)
    km = KMeans(6, n_init=2, random_state=0)
    np.testing.assert_array_equal(fit_words(km, X), km.labels_)
    np.testing.assert_array_equal(assign_words(km, X[:5]), km.predict(X[:5]))
    nmf = SklearnNMF(6, init="nndsvda", max_iter=300, random_state=0)
    words = fit_words(nmf, X)
    np.testing.assert_array_equal(assign_words(nmf, X[:5]), nmf.transform(X[:5]).argmax(1))
    assert words.shape == (len(X),) and words.max() < 6


@pytest.mark.slow
@needs(MSR_ROOT)
def test_quick_benchmark_on_real_msr_subset_writes_all_methods(tmp_path):
    script = _load_script()
    results = script.run_benchmark(MSR_ROOT, tmp_path, seeds=(0, 1), quick=True)
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["config"]["quick"] and saved["config"]["seeds"] == [0]         # --quick keeps one seed
    assert saved["machine"]["cpu_count"] >= 1 and saved["total_time_s"] > 0
    methods = set(script.METHODS)
    for protocol in script.PROTOCOLS:
        runs = [r for r in saved["runs"] if r["protocol"] == protocol]
        assert {r["method"] for r in runs} == methods
        for r in runs:
            for key in ("accuracy", "acc", "nmi", "ari", "time_s"):
                assert math.isfinite(r[key]), (r["method"], key)
            assert 0.0 <= r["accuracy"] <= 1.0 and 0.0 <= r["acc"] <= 1.0 and r["n_test"] > 0
    assert len(results["summary"]) == len(methods) * len(script.PROTOCOLS)
    table = (tmp_path / "results.md").read_text()
    assert "93.33%" in table and "arithmetic" in table and "| layer | cross_subject |" in table
    assert (tmp_path / "accuracy.png").stat().st_size > 1000


def test_benchmark_rejects_unknown_methods(tmp_path):
    script = _load_script()
    with pytest.raises(ValueError, match="unknown methods"):
        script.run_benchmark(MSR_ROOT, tmp_path, methods=("kmeans", "pca"))
