"""GEI+PCA+LDA: separable synthetic GEIs, clamped dimensions, the scikit-learn contract, and both protocols on a
tiny GEI cache through the comparison runner's gait benchmark (the split code the CNN data module uses)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import FunctionTransformer

from mocapkit.datasets.casia_b.cache import GEICache, write_gei_cache
from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.gait.gei_pca_lda import GEIPCALDA

SEQUENCES = [(0, s) for s in range(1, 7)] + [(1, 1), (1, 2), (2, 1), (2, 2)]  # (condition, repetition)


def make_tiny_gei_cache(
    root, num_subjects: int = 10, height: int = 32, width: int = 22, cycles: int = 1, noise: float = 0.03, seed: int = 0
) -> GEICache:
    """A CASIA-B-shaped GEI cache: every subject × 10 sequences × 11 views × ``cycles`` GEIs.

    A GEI = 0.5 + identity (3 shared "body shape" images weighted per subject, so LDA learnt on some
    subjects also separates new ones) + a view pattern + a condition pattern + per-GEI noise, in [0, 1].
    """
    rng = np.random.default_rng(seed)
    shape_basis = rng.normal(size=(3, height, width))
    view_pattern = rng.normal(size=(len(VIEWS), height, width))
    condition_pattern = rng.normal(size=(len(CONDITIONS), height, width))
    body = rng.normal(size=(num_subjects, 3))
    geis, rows = [], []
    for s in range(num_subjects):
        for condition, repetition in SEQUENCES:
            for v, view in enumerate(VIEWS):
                for cycle in range(cycles):
                    gei = (
                        0.5
                        + 0.12 * np.tensordot(body[s], shape_basis, 1)
                        + 0.06 * view_pattern[v]
                        + 0.06 * condition_pattern[condition]
                        + noise * rng.normal(size=(height, width))
                    )
                    geis.append(np.clip(gei, 0, 1))
                    rows.append(
                        (
                            f"{s + 1:03d}/{CONDITIONS[condition]}-{repetition:02d}/{view:03d}",
                            s + 1,
                            condition,
                            repetition,
                            view,
                            cycle,
                            30,
                        )
                    )
    names, subjects, conditions, sequences, views, cycle_ids, frames = zip(*rows)
    index = {
        "names": np.array(names),
        "subjects": np.array(subjects),
        "conditions": np.array(conditions),
        "sequences": np.array(sequences),
        "views": np.array(views),
        "cycles": np.array(cycle_ids),
        "frames": np.array(frames),
    }
    write_gei_cache(root, np.stack(geis), index, {"per": "cycle" if cycles > 1 else "sequence", "source": "test"})
    return GEICache(root)


def _blobs(num_subjects: int, per_subject: int, dims: int, seed: int):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(num_subjects, dims))
    labels = np.repeat(np.arange(num_subjects), per_subject)
    return centres[labels] + 0.3 * rng.normal(size=(len(labels), dims)), labels


def test_separable_geis_are_recognised_far_above_chance():
    X, y = _blobs(8, 12, 16 * 11, seed=0)
    geis = X.reshape(-1, 16, 11)
    train, test = np.arange(len(y)) % 3 != 0, np.arange(len(y)) % 3 == 0
    model = GEIPCALDA().fit(geis[train], y[train])
    accuracy = (model.predict(geis[test]) == y[test]).mean()
    assert accuracy >= 0.95  # chance: 1/8
    assert model.n_pca_ == min(train.sum() - 8, 150) and model.n_lda_ == 7
    assert model.transform(geis[test]).shape == (test.sum(), 7)
    assert np.array_equal(model.classes_[model.decision_function(geis[test]).argmax(1)], model.predict(geis[test]))
    # the same data with shuffled labels: nothing to learn, accuracy near chance (1/8)
    shuffled = np.random.default_rng(1).permutation(y)
    control = GEIPCALDA().fit(geis[train], shuffled[train])
    assert (control.predict(geis[test]) == shuffled[test]).mean() < 0.4
    assert model.score(geis[test], y[test]) == accuracy  # scikit-learn's ClassifierMixin


def test_more_pca_dims_than_samples_is_clamped_with_a_warning():
    X, y = _blobs(4, 5, 300, seed=2)  # 20 samples of 300 pixels
    with pytest.warns(UserWarning, match="n_pca=1000 exceeds"):
        model = GEIPCALDA(n_pca=1000).fit(X, y)
    assert model.n_pca_ == 20 - 4
    with pytest.warns(UserWarning, match="n_lda=50 exceeds"):
        assert GEIPCALDA(n_lda=50).fit(X, y).n_lda_ == 3
    assert (model.predict(X) == y).mean() == 1.0  # nearest training GEI is itself
    two_each = GEIPCALDA().fit(X[y < 2][[0, 1, 5, 6]], [0, 0, 1, 1])  # N − C = 2: PCA keeps 2 components
    assert two_each.n_pca_ == 2 and two_each.n_lda_ == 1
    with pytest.raises(ValueError, match="more training GEIs than subjects"):
        GEIPCALDA().fit(X[::5], y[::5])  # one GEI per subject: within-class scatter is zero


def test_bad_input_is_named():
    X, y = _blobs(3, 4, 20, seed=3)
    with pytest.raises(ValueError, match="at least 2 subjects"):
        GEIPCALDA().fit(X, np.zeros(len(y)))
    with pytest.raises(ValueError, match="subjects must have shape"):
        GEIPCALDA().fit(X, y[:-1])
    with pytest.raises(ValueError, match="NaN"):
        GEIPCALDA().fit(np.full_like(X, np.nan), y)
    with pytest.raises(ValueError, match="metric='l2'"):
        GEIPCALDA(metric="l2").fit(X, y)
    with pytest.raises(ValueError, match="n_pca=0"):
        GEIPCALDA(n_pca=0).fit(X, y)


def test_is_a_scikit_learn_estimator():
    X, y = _blobs(5, 8, 40, seed=4)
    model = GEIPCALDA(n_pca=12, metric="cos", random_state=3)
    assert model.get_params() == {"n_pca": 12, "n_lda": None, "metric": "cos", "random_state": 3}
    twin = clone(model)
    assert twin is not model and twin.get_params() == model.get_params()
    assert GEIPCALDA(metric="l2").metric == "l2" and GEIPCALDA(n_pca=-1).n_pca == -1  # untouched until fit
    assert model.set_params(n_lda=2) is model and model.n_lda == 2
    for call in (model.predict, model.transform, model.decision_function):
        with pytest.raises(NotFittedError):
            call(X)
    pipe = Pipeline([("scale", FunctionTransformer(lambda a: a * 2.0)), ("gei", GEIPCALDA())]).fit(X, y)
    assert (pipe.predict(X) == y).mean() == 1.0
    search = GridSearchCV(GEIPCALDA(), {"n_pca": [2, 10]}, cv=2).fit(X, y)
    assert search.best_params_["n_pca"] in (2, 10) and search.best_estimator_.n_pca_ == search.best_params_["n_pca"]
    fitted = GEIPCALDA().fit(X, y)
    with pytest.raises(ValueError, match="fitted on 40"):
        fitted.predict(X[:, :30])


def test_both_protocols_on_a_tiny_cache(tmp_path):
    from mocapkit.gait.benchmark import GaitBenchmark

    cache = make_tiny_gei_cache(tmp_path / "cache", cycles=2)
    benchmark = GaitBenchmark(str(cache.root), metric="cos")
    split = benchmark.split("closed_set", seed=0)
    closed = benchmark.evaluate_estimator(GEIPCALDA(), split)
    report = closed["detail"]["closed_set"]
    assert len(split.test) == 10 * 11 * 3 * 2 and len(split.train) == len(cache) - len(split.test)
    assert report["per"] == "cycle" and report["num_sequences"] == 10 * 11 * 3
    assert list(report["tasks"]) == ["subject"]
    assert closed["metrics"]["subject_accuracy"] == report["tasks"]["subject"]["accuracy"] >= 0.9  # chance 0.1
    assert set(report["tasks"]["subject"]["per_view"]) == {str(v) for v in VIEWS}
    assert report["tasks"]["subject"]["per_sequence"]["accuracy"] >= report["tasks"]["subject"]["accuracy"] - 0.05

    split = benchmark.split("cross_subject", seed=0)
    assert split.info["train_subjects"] == [1, 2, 3, 4, 5, 6] and split.info["test_subjects"] == [7, 8, 9, 10]
    cross = benchmark.evaluate_estimator(GEIPCALDA(metric="cos"), split)
    assert cross["detail"]["n_lda_"] == 5 and cross["detail"]["cross_view"]["metric"] == "cos"
    nm = cross["detail"]["cross_view"]["conditions"]["nm"]
    assert nm["missing_cells"] == [] and nm["num_probes"] == 4 * 2 * 11
    assert cross["metrics"]["rank1_nm"] == nm["mean"] >= 0.6  # unseen subjects, chance 0.25
    with pytest.raises(ValueError, match="protocol='loo'"):
        benchmark.split("loo", 0)
