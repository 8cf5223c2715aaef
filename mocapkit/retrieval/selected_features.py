"""Euclidean ranking on (selected) clip features: AMFS retrieval and its baselines (Wang 2017 ch. 5).

The pipeline of ``../shared/spec/thesis-wang-2017-mocap-processing.md`` §4.1 (Fig 5.1): every clip becomes a
fixed-length vector of one or two views (§4.5: :func:`~mocapkit.retrieval.features.hod`, the HOD of its
landmarks, and :class:`~mocapkit.retrieval.features.GPFBagOfWords`, the LLC bag of words of its geometric pose
features); the method learns on the database (label-free: the database is the training set) the GPF codebook, the
z-score of the stacked features and, with ``selector``, a feature selection (:class:`~mocapkit.retrieval.feature_selection.AMFS`, or a baseline: :class:`~mocapkit.retrieval.feature_selection.LaplacianScore`,
:class:`~mocapkit.retrieval.feature_selection.SPEC`, :class:`~mocapkit.retrieval.feature_selection.UDFS`); queries
get the same
codebook, z-score and selection, and the database is ranked by **plain Euclidean distance**.
"""

from __future__ import annotations

import numpy as np
from sklearn.metrics.pairwise import euclidean_distances

from mocapkit.retrieval.base import RetrievalMethod
from mocapkit.retrieval.feature_selection import AMFS, SPEC, UDFS, LaplacianScore
from mocapkit.retrieval.features import GPFBagOfWords, hod

VIEWS = ("hod", "gpf")
SELECTORS = (None, "amfs", "laplacian", "spec", "udfs")


class FeatureRetrieval(RetrievalMethod):
    """Query by example with Euclidean distances on HOD and / or GPF-BoVW clip features, optionally selected.

    Args:
        views: the feature views, any non-empty subset of ``("hod", "gpf")`` in any order (the stacking order).
        selector: ``None`` (all stacked features, z-scored), ``"amfs"`` (AMFS on the views), or on the stacked
            views ``"laplacian"`` (Laplacian Score), ``"spec"`` (SPEC, ``φ3``; its ``φ2`` is the Laplacian Score) or ``"udfs"`` (UDFS, its
            ``n_components`` and ``gamma`` at their defaults; one D × D eigenproblem per iteration).
        n_features: features kept by the selector (capped at the stacked dimension; ignored without selector).
        r, mu: AMFS's view-weight exponent and local-regression ridge (``mu`` is UDFS's ridge too).
        n_neighbors: the neighbourhood size of the selector (AMFS's and UDFS's local regressions, the sample
            included; the Laplacian Score's and SPEC's graph), capped by the database size.
        n_words: GPF codebook size.
        fps, heading: of :func:`~mocapkit.motion.geometry.normalised_landmarks`.
        random_state: seed of the GPF codebook and of AMFS's initial selection.

    Defaults: ``n_features=200``, ``n_neighbors=3``, ``n_words=64`` were chosen on HDM05 (the 11-class, 4-actor
    cut) by nested cross-actor retrieval inside the training actors (database = 2 actors, queries = the third):
    smaller neighbourhoods and codebooks were consistently better there (AMFS inner mAP 0.94 at k = 3, 64 words,
    200 features vs 0.80 at k = 10, 256 words); ``r`` and ``mu`` mattered little (r in 2–8, mu in 0.01–10).
    The spec (§4.5 [rec]) suggests 256–1024 words, which on this data set was worse.

    Learned attributes: ``gpf_`` (the fitted :class:`GPFBagOfWords`, or ``None``), ``mean_`` / ``scale_`` (the
    z-score of the stacked features ``[D]``), ``selected_`` (int64 column indices kept, ``arange(D)`` without
    selector), ``view_dims_``, ``selector_`` (the fitted selector, for inspection: ``alphas_``, ``objective_``;
    not restored by :meth:`_set_state`), ``database_`` float32 ``[n_database, n_selected]``.
    """

    label_free = True
    needs_run = False
    min_frames = 2

    def __init__(
        self,
        views=("hod", "gpf"),
        selector=None,
        n_features: int = 200,
        r: float = 4.0,
        mu: float = 0.1,
        n_neighbors: int = 3,
        n_words: int = 64,
        fps: float = 30.0,
        heading: str = "frame",
        random_state=0,
    ):
        self.views = views
        self.selector = selector
        self.n_features = n_features
        self.r = r
        self.mu = mu
        self.n_neighbors = n_neighbors
        self.n_words = n_words
        self.fps = fps
        self.heading = heading
        self.random_state = random_state

    # ------------------------------------------------------------------ checks and views
    def _views(self) -> tuple[str, ...]:
        views = (self.views,) if isinstance(self.views, str) else tuple(self.views)
        if not views or len(set(views)) != len(views) or not set(views) <= set(VIEWS):
            raise ValueError(f"views must be a non-empty subset of {VIEWS} without repeats, got {self.views!r}")
        if self.selector not in SELECTORS:
            raise ValueError(f"selector must be one of {SELECTORS}, got {self.selector!r}")
        return views

    def _new_gpf(self) -> GPFBagOfWords:
        return GPFBagOfWords(n_words=self.n_words, fps=self.fps, random_state=self.random_state)

    def _view_features(self, sequences: list[np.ndarray]) -> list[np.ndarray]:
        out = []
        for view in self._views():
            if view == "hod":
                out.append(np.stack([hod(s) for s in sequences]).astype(np.float64))
            else:
                out.append(self.gpf_.transform(sequences).astype(np.float64))
        return out

    # ------------------------------------------------------------------ RetrievalMethod
    def _fit_sequences(self, sequences: list[np.ndarray], y) -> np.ndarray:
        """Fit the codebook, z-score and selector on the database; returns its encoding (its views are computed
        once, here)."""
        views = self._views()
        self.gpf_ = self._new_gpf().fit(sequences) if "gpf" in views else None
        features = self._view_features(sequences)
        D = sum(f.shape[1] for f in features)
        d = int(min(int(self.n_features), D))
        if self.selector is None:
            X = np.concatenate(features, axis=1)
            self.mean_ = X.mean(0)
            std = X.std(0)
            self.scale_ = np.where(std > 1e-12, std, 1.0)
            self.selected_ = np.arange(D, dtype=np.int64)
            self.selector_ = None
        else:
            if self.selector == "amfs":
                sel = AMFS(
                    n_features=d, r=self.r, mu=self.mu, n_neighbors=self.n_neighbors, random_state=self.random_state
                )
            elif self.selector == "udfs":
                sel = UDFS(n_features=d, mu=self.mu, n_neighbors=self.n_neighbors)
            elif self.selector == "spec":
                sel = SPEC(n_features=d, n_neighbors=self.n_neighbors)
            else:
                sel = LaplacianScore(n_features=d, n_neighbors=self.n_neighbors)
            sel.fit(features)
            self.mean_, self.scale_ = sel.mean_, sel.scale_
            self.selected_ = np.asarray(sel.selected_, dtype=np.int64)
            self.selector_ = sel
            if hasattr(sel, "alphas_"):
                self.alphas_ = np.asarray(sel.alphas_, dtype=np.float64)
        self.view_dims_ = np.array([f.shape[1] for f in features], dtype=np.int64)
        return self._encode_features(features)

    def _encode_sequences(self, sequences: list[np.ndarray]) -> np.ndarray:
        """float32 ``[n, n_selected]``: the z-scored selected features of each sequence."""
        return self._encode_features(self._view_features(sequences))

    def _encode_features(self, features: list[np.ndarray]) -> np.ndarray:
        """float32 ``[n, n_selected]`` from the views ``[n, d_v]`` of :meth:`_view_features`."""
        X = np.concatenate(features, axis=1)
        if X.shape[1] != int(np.sum(self.view_dims_)):
            raise ValueError(
                f"views {self.views!r} give {X.shape[1]} features, the fitted state has "
                f"{int(np.sum(self.view_dims_))}: restore a state with the parameters it was fitted with"
            )
        s = self.selected_
        return ((X[:, s] - self.mean_[s]) / self.scale_[s]).astype(np.float32)

    def _distances(self, queries, database) -> np.ndarray:
        return euclidean_distances(np.asarray(queries, dtype=np.float64), np.asarray(database, dtype=np.float64))

    def _state(self) -> dict[str, np.ndarray]:
        self._check_fitted()
        state = {
            "mean": np.asarray(self.mean_, dtype=np.float64),
            "scale": np.asarray(self.scale_, np.float64),
            "selected": np.asarray(self.selected_, dtype=np.int64),
            "view_dims": np.asarray(self.view_dims_, dtype=np.int64),
            "views": np.array([VIEWS.index(v) for v in self._views()], dtype=np.int64),
            "database": np.asarray(self.database_, dtype=np.float32),
        }
        if self.gpf_ is not None:
            state.update(gpf_mean=self.gpf_.mean_, gpf_scale=self.gpf_.scale_, gpf_codebook=self.gpf_.codebook_)
        if self.selector_ is not None and hasattr(self.selector_, "alphas_"):
            state["alphas"] = np.asarray(self.selector_.alphas_, dtype=np.float64)
        return state

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        views = self._views()
        if "views" in state and [VIEWS[int(i)] for i in state["views"]] != list(views):
            raise ValueError(
                f"the state was fitted with views {[VIEWS[int(i)] for i in state['views']]}, "
                f"this method has views={self.views!r}"
            )
        if "gpf" in views:
            if "gpf_codebook" not in state:
                raise ValueError("state has no GPF codebook but views include 'gpf'")
            gpf = self._new_gpf()
            gpf.mean_ = np.asarray(state["gpf_mean"], dtype=np.float64)
            gpf.scale_ = np.asarray(state["gpf_scale"], dtype=np.float64)
            gpf.codebook_ = np.asarray(state["gpf_codebook"], dtype=np.float64)
            self.gpf_ = gpf
        else:
            self.gpf_ = None
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.scale_ = np.asarray(state["scale"], dtype=np.float64)
        self.selected_ = np.asarray(state["selected"], dtype=np.int64)
        self.view_dims_ = np.asarray(state["view_dims"], dtype=np.int64)
        self.selector_ = None
        if "alphas" in state:
            self.alphas_ = np.asarray(state["alphas"], dtype=np.float64)
        self.database_ = np.asarray(state["database"], dtype=np.float32)
        self.n_database_ = len(self.database_)
