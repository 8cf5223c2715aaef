"""Dynamic time warping retrieval: the baseline a user would otherwise reach for, and our label-free default.

:class:`DTWRetrieval` ranks the database by the multivariate DTW distance (dtaidistance's C implementation,
``dtw_ndim.distance_matrix_fast``: squared Euclidean inner distance, the square root of the warped sum) between a
query's frame sequence and each database clip's, on per-frame features of the normalised landmarks
(:func:`~mocapkit.motion.geometry.normalised_landmarks`, 30 fps by default):

- ``"positions"``: the 20 landmarks' coordinates, ``[T, 60]`` metres (Zhou 2014 §1.7 normalisation);
- ``"relational"``: the soft relational pose features of :func:`~mocapkit.retrieval.features.relational_features`
  (Müller & Röder style: which hand is raised, which knee bent, ...), ``[T, F]`` in ``[0, 1]``.

Given several features (``features=["positions", "relational"]``), each one's DTW distance is divided by its
**scale**, the median distance among database clips (learned at ``fit``), and the quotients are summed, so that
metres and relational units weigh alike.

``window`` is the Sakoe–Chiba band as a fraction of the longer sequence's length (None: unconstrained; the band
also lets DTW match clips whose lengths differ by more than the band, as dtaidistance widens it by the length
difference). ``length_normalised`` divides each distance by ``sqrt(len(query) + len(candidate))`` so that long
clips are not pushed down the list only for their length (the sum under the square root grows with the path).
``hubness="mutual_proximity"`` re-ranks the distances by :func:`~mocapkit.retrieval.hubness.mutual_proximity`
(no labels, no parameter), which discounts clips near to every query.

``fit`` keeps the database's feature sequences; with several features or mutual proximity it also computes the
DTW distances from every database clip to a reference subset of at most ``n_reference`` database clips (all of
them on libraries of up to ``n_reference`` clips), for the scales and the statistics.
"""

from __future__ import annotations

import numpy as np

from mocapkit.retrieval.base import RetrievalMethod, ragged_from_state, ragged_to_state
from mocapkit.retrieval.hubness import METHODS as HUBNESS_METHODS
from mocapkit.retrieval.hubness import (
    database_statistics,
    mutual_proximity,
    reference_indices,
)

FEATURES = ("positions", "relational")
#: Queries per dtaidistance call in :meth:`DTWRetrieval._feature_distances`.
QUERY_BLOCK = 256


def frame_features(sequence: np.ndarray, features: str, fps: float) -> np.ndarray:
    """float64 ``[T, d]`` per-frame features of a normalised landmark sequence ``[T, 20, 3]``."""
    if features == "positions":
        return sequence.reshape(len(sequence), -1).astype(np.float64)
    if features == "relational":
        from mocapkit.retrieval.features import relational_features

        return np.asarray(relational_features(sequence, fps=fps, soft=True), dtype=np.float64)
    raise ValueError(f"features must be one of {FEATURES}, got {features!r}")


class DTWRetrieval(RetrievalMethod):
    """Rank by DTW distance on per-frame features (see the module docstring).

    Args:
        features: ``"positions"``, ``"relational"``, or a list of them (distances scaled and summed).
        window: Sakoe–Chiba band, a fraction of the longer sequence (None: no band).
        length_normalised: divide by ``sqrt(len_q + len_db)``.
        hubness: None or ``"mutual_proximity"`` (:mod:`mocapkit.retrieval.hubness`).
        n_reference: the most database clips the scales and the mutual-proximity statistics are taken against.
        fps, heading: the normalisation (:func:`~mocapkit.motion.geometry.normalised_landmarks`).
        parallel: let dtaidistance use OpenMP threads.
    """

    def __init__(
        self,
        features: str | list[str] = "positions",
        window: float | None = None,
        length_normalised: bool = True,
        hubness: str | None = None,
        n_reference: int = 512,
        fps: float = 30.0,
        heading: str = "frame",
        parallel: bool = True,
    ):
        self.features = features
        self.window = window
        self.length_normalised = length_normalised
        self.hubness = hubness
        self.n_reference = n_reference
        self.fps = fps
        self.heading = heading
        self.parallel = parallel

    @property
    def feature_names(self) -> list[str]:
        names = [self.features] if isinstance(self.features, str) else list(self.features)
        unknown = [n for n in names if n not in FEATURES]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(f"features must be one of {FEATURES} or a list of distinct ones, got {self.features!r}")
        return names

    # ------------------------------------------------------------------ the contract
    def _encode_sequences(self, sequences):
        return {
            name: [np.ascontiguousarray(frame_features(s, name, self.fps)) for s in sequences]
            for name in self.feature_names
        }

    def _fit_sequences(self, sequences, y):
        if self.hubness is not None and self.hubness not in HUBNESS_METHODS:
            raise ValueError(f"hubness must be None or one of {HUBNESS_METHODS}, got {self.hubness!r}")
        database = self._encode_sequences(sequences)
        names = self.feature_names
        self.scales_ = np.ones(len(names))
        if len(names) == 1 and self.hubness is None:
            return database
        reference = reference_indices(len(sequences), int(self.n_reference))
        if len(reference) < 2:
            raise ValueError(
                f"{type(self).__name__}: several features or mutual proximity need a database of "
                f"at least 2 clips, got {len(sequences)}"
            )
        raw = [self._feature_distances(database[n], [database[n][i] for i in reference]) for n in names]
        off_diagonal = np.ones(raw[0].shape, dtype=bool)
        off_diagonal[reference, np.arange(len(reference))] = False
        if len(names) > 1:
            self.scales_ = np.array([np.median(d[off_diagonal]) for d in raw])
        if self.hubness is not None:
            combined = sum(d / s for d, s in zip(raw, self.scales_))
            self.database_mean_, self.database_std_ = database_statistics(combined, reference)
        return database

    def _distances(self, queries, database) -> np.ndarray:
        names = self.feature_names
        d = sum(self._feature_distances(queries[n], database[n]) / s for n, s in zip(names, self.scales_))
        if self.hubness is not None:
            d = mutual_proximity(d, self.database_mean_, self.database_std_)
        return d

    def _feature_distances(self, queries: list[np.ndarray], database: list[np.ndarray]) -> np.ndarray:
        """float64 ``[n_queries, n_database]`` DTW distances of one feature's sequences.

        Queries go to dtaidistance in blocks of :data:`QUERY_BLOCK` (its matrix is ``(queries + database)²``), with
        a progress bar on a terminal when there are several blocks (``fit`` with mutual proximity on a large library
        runs minutes: every clip against the reference clips).
        """
        from dtaidistance import dtw_ndim
        from tqdm import tqdm

        window = None
        if self.window is not None:
            longest = max(len(s) for s in (*queries, *database))
            window = max(1, int(np.ceil(float(self.window) * longest)))
        starts = range(0, len(queries), QUERY_BLOCK)
        blocks = []
        for start in tqdm(starts, desc="DTW", unit="block", disable=None if len(starts) > 1 else True, leave=False):
            chunk = list(queries[start : start + QUERY_BLOCK])
            nq = len(chunk)
            full = dtw_ndim.distance_matrix_fast(
                chunk + list(database),
                window=window,
                block=((0, nq), (nq, nq + len(database))),
                compact=False,
                parallel=bool(self.parallel),
            )
            blocks.append(np.asarray(full[:nq, nq:], dtype=np.float64))
        d = np.concatenate(blocks, axis=0) if blocks else np.zeros((0, len(database)))
        if self.length_normalised:
            lq = np.array([len(s) for s in queries], dtype=np.float64)
            ldb = np.array([len(s) for s in database], dtype=np.float64)
            d = d / np.sqrt(lq[:, None] + ldb[None, :])
        return d

    # ------------------------------------------------------------------ persistence
    def _state(self) -> dict[str, np.ndarray]:
        state = {"scales": self.scales_}
        for name in self.feature_names:
            state.update(ragged_to_state(f"database_{name}", self.database_[name]))
        if self.hubness is not None:
            state.update(database_mean=self.database_mean_, database_std=self.database_std_)
        return state

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.database_ = {name: ragged_from_state(f"database_{name}", state) for name in self.feature_names}
        self.scales_ = np.asarray(state["scales"], dtype=np.float64)
        if self.hubness is not None:
            self.database_mean_ = np.asarray(state["database_mean"], dtype=np.float64)
            self.database_std_ = np.asarray(state["database_std"], dtype=np.float64)
        self.n_database_ = len(self.database_[self.feature_names[0]])
