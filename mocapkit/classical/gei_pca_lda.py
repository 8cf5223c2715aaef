"""The classical GEI baseline: PCA, then LDA, then the nearest training GEI (Han & Bhanu 2006; Sarkar et al. 2005).

A Gait Energy Image ``[H, W]`` is flattened to a vector of ``H·W`` pixels. PCA first reduces it
to ``n_pca`` components, so that LDA's within-class scatter matrix is full rank (it has rank at
most ``N − C`` for ``N`` training GEIs of ``C`` subjects), then LDA projects to at most ``C − 1``
discriminant directions. A probe is given the subject of its nearest training GEI in that space.

:class:`GEIPCALDA` is a scikit-learn estimator (``fit``/``transform``/``predict``) built from
``PCA``, ``LinearDiscriminantAnalysis`` and ``KNeighborsClassifier(n_neighbors=1)`` in a
``Pipeline``. :func:`run_gei_pca_lda` applies it to a GEI cache under the thesis's closed-set
protocol and OpenGait's cross-subject protocol with the same splits as the CNN, and returns the
same report structures (:mod:`mocapkit.evaluation.gait`).
"""
from __future__ import annotations

import time
import warnings

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, TransformerMixin
from sklearn.decomposition import PCA
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.metrics import pairwise_distances
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.utils.validation import check_is_fitted

from mocapkit.datasets.formats.casia_b import VIEWS
from mocapkit.datasets.casia_b.splits import PROTOCOLS, closed_set_split, cross_subject_subjects
from mocapkit.evaluation.gait import closed_set_report, cross_view_rank1

#: Upper bound on the default number of PCA components.
DEFAULT_PCA_CAP = 150
_SKLEARN_METRIC = {"euc": "euclidean", "cos": "cosine"}


def _as_vectors(geis: np.ndarray, name: str = "geis") -> np.ndarray:
    """``[N, H, W]`` or ``[N, D]`` → float32 ``[N, D]``, rejecting other shapes and non-finite values."""
    geis = np.asarray(geis)
    if geis.ndim not in (2, 3) or len(geis) == 0:
        raise ValueError(f"{name} must be a non-empty [N, H, W] or [N, D] array, got shape {geis.shape}")
    vectors = geis.reshape(len(geis), -1).astype(np.float32)
    if not np.isfinite(vectors).all():
        raise ValueError(f"{name} contains NaN or infinite values")
    return vectors


class GEIPCALDA(ClassifierMixin, TransformerMixin, BaseEstimator):
    """GEI → PCA → LDA → 1-nearest-neighbour subject classifier.

    Args:
        n_pca: PCA components. None: ``min(N − C, 150, D)`` for ``N`` training GEIs of ``C`` subjects
            with ``D`` pixels, the largest that keeps LDA's within-class scatter well posed (Belhumeur's
            Fisherfaces rule), capped for speed. A larger value (e.g. more dimensions than samples)
            is clamped to ``min(N − C, D)`` with a warning; the value used is ``n_pca_``.
            LDA needs ``N > C`` (some subject with at least two training GEIs).
        n_lda: LDA components; None: ``min(C − 1, n_pca_)``; clamped the same way (``n_lda_``).
        metric: ``"euc"`` or ``"cos"``, for the nearest-neighbour search in the LDA space.
        random_state: seed of PCA's randomised SVD (used on large inputs).

    Attributes (after ``fit``): ``pipeline_`` (PCA → LDA → 1-NN), ``classes_`` (subject labels),
    ``n_pca_``, ``n_lda_``, ``train_embeddings_`` ``[N, n_lda_]``, ``train_labels_``.
    """

    def __init__(self, n_pca: int | None = None, n_lda: int | None = None, metric: str = "euc",
                 random_state: int = 0):
        self.n_pca = n_pca
        self.n_lda = n_lda
        self.metric = metric
        self.random_state = random_state

    def fit(self, geis: np.ndarray, subjects: np.ndarray) -> GEIPCALDA:
        """Fit on training GEIs ``[N, H, W]`` (or ``[N, D]``) with their subject labels ``[N]``."""
        if self.metric not in _SKLEARN_METRIC:
            raise ValueError(f"metric={self.metric!r}: expected one of {tuple(_SKLEARN_METRIC)}")
        X = _as_vectors(geis)
        y = np.asarray(subjects)
        if y.shape != (len(X),):
            raise ValueError(f"subjects must have shape ({len(X)},) like geis, got {y.shape}")
        classes = np.unique(y)
        if len(classes) < 2:
            raise ValueError(f"LDA needs at least 2 subjects in training, got {len(classes)}")
        n, dims, n_classes = len(X), X.shape[1], len(classes)
        if n <= n_classes:
            raise ValueError(f"LDA needs more training GEIs than subjects (some subject with two), got {n} GEIs "
                             f"of {n_classes} subjects")
        pca_limit = min(n - n_classes, dims)
        self.n_pca_ = self._clamped("n_pca", self.n_pca, min(pca_limit, DEFAULT_PCA_CAP), pca_limit)
        lda_limit = max(1, min(n_classes - 1, self.n_pca_))
        self.n_lda_ = self._clamped("n_lda", self.n_lda, lda_limit, lda_limit)
        self.pipeline_ = Pipeline([
            ("pca", PCA(n_components=self.n_pca_, random_state=self.random_state)),
            ("lda", LinearDiscriminantAnalysis(n_components=self.n_lda_, solver="svd")),
            ("nearest", KNeighborsClassifier(n_neighbors=1, metric=_SKLEARN_METRIC[self.metric], algorithm="brute")),
        ])
        with warnings.catch_warnings():  # few GEIs per subject make LDA's covariance near-singular; expected
            warnings.filterwarnings("ignore", message="Variables are collinear")
            self.pipeline_.fit(X, y)
        self.classes_ = self.pipeline_.classes_
        self.train_embeddings_ = self.pipeline_[:-1].transform(X)
        self.train_labels_ = y
        return self

    @staticmethod
    def _clamped(name: str, requested: int | None, default: int, limit: int) -> int:
        if requested is None:
            return default
        if requested < 1:
            raise ValueError(f"{name}={requested}: must be at least 1")
        if requested > limit:
            warnings.warn(f"{name}={requested} exceeds what the training data supports ({limit}); using {limit}",
                          stacklevel=3)
            return limit
        return int(requested)

    def transform(self, geis: np.ndarray) -> np.ndarray:
        """GEIs ``[N, H, W]`` or ``[N, D]`` → LDA embeddings ``[N, n_lda_]``."""
        check_is_fitted(self, "pipeline_")
        return self.pipeline_[:-1].transform(_as_vectors(geis))

    def predict(self, geis: np.ndarray) -> np.ndarray:
        """The subject of each GEI's nearest training GEI in the LDA space, ``[N]``."""
        check_is_fitted(self, "pipeline_")
        return self.pipeline_.predict(_as_vectors(geis))

    def decision_function(self, geis: np.ndarray) -> np.ndarray:
        """Scores ``[N, C]`` (columns = ``classes_``): minus the distance to each subject's nearest training GEI.

        ``argmax`` is the 1-NN prediction; summing the scores of a sequence's cycles gives a sequence vote.
        """
        check_is_fitted(self, "pipeline_")
        distance = pairwise_distances(self.transform(geis), self.train_embeddings_, metric=_SKLEARN_METRIC[self.metric])
        scores = np.empty((len(distance), len(self.classes_)))
        for k, subject in enumerate(self.classes_):
            scores[:, k] = -distance[:, self.train_labels_ == subject].min(1)
        return scores


def run_gei_pca_lda(cache, protocol: str, holdout_seed: int = 0, num_train_subjects: int | None = None,
                    n_pca: int | None = None, n_lda: int | None = None, metric: str = "euc",
                    aggregate: str = "sequence") -> dict:
    """GEI+PCA+LDA on a :class:`~mocapkit.datasets.casia_b.cache.GEICache` under one protocol.

    Args:
        cache: the GEI cache.
        protocol: ``"closed_set"``: fit on the training part of ``closed_set_split(seed=holdout_seed)``
            (all of it: the baseline needs no validation set, unlike the CNN) and classify the held-out
            GEIs over all subjects; ``"cross_subject"``: fit on every GEI of the training subjects of
            ``cross_subject_subjects(num_train_subjects)`` and match the test subjects' LDA embeddings
            gallery-to-probe.
        holdout_seed, num_train_subjects: as the CNN's data module (``data.holdout_seed``,
            ``data.num_train_subjects``), so both methods see the same split.
        n_pca, n_lda, metric: see :class:`GEIPCALDA`. aggregate: see :func:`cross_view_rank1`.

    Returns:
        ``{"method", "protocol", "n_pca", "n_lda", "metric", "train_geis", "test_geis", "train_subjects",
        "test_subjects", "fit_seconds", "report"}``; ``report`` is a :func:`closed_set_report` (subject task
        only) or a :func:`cross_view_rank1` report.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol={protocol!r}: expected one of {PROTOCOLS}")
    if len(cache) == 0:
        raise ValueError(f"{cache.root}: the GEI cache is empty")
    geis = cache.all_geis
    subjects = np.asarray(cache.subjects, dtype=np.int64)
    if protocol == "closed_set":
        train_idx, test_idx = closed_set_split(subjects, cache.conditions, cache.sequences, cache.views,
                                               seed=holdout_seed)
        train_subjects = test_subjects = np.unique(subjects)
    else:
        train_subjects, test_subjects = cross_subject_subjects(subjects, num_train_subjects)
        train_idx = np.flatnonzero(np.isin(subjects, train_subjects))
        test_idx = np.flatnonzero(np.isin(subjects, test_subjects))
    if not len(train_idx) or not len(test_idx):
        raise ValueError(f"{cache.root}: protocol {protocol} leaves {len(train_idx)} training and {len(test_idx)} "
                         "test GEIs; both need samples")
    unseen = np.setdiff1d(subjects[test_idx], subjects[train_idx]) if protocol == "closed_set" else []
    if len(unseen):
        raise ValueError(f"{cache.root}: closed-set test subjects {unseen.tolist()} have no training GEIs "
                         "(each needs a second sequence of some view and condition)")

    def pixels(idx: np.ndarray) -> np.ndarray:  # uint8 → float32 in [0, 1]
        return geis[idx].astype(np.float32) / np.float32(255)

    start = time.perf_counter()
    model = GEIPCALDA(n_pca=n_pca, n_lda=n_lda, metric=metric).fit(pixels(train_idx), subjects[train_idx])
    fit_seconds = time.perf_counter() - start
    view_labels = np.searchsorted(np.asarray(VIEWS), cache.views[test_idx])
    if protocol == "closed_set":
        scores = model.decision_function(pixels(test_idx))
        report = closed_set_report({
            "subject_logits": scores, "subjects": np.searchsorted(model.classes_, subjects[test_idx]),
            "subject_ids": subjects[test_idx], "views": view_labels, "conditions": cache.conditions[test_idx],
            "sequences": cache.sequences[test_idx]})
    else:
        report = cross_view_rank1(model.transform(pixels(test_idx)), subjects[test_idx],
                                  cache.conditions[test_idx], cache.sequences[test_idx], cache.views[test_idx],
                                  metric=metric, aggregate=aggregate)
    return {"method": "GEI+PCA+LDA", "protocol": protocol, "n_pca": int(model.n_pca_), "n_lda": int(model.n_lda_),
            "metric": metric, "train_geis": len(train_idx), "test_geis": len(test_idx),
            "train_subjects": train_subjects.tolist(), "test_subjects": test_subjects.tolist(),
            "fit_seconds": round(fit_seconds, 3), "report": report}
