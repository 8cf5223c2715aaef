"""Dynamic time warping retrieval: the baseline a user would otherwise reach for.

:class:`DTWRetrieval` ranks the database by the multivariate DTW distance (dtaidistance's C implementation,
``dtw_ndim.distance_matrix_fast``: squared Euclidean inner distance, the square root of the warped sum) between a
query's frame sequence and each database clip's, on one of two per-frame features of the normalised landmarks
(:func:`~mocapkit.retrieval.skeleton.normalised_landmarks`, 30 fps by default):

- ``"positions"``: the 20 landmarks' coordinates, ``[T, 60]`` metres (Zhou 2014 §1.7 normalisation);
- ``"relational"``: the soft relational pose features of :func:`~mocapkit.retrieval.features.relational_features`
  (Müller & Röder style: which hand is raised, which knee bent, ...), ``[T, F]`` in ``[0, 1]``.

``window`` is the Sakoe–Chiba band as a fraction of the longer sequence's length (None: unconstrained; the band
also lets DTW match clips whose lengths differ by more than the band, as dtaidistance widens it by the length
difference). ``length_normalised`` divides each distance by ``sqrt(len(query) + len(candidate))`` so that long
clips are not pushed down the list only for their length (the sum under the square root grows with the path).
There is nothing to learn: ``fit`` keeps the database's feature sequences.
"""
from __future__ import annotations

import numpy as np

from mocapkit.retrieval.base import RetrievalMethod, ragged_from_state, ragged_to_state

FEATURES = ("positions", "relational")


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
        features: ``"positions"`` or ``"relational"``.
        window: Sakoe–Chiba band, a fraction of the longer sequence (None: no band).
        length_normalised: divide by ``sqrt(len_q + len_db)``.
        fps, heading: the normalisation (:func:`~mocapkit.retrieval.skeleton.normalised_landmarks`).
        parallel: let dtaidistance use OpenMP threads.
    """

    def __init__(self, features: str = "positions", window: float | None = None, length_normalised: bool = True,
                 fps: float = 30.0, heading: str = "frame", parallel: bool = True):
        self.features = features
        self.window = window
        self.length_normalised = length_normalised
        self.fps = fps
        self.heading = heading
        self.parallel = parallel

    def _encode_sequences(self, sequences):
        if self.features not in FEATURES:
            raise ValueError(f"features must be one of {FEATURES}, got {self.features!r}")
        return [np.ascontiguousarray(frame_features(s, self.features, self.fps)) for s in sequences]

    def _distances(self, queries, database) -> np.ndarray:
        from dtaidistance import dtw_ndim

        nq, ndb = len(queries), len(database)
        series = list(queries) + list(database)
        window = None
        if self.window is not None:
            longest = max(len(s) for s in series)
            window = max(1, int(np.ceil(float(self.window) * longest)))
        full = dtw_ndim.distance_matrix_fast(series, window=window, block=((0, nq), (nq, nq + ndb)), compact=False,
                                             parallel=bool(self.parallel))
        d = np.asarray(full[:nq, nq:], dtype=np.float64)
        if self.length_normalised:
            lq = np.array([len(s) for s in queries], dtype=np.float64)
            ldb = np.array([len(s) for s in database], dtype=np.float64)
            d = d / np.sqrt(lq[:, None] + ldb[None, :])
        return d

    def _state(self) -> dict[str, np.ndarray]:
        return ragged_to_state("database", self.database_)

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.database_ = ragged_from_state("database", state)
        self.n_database_ = len(self.database_)
