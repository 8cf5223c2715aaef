"""The bag-of-clip-words pipeline (mocapkit.classical.bag_of_words) and the MSR Action3D NMF benchmark script."""
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from sklearn.cluster import KMeans
from sklearn.decomposition import NMF as SklearnNMF

from mocapkit.classical import NMF
from mocapkit.classical.bag_of_words import (
    BagOfWordsClassifier,
    ClipConditioner,
    assign_codes,
    assign_words,
    code_histograms,
    fit_words,
    word_histograms,
)
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


def test_code_histograms_average_l1_normalised_codes():
    codes = np.array([[1.0, 3.0, 0.0], [0.0, 0.0, 2.0], [5.0, 5.0, 0.0], [0.0, 0.0, 0.0]])
    hist = code_histograms(codes, [0, 0, 2, 2], n_sequences=3)
    np.testing.assert_allclose(hist, [[0.125, 0.375, 0.5], [0, 0, 0], [0.5, 0.5, 0]])   # zero code row: no word
    with pytest.raises(ValueError, match="non-negative"):
        code_histograms(-codes, [0, 0, 2, 2], 3)
    with pytest.raises(ValueError, match=r"sequence_of_clip must lie in \[0, 2\)"):
        code_histograms(codes, [0, 0, 2, 2], 2)


def test_clip_conditioner_centres_the_signed_clips_and_sign_splits_again():
    rng = np.random.default_rng(0)
    signed = rng.normal(1.0, 0.5, size=(50, 6))                              # a shared offset ("mean pose")
    X = np.concatenate([np.maximum(signed, 0), np.maximum(-signed, 0)], 1)
    conditioner = ClipConditioner().fit(X[:40])
    np.testing.assert_allclose(conditioner.mean_, signed[:40].mean(0))
    out = conditioner.transform(X)
    assert out.shape == X.shape and out.min() >= 0
    np.testing.assert_allclose(out[:, :6] - out[:, 6:], signed - signed[:40].mean(0), atol=1e-12)
    np.testing.assert_allclose((out[:40, :6] - out[:40, 6:]).mean(0), 0, atol=1e-12)
    assert (np.minimum(out[:, :6], out[:, 6:]) == 0).all()                      # one side of each sign is zero
    np.testing.assert_allclose(ClipConditioner(centre=False).fit(X).transform(X), X)
    unit = ClipConditioner(unit_norm=True).fit(X).transform(X)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=1), 1.0)
    with pytest.raises(ValueError, match="even number of columns"):
        ClipConditioner().fit(X[:, :5])
    with pytest.raises(ValueError, match="non-negative"):
        ClipConditioner().fit(-X)
    with pytest.raises(ValueError, match="fitted with 12"):
        conditioner.transform(X[:, :10])
    with pytest.raises(RuntimeError, match="not fitted"):
        ClipConditioner().transform(X)


def test_centring_spreads_nmf_words_that_a_shared_pose_collapses():
    """A large shared offset makes one component win every arg-max; centring removes it."""
    rng = np.random.default_rng(1)
    directions = np.eye(8)[:4] * 0.4
    signed = 3.0 + directions[rng.integers(4, size=120)] + rng.normal(0, 0.02, size=(120, 8))
    X = np.concatenate([np.maximum(signed, 0), np.maximum(-signed, 0)], 1)
    raw_words = NMF(4, init="nndsvda", max_iter=300, random_state=0).fit(X).labels_
    centred = ClipConditioner().fit_transform(X)
    centred_words = NMF(4, init="nndsvda", max_iter=300, random_state=0).fit(centred).labels_
    assert len(np.unique(centred_words)) == 4
    assert np.bincount(raw_words).max() > np.bincount(centred_words).max()


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


def test_soft_prefit_model_reuses_the_fitted_clusterer_and_conditioner():
    X, owner, y = _clip_data(0)
    X_test, owner_test, y_test = _clip_data(1)
    hard = BagOfWordsClassifier(NMF(6, init="nndsvda", max_iter=300, random_state=0),
                                conditioner=ClipConditioner(centre=False)).fit(X, owner, y)
    soft = BagOfWordsClassifier(hard.clusterer_, assignment="soft", conditioner=hard.conditioner_,
                                prefit=True).fit(X, owner, y)
    assert soft.clusterer_ is hard.clusterer_ and soft.conditioner_ is hard.conditioner_
    codes = assign_codes(hard.clusterer_, hard.conditioner_.transform(X_test))
    np.testing.assert_allclose(soft.histograms(X_test, owner_test, len(y_test)),
                               code_histograms(codes, owner_test, len(y_test)))
    assert soft.score(X_test, owner_test, y_test) == 1.0
    with pytest.raises(ValueError, match="assignment must be one of"):
        BagOfWordsClassifier(hard.clusterer_, assignment="fuzzy")


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
    results = script.run_benchmark(MSR_ROOT, tmp_path, seeds=(0, 1), quick=True, select=True)
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["config"]["quick"] and saved["config"]["seeds"] == [0]         # --quick keeps one seed
    for protocol in script.PROTOCOLS:                                            # selection: CV on training only
        chosen = saved["selection"][f"window30_{protocol}"]["methods"]
        assert set(chosen) == set(script.METHODS) - {"layer"}
        for entry in chosen.values():
            assert entry["params"]["k"] in (3, 5) and len(entry["cv"]) >= 2
            assert entry["cv_accuracy"] == max(t["cv_accuracy"] for t in entry["cv"])
    assert saved["machine"]["cpu_count"] >= 1 and saved["total_time_s"] > 0
    methods = set(script.METHODS)
    for protocol in script.PROTOCOLS:
        runs = [r for r in saved["runs"] if r["protocol"] == protocol]
        assert {r["method"] for r in runs} == methods
        assert {r["method"] for r in runs if r["variant"] == "soft"} == methods - {"kmeans", "layer"}
        for r in runs:
            for key in ("accuracy", "acc", "nmi", "ari", "time_s"):
                assert math.isfinite(r[key]), (r["method"], key)
            assert 0.0 <= r["accuracy"] <= 1.0 and 0.0 <= r["acc"] <= 1.0 and r["n_test"] > 0
    assert len(results["summary"]) == (2 * len(methods) - 2) * len(script.PROTOCOLS)
    table = (tmp_path / "results.md").read_text()
    assert "93.33%" in table and "arithmetic" in table and "| 30 | layer | cross_subject |" in table
    assert "| 30 | nmc + soft | random_half |" in table
    assert (tmp_path / "accuracy.png").stat().st_size > 1000


def test_benchmark_rejects_unknown_methods(tmp_path):
    script = _load_script()
    with pytest.raises(ValueError, match="unknown methods"):
        script.run_benchmark(MSR_ROOT, tmp_path, methods=("kmeans", "pca"))
