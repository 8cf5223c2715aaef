"""Bag of clip words: condition the clips, cluster them, describe each sequence by a histogram, classify.

The recognition pipeline of the thesis (§6.3.4): a clusterer (k-means, or an NMF
variant whose word is the arg-max of a clip's code row) is fitted on the *training* clips only;
new clips get the word of their nearest centre (``predict``) or the arg-max of their code with the
components fixed (``transform``); each sequence becomes the histogram of its clips' words, divided
by its clip count; a linear scikit-learn classifier (``LogisticRegression`` or ``LinearSVC``) with
its ``C`` chosen by stratified cross-validation on the training sequences reads the histograms.

Clusterers are duck-typed scikit-learn estimators: centroid models (``n_clusters``; ``fit`` then ``labels_``
and ``predict``, e.g. ``KMeans``) or factorisations (``fit_transform`` / ``transform`` and ``components_``, e.g.
the :mod:`mocapkit.clustering.nmf` family or ``sklearn.decomposition.NMF``), whose word is the arg-max of a
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

Every class here is a scikit-learn estimator: parameters are stored untouched in ``__init__`` and checked in
``fit`` (``check_array`` / ``check_non_negative``), fitted attributes end in ``_``, and using a model before
``fit`` raises ``sklearn.exceptions.NotFittedError``. The sample is a **sequence**: :class:`SequenceClips`
turns skeleton sequences ``[T_i, J, 3]`` into per-sequence clip features ``[n_clips_i, d]`` and
:class:`BagOfWordsClassifier` takes a list of those with one label per sequence, so the whole recognition
pipeline is ``Pipeline([("clips", SequenceClips(...)), ("bow", BagOfWordsClassifier(...))])`` and
``GridSearchCV`` can tune e.g. ``bow__clusterer__n_components`` with folds over sequences.
"""

from __future__ import annotations

import copy
import time

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, TransformerMixin, clone
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.svm import LinearSVC
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted, check_non_negative, column_or_1d

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

    @staticmethod
    def _signed(X) -> np.ndarray:
        X = check_array(X, dtype=np.float64, input_name="ClipConditioner features")
        if X.shape[1] % 2:
            raise ValueError(
                f"ClipConditioner needs sign-split features [n_clips, 2h] (an even number of "
                f"columns), got shape {X.shape}"
            )
        check_non_negative(X, "ClipConditioner (sign-split features must be non-negative)")
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
        check_is_fitted(self, "mean_")
        signed = self._signed(X)
        if signed.shape[1] != len(self.mean_):
            raise ValueError(
                f"X has {2 * signed.shape[1]} features but the conditioner was fitted with {2 * len(self.mean_)}"
            )
        signed = signed - self.mean_
        out = np.concatenate([np.maximum(signed, 0.0), np.maximum(-signed, 0.0)], axis=1)
        if self.unit_norm:
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
        return out


class SequenceClips(TransformerMixin, BaseEstimator):
    """Skeleton sequences → their clip features, one array per sequence (:mod:`mocapkit.features.clips`).

    ``transform(X)``: ``X`` = a sequence of ``n`` arrays ``[T_i, J, 3]`` (metres; all-zero joints = untracked)
    → a list of ``n`` float32 arrays ``[n_clips_i, d]`` with ``d = 2 · frames_per_clip · J · 3`` (sign-split,
    non-negative), ``n_clips_i = ⌊(T_i − window)/stride⌋ + 1`` (1 when ``T_i < window``). Stateless: ``fit``
    only checks the parameters.

    Args:
        window: clip length ``M`` in frames. stride: frames between clip starts (None: ``M // 2``).
        frames_per_clip: frames sampled per clip. layout: the skeleton layout name (e.g. ``"msr20"``).
    """

    def __init__(self, window: int = 30, stride: int | None = None, frames_per_clip: int = 10, layout: str = "msr20"):
        self.window = window
        self.stride = stride
        self.frames_per_clip = frames_per_clip
        self.layout = layout

    def fit(self, X=None, y=None) -> SequenceClips:
        """Check the parameters (``window`` ≥ 2 without a stride, ``frames_per_clip`` ≥ 1, a known layout)."""
        from mocapkit.features.clips import clip_count
        from mocapkit.motion.layouts import get_layout

        clip_count(1, self.window, self.stride)  # raises naming a bad window / stride
        if int(self.frames_per_clip) < 1:
            raise ValueError(f"frames_per_clip must be at least 1, got {self.frames_per_clip}")
        self.layout_ = get_layout(self.layout)
        self.n_features_out_ = 2 * int(self.frames_per_clip) * self.layout_.num_joints * 3
        return self

    def transform(self, X) -> list[np.ndarray]:
        """Clip features ``[n_clips_i, d]`` of every sequence of ``X``."""
        from mocapkit.features.clips import clip_features

        check_is_fitted(self, "layout_")
        out = []
        for i, positions in enumerate(X):
            positions = np.asarray(positions)
            if positions.ndim != 3 or positions.shape[1:] != (self.layout_.num_joints, 3):
                raise ValueError(
                    f"sequence {i}: expected [frames, {self.layout_.num_joints}, 3] positions of the "
                    f"{self.layout} layout, got shape {positions.shape}"
                )
            try:
                out.append(clip_features(positions, self.window, self.stride, self.frames_per_clip, self.layout_))
            except ValueError as exc:
                raise ValueError(f"sequence {i}: {exc}") from exc
        return out


def stack_clips(X, name: str = "X") -> tuple[np.ndarray, np.ndarray]:
    """Per-sequence clip features → ``(clips [sum n_clips_i, d], sequence_of_clip [sum n_clips_i])``.

    ``X``: a sequence of ``n`` arrays ``[n_clips_i, d]`` (each with at least one clip, equal ``d``), or one
    ``[n, n_clips, d]`` array. The clips are checked with ``check_array`` (finite, numeric; the dtype is kept)
    and ``check_non_negative`` (sign-split features; NMF needs them ≥ 0).
    """
    sequences = [np.asarray(x) for x in X]
    if not sequences:
        raise ValueError(f"{name} holds no sequences")
    for i, clips in enumerate(sequences):
        if clips.ndim != 2 or len(clips) == 0 or clips.shape[1] != sequences[0].shape[1]:
            raise ValueError(
                f"{name}[{i}] must be a [n_clips, d] array with at least one clip and "
                f"d = {sequences[0].shape[-1]} like {name}[0], got shape {clips.shape}"
            )
    clips = check_array(np.concatenate(sequences), dtype="numeric", input_name=f"{name} (clip features)")
    check_non_negative(clips, f"BagOfWordsClassifier ({name} clip features)")
    owner = np.repeat(np.arange(len(sequences)), [len(c) for c in sequences])
    return clips, owner


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
        raise ValueError(f"codes must be [n_clips, k] and sequence_of_clip [n_clips], got {codes.shape}, {owner.shape}")
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

    ``labels_`` after ``fit`` (k-means; the :mod:`mocapkit.clustering.nmf` family: arg-max of each row of the
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


class BagOfWordsClassifier(ClassifierMixin, BaseEstimator):
    """(Conditioner →) clusterer → per-sequence histograms → linear classifier with cross-validated ``C``.

    The samples are sequences: ``fit(X, y)`` takes ``X`` = a sequence of ``n`` clip-feature arrays
    ``[n_clips_i, d]`` (non-negative, e.g. from :class:`SequenceClips`) and ``y [n]``, one label per sequence.

    Args:
        clusterer: an unfitted scikit-learn-style clusterer (cloned on ``fit``), or a fitted one with ``prefit``.
        classifier: ``"logistic"`` or ``"linear_svc"``.
        Cs: the grid of ``C`` values searched.
        cv: folds of the stratified cross-validation over training *sequences* (capped by the
            smallest class size; with fewer than 2 per class the first ``C`` ≥ 1 is used without CV).
        random_state: seeds the classifier and the folds.
        assignment: ``"hard"`` (the thesis: histogram of arg-max words, training words = the fit's ``labels_``)
            or ``"soft"`` (:func:`code_histograms` of the ``transform`` codes, training and test clips alike).
        conditioner: an optional transformer applied to the clips before the clusterer (e.g.
            :class:`ClipConditioner`), fitted on the training clips (used as fitted with ``prefit``).
        prefit: use ``clusterer`` (and ``conditioner``) as already fitted on the training clips (e.g. the
            ``clusterer_`` of a hard model, to read the same clustering with soft histograms without refitting);
            the training words are then recomputed with ``assign_words``.

    Attributes after ``fit``: ``conditioner_`` (None without one), ``clusterer_``, ``classifier_``, ``classes_``,
    ``best_C_``, ``n_features_in_`` (``d``), ``train_words_`` ``[n_clips]`` and ``train_clip_sequence_``
    ``[n_clips]`` (the training clips' words and the index of their sequence in ``X``), ``n_words_``,
    ``cluster_time_``, ``classifier_time_`` (seconds).
    """

    def __init__(
        self,
        clusterer,
        classifier: str = "logistic",
        Cs=(0.1, 1.0, 10.0, 100.0),
        cv: int = 3,
        random_state: int = 0,
        assignment: str = "hard",
        conditioner=None,
        prefit: bool = False,
    ):
        self.clusterer = clusterer
        self.classifier = classifier
        self.Cs = Cs
        self.cv = cv
        self.random_state = random_state
        self.assignment = assignment
        self.conditioner = conditioner
        self.prefit = prefit

    def fit(self, X, y) -> BagOfWordsClassifier:
        """Fit on the clips of ``n`` training sequences ``X`` (``[n_clips_i, d]`` each) with labels ``y [n]``."""
        if self.assignment not in ASSIGNMENTS:
            raise ValueError(f"assignment must be one of {ASSIGNMENTS}, got {self.assignment!r}")
        if self.classifier not in CLASSIFIERS:
            raise ValueError(f"unknown classifier {self.classifier!r}; choose from {CLASSIFIERS}")
        Cs = [float(c) for c in self.Cs]
        if not Cs or min(Cs) <= 0:
            raise ValueError(f"Cs must be a non-empty list of positive values, got {self.Cs!r}")
        clips, owner = stack_clips(X)
        y = column_or_1d(y, warn=True)
        check_classification_targets(y)
        if len(y) != owner[-1] + 1:
            raise ValueError(f"y has {len(y)} labels for {owner[-1] + 1} sequences in X")
        start = time.perf_counter()
        if self.prefit:
            check_is_fitted(self.clusterer)
            self.conditioner_, self.clusterer_ = self.conditioner, self.clusterer
            clips = clips if self.conditioner_ is None else self.conditioner_.transform(clips)
            self.train_words_ = assign_words(self.clusterer_, clips)
        else:
            self.conditioner_ = None if self.conditioner is None else _clone(self.conditioner)
            clips = clips if self.conditioner_ is None else self.conditioner_.fit_transform(clips)
            self.clusterer_ = _clone(self.clusterer)
            self.train_words_ = fit_words(self.clusterer_, clips)
        self.cluster_time_ = time.perf_counter() - start
        self.n_words_ = n_words_of(self.clusterer_)
        self.n_features_in_ = int(clips.shape[1])
        self.train_clip_sequence_ = owner
        histograms = self._histograms(clips, owner, len(y), self.train_words_)
        start = time.perf_counter()
        base = make_classifier(self.classifier, self.random_state)
        folds = min(int(self.cv), int(np.bincount(np.unique(y, return_inverse=True)[1]).min()))
        if folds >= 2:
            search = GridSearchCV(
                base, {"C": Cs}, cv=StratifiedKFold(folds, shuffle=True, random_state=self.random_state)
            )
            search.fit(histograms, y)
            self.classifier_, self.best_C_ = search.best_estimator_, float(search.best_params_["C"])
        else:
            self.best_C_ = float(next((c for c in Cs if c >= 1.0), Cs[-1]))
            self.classifier_ = clone(base).set_params(C=self.best_C_).fit(histograms, y)
        self.classes_ = self.classifier_.classes_
        self.classifier_time_ = time.perf_counter() - start
        return self

    def _histograms(self, X_conditioned, sequence_of_clip, n_sequences: int, words=None) -> np.ndarray:
        if self.assignment == "soft":
            return code_histograms(assign_codes(self.clusterer_, X_conditioned), sequence_of_clip, n_sequences)
        words = assign_words(self.clusterer_, X_conditioned) if words is None else words
        return word_histograms(words, sequence_of_clip, n_sequences, self.n_words_)

    def histograms(self, X) -> np.ndarray:
        """Histograms ``[n, n_words_]`` of ``n`` new sequences ``X`` (conditioned and coded with the fitted models)."""
        check_is_fitted(self, "classifier_")
        clips, owner = stack_clips(X)
        if clips.shape[1] != self.n_features_in_:
            raise ValueError(f"X has clips of {clips.shape[1]} features, the model was fitted on {self.n_features_in_}")
        clips = clips if self.conditioner_ is None else self.conditioner_.transform(clips)
        return self._histograms(clips, owner, owner[-1] + 1)

    def predict(self, X) -> np.ndarray:
        """Predicted labels ``[n]`` of the sequences ``X``."""
        histograms = self.histograms(X)  # checks the fit first (NotFittedError)
        return self.classifier_.predict(histograms)

    def decision_function(self, X) -> np.ndarray:
        """The linear classifier's scores ``[n, n_classes]`` (``[n]`` for two classes) of the sequences ``X``."""
        histograms = self.histograms(X)
        return self.classifier_.decision_function(histograms)
