"""Bag of clip words: condition the clips, cluster them, describe each sequence by a histogram, classify.

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

Two optional steps, both fitted on the training clips only:

* **conditioning** (:class:`ClipConditioner`): recover the signed coordinates from the sign-split features of
  :mod:`mocapkit.features.clips`, subtract the mean training clip, sign-split again and optionally scale every
  clip to unit ℓ2 norm. Without centring, every clip shares the standing pose, one "mean pose" component takes
  the arg-max of most clips and the histograms collapse onto a few words; centred components encode deviations
  from the mean clip (the usual NMF-clustering practice of conditioning the data, cf. Cai et al. 2011, who
  normalise the samples).
* **assignment**: ``"hard"`` = the thesis's histogram of arg-max words; ``"soft"`` = the mean of the clips'
  ℓ1-normalised code rows (:func:`code_histograms`), with the codes of ``transform`` (components fixed) for
  training and test clips alike. Centroid models (k-means) have one-hot codes, so soft equals hard for them.
"""
from __future__ import annotations

import copy
import time

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.svm import LinearSVC

CLASSIFIERS = ("logistic", "linear_svc")
ASSIGNMENTS = ("hard", "soft")


class ClipConditioner(TransformerMixin, BaseEstimator):
    """Centre sign-split clip features on the mean training clip and sign-split them again: ``[n, 2h] → [n, 2h]``.

    Input: the non-negative features of :func:`~mocapkit.features.clips.clip_features`, ``[x⁺, x⁻]`` with ``h``
    columns each, so that the signed clip is ``x = x⁺ − x⁻``. Output: ``[max(x − m, 0), max(m − x, 0)]`` with
    ``m [h]`` = the mean signed training clip (``centre=False``: ``m = 0``, the input unchanged), each row then
    divided by its ℓ2 norm when ``unit_norm`` (an all-zero row stays zero). Output is non-negative, as NMF needs.

    Args:
        centre: subtract the mean training clip (``mean_``, fitted in ``fit``).
        unit_norm: scale every output row to unit ℓ2 norm.
    """

    def __init__(self, centre: bool = True, unit_norm: bool = False):
        self.centre = centre
        self.unit_norm = unit_norm

    def _signed(self, X) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[0] == 0 or X.shape[1] == 0 or X.shape[1] % 2:
            raise ValueError(f"ClipConditioner needs sign-split features [n_clips, 2h] (n_clips >= 1, an even "
                             f"number of columns), got shape {X.shape}")
        if not np.isfinite(X).all():
            row = int(np.flatnonzero(~np.isfinite(X).all(1))[0])
            raise ValueError(f"ClipConditioner: features contain NaN or inf (first at clip {row})")
        if X.min() < 0:
            raise ValueError(f"ClipConditioner: sign-split features must be non-negative, min is {X.min():.4g} "
                             f"(clip {int(np.argmin(X.min(1)))})")
        half = X.shape[1] // 2
        return X[:, :half] - X[:, half:]

    def fit(self, X, y=None) -> ClipConditioner:
        """Store ``mean_ [h]``, the mean signed clip of ``X [n, 2h]`` (zeros when ``centre=False``)."""
        signed = self._signed(X)
        self.mean_ = signed.mean(0) if self.centre else np.zeros(signed.shape[1])
        self.n_features_in_ = 2 * signed.shape[1]
        return self

    def transform(self, X) -> np.ndarray:
        """Conditioned features ``[n, 2h]`` (float64, non-negative)."""
        if not hasattr(self, "mean_"):
            raise RuntimeError("this ClipConditioner is not fitted yet; call fit first")
        signed = self._signed(X)
        if signed.shape[1] != len(self.mean_):
            raise ValueError(f"X has {2 * signed.shape[1]} features but the conditioner was fitted with "
                             f"{2 * len(self.mean_)}")
        signed = signed - self.mean_
        out = np.concatenate([np.maximum(signed, 0.0), np.maximum(-signed, 0.0)], axis=1)
        if self.unit_norm:
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
        return out


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


def code_histograms(codes, sequence_of_clip, n_sequences: int) -> np.ndarray:
    """Soft bag of words ``[n_sequences, k]``: the mean over a sequence's clips of their ℓ1-normalised codes.

    ``codes [n_clips, k]`` ≥ 0 (NMF codes ``W``, or one-hot words); a code row of all zeros counts as no word,
    a sequence without clips gets an all-zero row. Rows sum to 1 otherwise.
    """
    codes = _numpy(codes).astype(np.float64)
    owner = np.asarray(sequence_of_clip, dtype=np.int64)
    if codes.ndim != 2 or owner.shape != (len(codes),):
        raise ValueError(f"codes must be [n_clips, k] and sequence_of_clip [n_clips], got {codes.shape}, "
                         f"{owner.shape}")
    if len(codes) and (codes.min() < 0 or not np.isfinite(codes).all()):
        raise ValueError("codes must be finite and non-negative")
    if len(owner) and (owner.min() < 0 or owner.max() >= n_sequences):
        raise ValueError(f"sequence_of_clip must lie in [0, {n_sequences}), got [{owner.min()}, {owner.max()}]")
    rows = codes / np.maximum(codes.sum(1, keepdims=True), 1e-300)
    sums = np.zeros((n_sequences, codes.shape[1]))
    np.add.at(sums, owner, rows)
    return sums / np.maximum(sums.sum(1, keepdims=True), 1e-300)


def assign_codes(clusterer, X: np.ndarray) -> np.ndarray:
    """Codes ``[n, k]`` of clips ``X`` with the fitted clusterer fixed: one-hot ``predict`` words for centroid
    models, ``transform`` for factorisations."""
    if hasattr(clusterer, "cluster_centers_"):
        return np.eye(n_words_of(clusterer))[clusterer.predict(X)]
    return _numpy(clusterer.transform(X))


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


def _clone(estimator):
    try:
        return clone(estimator)
    except TypeError:  # not a full scikit-learn estimator (no get_params)
        return copy.deepcopy(estimator)


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
    """(Conditioner →) clusterer → per-sequence histograms → linear classifier with cross-validated ``C``.

    Args:
        clusterer: an unfitted scikit-learn-style clusterer (cloned on ``fit``), or a fitted one with ``prefit``.
        assignment: ``"hard"`` (the thesis: histogram of arg-max words, training words = the fit's ``labels_``)
            or ``"soft"`` (:func:`code_histograms` of the ``transform`` codes, training and test clips alike).
        conditioner: an optional transformer applied to the clips before the clusterer (e.g.
            :class:`ClipConditioner`), fitted on the training clips (used as fitted with ``prefit``).
        prefit: use ``clusterer`` (and ``conditioner``) as already fitted on the training clips (e.g. the
            ``clusterer_`` of a hard model, to read the same clustering with soft histograms without refitting);
            the training words are then recomputed with ``assign_words``.
        classifier: ``"logistic"`` or ``"linear_svc"``.
        Cs: the grid of ``C`` values searched.
        cv: folds of the stratified cross-validation over training *sequences* (capped by the
            smallest class size; with fewer than 2 per class the first ``C`` ≥ 1 is used without CV).
        random_state: seeds the classifier and the folds.

    Attributes after ``fit``: ``conditioner_`` (None without one), ``clusterer_``, ``classifier_``, ``best_C_``,
    ``train_words_``, ``n_words_``, ``cluster_time_``, ``classifier_time_`` (seconds).
    """

    def __init__(self, clusterer, classifier: str = "logistic", Cs=(0.1, 1.0, 10.0, 100.0), cv: int = 3,
                 random_state: int = 0, assignment: str = "hard", conditioner=None, prefit: bool = False):
        if assignment not in ASSIGNMENTS:
            raise ValueError(f"assignment must be one of {ASSIGNMENTS}, got {assignment!r}")
        self.clusterer = clusterer
        self.assignment = assignment
        self.conditioner = conditioner
        self.prefit = prefit
        self.classifier = classifier
        self.Cs = tuple(Cs)
        self.cv = cv
        self.random_state = random_state

    def fit(self, X: np.ndarray, sequence_of_clip: np.ndarray, y: np.ndarray) -> "BagOfWordsClassifier":
        """Fit on clips ``X [n_clips, d]`` of sequences ``sequence_of_clip`` (0..n_seq-1) with labels ``y [n_seq]``."""
        y = np.asarray(y)
        start = time.perf_counter()
        if self.prefit:
            self.conditioner_, self.clusterer_ = self.conditioner, self.clusterer
            X = X if self.conditioner_ is None else self.conditioner_.transform(X)
            self.train_words_ = assign_words(self.clusterer_, X)
        else:
            self.conditioner_ = None if self.conditioner is None else _clone(self.conditioner)
            X = X if self.conditioner_ is None else self.conditioner_.fit_transform(X)
            self.clusterer_ = _clone(self.clusterer)
            self.train_words_ = fit_words(self.clusterer_, X)
        self.cluster_time_ = time.perf_counter() - start
        self.n_words_ = n_words_of(self.clusterer_)
        histograms = self._histograms(X, sequence_of_clip, len(y), self.train_words_)
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

    def _histograms(self, X_conditioned, sequence_of_clip, n_sequences: int, words=None) -> np.ndarray:
        if self.assignment == "soft":
            return code_histograms(assign_codes(self.clusterer_, X_conditioned), sequence_of_clip, n_sequences)
        words = assign_words(self.clusterer_, X_conditioned) if words is None else words
        return word_histograms(words, sequence_of_clip, n_sequences, self.n_words_)

    def histograms(self, X: np.ndarray, sequence_of_clip: np.ndarray, n_sequences: int) -> np.ndarray:
        """Histograms ``[n_sequences, n_words]`` of new clips (conditioned and coded with the fitted models)."""
        X = X if self.conditioner_ is None else self.conditioner_.transform(X)
        return self._histograms(X, sequence_of_clip, n_sequences)

    def predict(self, X: np.ndarray, sequence_of_clip: np.ndarray, n_sequences: int) -> np.ndarray:
        """Predicted labels ``[n_sequences]`` of the sequences whose clips are ``X``."""
        return self.classifier_.predict(self.histograms(X, sequence_of_clip, n_sequences))

    def score(self, X: np.ndarray, sequence_of_clip: np.ndarray, y: np.ndarray) -> float:
        """Recognition accuracy on sequences with labels ``y``."""
        y = np.asarray(y)
        return float((self.predict(X, sequence_of_clip, len(y)) == y).mean())
