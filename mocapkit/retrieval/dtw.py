"""Dynamic time warping retrieval: the baseline a user would otherwise reach for, and our label-free default.

:class:`DTWRetrieval` ranks the database by the multivariate DTW distance (dtaidistance's C implementation,
``dtw_ndim.distance_matrix_fast``: squared Euclidean inner distance, the square root of the warped sum) between a
query's frame sequence and each database clip's, on per-frame features of the normalised landmarks
(:func:`~mocapkit.motion.geometry.normalised_landmarks`, 30 fps by default):

- ``"positions"``: the 20 landmarks' coordinates, ``[T, 60]`` metres (Zhou 2014 §1.7 normalisation);
- ``"relational"``: the soft relational pose features of :func:`~mocapkit.retrieval.features.relational_features`
  (Müller & Röder style: which hand is raised, which knee bent, ...), ``[T, F]`` in ``[0, 1]``.

Given several features (``features=["positions", "relational"]``), each one's DTW distance is divided by its
**scale**, learned at ``fit``, and the quotients are summed, so that metres and relational units weigh alike: with
``scaling="dtw"`` the median DTW distance among database clips; with ``scaling="frames"`` the root-mean-square
distance of the database's frames to their mean frame (linear in the library's frames, no DTW between clips: for
libraries of long takes, ``dtw_takes``, whose clip-to-clip DTW would be quadratic in their length).

``window`` is the Sakoe–Chiba band as a fraction of the longer sequence's length (None: unconstrained; the band
also lets DTW match clips whose lengths differ by more than the band, as dtaidistance widens it by the length
difference). ``length_normalised`` divides each distance by ``sqrt(len(query) + len(candidate))`` so that long
clips are not pushed down the list only for their length (the sum under the square root grows with the path).
``hubness="mutual_proximity"`` re-ranks the distances by :func:`~mocapkit.retrieval.hubness.mutual_proximity`
(no labels, no parameter), which discounts clips near to every query.

``fit`` keeps the database's feature sequences; with several features or mutual proximity it also computes the
DTW distances from every database clip to a reference subset of at most ``n_reference`` database clips (all of
them on libraries of up to ``n_reference`` clips), for the scales and the statistics, and keeps them, so that
:meth:`~mocapkit.retrieval.base.RetrievalMethod.add` appends clips without recomputing the old ones' distances.

:class:`PlainDTWRetrieval` is the baseline a user writes without this package: DTW on **every joint** of the
skeleton as the file gives it, root-centred, resampled to ``fps`` (no landmarks, no retargeting, no heading).
"""

from __future__ import annotations

import numpy as np

from mocapkit.motion.geometry import SkeletonInputError
from mocapkit.retrieval.base import RetrievalMethod, motion_list, ragged_from_state, ragged_to_state
from mocapkit.retrieval.hubness import METHODS as HUBNESS_METHODS
from mocapkit.retrieval.hubness import (
    database_statistics,
    mutual_proximity,
    reference_indices,
)

FEATURES = ("positions", "relational")
SCALINGS = ("dtw", "frames")
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


def frame_moments(sequences: list[np.ndarray]) -> np.ndarray:
    """float64 ``[2 + d]``: the frame count, the sum of the squared frame norms and the sum of the frames of
    ``sequences`` (each ``[T, d]``): what :func:`moments_scale` needs, and additive over libraries."""
    x = np.concatenate([np.asarray(s, dtype=np.float64) for s in sequences])
    return np.concatenate([[len(x), float((x**2).sum())], x.sum(axis=0)])


def moments_scale(moments: np.ndarray) -> float:
    """The root-mean-square distance of the frames to their mean frame, from :func:`frame_moments`."""
    n, squares, total = moments[0], moments[1], moments[2:]
    return float(np.sqrt(max(squares / n - float((total / n) @ (total / n)), 1e-24)))


class DTWRetrieval(RetrievalMethod):
    """Rank by DTW distance on per-frame features (see the module docstring).

    Args:
        features: ``"positions"``, ``"relational"``, or a list of them (distances scaled and summed).
        window: Sakoe–Chiba band, a fraction of the longer sequence (None: no band).
        length_normalised: divide by ``sqrt(len_q + len_db)``.
        hubness: None or ``"mutual_proximity"`` (:mod:`mocapkit.retrieval.hubness`).
        n_reference: the most database clips the scales and the mutual-proximity statistics are taken against.
        scaling: ``"dtw"`` or ``"frames"``, how several features' scales are learned (module docstring).
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
        scaling: str = "dtw",
    ):
        self.features = features
        self.window = window
        self.length_normalised = length_normalised
        self.hubness = hubness
        self.n_reference = n_reference
        self.scaling = scaling
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
        if self.scaling not in SCALINGS:
            raise ValueError(f"scaling must be one of {SCALINGS}, got {self.scaling!r}")
        database = self._encode_sequences(sequences)
        names = self.feature_names
        self.scales_ = np.ones(len(names))
        if self._frame_scaled:
            self.frame_moments_ = {n: frame_moments(database[n]) for n in names}
            self.scales_ = np.array([moments_scale(self.frame_moments_[n]) for n in names])
        if not self._needs_reference:
            return database
        reference = reference_indices(len(sequences), int(self.n_reference))
        if len(reference) < 2:
            raise ValueError(
                f"{type(self).__name__}: several features or mutual proximity need a database of "
                f"at least 2 clips, got {len(sequences)}"
            )
        raw = {n: self._feature_distances(database[n], [database[n][i] for i in reference]) for n in names}
        self._set_reference(reference, raw)
        return database

    @property
    def _frame_scaled(self) -> bool:
        """Whether several features are scaled by their frames' spread (``scaling="frames"``)."""
        return len(self.feature_names) > 1 and self.scaling == "frames"

    @property
    def _needs_reference(self) -> bool:
        """Whether the distances need DTW statistics of the database (scales by DTW, or hubness)."""
        return (len(self.feature_names) > 1 and not self._frame_scaled) or self.hubness is not None

    def _set_reference(self, reference: np.ndarray, raw: dict[str, np.ndarray]) -> None:
        """The reference clips, their raw distances ``[n_database, n_reference]`` per feature, and what is learned
        from them: the scales (median off-diagonal distance per feature) and the mutual-proximity statistics."""
        self.reference_ = np.asarray(reference, dtype=np.int64)
        self.reference_distances_ = raw
        names = self.feature_names
        off_diagonal = np.ones(raw[names[0]].shape, dtype=bool)
        off_diagonal[self.reference_, np.arange(len(self.reference_))] = False
        if len(names) > 1 and not self._frame_scaled:
            self.scales_ = np.array([np.median(raw[n][off_diagonal]) for n in names])
        if self.hubness is not None:
            combined = sum(raw[n] / s for n, s in zip(names, self.scales_))
            self.database_mean_, self.database_std_ = database_statistics(combined, self.reference_)

    def _add_sequences(self, sequences) -> None:
        """Append clips. With scales or mutual proximity: while the union has at most ``n_reference`` clips every
        clip stays a reference clip and the new clips' distances to all clips are added, so the scales and
        statistics are exactly those of ``fit`` on the union; beyond that the reference clips and the scales are
        kept, and only the new clips' statistics (against the same reference clips) are computed."""
        new = self._encode_sequences(sequences)
        names = self.feature_names
        n_old = self.n_database_
        union = {n: list(self.database_[n]) + new[n] for n in names}
        n_total = n_old + len(sequences)
        exact = not self._needs_reference or (n_total <= int(self.n_reference) and len(self.reference_) == n_old)
        if self._frame_scaled:  # the moments of the union's frames: the scales fit on the union would learn
            self.frame_moments_ = {n: self.frame_moments_[n] + frame_moments(new[n]) for n in names}
            if exact:  # (past n_reference clips with mutual proximity the scales are kept, as its statistics are)
                self.scales_ = np.array([moments_scale(self.frame_moments_[n]) for n in names])
        if self._needs_reference:
            if exact:
                raw = {}
                for n in names:
                    # DTW is symmetric: the old clips' distances to the new ones are the transposed new rows
                    cross = self._feature_distances(new[n], union[n])  # [n_new, n_total]
                    old = np.hstack([self.reference_distances_[n], cross[:, :n_old].T])
                    raw[n] = np.vstack([old, cross])
                self._set_reference(np.arange(n_total, dtype=np.int64), raw)
            else:
                rows = {n: self._feature_distances(new[n], [union[n][i] for i in self.reference_]) for n in names}
                if self.hubness is not None:  # the new clips are not reference clips: no self-distance to leave out
                    combined = sum(rows[n] / s for n, s in zip(names, self.scales_))
                    self.database_mean_ = np.concatenate([self.database_mean_, combined.mean(axis=1)])
                    self.database_std_ = np.concatenate([self.database_std_, combined.std(axis=1)])
                self.reference_distances_ = {n: np.vstack([self.reference_distances_[n], rows[n]]) for n in names}
        self.database_ = union

    def _distances(self, queries, database) -> np.ndarray:
        names = self.feature_names
        d = sum(self._feature_distances(queries[n], database[n]) / s for n, s in zip(names, self.scales_))
        if self.hubness is not None:
            d = mutual_proximity(d, self.database_mean_, self.database_std_)
        return d

    def scaled_frames(self, encoded: dict[str, list[np.ndarray]]) -> list[np.ndarray]:
        """float64 ``[T, d]`` per clip of an encoding (``database_`` or :meth:`encode`'s): each feature's frames
        divided by its scale, side by side, so that frame distances weigh the features as the summed DTW distances
        do (what :mod:`mocapkit.retrieval.subsequence` searches inside takes)."""
        names = self.feature_names
        return [
            np.hstack([np.asarray(encoded[n][i], dtype=np.float64) / s for n, s in zip(names, self.scales_)])
            for i in range(len(encoded[names[0]]))
        ]

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
        if self._frame_scaled:
            state.update({f"frame_moments_{n}": m for n, m in self.frame_moments_.items()})
        if self._needs_reference:
            state["reference"] = self.reference_
            state.update({f"reference_distances_{n}": d for n, d in self.reference_distances_.items()})
        if self.hubness is not None:
            state.update(database_mean=self.database_mean_, database_std=self.database_std_)
        return state

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.database_ = {name: ragged_from_state(f"database_{name}", state) for name in self.feature_names}
        self.scales_ = np.asarray(state["scales"], dtype=np.float64)
        if self._frame_scaled:
            self.frame_moments_ = {n: np.asarray(state[f"frame_moments_{n}"], np.float64) for n in self.feature_names}
        if self._needs_reference:
            self.reference_ = np.asarray(state["reference"], dtype=np.int64)
            self.reference_distances_ = {
                n: np.asarray(state[f"reference_distances_{n}"], dtype=np.float64) for n in self.feature_names
            }
        if self.hubness is not None:
            self.database_mean_ = np.asarray(state["database_mean"], dtype=np.float64)
            self.database_std_ = np.asarray(state["database_std"], dtype=np.float64)
        self.n_database_ = len(self.database_[self.feature_names[0]])


def root_centred_joints(motion, fps: float | None = 30.0, min_frames: int = 2) -> np.ndarray:
    """float32 ``[frames, joints, 3]`` metres: every joint of ``motion`` as the file gives it, resampled to ``fps``
    (None: as it is), gaps filled by linear interpolation in time (a joint never observed takes the root's
    positions), minus the root joint (the joint without a parent; the first joint of a marker set). No up-axis
    turn, no retargeting, no heading: what :class:`PlainDTWRetrieval` compares.

    Raises:
        SkeletonInputError: fewer than ``min_frames`` frames after resampling, a root never observed, or
            non-finite observed positions (each names the file).
    """
    label = motion.source or motion.name or "motion"
    if fps is not None and float(fps) != motion.fps:
        motion = motion.resample(float(fps))
    if motion.num_frames < max(int(min_frames), 1):
        raise SkeletonInputError(
            f"{label}: {motion.num_frames} frames at {motion.fps:g} fps; at least {min_frames} are needed"
        )
    root = motion.parents.index(-1) if motion.parents is not None else 0
    observed = ~motion.missing
    if not observed[:, root].any():
        raise SkeletonInputError(f"{label}: the root joint {motion.joint_names[root]!r} is never observed")
    positions = np.asarray(motion.positions, dtype=np.float64)
    if not np.isfinite(positions[observed]).all():
        raise SkeletonInputError(f"{label}: non-finite observed positions")
    t = np.arange(motion.num_frames)
    out = positions.copy()
    for j in range(motion.num_joints):
        seen = observed[:, j]
        if seen.all() or not seen.any():
            continue
        for axis in range(3):
            out[:, j, axis] = np.interp(t, t[seen], positions[seen, j, axis])
    never = ~observed.any(axis=0)
    out[:, never] = out[:, root : root + 1]
    return (out - out[:, root : root + 1]).astype(np.float32)


class PlainDTWRetrieval(DTWRetrieval):
    """DTW on every joint, root-centred, resampled to ``fps`` (:func:`root_centred_joints`): the plain baseline.

    Queries and database clips must have the same joints in the same order (one skeleton, as within one data
    set); a query of another skeleton is refused naming both joint counts.

    Args:
        window, length_normalised, fps, parallel: as :class:`DTWRetrieval` (features are the positions).
    """

    # DTWRetrieval's other parameters, fixed (not parameters of this class): one feature, nothing turned or scaled
    features = "positions"
    heading = "none"
    hubness = None
    n_reference = 512
    scaling = "dtw"

    def __init__(
        self,
        window: float | None = None,
        length_normalised: bool = True,
        fps: float = 30.0,
        parallel: bool = True,
    ):
        self.window = window
        self.length_normalised = length_normalised
        self.fps = fps
        self.parallel = parallel

    def sequences(self, motions, what: str = "input") -> list[np.ndarray]:
        """Root-centred joints ``[T, J, 3]`` of every motion; every one must have the database's ``J`` joints."""
        out = []
        joints = None
        if hasattr(self, "database_") and self.database_["positions"]:
            joints = self.database_["positions"][0].shape[1] // 3
        for motion in motion_list(motions, what):
            seq = root_centred_joints(motion, fps=self.fps, min_frames=self.min_frames)
            joints = seq.shape[1] if joints is None else joints
            if seq.shape[1] != joints:
                raise SkeletonInputError(
                    f"{motion.source or motion.name or 'motion'}: {seq.shape[1]} joints, the database clips have "
                    f"{joints}; plain DTW compares joint by joint (use a landmark method such as dtw_positions "
                    "to mix skeletons)"
                )
            out.append(seq)
        return out
