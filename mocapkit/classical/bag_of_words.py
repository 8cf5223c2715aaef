"""Bag of clip words: cluster the clips, describe each sequence by its ℓ1-normalised word histogram, classify.

The recognition pipeline of the thesis (§6.3.4; spec §5.3): a clusterer (k-means, or an NMF
variant whose word is the arg-max of a clip's code row) is fitted on the *training* clips only;
new clips get the word of their nearest centre (``predict``) or the arg-max of their code with the
components fixed (``transform``); each sequence becomes the histogram of its clips' words, divided
by its clip count; a linear scikit-learn classifier (``LogisticRegression`` or ``LinearSVC``) with
its ``C`` chosen by stratified cross-validation on the training sequences reads the histograms.

Clusterers are duck-typed scikit-learn estimators: centroid models (``n_clusters``; ``fit`` then ``labels_``
and ``predict``, e.g. ``KMeans``) or factorisations (``fit_transform`` / ``transform`` and ``components_``, e.g.
the :mod:`mocapkit.classical` NMF family or ``sklearn.decomposition.NMF``), whose word is the arg-max of a
clip's code row (the thesis's ``argmax_c G_c,clip``; we tried ``argmax_c W_ic ‖H_c‖`` instead and it was worse
on MSR: one dominant "mean pose" component then takes most clips).
For graph-regularised models (GNMF, NMC) the graph couples the training clips only; test clips
are coded one by one against the fixed components.
"""
from __future__ import annotations

import copy
import time

import numpy as np
from sklearn.base import clone
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.svm import LinearSVC

CLASSIFIERS = ("logistic", "linear_svc")


def word_histograms(words, sequence_of_clip, n_sequences: int, n_words: int) -> np.ndarray:
    """ℓ1-normalised histograms ``[n_sequences, n_words]`` (float64) of clip ``words`` grouped by sequence.

    A sequence without clips gets an all-zero row (the clip pipeline always gives at least one).
    """
    words, owner = np.asarray(words, dtype=np.int64), np.asarray(sequence_of_clip, dtype=np.int64)
    if words.shape != owner.shape or words.ndim != 1:
        raise ValueError(f"words and sequence_of_clip must be 1-D of equal length, got {words.shape}, {owner.shape}")
    if len(words) and (words.min() < 0 or words.max() >= n_words):
        raise ValueError(f"words must lie in [0, {n_words}), got range [{words.min()}, {words.max()}]")
    if len(owner) and (owner.min() < 0 or owner.max() >= n_sequences):
        raise ValueError(f"sequence_of_clip must lie in [0, {n_sequences}), got [{owner.min()}, {owner.max()}]")
    counts = np.zeros((n_sequences, n_words))
    np.add.at(counts, (owner, words), 1.0)
    return counts / np.maximum(counts.sum(1, keepdims=True), 1.0)


def fit_words(clusterer, X: np.ndarray) -> np.ndarray:
    """Fit ``clusterer`` on clips ``X [n, d]``; the training clips' words.

    ``labels_`` after ``fit`` (k-means; the :mod:`mocapkit.classical` NMF family: arg-max of each row of the
    fitted codes W, the thesis's ``argmax_c G_c,clip``), else the arg-max of ``fit_transform`` (e.g.
    ``sklearn.decomposition.NMF``).
    """
    if hasattr(clusterer, "fit_transform") and not hasattr(clusterer, "n_clusters"):
        codes = clusterer.fit_transform(X)
        labels = getattr(clusterer, "labels_", None)
        return np.asarray(labels if labels is not None else _numpy(codes).argmax(1), dtype=np.int64)
    clusterer.fit(X)
    return np.asarray(clusterer.labels_, dtype=np.int64)


def assign_words(clusterer, X: np.ndarray) -> np.ndarray:
    """Words of new clips ``X [n, d]``: ``predict`` for centroid models (``cluster_centers_``), else the arg-max
    of ``transform`` (components fixed; graph terms, which couple training samples only, do not apply)."""
    if hasattr(clusterer, "cluster_centers_"):
        return np.asarray(clusterer.predict(X), dtype=np.int64)
    return _numpy(clusterer.transform(X)).argmax(1).astype(np.int64)


def _numpy(a) -> np.ndarray:
    return a.detach().cpu().numpy() if hasattr(a, "detach") else np.asarray(a)


def n_words_of(clusterer) -> int:
    """Vocabulary size of a fitted clusterer (``n_clusters`` or ``n_components``)."""
    for key in ("n_clusters", "n_components"):
        value = getattr(clusterer, key, None)
        if value is not None:
            return int(value)
    raise ValueError(f"{type(clusterer).__name__} has neither n_clusters nor n_components")


def make_classifier(kind: str = "logistic", random_state: int = 0):
    """An unfitted linear classifier: ``"logistic"`` (multinomial LogisticRegression) or ``"linear_svc"``."""
    if kind == "logistic":
        return LogisticRegression(max_iter=2000, random_state=random_state)
    if kind == "linear_svc":
        return LinearSVC(max_iter=20000, random_state=random_state)
    raise ValueError(f"unknown classifier {kind!r}; choose from {CLASSIFIERS}")


class BagOfWordsClassifier:
    """Clusterer → per-sequence word histograms → linear classifier with cross-validated ``C``.

    Args:
        clusterer: an unfitted scikit-learn-style clusterer (cloned on ``fit``).
        classifier: ``"logistic"`` or ``"linear_svc"``.
        Cs: the grid of ``C`` values searched.
        cv: folds of the stratified cross-validation over training *sequences* (capped by the
            smallest class size; with fewer than 2 per class the first ``C`` ≥ 1 is used without CV).
        random_state: seeds the classifier and the folds.

    Attributes after ``fit``: ``clusterer_``, ``classifier_``, ``best_C_``, ``train_words_``,
    ``n_words_``, ``cluster_time_``, ``classifier_time_`` (seconds).
    """

    def __init__(self, clusterer, classifier: str = "logistic", Cs=(0.1, 1.0, 10.0, 100.0), cv: int = 3,
                 random_state: int = 0):
        self.clusterer = clusterer
        self.classifier = classifier
        self.Cs = tuple(Cs)
        self.cv = cv
        self.random_state = random_state

    def fit(self, X: np.ndarray, sequence_of_clip: np.ndarray, y: np.ndarray) -> "BagOfWordsClassifier":
        """Fit on clips ``X [n_clips, d]`` of sequences ``sequence_of_clip`` (0..n_seq-1) with labels ``y [n_seq]``."""
        y = np.asarray(y)
        start = time.perf_counter()
        try:
            self.clusterer_ = clone(self.clusterer)
        except TypeError:  # not a full scikit-learn estimator (no get_params)
            self.clusterer_ = copy.deepcopy(self.clusterer)
        self.train_words_ = fit_words(self.clusterer_, X)
        self.cluster_time_ = time.perf_counter() - start
        self.n_words_ = n_words_of(self.clusterer_)
        histograms = word_histograms(self.train_words_, sequence_of_clip, len(y), self.n_words_)
        start = time.perf_counter()
        base = make_classifier(self.classifier, self.random_state)
        folds = min(self.cv, int(np.bincount(np.unique(y, return_inverse=True)[1]).min()))
        if folds >= 2:
            search = GridSearchCV(base, {"C": list(self.Cs)}, cv=StratifiedKFold(folds, shuffle=True,
                                                                                   random_state=self.random_state))
            search.fit(histograms, y)
            self.classifier_, self.best_C_ = search.best_estimator_, float(search.best_params_["C"])
        else:
            self.best_C_ = float(next((c for c in self.Cs if c >= 1.0), self.Cs[-1]))
            self.classifier_ = clone(base).set_params(C=self.best_C_).fit(histograms, y)
        self.classifier_time_ = time.perf_counter() - start
        return self

    def histograms(self, X: np.ndarray, sequence_of_clip: np.ndarray, n_sequences: int) -> np.ndarray:
        """Word histograms ``[n_sequences, n_words]`` of new clips (assigned with the fitted clusterer)."""
        return word_histograms(assign_words(self.clusterer_, X), sequence_of_clip, n_sequences, self.n_words_)

    def predict(self, X: np.ndarray, sequence_of_clip: np.ndarray, n_sequences: int) -> np.ndarray:
        """Predicted labels ``[n_sequences]`` of the sequences whose clips are ``X``."""
        return self.classifier_.predict(self.histograms(X, sequence_of_clip, n_sequences))

    def score(self, X: np.ndarray, sequence_of_clip: np.ndarray, y: np.ndarray) -> float:
        """Recognition accuracy on sequences with labels ``y``."""
        y = np.asarray(y)
        return float((self.predict(X, sequence_of_clip, len(y)) == y).mean())
