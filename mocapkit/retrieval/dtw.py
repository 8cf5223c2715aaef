"""Dynamic time warping retrieval: the baseline a user would otherwise reach for, and our label-free default.

:class:`DTWRetrieval` ranks the database by the multivariate DTW distance (squared Euclidean inner distance, the
square root of the warped sum: dtaidistance's ``dtw_ndim.distance``; without a band computed by
:class:`~mocapkit.retrieval.frames.CandidateCosts`, about 6x faster, with one by dtaidistance's C) between a
query's frame sequence and each database clip's, on per-frame features of the normalised landmarks
(:func:`~mocapkit.motion.geometry.normalised_landmarks`, 30 fps by default):

- ``"positions"``: the 20 landmarks' coordinates, ``[T, 60]`` metres (Zhou 2014 §1.7 normalisation);
- ``"relational"``: the soft relational pose features of :func:`~mocapkit.retrieval.features.relational_features`
  (Müller & Röder style: which hand is raised, which knee bent, ...), ``[T, F]`` in ``[0, 1]``;
- ``"world_positions"``: the same landmarks not turned, ``[T, 60]`` metres: the posture as the file's frame sees it
  (which way the body faces);
- ``"world_velocity"``: the pelvis's velocity in the file's frame, ``[T, 3]`` metres of the template body per second
  (smoothed over :data:`VELOCITY_SMOOTHING` frames): where the body goes (a walk to the left, a walk back);
- ``"speeds"``: each landmark's speed in the body's frame (the norm of the velocity of the normalised landmarks,
  smoothed over :data:`VELOCITY_SMOOTHING` frames), ``[T, 20]`` metres of the template body per second: how
  vigorously each limb moves, whichever way the body faces;
- ``"joints"``: every joint of the file's skeleton, root-centred, not turned, retargeted or scaled
  (:func:`root_centred_joints`), ``[T, 3J]`` metres: what plain DTW (:class:`PlainDTWRetrieval`) compares. It needs
  one skeleton: ``fit`` keeps it only when the database's clips share one joint count, and refuses a query or an
  added clip of another (:class:`~mocapkit.motion.geometry.SkeletonInputError`, naming both counts).

The three **world** features mean something only when the library's clips share one frame, as takes of one studio
set-up or one camera do; across takes that face every way (HDM05's performers) they only add noise. With
``world_frame="auto"`` (the default) ``fit`` keeps them only when the database's clips start facing alike: the
mean resultant length ``R`` of each clip's heading over its first half second is at least
:data:`WORLD_MIN_CONCENTRATION` (``heading_concentration_``; ``features_`` lists the features used). ``"on"``
always keeps them, ``"off"`` never.

Given several features (``features=["positions", "relational"]``), each one's DTW distance is divided by its
**scale**, learned at ``fit``, and the quotients, times the feature's ``weights`` (1 unless given), are summed, so
that metres and relational units weigh alike: with
``scaling="dtw"`` the median DTW distance among database clips; with ``scaling="frames"`` the root-mean-square
distance of the database's frames to their mean frame (linear in the library's frames, no DTW between clips: for
libraries of long takes, ``dtw_takes``, whose clip-to-clip DTW would be quadratic in their length).

``window`` is the Sakoe–Chiba band as a fraction of the longer sequence's length (None: unconstrained; the band
also lets DTW match clips whose lengths differ by more than the band, as dtaidistance widens it by the length
difference). ``length_normalised`` divides each distance by ``sqrt(len(query) + len(candidate))`` so that long
clips are not pushed down the list only for their length (the sum under the square root grows with the path).
``hubness="mutual_proximity"`` re-ranks the distances by :func:`~mocapkit.retrieval.hubness.mutual_proximity`
(no labels, no parameter), which discounts clips near to every query.

**Prefiltered search** (``prefilter=K``, for large libraries): :meth:`DTWRetrieval.search` first takes each
query's ``K`` nearest clips by Euclidean distance between fixed-length descriptors — every feature's frames
resampled to :data:`PREFILTER_FRAMES` frames, divided by the feature's scale, side by side, projected on their
first :data:`PREFILTER_DIMS` principal axes — from a FAISS index (:mod:`mocapkit.retrieval.ann`: exact below
20,000 clips, HNSW from there), then ranks only those ``K`` by the method's own distance. DTW runs on them in the
order of their lower bounds (:meth:`~mocapkit.retrieval.frames.CandidateCosts.lower_bounds`, summed and re-ranked
as the distances are) and stops when the next bound passes the ``k``-th distance found: the ranking is that of DTW
on all ``K``. With mutual proximity the query's statistics come from its distances to the reference clips, in
exact search as in a prefiltered one (and as each database clip's do), so that both rank alike. ``dtw_large`` (the
registry) is the default set up for large libraries this way.

``fit`` keeps the database's feature sequences (:class:`~mocapkit.retrieval.frames.RaggedFrames`, float32; an
index opens them memory-mapped); with several features or mutual proximity it also computes the
DTW distances from every database clip to a reference subset of at most ``n_reference`` database clips (all of
them on libraries of up to ``n_reference`` clips), for the scales and the statistics, and keeps them, so that
:meth:`~mocapkit.retrieval.base.RetrievalMethod.add` appends clips without recomputing the old ones' distances.

:class:`PlainDTWRetrieval` is the baseline a user writes without this package: DTW on **every joint** of the
skeleton as the file gives it, root-centred, resampled to ``fps`` (no landmarks, no retargeting, no heading).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from mocapkit.motion.geometry import (
    L_HIP,
    R_HIP,
    LandmarkTrack,
    SkeletonInputError,
    hip_line_heading,
    landmark_track,
    turn_about_up,
)
from mocapkit.retrieval import ann
from mocapkit.retrieval.base import RetrievalMethod, motion_list
from mocapkit.retrieval.frames import CandidateCosts, RaggedFrames, candidate_dtw
from mocapkit.retrieval.hubness import METHODS as HUBNESS_METHODS
from mocapkit.retrieval.hubness import (
    database_statistics,
    mutual_proximity,
    reference_indices,
)

FEATURES = ("positions", "relational", "world_positions", "world_velocity", "speeds", "joints")
#: The features that read the file's frame (kept or dropped by ``world_frame``).
WORLD_FEATURES = ("world_positions", "world_velocity", "joints")
WORLD_FRAMES = ("auto", "on", "off")
#: ``world_frame="auto"`` keeps the world features when the database clips' starting headings have at least this
#: mean resultant length (a circular spread of about 48°). Set before the selection run; there, HDM05's performers
#: gave 0.24, Bandai's styles 0.89 and MSR Action3D's subjects 0.97 (docs/decisions.md#retrieval-default-world-frame).
WORLD_MIN_CONCENTRATION = 0.7
#: Frames (at ``fps``) of the moving average over the pelvis path (and the landmarks) before a velocity is taken.
VELOCITY_SMOOTHING = 5
SCALINGS = ("dtw", "frames")
#: ``prefilter``'s descriptor: frames each feature is resampled to, and principal axes kept.
PREFILTER_FRAMES, PREFILTER_DIMS = 16, 128
#: Candidates of a prefiltered search whose exact DTW is computed at once, in their lower bounds' order
#: (:meth:`DTWRetrieval._rank_candidates`).
PRUNE_BATCH = 32
#: Queries per dtaidistance call in :meth:`DTWRetrieval._feature_distances` (with a band).
QUERY_BLOCK = 256
#: Database frames per matrix product in :meth:`DTWRetrieval._feature_distances` (without a band): a query of 100
#: frames against them makes a 26 MB cost table.
CHUNK_FRAMES = 32_768


def frame_features(track: LandmarkTrack, features: str, fps: float) -> np.ndarray:
    """float64 ``[T, d]`` per-frame features (the module docstring) of one clip's :class:`LandmarkTrack`, whose
    ``landmarks`` are turned per frame (``heading="frame"``) or not, as the method's ``heading`` says."""
    landmarks = track.landmarks
    if features == "positions":
        return landmarks.reshape(len(landmarks), -1).astype(np.float64)
    if features == "relational":
        from mocapkit.retrieval.features import relational_features

        return np.asarray(relational_features(landmarks, fps=fps, soft=True), dtype=np.float64)
    if features == "world_positions":
        # the landmarks were turned by -(this frame's heading) unless heading="none"; the heading of the turned
        # posture is what is left of it, so turning back by the difference undoes any of the three options
        left = hip_line_heading(landmarks.astype(np.float64), L_HIP, R_HIP, along="-x")
        world = turn_about_up(landmarks.astype(np.float64), left - track.heading, along="-x")
        return world.reshape(len(world), -1)
    if features == "world_velocity":
        from scipy.ndimage import uniform_filter1d

        path = uniform_filter1d(np.asarray(track.pelvis, np.float64), VELOCITY_SMOOTHING, axis=0, mode="nearest")
        return np.gradient(path, axis=0) * float(fps) if len(path) > 1 else np.zeros_like(path)
    if features == "speeds":
        from scipy.ndimage import uniform_filter1d

        if len(landmarks) < 2:
            return np.zeros(landmarks.shape[:2])
        smooth = uniform_filter1d(landmarks.astype(np.float64), VELOCITY_SMOOTHING, axis=0, mode="nearest")
        return np.linalg.norm(np.gradient(smooth, axis=0), axis=-1) * float(fps)
    if features == "joints":
        if track.joints is None:
            raise ValueError("the joints feature needs the track's root-centred joints (DTWRetrieval.sequences)")
        return track.joints.reshape(len(track.joints), -1).astype(np.float64)
    raise ValueError(f"features must be one of {FEATURES}, got {features!r}")


def heading_concentration(tracks: list[LandmarkTrack], fps: float, seconds: float = 0.5) -> float:
    """The mean resultant length (0: every way, 1: all alike) of the clips' headings over their first ``seconds``
    (each clip's circular mean): whether a library's clips share a frame in which facing means something."""
    starts = []
    for track in tracks:
        first = np.asarray(track.heading[: max(1, int(round(seconds * fps)))], dtype=np.float64)
        starts.append(np.arctan2(np.sin(first).mean(), np.cos(first).mean()))
    starts = np.asarray(starts)
    return float(np.hypot(np.cos(starts).mean(), np.sin(starts).mean())) if len(starts) else 0.0


def frame_moments(sequences: list[np.ndarray] | RaggedFrames) -> np.ndarray:
    """float64 ``[2 + d]``: the frame count, the sum of the squared frame norms and the sum of the frames of
    ``sequences`` (each ``[T, d]``): what :func:`moments_scale` needs, and additive over libraries."""
    store = sequences if isinstance(sequences, RaggedFrames) else RaggedFrames.from_list(sequences)
    moments = np.zeros(2 + store.dim)
    for start in range(0, len(store.data), CHUNK_FRAMES):  # in float64 a chunk at a time (a memory map is large)
        x = np.asarray(store.data[start : start + CHUNK_FRAMES], dtype=np.float64)
        moments += np.concatenate([[len(x), float((x**2).sum())], x.sum(axis=0)])
    return moments


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
        parallel: compute the distances of several queries (``fit``'s reference distances, exact search of many
            queries) on every CPU thread.
        world_frame: ``"auto"``, ``"on"`` or ``"off"``: whether the world features among ``features`` are used
            (module docstring).
        weights: ``{feature: weight}`` for the sum of several features' scaled distances (1 for the others).
        prefilter: None (``search`` ranks every clip) or ``K``: ``search`` ranks only the ``K`` clips nearest by
            descriptor (module docstring); ``prefilter_index``: ``"auto"``, ``"flat"`` or ``"hnsw"`` for them.

    Learned: ``features_`` (the features used), ``heading_concentration_``, ``scales_`` (each feature's scale over
    its weight: what its distance is divided by) and, with several features or mutual proximity, the reference
    distances and statistics.
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
        world_frame: str = "auto",
        prefilter: int | None = None,
        prefilter_index: str = "auto",
        weights: dict[str, float] | None = None,
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
        self.world_frame = world_frame
        self.prefilter = prefilter
        self.prefilter_index = prefilter_index
        self.weights = weights

    @property
    def feature_names(self) -> list[str]:
        names = [self.features] if isinstance(self.features, str) else list(self.features)
        unknown = [n for n in names if n not in FEATURES]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(f"features must be one of {FEATURES} or a list of distinct ones, got {self.features!r}")
        return names

    # ------------------------------------------------------------------ the contract
    def sequences(self, motions, what: str = "input") -> list[LandmarkTrack]:
        """Each motion's :class:`~mocapkit.motion.geometry.LandmarkTrack` (the normalised landmarks with the
        heading and pelvis path the world features read, and the root-centred joints when ``joints`` is asked
        for); checks as the base class's, and a fitted method that compares joints refuses another skeleton."""
        tracks = []
        # a fitted method computes the joints only where its features use them (a query of a library that left them
        # out needs none); a database being fitted, where they are asked for
        used = self.feature_names if what == "database" or not hasattr(self, "features_") else self.features_
        with_joints = "joints" in used
        joints = self.database_["joints"].dim // 3 if "joints" in getattr(self, "database_", {}) else None
        for motion in motion_list(motions, what):
            track = landmark_track(motion, fps=self.fps, heading=self.heading, min_frames=self.min_frames)
            if with_joints:
                track = track._replace(joints=root_centred_joints(motion, fps=self.fps, min_frames=self.min_frames))
                if joints is not None and track.joints.shape[1] != joints:
                    raise SkeletonInputError(
                        f"{motion.source or motion.name or 'motion'}: {_skeleton_mismatch(track.joints.shape[1], joints)}"
                    )
            tracks.append(track)
        return tracks

    def _encode_sequences(self, sequences):
        return {
            name: [np.ascontiguousarray(frame_features(s, name, self.fps)) for s in sequences]
            for name in self.features_
        }

    def _choose_features(self, sequences) -> list[str]:
        """The features used (``features_``): the world features dropped by ``world_frame`` (module docstring)."""
        names = self.feature_names
        if self.world_frame not in WORLD_FRAMES:
            raise ValueError(f"world_frame must be one of {WORLD_FRAMES}, got {self.world_frame!r}")
        self.heading_concentration_ = heading_concentration(sequences, float(self.fps))
        keep_world = self.world_frame == "on" or (
            self.world_frame == "auto" and self.heading_concentration_ >= WORLD_MIN_CONCENTRATION
        )
        chosen = [n for n in names if keep_world or n not in WORLD_FEATURES]
        if "joints" in chosen and any(s.joints is None for s in sequences):
            raise ValueError(f"{type(self).__name__}: the joints feature needs tracks made by its own sequences()")
        counts = sorted({s.joints.shape[1] for s in sequences}) if "joints" in chosen else []
        if len(counts) > 1:  # joint by joint needs one skeleton
            if self.world_frame == "on":
                raise ValueError(
                    f"{type(self).__name__}: the joints feature compares joint by joint, and the database's clips have "
                    f"{counts} joints; index one skeleton, or set world_frame=auto to leave it out"
                )
            chosen.remove("joints")
        if not chosen:
            raise ValueError(
                f"{type(self).__name__}: features {names} are all world features and world_frame="
                f"{self.world_frame!r} drops them (the database's heading concentration is "
                f"{self.heading_concentration_:.2f}, below {WORLD_MIN_CONCENTRATION}); add a frame-free feature "
                "such as positions, or set world_frame=on"
            )
        return chosen

    def _weighted(self, scales) -> np.ndarray:
        """``scales`` (one per feature of ``features_``) divided by the features' ``weights``."""
        weights = dict(self.weights or {})
        unknown = sorted(set(weights) - set(self.feature_names))
        if unknown:
            raise ValueError(f"weights: {unknown} are not among the features {self.feature_names}")
        bad = {n: w for n, w in weights.items() if not (np.isfinite(float(w)) and float(w) > 0)}
        if bad:
            raise ValueError(f"weights must be positive numbers, got {bad}")
        return np.asarray(scales, dtype=np.float64) / np.array([float(weights.get(n, 1.0)) for n in self.features_])

    def _fit_sequences(self, sequences, y):
        if self.hubness is not None and self.hubness not in HUBNESS_METHODS:
            raise ValueError(f"hubness must be None or one of {HUBNESS_METHODS}, got {self.hubness!r}")
        if self.scaling not in SCALINGS:
            raise ValueError(f"scaling must be one of {SCALINGS}, got {self.scaling!r}")
        self.features_ = self._choose_features(sequences)
        self._weighted(np.ones(len(self.features_)))  # refuses bad weights whether or not they are used
        database = {n: RaggedFrames.from_list(frames) for n, frames in self._encode_sequences(sequences).items()}
        names = self.features_
        self.scales_ = np.ones(len(names))
        if self._frame_scaled:
            self.frame_moments_ = {n: frame_moments(database[n]) for n in names}
            self.scales_ = self._weighted([moments_scale(self.frame_moments_[n]) for n in names])
        if not self._needs_reference:
            return database
        reference = reference_indices(len(sequences), int(self.n_reference))
        if len(reference) < 2:
            raise ValueError(
                f"{type(self).__name__}: several features or mutual proximity need a database of "
                f"at least 2 clips, got {len(sequences)}"
            )
        raw = {n: self._feature_distances(database[n], database[n].subset(reference)) for n in names}
        self._set_reference(reference, raw)
        return database

    def fit_sequences(self, sequences, y=None) -> DTWRetrieval:
        super().fit_sequences(sequences, y)
        self._build_prefilter()
        return self

    def add_sequences(self, sequences) -> DTWRetrieval:
        n_old, scales = self.n_database_, self.scales_.copy()
        super().add_sequences(sequences)
        if self.prefilter is None:
            return self
        if np.array_equal(scales, self.scales_):  # the indexed descriptors still hold: the new clips' join them
            new = {n: self.database_[n].subset(np.arange(n_old, self.n_database_)) for n in self.features_}
            self.prefilter_index_, self.prefilter_kind_ = ann.extend(
                self.prefilter_index_, self.prefilter_kind_, self._project(self._descriptors(new)), self.prefilter_index
            )
        else:  # the scales follow the clips (a library of at most n_reference clips): every descriptor again
            self._index_descriptors(self._descriptors(self.database_))
        return self

    def store_frames(self, folder: str | os.PathLike) -> DTWRetrieval:
        """Keep the database's frames in ``.npy`` files in ``folder`` (``database_{feature}_frames.npy``, the names
        :class:`~mocapkit.retrieval.index.MotionIndex` saves them under), memory-mapped, instead of in memory: clips
        added afterwards are appended to those files. How a library larger than memory is built: fit on a first
        part, store the frames, add the rest in parts (docs/scaling.md#a-million-clips)."""
        self._check_fitted()
        Path(folder).mkdir(parents=True, exist_ok=True)
        self.database_ = {n: self.database_[n].save(Path(folder) / f"database_{n}_frames.npy") for n in self.features_}
        return self

    # ------------------------------------------------------------------ prefiltered search
    def _descriptors(self, encoded: dict[str, list[np.ndarray]]) -> np.ndarray:
        """float32 ``[n, d]``: each clip's features resampled to :data:`PREFILTER_FRAMES` frames, divided by their
        scales and by ``sqrt(frames)`` (so that Euclidean distances weigh the features as the summed DTW does)."""
        from mocapkit.retrieval.embedding import resample_frames

        names = self.features_
        rows = [
            np.concatenate(
                [resample_frames(encoded[n][i], PREFILTER_FRAMES).ravel() / s for n, s in zip(names, self.scales_)]
            )
            for i in range(len(encoded[names[0]]))
        ]
        return np.asarray(rows, dtype=np.float32) / np.sqrt(PREFILTER_FRAMES)

    def _build_prefilter(self) -> None:
        """With ``prefilter``: the principal axes of the database's descriptors (``prefilter_mean_``,
        ``prefilter_axes_``; learned from at most 4,096 clips at fit) and the FAISS index of their
        projections (``prefilter_index_``, of kind ``prefilter_kind_``); a no-op otherwise. Added clips join the
        index without rebuilding it (:meth:`add_sequences`)."""
        if self.prefilter is None:
            return
        if int(self.prefilter) < 1:
            raise ValueError(f"prefilter must be None or a positive number of clips, got {self.prefilter!r}")
        x = self._descriptors(self.database_)
        sample = x[reference_indices(len(x), 4096)] if len(x) > 1 else x
        self.prefilter_mean_ = sample.mean(axis=0)
        _, _, vt = np.linalg.svd(sample - self.prefilter_mean_, full_matrices=False)
        self.prefilter_axes_ = np.ascontiguousarray(vt[:PREFILTER_DIMS].T, dtype=np.float32)  # [d, dims]
        self._index_descriptors(x)

    def _index_descriptors(self, descriptors: np.ndarray) -> None:
        """``prefilter_index_`` (of the kind ``prefilter_index`` resolves to for their number) over every database
        clip's ``descriptors``, projected on the learned axes."""
        self.prefilter_kind_ = ann.resolved_kind(self.prefilter_index, len(descriptors))
        self.prefilter_index_ = ann.build(self._project(descriptors), self.prefilter_kind_, metric="l2")

    def _project(self, descriptors: np.ndarray) -> np.ndarray:
        return (descriptors - self.prefilter_mean_) @ self.prefilter_axes_

    def search(self, queries, k: int = 10) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest database clips per query, nearest first; with ``prefilter`` among each query's
        ``max(prefilter, k)`` descriptor neighbours only (module docstring), else exactly."""
        self._check_fitted()
        n = int(self.n_database_)
        k = n if k <= 0 or k > n else int(k)
        if self.prefilter is None or max(int(self.prefilter), k) >= n:
            return super().search(queries, k)
        encoded = self.encode(queries)
        names = self.features_
        candidates = ann.search(
            self.prefilter_index_,
            self.prefilter_kind_,
            self._project(self._descriptors(encoded)),
            max(int(self.prefilter), k),
        )
        indices, distances = [], []
        # a query's features on their own threads (matrix products and the compiled programme release the GIL)
        threads = min(len(names), os.cpu_count() or 1) if self.parallel else 1
        with ThreadPoolExecutor(threads) as pool:
            for i, row in enumerate(candidates):
                query = {nm: encoded[nm][i] for nm in names}
                found, d = self._rank_candidates(query, row[row >= 0], k, pool.map)
                indices.append(found)
                distances.append(d)
        return np.asarray(indices, dtype=np.int64), np.asarray(distances, dtype=np.float64)

    def _rank_candidates(
        self, query: dict[str, np.ndarray], row: np.ndarray, k: int, each=map
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest of the database clips ``row`` to one encoded query, by the method's distance, nearest
        first; DTW runs only on the candidates whose lower bound (summed as the distances are, and re-ranked by the
        same mutual proximity) is below the ``k``-th best distance found so far, in the bounds' order, a batch of
        :data:`PRUNE_BATCH` at a time. ``each`` maps over the features (a thread pool's ``map``: one a thread)."""
        names = self.features_
        lengths = self.database_[names[0]].lengths[row].astype(np.float64)
        length_scale = np.ones(len(row))
        if self.length_normalised:
            length_scale = 1.0 / np.sqrt(len(query[names[0]]) + lengths)
        costs = list(each(lambda nm: CandidateCosts(query[nm], self.database_[nm].subset(row)), names))
        bounds = sum(b / s for b, s in zip(each(CandidateCosts.lower_bounds, costs), self.scales_)) * length_scale
        ranked = self._candidate_ranking(query, row, each)
        bounds = ranked(bounds, np.arange(len(row)))
        found = np.full(len(row), np.inf)
        order = np.argsort(bounds, kind="stable")
        for start in range(0, len(order), PRUNE_BATCH):
            kth = np.partition(found, k - 1)[k - 1] if k <= len(found) else np.inf
            if bounds[order[start]] > kth:  # every candidate left is bounded beyond the k-th found: none can enter
                break
            batch = order[start : start + PRUNE_BATCH]
            if self.window is None:
                raw = list(each(lambda c, batch=batch: c.distances(batch), costs))
            else:  # the band's DTW is dtaidistance's; the unbanded bounds bound it too (a band only removes paths)
                raw = [
                    self._banded_distances([query[nm]], list(self.database_[nm].subset(row[batch])))[0] for nm in names
                ]
            d = sum(r / s for r, s in zip(raw, self.scales_)) * length_scale[batch]
            found[batch] = ranked(d, batch)
        top = np.lexsort((row, found))[:k]
        return row[top], found[top]

    def _candidate_ranking(self, query: dict[str, np.ndarray], row: np.ndarray, each=map):
        """``ranked(d, which)``: the method's distance from raw summed distances ``d`` to the candidates
        ``row[which]`` (mutual proximity, with the query's statistics from the reference clips, or nothing).
        Increasing in ``d`` for each candidate, so it keeps a lower bound a lower bound."""
        if self.hubness is None:
            return lambda d, which: d
        names = self.features_
        each_feature = each(
            lambda nm: self._feature_distances([query[nm]], self.database_[nm].kept_subset(self.reference_))[0], names
        )
        to_reference = sum(d / s for d, s in zip(each_feature, self.scales_))
        mean, std = to_reference.mean(), to_reference.std()
        return lambda d, which: mutual_proximity(
            d[None], self.database_mean_[row[which]], self.database_std_[row[which]], [mean], [std]
        )[0]

    @property
    def _frame_scaled(self) -> bool:
        """Whether several features are scaled by their frames' spread (``scaling="frames"``)."""
        return len(self.features_) > 1 and self.scaling == "frames"

    @property
    def _needs_reference(self) -> bool:
        """Whether the distances need DTW statistics of the database (scales by DTW, or hubness)."""
        return (len(self.features_) > 1 and not self._frame_scaled) or self.hubness is not None

    def _set_reference(self, reference: np.ndarray, raw: dict[str, np.ndarray]) -> None:
        """The reference clips, their raw distances ``[n_database, n_reference]`` per feature, and what is learned
        from them: the scales (median off-diagonal distance per feature) and the mutual-proximity statistics. The
        distances are kept (``reference_distances_``) only while every clip is a reference clip, for an added clip
        to extend them exactly; beyond, they would cost 2 GB at 10^6 clips and are never read again (None)."""
        self.reference_ = np.asarray(reference, dtype=np.int64)
        names = self.features_
        every_clip = len(self.reference_) == raw[names[0]].shape[0]
        self.reference_distances_ = raw if every_clip else None
        off_diagonal = np.ones(raw[names[0]].shape, dtype=bool)
        off_diagonal[self.reference_, np.arange(len(self.reference_))] = False
        if len(names) > 1 and not self._frame_scaled:
            self.scales_ = self._weighted([np.median(raw[n][off_diagonal]) for n in names])
        if self.hubness is not None:
            combined = sum(raw[n] / s for n, s in zip(names, self.scales_))
            self.database_mean_, self.database_std_ = database_statistics(combined, self.reference_)

    def _add_sequences(self, sequences) -> None:
        """Append clips. With scales or mutual proximity: while the union has at most ``n_reference`` clips every
        clip stays a reference clip and the new clips' distances to all clips are added, so the scales and
        statistics are exactly those of ``fit`` on the union; beyond that the reference clips and the scales are
        kept, and only the new clips' statistics (against the same reference clips) are computed."""
        if "joints" in self.features_:  # sequences made one file at a time (the index's workers) are checked here
            joints = self.database_["joints"].dim // 3
            for i, track in enumerate(sequences):
                if track.joints.shape[1] != joints:
                    error = SkeletonInputError(f"clip {i}: {_skeleton_mismatch(track.joints.shape[1], joints)}")
                    error.clip = i
                    raise error
        new = self._encode_sequences(sequences)
        names = self.features_
        n_old = self.n_database_
        union = {n: self.database_[n].extend(new[n]) for n in names}
        n_total = n_old + len(sequences)
        exact = not self._needs_reference or (
            n_total <= int(self.n_reference) and self.reference_distances_ is not None
        )
        if self._frame_scaled:  # the moments of the union's frames: the scales fit on the union would learn
            self.frame_moments_ = {n: self.frame_moments_[n] + frame_moments(new[n]) for n in names}
            if exact:  # (past n_reference clips with mutual proximity the scales are kept, as its statistics are)
                self.scales_ = self._weighted([moments_scale(self.frame_moments_[n]) for n in names])
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
                rows = {n: self._feature_distances(new[n], union[n].subset(self.reference_)) for n in names}
                if self.hubness is not None:  # the new clips are not reference clips: no self-distance to leave out
                    combined = sum(rows[n] / s for n, s in zip(names, self.scales_))
                    self.database_mean_ = np.concatenate([self.database_mean_, combined.mean(axis=1)])
                    self.database_std_ = np.concatenate([self.database_std_, combined.std(axis=1)])
                self.reference_distances_ = None
        self.database_ = union

    def _distances(self, queries, database) -> np.ndarray:
        names = self.features_
        d = sum(self._feature_distances(queries[n], database[n]) / s for n, s in zip(names, self.scales_))
        if self.hubness is not None:
            # the queries' statistics from their distances to the reference clips, as the database clips' are (the
            # whole library when it has at most n_reference clips): what a prefiltered search can compute too
            to_reference = d[:, self.reference_]
            d = mutual_proximity(
                d, self.database_mean_, self.database_std_, to_reference.mean(axis=1), to_reference.std(axis=1)
            )
        return d

    def scaled_frames(self, encoded: dict[str, list[np.ndarray]]) -> list[np.ndarray]:
        """float64 ``[T, d]`` per clip of an encoding (``database_`` or :meth:`encode`'s): each feature's frames
        divided by its scale, side by side, so that frame distances weigh the features as the summed DTW distances
        do (what :mod:`mocapkit.retrieval.subsequence` searches inside takes)."""
        names = self.features_
        return [
            np.hstack([np.asarray(encoded[n][i], dtype=np.float64) / s for n, s in zip(names, self.scales_)])
            for i in range(len(encoded[names[0]]))
        ]

    def _feature_distances(
        self, queries: list[np.ndarray] | RaggedFrames, database: list[np.ndarray] | RaggedFrames
    ) -> np.ndarray:
        """float64 ``[n_queries, n_database]`` DTW distances of one feature's sequences.

        Without a band (``window=None``) by :func:`~mocapkit.retrieval.frames.candidate_dtw`: the database in chunks
        of :data:`CHUNK_FRAMES` frames, every query against a chunk (one matrix product each; queries spread over
        the CPU's threads when ``parallel``). With a band by dtaidistance, queries in blocks of :data:`QUERY_BLOCK`
        (the distances of a block come back compact). A progress bar shows on a terminal when the work is large
        (``fit`` with mutual proximity on a large library runs minutes: every clip against the reference clips).
        """
        store = database if isinstance(database, RaggedFrames) else RaggedFrames.from_list(database)
        if self.window is None:
            d = self._unbanded_distances(queries, store)  # (a RaggedFrames of queries is read one clip at a time)
        else:
            d = self._banded_distances(list(queries), list(store))
        if self.length_normalised:
            lq = queries.lengths if isinstance(queries, RaggedFrames) else np.array([len(s) for s in queries])
            lq = lq.astype(np.float64)
            d = d / np.sqrt(lq[:, None] + store.lengths[None, :].astype(np.float64))
        return d

    def _unbanded_distances(self, queries: list[np.ndarray] | RaggedFrames, store: RaggedFrames) -> np.ndarray:
        from tqdm import tqdm

        d = np.zeros((len(queries), len(store)))
        chunks = store.chunks(CHUNK_FRAMES)
        threads = (os.cpu_count() or 1) if self.parallel and len(queries) > 1 else 1
        work = len(queries) * len(chunks)
        with (
            ThreadPoolExecutor(threads) as pool,
            tqdm(
                total=work, desc="DTW", unit="query", disable=None if work > QUERY_BLOCK else True, leave=False
            ) as bar,
        ):
            for first, end in chunks:
                # read once for all queries (a memory map reads from disk)
                frames = np.asarray(store.data[store.offsets[first] : store.offsets[end]], dtype=np.float32)
                chunk = RaggedFrames(frames, store.offsets[first : end + 1] - store.offsets[first])

                def one(i, chunk=chunk, first=first, end=end):
                    d[i, first:end] = candidate_dtw(queries[i], chunk)

                for _ in pool.map(one, range(len(queries))):
                    bar.update()
        return d

    def _banded_distances(self, queries: list[np.ndarray], database: list[np.ndarray]) -> np.ndarray:
        from dtaidistance import dtw_ndim
        from tqdm import tqdm

        longest = max(len(s) for s in (*queries, *database))
        window = max(1, int(np.ceil(float(self.window) * longest)))
        starts = range(0, len(queries), QUERY_BLOCK)
        blocks = []
        for start in tqdm(starts, desc="DTW", unit="block", disable=None if len(starts) > 1 else True, leave=False):
            chunk = [np.ascontiguousarray(s, dtype=np.float64) for s in queries[start : start + QUERY_BLOCK]]
            nq = len(chunk)
            # compact: only the block's nq x n_database distances, row by row (the full form is an
            # (nq + n_database)^2 matrix: 75 GB at 10^5 clips)
            block = dtw_ndim.distance_matrix_fast(
                chunk + list(database),
                window=window,
                block=((0, nq), (nq, nq + len(database))),
                compact=True,
                parallel=bool(self.parallel),
            )
            blocks.append(np.asarray(block, dtype=np.float64).reshape(nq, len(database)))
        return np.concatenate(blocks, axis=0) if blocks else np.zeros((0, len(database)))

    # ------------------------------------------------------------------ persistence
    def _state(self) -> dict[str, np.ndarray]:
        state = {
            "scales": self.scales_,
            "features": np.array(self.features_),
            "heading_concentration": np.array(self.heading_concentration_, dtype=np.float64),
        }
        for name in self.features_:
            state.update(self.database_[name].to_state(f"database_{name}"))
        if self._frame_scaled:
            state.update({f"frame_moments_{n}": m for n, m in self.frame_moments_.items()})
        if self._needs_reference:
            state["reference"] = self.reference_
            if self.reference_distances_ is not None:
                state.update({f"reference_distances_{n}": d for n, d in self.reference_distances_.items()})
        if self.hubness is not None:
            state.update(database_mean=self.database_mean_, database_std=self.database_std_)
        if self.prefilter is not None:
            state.update(prefilter_mean=self.prefilter_mean_, prefilter_axes=self.prefilter_axes_)
            state["prefilter_index"] = ann.serialise(self.prefilter_index_)
        return state

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.features_ = [str(n) for n in state["features"]]
        self.heading_concentration_ = float(state["heading_concentration"])
        self.database_ = {name: RaggedFrames.from_state(f"database_{name}", state) for name in self.features_}
        self.scales_ = np.asarray(state["scales"], dtype=np.float64)
        if self._frame_scaled:
            self.frame_moments_ = {n: np.asarray(state[f"frame_moments_{n}"], np.float64) for n in self.features_}
        if self._needs_reference:
            self.reference_ = np.asarray(state["reference"], dtype=np.int64)
            self.reference_distances_ = (
                {n: np.asarray(state[f"reference_distances_{n}"], dtype=np.float64) for n in self.features_}
                if f"reference_distances_{self.features_[0]}" in state
                else None
            )
        if self.hubness is not None:
            self.database_mean_ = np.asarray(state["database_mean"], dtype=np.float64)
            self.database_std_ = np.asarray(state["database_std"], dtype=np.float64)
        self.n_database_ = len(self.database_[self.features_[0]])
        if self.prefilter is not None:
            self.prefilter_mean_ = np.asarray(state["prefilter_mean"], dtype=np.float32)
            self.prefilter_axes_ = np.asarray(state["prefilter_axes"], dtype=np.float32)
            self.prefilter_index_ = ann.deserialise(state["prefilter_index"])
            self.prefilter_kind_ = "hnsw" if "HNSW" in type(self.prefilter_index_).__name__ else "flat"


def _skeleton_mismatch(joints: int, database: int) -> str:
    return (
        f"{joints} joints, the database clips have {database}; the joints feature compares joint by joint (index "
        "with world_frame=off, or a landmark method such as dtw_positions, to mix skeletons)"
    )


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
    world_frame = "off"
    weights = None
    prefilter = None
    prefilter_index = "auto"

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
        if hasattr(self, "database_") and len(self.database_["positions"]):
            joints = self.database_["positions"].dim // 3
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

    def _fit_sequences(self, sequences, y):
        self._check_joints(sequences)
        return super()._fit_sequences(sequences, y)

    def _add_sequences(self, sequences) -> None:
        self._check_joints(sequences, self.database_["positions"].dim // 3)
        super()._add_sequences(sequences)

    @staticmethod
    def _check_joints(sequences, joints: int | None = None) -> None:
        """Every sequence has ``joints`` joints (None: the first one's), for sequences computed one file at a time
        (the index's workers): a ``SkeletonInputError`` otherwise, its ``clip`` the position of the first that
        differs (the index names the file)."""
        for i, seq in enumerate(sequences):
            joints = seq.shape[1] if joints is None else joints
            if seq.shape[1] != joints:
                error = SkeletonInputError(
                    f"clip {i}: {seq.shape[1]} joints, the database clips have {joints}; plain DTW compares joint by "
                    "joint (use a landmark method such as dtw_positions to mix skeletons)"
                )
                error.clip = i
                raise error

    def _choose_features(self, sequences) -> list[str]:
        self.heading_concentration_ = float("nan")  # the joints as the file gives them: no heading is read
        return ["positions"]

    def _encode_sequences(self, sequences):
        return {"positions": [np.ascontiguousarray(s.reshape(len(s), -1), dtype=np.float64) for s in sequences]}
