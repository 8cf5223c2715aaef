"""TSR + STPM motion retrieval (Zhou 2014, chapter 3): sparse codes of postures, their temporal co-activation,
pooled in a spatio-temporal pyramid and matched by a histogram-intersection kernel.

Spec: ``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §2 (algorithm §2.9) and §7 "Chapter 3".

Pipeline (:class:`TSRSTPMRetrieval`):

1. every clip → :func:`~mocapkit.motion.geometry.normalised_landmarks` at ``fps`` (120 Hz by default, HDM05's
   rate, at which the thesis tuned ``sigma``), flattened to ``[T, 60]`` positions in **centimetres** (spec §7.5);
2. ``fit``: a K-SVD dictionary (:class:`~mocapkit.retrieval.ksvd.KSVD`) of ``n_atoms`` unit-norm atoms learned
   on the database's frames (at most ``max_dictionary_frames`` randomly chosen ones, ``ksvd_iter`` iterations);
3. every frame → its OMP code ``x_t ∈ ℝ^q`` with ``n_nonzero`` non-zeros;
4. **TSR**: slices ``s_i = x_i x_jᵀ`` (``q × q``) for ``i = 1, 1+σ, …, 1+kσ`` with ``k = max{k : 1+kσ < t}`` and
   ``j = min(i+σ, t)`` (1-based; the spec's toy example ``t = 7, σ = 2`` gives (1,3), (3,5), (5,7);
   :func:`tsr_pairs` is 0-based);
5. **STPM pooling**: at level ``l`` the slices are cut into ``2^l`` temporal segments and the ``q × q`` plane into
   ``(l+1) × (l+1)`` spatial blocks, ``2^l (l+1)^2`` cubes (1, 8, 36, 128 for ``l = 0..3``); each cube is
   ``Z_lh = max over its slices of |s|`` (element-wise);
6. **kernel** ``K(Z, Z') = Σ_l 2^-l Σ_h HIK(Z_lh, Z'_lh)``, ``HIK(A, B) = Σ min(A, B)``; ``distances`` returns
   ``−K`` (smaller = nearer), so ranking by distance is the thesis's ranking by descending score.

Choices where the thesis is ambiguous (spec §7, Chapter 3):

* **Levels** (§7.1): ``n_levels`` counts levels, ``0 .. n_levels − 1``; the default 3 (levels 0, 1, 2) is the
  thesis's best "l = 3"; ``n_levels = 1`` is "no pyramid".
* **The spatial split** (§7.2): pooling is element-wise and HIK sums element-wise minima, so with
  ``block_norm="none"`` the sum over the ``(l+1)^2`` spatial blocks equals the HIK of the whole ``q × q``
  matrix of the temporal segment: the spatial partition is a **no-op**, and STPM reduces to a temporal pyramid
  (that is the thesis-literal reproduction, and the default). ``block_norm="l1"`` / ``"l2"`` divides each cube by
  its own L1 / L2 norm (an all-zero cube stays zero), which makes the spatial blocks matter.
* **Uneven splits** (§7.3): temporal segments and spatial blocks are ``numpy.array_split``'s near-equal parts
  (the first parts one longer); a segment with no slice (a clip with fewer slices than ``2^l``) is an all-zero
  histogram.
* **σ** (§7.6) is in frames **at ``fps``**: 7 frames at the default 120 Hz is the thesis's 58 ms. Queries of any
  rate (Kinect at 30 Hz) are resampled to ``fps`` first, so σ keeps its duration. A clip needs at least ``σ + 1``
  frames at ``fps`` (:attr:`TSRSTPMRetrieval.min_frames`); a shorter one raises
  :class:`~mocapkit.motion.geometry.SkeletonInputError` naming the file.
* **Codes** (§7.7): ``m = 35`` of ``q = 700`` with ``d = 60`` as stated; no centring; OMP codes may be negative,
  the pooled cubes hold absolute values; the K-SVD seed is ``random_state``.
* **No kernel normalisation** (the thesis mentions none) by default, so a long clip with many distinct
  co-activations scores high against every query and becomes a "hub" (on HDM05 the thesis-literal kernel ranks a
  few long clips first for most queries). ``normalize_kernel=True`` (this implementation's addition, off by
  default) ranks by ``K(a, b) / sqrt(K(a, a) K(b, b))`` instead (``K(a, a)`` is the sum of ``a``'s weighted
  pooled values, so it costs nothing); ``block_norm`` bounds each cube instead.

Efficiency: a slice has at most ``m² = 1225`` non-zeros of its ``q² = 490 000`` entries and dense slices are
never formed. Each pooled temporal segment (all spatial blocks of one ``(clip, level, segment)``) is one sparse
row over the ``q²`` flattened entries (``scipy.sparse`` CSR, float32), built per clip by sorting the slices'
entries by (segment, entry) and max-reducing. Since ``HIK(w a, w b) = w HIK(a, b)`` for ``w > 0``, the level
weights are folded into the values, so the whole kernel is one HIK between long sparse vectors; the database is
indexed by column (CSC) and a query's kernel against every database clip is ``Σ min`` over the database entries in the query's columns (gathered, ``minimum``-ed and ``bincount``-ed in a
few vectorised passes), never touching columns the query lacks. Measured on the 232 HDM05 clips (2 shared
CPU cores, one thread): K-SVD (q = 700, m = 35, 10 iterations on 20 000 frames) ≈ 85 s, encoding all clips ≈ 20 s,
about 20 M stored non-zeros (≈ 160 MB as float32 + int32), one query ≈ 0.2 s to encode and ≈ 0.13 s to score
against the whole database (the first query also builds the column index, ≈ 2.5 s).

Measured behaviour (HDM05, 11 classes, cross-performer): with the thesis's ``m = 35`` non-zeros out of
``d = 60`` the codes are one dominant "pose" atom plus ~34 small, actor-specific ones whose co-activations carry
most of the HIK mass, and retrieval across actors is near chance (mAP ≈ 0.18); sparser codes work
(``n_atoms=64, n_nonzero=4``: mAP ≈ 0.82, P@1 ≈ 0.94). The defaults stay the thesis's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
import scipy.sparse as sp
from sklearn.exceptions import NotFittedError

from mocapkit.retrieval.base import RetrievalMethod
from mocapkit.retrieval.ksvd import KSVD, batch_omp

BLOCK_NORMS = ("none", "l1", "l2")
#: Positions are fed to K-SVD in centimetres (metres × 100), as the spec suggests.
UNITS_PER_METRE = 100.0
#: Database entries gathered per vectorised HIK pass (bounds the temporary memory of :func:`stpm_kernel`).
HIK_CHUNK = 4_000_000


# --------------------------------------------------------------------------- TSR and the pyramid partition


def tsr_pairs(n_frames: int, sigma: int) -> tuple[np.ndarray, np.ndarray]:
    """0-based frame pairs ``(i, j)`` of the TSR slices of a ``n_frames``-frame clip (spec §2.5).

    ``i = 0, σ, 2σ, …`` while ``i < n_frames − 1`` (1-based ``1 + kσ < t``); ``j = min(i + σ, n_frames − 1)``.
    """
    sigma = int(sigma)
    if sigma < 1:
        raise ValueError(f"sigma must be >= 1, got {sigma}")
    i = np.arange(0, max(int(n_frames) - 1, 0), sigma, dtype=np.int64)
    return i, np.minimum(i + sigma, int(n_frames) - 1)


def split_bounds(n: int, parts: int) -> np.ndarray:
    """``numpy.array_split``'s boundaries of ``n`` items in ``parts`` near-equal parts (``parts + 1`` values)."""
    sizes = np.full(parts, n // parts, dtype=np.int64)
    sizes[: n % parts] += 1
    return np.concatenate([[0], np.cumsum(sizes)])


def n_cubes(level: int) -> int:
    """Cubes at pyramid level ``level``: ``2^l`` temporal segments × ``(l+1)²`` spatial blocks."""
    return 2**level * (level + 1) ** 2


def stpm_cubes(n_slices: int, n_atoms: int, level: int) -> list[tuple[slice, slice, slice]]:
    """The cubes of level ``level`` as ``(slices, rows, cols)`` index ranges of a ``[n_slices, q, q]`` TSR,
    temporal segment major (empty ranges where a clip has fewer slices than segments)."""
    t = split_bounds(n_slices, 2**level)
    s = split_bounds(n_atoms, level + 1)
    return [
        (slice(t[a], t[a + 1]), slice(s[b], s[b + 1]), slice(s[c], s[c + 1]))
        for a in range(2**level)
        for b in range(level + 1)
        for c in range(level + 1)
    ]


def rows_per_clip(n_levels: int) -> int:
    """Sparse rows (temporal segments over all levels) of one clip's pyramid: ``2^n_levels − 1``."""
    return 2 ** int(n_levels) - 1


def level_of_rows(n_levels: int) -> np.ndarray:
    """The level of each of a clip's :func:`rows_per_clip` rows (level-major, then segment)."""
    return np.repeat(np.arange(int(n_levels)), 2 ** np.arange(int(n_levels)))


def pool_pyramid(
    indices: np.ndarray, coefs: np.ndarray, n_atoms: int, sigma: int, n_levels: int, block_norm: str = "none"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The STPM pyramid of one clip from its OMP codes, as sparse rows (no level weights).

    Args:
        indices, coefs: ``[T, m]`` atoms and coefficients of every frame (a zero coefficient is ignored).

    Returns:
        ``(data float32, columns int64, row_lengths int64 [2^n_levels − 1])``: the CSR pieces of the clip's rows
        (one per (level, temporal segment), level-major); column ``a·q + b`` is entry ``(a, b)`` of the pooled
        ``q × q`` matrix ``max_τ |x_i x_jᵀ|`` of the segment, each spatial block normalised by ``block_norm``.
    """
    if block_norm not in BLOCK_NORMS:
        raise ValueError(f"block_norm must be one of {BLOCK_NORMS}, got {block_norm!r}")
    q = int(n_atoms)
    qq = q * q
    indices = np.asarray(indices, dtype=np.int64)
    i, j = tsr_pairs(len(indices), sigma)
    n_slices, m = len(i), indices.shape[1]
    a = np.abs(np.asarray(coefs, dtype=np.float64))
    flat = (indices[i][:, :, None] * q + indices[j][:, None, :]).reshape(n_slices, m * m)
    val = (a[i][:, :, None] * a[j][:, None, :]).reshape(n_slices, m * m)
    keep = val > 0
    slice_of = np.broadcast_to(np.arange(n_slices)[:, None], flat.shape)[keep]
    flat, val = flat[keep], val[keep]
    datas, cols, lengths = [], [], []
    for level in range(int(n_levels)):
        n_seg = 2**level
        seg = np.searchsorted(split_bounds(n_slices, n_seg), slice_of, side="right") - 1
        key = seg * qq + flat
        order = np.argsort(key, kind="stable")
        sk = key[order]
        starts = np.flatnonzero(np.concatenate([[True], sk[1:] != sk[:-1]])) if len(sk) else np.zeros(0, np.int64)
        pooled = np.maximum.reduceat(val[order], starts) if len(sk) else np.zeros(0)
        ukey = sk[starts]
        useg, ucol = ukey // qq, ukey % qq
        if block_norm != "none":
            nb = level + 1
            block = np.repeat(np.arange(nb), np.diff(split_bounds(q, nb)))
            group = (useg * nb + block[ucol // q]) * nb + block[ucol % q]
            w = pooled if block_norm == "l1" else pooled**2
            norm = np.bincount(group, weights=w, minlength=n_seg * nb * nb)
            if block_norm == "l2":
                norm = np.sqrt(norm)
            pooled = pooled / norm[group]
        datas.append(pooled.astype(np.float32))
        cols.append(ucol)
        lengths.append(np.bincount(useg, minlength=n_seg))
    return np.concatenate(datas), np.concatenate(cols).astype(np.int64), np.concatenate(lengths).astype(np.int64)


# --------------------------------------------------------------------------- pyramids and the kernel


@dataclass
class STPMPyramids:
    """The encoded clips: ``matrix`` CSR float32 ``[n_clips · (2^n_levels − 1), q²]``, one row per
    (clip, level, temporal segment), clip-major then level then segment; values unweighted."""

    matrix: sp.csr_matrix
    n_levels: int
    n_atoms: int
    _index: object = field(default=None, repr=False, compare=False)

    @property
    def n_clips(self) -> int:
        return self.matrix.shape[0] // rows_per_clip(self.n_levels)

    def __len__(self) -> int:
        return self.n_clips

    def clip_vectors(self) -> sp.csr_matrix:
        """One weighted row per clip, ``[n_clips, (2^n_levels − 1) · q²]``: the rows of a clip side by side, each
        scaled by its level weight ``2^-l``, so that the STPM kernel is one HIK between these rows."""
        R, qq = rows_per_clip(self.n_levels), self.n_atoms**2
        M = self.matrix
        lengths = np.diff(M.indptr)
        row_in_clip = np.arange(M.shape[0]) % R
        weights = (0.5 ** level_of_rows(self.n_levels))[row_in_clip]
        data = M.data.astype(np.float32) * np.repeat(weights, lengths).astype(np.float32)
        cols = M.indices.astype(np.int64) + np.repeat(row_in_clip.astype(np.int64) * qq, lengths)
        return sp.csr_matrix((data, cols, M.indptr[::R].astype(np.int64)), shape=(self.n_clips, R * qq))

    def column_index(self) -> _ColumnIndex:
        """The database side of :func:`stpm_kernel` (built once, cached)."""
        if self._index is None:
            self._index = _ColumnIndex(self.clip_vectors())
        return self._index


class _ColumnIndex:
    """The weighted clip vectors by column (CSC), for :func:`stpm_kernel`; ``self_similarity`` = ``K(z, z)``."""

    def __init__(self, vectors: sp.csr_matrix):
        self.csc = vectors.tocsc()
        self.csc.sort_indices()
        self.n_rows = vectors.shape[0]
        self.self_similarity = np.asarray(vectors.sum(axis=1), dtype=np.float64).ravel()

    def hik(self, vectors: sp.csr_matrix) -> np.ndarray:
        """``[n_queries, n_rows]``: ``Σ min(query, row)`` over the shared columns (values are non-negative)."""
        if vectors.shape[1] != self.csc.shape[1]:
            raise ValueError(f"query vectors have {vectors.shape[1]} columns, the database {self.csc.shape[1]}")
        indptr, rows, data = self.csc.indptr, self.csc.indices, self.csc.data
        out = np.zeros((vectors.shape[0], self.n_rows))
        for qi in range(vectors.shape[0]):
            lo, hi = vectors.indptr[qi], vectors.indptr[qi + 1]
            cols, vals = vectors.indices[lo:hi].astype(np.int64), vectors.data[lo:hi]
            starts = indptr[cols].astype(np.int64)
            lengths = indptr[cols + 1] - starts
            ends = np.cumsum(lengths)
            total = int(ends[-1]) if len(ends) else 0
            cuts = np.searchsorted(ends, np.arange(HIK_CHUNK, total, HIK_CHUNK), side="right")
            for a, b in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [len(cols)]])):
                ln = lengths[a:b]
                n = int(ln.sum())
                if not n:
                    continue
                gather = np.repeat(starts[a:b] - (np.cumsum(ln) - ln), ln) + np.arange(n)
                mins = np.minimum(data[gather], np.repeat(vals[a:b], ln))
                out[qi] += np.bincount(rows[gather], weights=mins, minlength=self.n_rows)
        return out


def stpm_kernel(queries: STPMPyramids, database: STPMPyramids, normalize: bool = False) -> np.ndarray:
    """float64 ``[n_queries, n_database]``: ``K = Σ_l 2^-l Σ_h HIK(Z_lh, Z'_lh)`` between pyramids
    (``normalize``: ``K(a, b) / sqrt(K(a, a) K(b, b))``, where ``K(a, a) = Σ`` of ``a``'s weighted values)."""
    if (queries.n_levels, queries.n_atoms) != (database.n_levels, database.n_atoms):
        raise ValueError(
            f"pyramids differ: queries (n_levels, n_atoms) = {(queries.n_levels, queries.n_atoms)}, "
            f"database {(database.n_levels, database.n_atoms)}"
        )
    index = database.column_index()
    vectors = queries.clip_vectors()
    K = index.hik(vectors)
    if normalize:
        own = np.asarray(vectors.sum(axis=1), dtype=np.float64).ravel()
        scale = np.sqrt(np.outer(own, index.self_similarity))
        K = np.divide(K, scale, out=np.zeros_like(K), where=scale > 0)
    return K


def pyramids_from_codes(
    codes: list[tuple[np.ndarray, np.ndarray]], n_atoms: int, sigma: int, n_levels: int, block_norm: str = "none"
) -> STPMPyramids:
    """The :class:`STPMPyramids` of clips given by their OMP codes ``[(indices [T, m], coefs [T, m]), …]``."""
    datas, cols, lengths = [], [], []
    for indices, coefs in codes:
        d, c, n = pool_pyramid(indices, coefs, n_atoms, sigma, n_levels, block_norm)
        datas.append(d)
        cols.append(c)
        lengths.append(n)
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(lengths))]).astype(np.int64)
    q = int(n_atoms)
    matrix = sp.csr_matrix((np.concatenate(datas), np.concatenate(cols), indptr), shape=(len(indptr) - 1, q * q))
    return STPMPyramids(matrix, int(n_levels), q)


# --------------------------------------------------------------------------- the retrieval method


class _MinFrames:
    """``min_frames`` = ``sigma + 1`` on an instance (one TSR slice); the default σ's value on the class."""

    def __get__(self, obj, owner=None) -> int:
        sigma = 7 if obj is None else obj.sigma
        return int(sigma) + 1


class TSRSTPMRetrieval(RetrievalMethod):
    """Zhou (2014) ch. 3 retrieval: K-SVD/OMP codes → TSR → STPM pyramid → HIK kernel (see the module docstring).

    Args:
        n_atoms: ``q``, dictionary atoms (thesis: 700).
        n_nonzero: ``m``, OMP non-zeros per frame (thesis: 35).
        sigma: TSR frame gap **in frames at ``fps``** (thesis: 7 at 120 Hz, 58 ms).
        n_levels: pyramid levels ``0 .. n_levels − 1`` (thesis "l = 3" → 3).
        block_norm: ``"none"`` (thesis-literal; the spatial split is then a no-op), ``"l1"`` or ``"l2"`` per cube.
        ksvd_iter: K-SVD iterations.
        max_dictionary_frames: frames (randomly chosen) the dictionary is learned on (``None``: all).
        normalize_kernel: ``False`` (thesis-literal: raw ``K``) or ``True``: the cosine-normalised
            ``K(a, b) / sqrt(K(a, a) K(b, b))``, an addition of this implementation (not in the thesis).
        fps: frame rate every clip is resampled to (thesis: HDM05's 120 Hz).
        heading: :func:`~mocapkit.motion.geometry.normalised_landmarks`'s heading (``"frame"``: per frame).
        random_state: seed of the K-SVD initialisation and frame sub-sampling.

    Attributes (after ``fit``): ``ksvd_`` (the fitted :class:`~mocapkit.retrieval.ksvd.KSVD`), ``database_``
    (:class:`STPMPyramids`), ``n_database_``.
    """

    label_free = True
    needs_run = False
    min_frames = _MinFrames()

    def __init__(
        self,
        n_atoms: int = 700,
        n_nonzero: int = 35,
        sigma: int = 7,
        n_levels: int = 3,
        block_norm: str = "none",
        ksvd_iter: int = 10,
        max_dictionary_frames: int | None = 20000,
        normalize_kernel: bool = False,
        fps: float = 120.0,
        heading: str = "frame",
        random_state=0,
    ):
        self.n_atoms = n_atoms
        self.n_nonzero = n_nonzero
        self.sigma = sigma
        self.n_levels = n_levels
        self.block_norm = block_norm
        self.ksvd_iter = ksvd_iter
        self.max_dictionary_frames = max_dictionary_frames
        self.normalize_kernel = normalize_kernel
        self.fps = fps
        self.heading = heading
        self.random_state = random_state

    def _check_params(self) -> None:
        if self.block_norm not in BLOCK_NORMS:
            raise ValueError(f"block_norm must be one of {BLOCK_NORMS}, got {self.block_norm!r}")
        for name in ("n_atoms", "n_nonzero", "sigma", "n_levels", "ksvd_iter"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        if int(self.n_atoms) > 46340:
            raise ValueError(f"n_atoms={self.n_atoms}: at most 46340 (q² column indices)")

    @staticmethod
    def _frames(sequences: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([s.reshape(len(s), -1) for s in sequences]).astype(np.float64) * UNITS_PER_METRE

    def _fit_sequences(self, sequences: list[np.ndarray], y) -> None:
        self._check_params()
        self.ksvd_ = KSVD(
            n_atoms=int(self.n_atoms),
            n_nonzero=int(self.n_nonzero),
            max_iter=int(self.ksvd_iter),
            random_state=self.random_state,
            max_samples=self.max_dictionary_frames,
        )
        self.ksvd_.fit(self._frames(sequences))

    def _encode_sequences(self, sequences: list[np.ndarray]) -> STPMPyramids:
        if not hasattr(self, "ksvd_"):
            raise NotFittedError(f"{type(self).__name__} is not fitted: call fit(database_motions) first")
        self._check_params()
        indices, coefs = batch_omp(self._frames(sequences), self.ksvd_.components_, int(self.n_nonzero))
        bounds = np.concatenate([[0], np.cumsum([len(s) for s in sequences])])
        return pyramids_from_codes(
            [(indices[a:b], coefs[a:b]) for a, b in pairwise(bounds)],
            int(self.n_atoms),
            int(self.sigma),
            int(self.n_levels),
            self.block_norm,
        )

    def _distances(self, queries: STPMPyramids, database: STPMPyramids) -> np.ndarray:
        return -stpm_kernel(queries, database, normalize=bool(self.normalize_kernel))

    def kernel(self, queries) -> np.ndarray:
        """The STPM similarity ``[n_queries, n_database]`` (``−distances``)."""
        return -self.distances(queries)

    # ------------------------------------------------------------------ state
    def _state(self) -> dict[str, np.ndarray]:
        self._check_fitted()
        M = self.database_.matrix
        return {
            "dictionary": np.asarray(self.ksvd_.components_, dtype=np.float64),
            "ksvd_error": np.asarray(self.ksvd_.error_, dtype=np.float64),
            "pyramid_data": np.asarray(M.data, dtype=np.float32),
            "pyramid_indices": np.asarray(M.indices, dtype=np.int32),
            "pyramid_indptr": np.asarray(M.indptr, dtype=np.int64),
            "pyramid_shape": np.array(
                [self.database_.n_clips, self.database_.n_levels, self.database_.n_atoms], dtype=np.int64
            ),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self._check_params()
        n_clips, n_levels, q = (int(v) for v in state["pyramid_shape"])
        D = np.asarray(state["dictionary"], dtype=np.float64)
        if (n_levels, q) != (int(self.n_levels), int(self.n_atoms)) or D.shape[0] != q:
            raise ValueError(
                f"state was saved with n_levels={n_levels}, n_atoms={q} (dictionary {D.shape}); "
                f"this instance has n_levels={self.n_levels}, n_atoms={self.n_atoms}"
            )
        indptr = np.asarray(state["pyramid_indptr"], dtype=np.int64)
        if len(indptr) != n_clips * rows_per_clip(n_levels) + 1:
            raise ValueError(f"state: {len(indptr) - 1} pyramid rows for {n_clips} clips of {n_levels} levels")
        ksvd = KSVD(
            n_atoms=q,
            n_nonzero=int(self.n_nonzero),
            max_iter=int(self.ksvd_iter),
            random_state=self.random_state,
            max_samples=self.max_dictionary_frames,
        )
        ksvd.components_ = D
        ksvd.error_ = [float(e) for e in state.get("ksvd_error", [])]
        ksvd.n_iter_ = len(ksvd.error_)
        self.ksvd_ = ksvd
        matrix = sp.csr_matrix(
            (
                np.asarray(state["pyramid_data"], dtype=np.float32),
                np.asarray(state["pyramid_indices"], dtype=np.int64),
                indptr,
            ),
            shape=(len(indptr) - 1, q * q),
        )
        self.database_ = STPMPyramids(matrix, n_levels, q)
        self.n_database_ = n_clips
