"""The one contract of every retrieval method, classical or learned: fit on a database, rank queries.

A retrieval method is a scikit-learn estimator (parameters stored untouched in ``__init__``, learned state in
attributes ending in ``_``, ``NotFittedError`` before ``fit``):

``fit(motions, y=None) -> self``
    the **database**: a sequence of :class:`~mocapkit.motion.container.Motion` (any layout with body
    landmarks, any frame rate). The method learns what it learns from them (a dictionary, a codebook, a feature
    selection; labels ``y`` only where ``supervised``) and keeps the encoding of every database clip.
``distances(queries) -> float64 [n_queries, n_database]``
    smaller is nearer; a similarity method returns its negated score.
``search(queries, k) -> (indices int64 [n_queries, k], distances float64 [n_queries, k])``
    the ``k`` nearest database clips of each query, nearest first (ties by database order); the default sorts
    :meth:`distances`, an embedding method answers from an approximate-nearest-neighbour index.
``encode(motions)``
    the method's representation of clips (what ``fit`` stores for the database), for inspection and reuse.
``fit_sequences(sequences, y=None)`` / ``add_sequences(sequences)``
    the same from what :meth:`~RetrievalMethod.sequences` returned for the motions (the index computes them in
    worker processes).
``add(motions) -> self``
    append clips to the fitted database without fitting again (``mocapkit index --add``): they are encoded with
    what ``fit`` learned and take the database indices ``n_database_`` onwards, in order. A method with nothing
    to learn answers afterwards exactly as if fitted on the union; one that learns from the database (a codebook,
    a feature selection, a dictionary) keeps what it learned from the clips it was fitted on.

Every method first turns a motion into :func:`~mocapkit.motion.geometry.normalised_landmarks` ``[T, 20, 3]``
(parameters ``fps`` and ``heading`` of every method). Subclasses implement:

``_fit_sequences(sequences, y)``   learn from the database's landmark sequences (default: nothing to learn); it
                                   may return the database's encoding when learning computed it (else None);
``_encode_sequences(sequences)``   the representation of sequences;
``_add_sequences(sequences)``      append new database sequences (default: their encodings as rows of a 2-D
                                   ``database_`` array; a method whose database is not one raises
                                   ``NotImplementedError``, and the index refuses ``--add``);
``_distances(encoded_queries, encoded_database)``   ``[n_q, n_db]``;
``_state() -> dict[str, np.ndarray]`` / ``_set_state(state)``   learned parameters and database encodings as
plain arrays (no pickles), which :mod:`mocapkit.retrieval.index` writes to ``state.npz`` beside a JSON manifest.

Class attributes: ``label_free`` (False when ``fit`` needs labels), ``needs_run`` (True when the method needs
a trained checkpoint), ``min_frames`` (the shortest clip, in frames after resampling, the method can encode).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import SkeletonInputError, normalised_landmarks


def motion_list(motions: Motion | Sequence[Motion], what: str = "input") -> list[Motion]:
    """``motions`` as a non-empty list of :class:`Motion` (one Motion is a list of one); a clear error otherwise."""
    motions = [motions] if isinstance(motions, Motion) else list(motions)
    if not motions:
        raise SkeletonInputError(f"no {what} motions (an empty list or folder)")
    for motion in motions:
        if not isinstance(motion, Motion):
            raise TypeError(f"{what} items must be Motion objects (read_motion), got {type(motion).__name__}")
    return motions


class RetrievalMethod(BaseEstimator):
    """Base class of retrieval methods (see the module docstring). Subclasses set ``fps`` and ``heading``."""

    label_free = True
    needs_run = False
    min_frames = 2

    # ------------------------------------------------------------------ public contract
    def fit(self, motions: Sequence[Motion], y=None) -> RetrievalMethod:
        return self.fit_sequences(self.sequences(motions, what="database"), y)

    def fit_sequences(self, sequences: list, y=None) -> RetrievalMethod:
        """:meth:`fit` from what :meth:`sequences` returned for the database motions (computed elsewhere: the index
        reads and normalises files in worker processes)."""
        if not self.label_free:
            if y is None:
                raise ValueError(f"{type(self).__name__} is supervised: fit(motions, y) needs one label per motion")
            y = np.asarray(y)
            if len(y) != len(sequences):
                raise ValueError(f"{len(y)} labels for {len(sequences)} database motions")
        encoded = self._fit_sequences(sequences, y)
        self.database_ = self._encode_sequences(sequences) if encoded is None else encoded
        self.n_database_ = len(sequences)
        return self

    def add(self, motions: Sequence[Motion]) -> RetrievalMethod:
        """Append database clips without fitting again (the module docstring); returns ``self``.

        Raises:
            NotImplementedError: the method cannot append to its database (fit it on the union instead).
        """
        self._check_fitted()
        return self.add_sequences(self.sequences(motions, what="added"))

    def add_sequences(self, sequences: list) -> RetrievalMethod:
        """:meth:`add` from what :meth:`sequences` returned for the new motions."""
        self._check_fitted()
        self._add_sequences(sequences)
        self.n_database_ += len(sequences)
        return self

    def encode(self, motions: Sequence[Motion]):
        self._check_fitted()
        return self._encode_sequences(self.sequences(motions, what="query"))

    def distances(self, queries: Sequence[Motion]) -> np.ndarray:
        """float64 ``[n_queries, n_database]``, smaller = nearer."""
        self._check_fitted()
        return np.asarray(self._distances(self.encode(queries), self.database_), dtype=np.float64)

    def search(self, queries: Sequence[Motion], k: int = 10) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest database clips per query (``k <= 0`` or above the size: all), nearest first."""
        d = self.distances(queries)
        return top_k(d, k)

    def sequences(self, motions: Sequence[Motion], what: str = "input") -> list[np.ndarray]:
        """The normalised landmarks ``[T, 20, 3]`` of every motion (checks types and lengths, naming the file)."""
        return [
            normalised_landmarks(motion, fps=self.fps, heading=self.heading, min_frames=self.min_frames)
            for motion in motion_list(motions, what)
        ]

    # ------------------------------------------------------------------ for subclasses
    def _fit_sequences(self, sequences: list[np.ndarray], y):
        """Learn from the database sequences (a no-op for methods with nothing to learn); return the database's
        encoding if learning already computed it, None to have :meth:`_encode_sequences` compute it."""

    def _encode_sequences(self, sequences: list[np.ndarray]):
        raise NotImplementedError

    def _add_sequences(self, sequences: list[np.ndarray]) -> None:
        """Append the encodings of new database sequences (default: rows of a 2-D array ``database_``)."""
        if not isinstance(self.database_, np.ndarray) or self.database_.ndim != 2:
            raise NotImplementedError(
                f"{type(self).__name__} cannot append clips to a fitted database (fit it on all the clips)"
            )
        new = np.asarray(self._encode_sequences(sequences), dtype=self.database_.dtype)
        self.database_ = np.concatenate([self.database_, new], axis=0)

    def _distances(self, queries, database) -> np.ndarray:
        raise NotImplementedError

    def _state(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        raise NotImplementedError

    def _check_fitted(self) -> None:
        if not hasattr(self, "database_"):
            raise NotFittedError(f"{type(self).__name__} is not fitted: call fit(database_motions) first")


def top_k(distances: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices and distances of the ``k`` smallest entries of each row, ascending, ties by index
    (``k <= 0`` or ``k`` above the row length: every entry)."""
    d = np.asarray(distances, dtype=np.float64)
    n = d.shape[1]
    k = n if k <= 0 or k > n else int(k)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    return order.astype(np.int64), np.take_along_axis(d, order, axis=1)


def file_sha1(path: str | os.PathLike) -> str:
    """The hex SHA-1 of a file's bytes (which model an index or an embedding method was built with)."""
    digest = hashlib.sha1()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
