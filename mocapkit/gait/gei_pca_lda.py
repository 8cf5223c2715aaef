"""The classical GEI baseline: PCA, then LDA, then the nearest training GEI (Han & Bhanu 2006; Sarkar et al. 2005).

A Gait Energy Image ``[H, W]`` is flattened to a vector of ``H·W`` pixels. PCA first reduces it
to ``n_pca`` components, so that LDA's within-class scatter matrix is full rank (it has rank at
most ``N − C`` for ``N`` training GEIs of ``C`` subjects), then LDA projects to at most ``C − 1``
discriminant directions. A probe is given the subject of its nearest training GEI in that space.

:class:`GEIPCALDA` is a scikit-learn estimator (``fit``/``transform``/``predict``) built from
``PCA``, ``LinearDiscriminantAnalysis`` and ``KNeighborsClassifier(n_neighbors=1)`` in a
``Pipeline``: parameters are stored untouched in ``__init__`` and checked in ``fit``, so it clones,
takes ``set_params`` and runs inside scikit-learn's ``Pipeline`` and ``GridSearchCV``. The comparison
runner (:mod:`mocapkit.evaluation.compare`, ``configs/compare/gei_pca_lda.yaml``) applies it to a GEI
cache under the thesis's closed-set protocol and OpenGait's cross-subject protocol on the same splits
as the CNNs and scores it with the same metric code (:mod:`mocapkit.gait.metrics`).
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, TransformerMixin
from sklearn.decomposition import PCA
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.metrics import pairwise_distances
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted

#: Upper bound on the default number of PCA components.
DEFAULT_PCA_CAP = 150
_SKLEARN_METRIC = {"euc": "euclidean", "cos": "cosine"}


def _as_vectors(geis, name: str = "geis") -> np.ndarray:
    """``[N, H, W]`` or ``[N, D]`` → float32 ``[N, D]`` (``check_array``: non-empty, finite, numeric)."""
    geis = check_array(geis, allow_nd=True, dtype=np.float32, input_name=name)
    if geis.ndim not in (2, 3):
        raise ValueError(f"{name} must be a non-empty [N, H, W] or [N, D] array, got shape {geis.shape}")
    return geis.reshape(len(geis), -1)


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
    ``n_features_in_`` (pixels ``D``), ``n_pca_``, ``n_lda_``, ``train_embeddings_`` ``[N, n_lda_]``,
    ``train_labels_``. Before ``fit``, ``transform`` / ``predict`` / ``decision_function`` raise
    ``sklearn.exceptions.NotFittedError``.
    """

    def __init__(self, n_pca: int | None = None, n_lda: int | None = None, metric: str = "euc", random_state: int = 0):
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
        check_classification_targets(y)
        classes = np.unique(y)
        if len(classes) < 2:
            raise ValueError(f"LDA needs at least 2 subjects in training, got {len(classes)}")
        n, dims, n_classes = len(X), X.shape[1], len(classes)
        if n <= n_classes:
            raise ValueError(
                f"LDA needs more training GEIs than subjects (some subject with two), got {n} GEIs "
                f"of {n_classes} subjects"
            )
        pca_limit = min(n - n_classes, dims)
        self.n_pca_ = self._clamped("n_pca", self.n_pca, min(pca_limit, DEFAULT_PCA_CAP), pca_limit)
        lda_limit = max(1, min(n_classes - 1, self.n_pca_))
        self.n_lda_ = self._clamped("n_lda", self.n_lda, lda_limit, lda_limit)
        self.pipeline_ = Pipeline(
            [
                ("pca", PCA(n_components=self.n_pca_, random_state=self.random_state)),
                ("lda", LinearDiscriminantAnalysis(n_components=self.n_lda_, solver="svd")),
                (
                    "nearest",
                    KNeighborsClassifier(n_neighbors=1, metric=_SKLEARN_METRIC[self.metric], algorithm="brute"),
                ),
            ]
        )
        with warnings.catch_warnings():  # few GEIs per subject make LDA's covariance near-singular; expected
            warnings.filterwarnings("ignore", message="Variables are collinear")
            self.pipeline_.fit(X, y)
        self.classes_ = self.pipeline_.classes_
        self.n_features_in_ = dims
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
            warnings.warn(
                f"{name}={requested} exceeds what the training data supports ({limit}); using {limit}", stacklevel=3
            )
            return limit
        return int(requested)

    def _check_features(self, geis) -> np.ndarray:
        X = _as_vectors(geis)
        if X.shape[1] != self.n_features_in_:
            raise ValueError(f"geis have {X.shape[1]} pixels each, the model was fitted on {self.n_features_in_}")
        return X

    def transform(self, geis: np.ndarray) -> np.ndarray:
        """GEIs ``[N, H, W]`` or ``[N, D]`` → LDA embeddings ``[N, n_lda_]``."""
        check_is_fitted(self, "pipeline_")
        return self.pipeline_[:-1].transform(self._check_features(geis))

    def predict(self, geis: np.ndarray) -> np.ndarray:
        """The subject of each GEI's nearest training GEI in the LDA space, ``[N]``."""
        check_is_fitted(self, "pipeline_")
        return self.pipeline_.predict(self._check_features(geis))

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
