"""The bag-of-clip-words pipeline (mocapkit.clustering.bag_of_words) as scikit-learn estimators, and the MSR Action3D
NMF benchmark (``configs/compare/msr3d_nmf.yaml`` through the comparison runner) on a small subset of the real data."""

import json
import math

import numpy as np
import pytest
from omegaconf import OmegaConf
from sklearn.base import clone
from sklearn.cluster import KMeans
from sklearn.decomposition import NMF as SklearnNMF
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline

from mocapkit.clustering.bag_of_words import (
    BagOfWordsClassifier,
    ClipConditioner,
    SequenceClips,
    assign_codes,
    assign_words,
    code_histograms,
    fit_words,
    word_histograms,
)
from mocapkit.clustering.nmf import NMF
from tests.shared_data import SHARED, needs

MSR_ROOT = SHARED / "data" / "msr_action3d"


def test_word_histograms_are_l1_normalised_per_sequence():
    hist = word_histograms([0, 2, 2, 1, 1], [0, 0, 0, 2, 2], n_sequences=3, n_words=3)
    np.testing.assert_allclose(hist, [[1 / 3, 0, 2 / 3], [0, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match=r"words must lie in \[0, 3\)"):
        word_histograms([3], [0], 1, 3)


def test_code_histograms_average_l1_normalised_codes():
    codes = np.array([[1.0, 3.0, 0.0], [0.0, 0.0, 2.0], [5.0, 5.0, 0.0], [0.0, 0.0, 0.0]])
    hist = code_histograms(codes, [0, 0, 2, 2], n_sequences=3)
    np.testing.assert_allclose(hist, [[0.125, 0.375, 0.5], [0, 0, 0], [0.5, 0.5, 0]])  # zero code row: no word
    with pytest.raises(ValueError, match="non-negative"):
        code_histograms(-codes, [0, 0, 2, 2], 3)
    with pytest.raises(ValueError, match=r"sequence_of_clip must lie in \[0, 2\)"):
        code_histograms(codes, [0, 0, 2, 2], 2)


def test_clip_conditioner_centres_the_signed_clips_and_sign_splits_again():
    rng = np.random.default_rng(0)
    signed = rng.normal(1.0, 0.5, size=(50, 6))  # a shared offset ("mean pose")
    X = np.concatenate([np.maximum(signed, 0), np.maximum(-signed, 0)], 1)
    conditioner = ClipConditioner().fit(X[:40])
    np.testing.assert_allclose(conditioner.mean_, signed[:40].mean(0))
    out = conditioner.transform(X)
    assert out.shape == X.shape and out.min() >= 0
    np.testing.assert_allclose(out[:, :6] - out[:, 6:], signed - signed[:40].mean(0), atol=1e-12)
    np.testing.assert_allclose((out[:40, :6] - out[:40, 6:]).mean(0), 0, atol=1e-12)
    assert (np.minimum(out[:, :6], out[:, 6:]) == 0).all()  # one side of each sign is zero
    np.testing.assert_allclose(ClipConditioner(centre=False).fit(X).transform(X), X)
    unit = ClipConditioner(unit_norm=True).fit(X).transform(X)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=1), 1.0)
    with pytest.raises(ValueError, match="even number of columns"):
        ClipConditioner().fit(X[:, :5])
    with pytest.raises(ValueError, match="must be non-negative"):
        ClipConditioner().fit(-X)
    with pytest.raises(ValueError, match="fitted with 12"):
        conditioner.transform(X[:, :10])
    with pytest.raises(NotFittedError):
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
    """Each class draws its clips from its own two of six non-negative prototypes: ``(X [n_clips, 12], owner, y)``."""
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


def _sequences(seed: int, **kwargs):
    """:func:`_clip_data` as the estimators take it: a list of per-sequence clip arrays and the labels."""
    X, owner, y = _clip_data(seed, **kwargs)
    return [X[owner == s] for s in range(len(y))], y


@pytest.mark.parametrize(
    "clusterer", [KMeans(6, n_init=4, random_state=0), SklearnNMF(6, init="nndsvda", max_iter=500, random_state=0)]
)
def test_bag_of_words_classifier_recognises_separable_sequences(clusterer):
    X, y = _sequences(0)
    X_test, y_test = _sequences(1)
    model = BagOfWordsClassifier(clusterer).fit(X, y)
    assert model.n_words_ == 6 and len(model.train_words_) == sum(len(x) for x in X)
    np.testing.assert_array_equal(model.train_clip_sequence_, np.repeat(np.arange(len(y)), 4))
    assert model.best_C_ in model.Cs and list(model.classes_) == [0, 1, 2]
    assert model.score(X_test, y_test) == 1.0  # ClassifierMixin.score: accuracy over sequences
    hist = model.histograms(X_test)
    assert hist.shape == (len(y_test), 6)
    np.testing.assert_allclose(hist.sum(1), 1.0)


def test_soft_prefit_model_reuses_the_fitted_clusterer_and_conditioner():
    X, y = _sequences(0)
    X_test, y_test = _sequences(1)
    hard = BagOfWordsClassifier(
        NMF(6, init="nndsvda", max_iter=300, random_state=0), conditioner=ClipConditioner(centre=False)
    ).fit(X, y)
    soft = BagOfWordsClassifier(hard.clusterer_, assignment="soft", conditioner=hard.conditioner_, prefit=True).fit(
        X, y
    )
    assert soft.clusterer_ is hard.clusterer_ and soft.conditioner_ is hard.conditioner_
    codes = assign_codes(hard.clusterer_, hard.conditioner_.transform(np.concatenate(X_test)))
    np.testing.assert_allclose(
        soft.histograms(X_test), code_histograms(codes, np.repeat(np.arange(len(y_test)), 4), len(y_test))
    )
    assert soft.score(X_test, y_test) == 1.0
    # a soft model fitted from scratch with the same seed reads the same clustering
    refit = BagOfWordsClassifier(
        NMF(6, init="nndsvda", max_iter=300, random_state=0),
        assignment="soft",
        conditioner=ClipConditioner(centre=False),
    ).fit(X, y)
    np.testing.assert_allclose(refit.histograms(X_test), soft.histograms(X_test))
    with pytest.raises(ValueError, match="assignment must be one of"):
        BagOfWordsClassifier(hard.clusterer_, assignment="fuzzy").fit(X, y)  # checked in fit, not __init__


def test_bag_of_words_classifier_follows_the_scikit_learn_contract():
    X, y = _sequences(0)
    model = BagOfWordsClassifier(KMeans(6, n_init=2, random_state=0), Cs=[1.0, 10.0], cv=2)
    params = model.get_params()
    assert params["Cs"] == [1.0, 10.0] and params["clusterer__n_clusters"] == 6  # stored untouched, nested
    twin = clone(model)
    assert twin.get_params()["clusterer"] is not model.clusterer
    assert twin.set_params(clusterer__n_clusters=4, assignment="soft").clusterer.n_clusters == 4
    assert model.clusterer.n_clusters == 6  # the clone is independent
    assert BagOfWordsClassifier(None, assignment="nope").assignment == "nope"  # no validation in __init__
    with pytest.raises(NotFittedError):
        model.predict(X)
    with pytest.raises(ValueError, match="Negative values"):
        BagOfWordsClassifier(KMeans(2)).fit([-x for x in X], y)
    with pytest.raises(ValueError, match="NaN"):
        BagOfWordsClassifier(KMeans(2)).fit([np.full_like(x, np.nan) for x in X], y)
    with pytest.raises(ValueError, match="24 sequences"):
        BagOfWordsClassifier(KMeans(2)).fit(X, y[:-1])
    with pytest.raises(ValueError, match=r"X\[1\] must be a \[n_clips, d\] array"):
        BagOfWordsClassifier(KMeans(2)).fit([X[0], X[1][:, :5]], y[:2])


def test_bag_of_words_in_a_pipeline_and_grid_search_over_sequences():
    """SequenceClips → BagOfWordsClassifier from skeleton sequences; GridSearchCV folds over sequences."""
    rng = np.random.default_rng(0)
    gestures = rng.normal(0, 0.3, size=(2, 20, 3))  # per class, a joint displacement pattern
    sequences, labels = [], []
    for c in range(2):
        for _ in range(8):
            t = np.linspace(0, 2 * np.pi, int(rng.integers(24, 40)))[:, None, None]
            base = np.zeros((len(t), 20, 3), np.float32)
            base[:, :, 1] = np.linspace(0, 1.6, 20)  # a standing body: joints up the y axis
            sequences.append((base + np.sin(t) * gestures[c] + rng.normal(0, 0.01, base.shape)).astype(np.float32))
            labels.append(c)
    labels = np.array(labels)
    pipe = Pipeline(
        [
            ("clips", SequenceClips(window=10, layout="msr20")),
            ("bow", BagOfWordsClassifier(KMeans(4, n_init=2, random_state=0), cv=2)),
        ]
    )
    clips = clone(pipe[0]).fit(sequences).transform(sequences[:2])
    assert [c.shape for c in clips] == [((len(s) - 10) // 5 + 1, 1200) for s in sequences[:2]]
    pipe.fit(sequences, labels)
    assert pipe.score(sequences, labels) >= 0.9
    search = GridSearchCV(pipe, {"bow__clusterer__n_clusters": [2, 4]}, cv=2).fit(sequences, labels)
    assert search.best_params_["bow__clusterer__n_clusters"] in (2, 4)
    assert search.best_estimator_[-1].n_words_ == search.best_params_["bow__clusterer__n_clusters"]
    assert len(search.cv_results_["mean_test_score"]) == 2
    with pytest.raises(NotFittedError):
        SequenceClips().transform(sequences)
    with pytest.raises(ValueError, match="sequence 0: expected"):
        SequenceClips().fit().transform([np.zeros((30, 25, 3))])


def test_words_of_kmeans_and_nmf_follow_their_conventions():
    X, _, _ = _clip_data(0)
    km = KMeans(6, n_init=2, random_state=0)
    np.testing.assert_array_equal(fit_words(km, X), km.labels_)
    np.testing.assert_array_equal(assign_words(km, X[:5]), km.predict(X[:5]))
    nmf = SklearnNMF(6, init="nndsvda", max_iter=300, random_state=0)
    words = fit_words(nmf, X)
    np.testing.assert_array_equal(assign_words(nmf, X[:5]), nmf.transform(X[:5]).argmax(1))
    assert words.shape == (len(X),) and words.max() < 6


def _msr_quick_config(tmp_path, only, overrides=()):
    """configs/compare/msr3d_nmf.yaml on the first take of actions a08-a11 (40 files), tiny vocabularies."""
    from mocapkit.evaluation.compare import compose

    cfg = compose(
        [
            "msr3d_nmf",
            f"benchmark.root={MSR_ROOT}",
            f"out={tmp_path / 'out'}",
            "benchmark.actions=[8,9,10,11]",
            "benchmark.takes=[1]",
            "seeds=[0]",
            f"only=[{','.join(only)}]",
            *overrides,
        ]
    )
    for name in ("kmeans", "nmf", "onmf", "gnmf", "nmc"):  # 5 words, 20 iterations: seconds, not minutes
        key = "n_clusters" if name == "kmeans" else "n_components"
        OmegaConf.update(cfg, f"templates.{name}.steps.1.1.clusterer.{key}", 5)
        OmegaConf.update(cfg, f"templates.{name}.steps.1.1.clusterer.max_iter", 20)
    for name in ("select_k", "select_k_lam", "select_k_lambda2"):
        OmegaConf.update(cfg, f"templates.{name}.stages.0", {"bow__clusterer__n_components": [3, 5]}, merge=False)
    OmegaConf.update(cfg, "methods.kmeans_w30.select.stages.0", {"bow__clusterer__n_clusters": [3, 5]}, merge=False)
    return cfg


@needs(MSR_ROOT)
def test_msr_nmf_comparison_on_a_real_subset(tmp_path):
    """k-means and NMC (hard and soft) with CV selection, both protocols, on 40 real files: every cell, the
    selection on training sequences only, the same test sequences for every method."""
    from mocapkit.evaluation.compare import run_comparison

    methods = ["kmeans_w30", "nmc_w30", "nmc_soft_w30"]
    results = run_comparison(_msr_quick_config(tmp_path, methods))
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved["benchmark"]["n_sequences"] == 40 and saved["benchmark"]["subset"]["actions"] == [8, 9, 10, 11]
    assert {(c["method"], c["protocol"], c["seed"]) for c in saved["cells"]} == {
        (m, p, 0) for m in methods for p in ("random_half", "cross_subject")
    }
    for protocol in ("random_half", "cross_subject"):
        chosen = saved["selection"]["nmc_w30"][protocol]
        assert chosen["params"]["bow__clusterer__n_components"] in (3, 5) and len(chosen["tried"]) == 2 + 2
        assert chosen["cv_score"] == max(t["cv_score"] for t in chosen["tried"])
        assert set(saved["selection"]) == {"kmeans_w30", "nmc_w30"}  # soft reuses the hard selection
        cells = {c["method"]: c for c in saved["cells"] if c["protocol"] == protocol}
        assert cells["nmc_soft_w30"]["params"] == {"bow__assignment": "soft", **chosen["params"]}
        assert len({c["test_sha1"] for c in cells.values()}) == 1  # same test sequences
        assert cells["kmeans_w30"]["test_sha1"] == saved["splits"][protocol]["0"]["test_sha1"]
        for c in cells.values():
            for key in ("accuracy", "clip_acc", "clip_nmi", "clip_ari"):
                assert math.isfinite(c["metrics"][key]) and 0.0 <= c["metrics"][key] <= 1.0, (c["method"], key)
        test = set(saved["splits"][protocol]["0"]["test_indices"])
        assert test.isdisjoint(set(range(40)) - test) and 0 < len(test) < 40
    assert results["summary"][0]["metrics"]["accuracy"]["n"] == 1
    table = (tmp_path / "out" / "results.md").read_text()
    assert "| NMC soft (M=30) | estimator | " in table and "93.33 %" in table and "arithmetic" in table
    assert (tmp_path / "out" / "summary.png").stat().st_size > 1000


@pytest.mark.slow
@needs(MSR_ROOT)
def test_msr_nmf_layer_cell_scores_the_same_test_sequences(tmp_path):
    """The end-to-end NMF layer (2 epochs) beside k-means: trained with train(), scored with evaluate()."""
    from mocapkit.evaluation.compare import run_comparison

    cfg = _msr_quick_config(
        tmp_path,
        ["kmeans_w30", "layer_w30"],
        [
            "protocols=[cross_subject]",
            (
                "learned_overrides=['trainer.max_epochs=2','model.n_components=8',"
                "'model.encoder_hidden=16','data.val_fraction=0.2',"
                "'trainer.enable_progress_bar=false']"
            ),
        ],
    )
    results = run_comparison(cfg)
    layer, kmeans = (next(c for c in results["cells"] if c["method"] == m) for m in ("layer_w30", "kmeans_w30"))
    assert layer["test_sha1"] == kmeans["test_sha1"] and layer["kind"] == "learned"
    assert 0.0 <= layer["metrics"]["accuracy"] <= 1.0 and math.isfinite(layer["metrics"]["clip_nmi"])
    assert layer["run_dir"].endswith("layer_w30_cross_subject_seed0")


def test_msr_nmf_config_lists_every_method_and_window():
    from mocapkit.evaluation.compare import compose
    from mocapkit.evaluation.compare.runner import parse_methods

    cfg = compose(["msr3d_nmf"])
    methods = parse_methods(OmegaConf.to_container(cfg.methods, resolve=True))
    assert list(cfg.protocols) == ["random_half", "cross_subject"] and list(cfg.seeds) == [0, 1, 2]
    for window in (30, 10):
        keys = [k for k in methods if k.endswith(f"_w{window}")]
        assert [k.rsplit("_", 1)[0] for k in keys] == [
            "kmeans",
            "nmf",
            "nmf_soft",
            "onmf",
            "onmf_soft",
            "gnmf",
            "gnmf_soft",
            "nmc",
            "nmc_soft",
            "layer",
        ]
        assert methods[f"layer_w{window}"].spec["overrides"][0] == f"model.window={window}"
    assert methods["nmc_w10"].params == {"clips__window": 10}
    assert methods["gnmf_w30"].select["stages"][1] == {"bow__clusterer__lam": [0.01, 0.1, 1.0]}
