"""Clips' per-frame features stored end to end, and the exact DTW of one query against many of them.

:class:`RaggedFrames` is how a DTW method keeps its database: every clip's ``[T_i, d]`` frames in one float32
array ``data [sum T_i, d]`` with ``offsets [n + 1]`` (clip ``i`` is ``data[offsets[i]:offsets[i + 1]]``). One array
instead of ``n`` small ones halves the memory of float64 lists, gathers candidates with one fancy index, and can be a
memory map: :mod:`mocapkit.retrieval.index` saves it as its own ``.npy`` file and opens it memory-mapped, so the
frames of a large library stay on disk and only the clips a query compares against are read. A writable map grows
in place (:meth:`RaggedFrames.extend`): clips added to a large library write only their own frames.

:class:`CandidateCosts` holds the frame-to-frame costs of one query against ``K`` clips, from matrix products
(BLAS, float32, in blocks that stay in cache); from them it reads every clip's lower bound in one pass and the DTW
distance of any clip by a dynamic programme compiled with numba. dtaidistance computes each cell's cost inside its
loop; on one query against 2,000 HDM05 clips this is about 6 times faster with the same distances (squared
Euclidean frame costs, the square root of the cheapest warping path's sum, no band) to float32 rounding
(``bench/bench_retrieval.py``). :func:`candidate_dtw` is the distances alone.
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Sequence

import numpy as np
from numba import njit


class RaggedFrames:
    """Clips' frame sequences end to end (module docstring).

    Args:
        data: ``[sum T_i, d]`` frames (float32 ``ndarray`` or a read-only ``np.memmap``).
        offsets: int64 ``[n + 1]``, ``offsets[0] == 0``, non-decreasing, ``offsets[-1] == len(data)``.
    """

    def __init__(self, data: np.ndarray, offsets: np.ndarray):
        offsets = np.asarray(offsets, dtype=np.int64)
        if data.ndim != 2 or offsets.ndim != 1 or len(offsets) < 1 or offsets[0] != 0 or offsets[-1] != len(data):
            raise ValueError(
                f"RaggedFrames: data must be [frames, d] and offsets [n + 1] from 0 to len(data), got data "
                f"{data.shape} and offsets of length {len(offsets)} ending at {offsets[-1] if len(offsets) else None}"
            )
        if np.any(np.diff(offsets) < 0):
            raise ValueError("RaggedFrames: offsets must not decrease")
        self.data = data
        self.offsets = offsets

    @classmethod
    def from_list(cls, arrays: Sequence[np.ndarray], dim: int | None = None) -> RaggedFrames:
        """float32 frames of ``arrays`` (each ``[T_i, d]``); ``dim`` gives ``d`` when ``arrays`` is empty."""
        if not len(arrays):
            return cls(np.zeros((0, dim or 0), dtype=np.float32), np.zeros(1, dtype=np.int64))
        lengths = np.array([len(a) for a in arrays], dtype=np.int64)
        data = np.concatenate([np.asarray(a, dtype=np.float32) for a in arrays], axis=0)
        return cls(data, np.concatenate([[0], np.cumsum(lengths)]))

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, i: int) -> np.ndarray:
        """Clip ``i``'s frames, float64 ``[T_i, d]`` C-contiguous (what dtaidistance takes)."""
        return np.ascontiguousarray(self.data[self.offsets[i] : self.offsets[i + 1]], dtype=np.float64)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    @property
    def dim(self) -> int:
        return int(self.data.shape[1])

    @property
    def lengths(self) -> np.ndarray:
        """int64 ``[n]``: each clip's frame count."""
        return np.diff(self.offsets)

    def extend(self, arrays: Sequence[np.ndarray]) -> RaggedFrames:
        """A new store with ``arrays`` appended: in memory, or, when this store is a writable memory map of a
        ``.npy`` file (:meth:`save`, :func:`open_frames` with ``writable``), appended to that file in place, so that
        only the new frames are written and none is held in memory."""
        new = RaggedFrames.from_list(arrays, dim=self.dim)
        offsets = np.concatenate([self.offsets, self.offsets[-1] + new.offsets[1:]])
        if isinstance(self.data, np.memmap) and self.data.mode == "r+":
            return RaggedFrames(_append_npy(self.data.filename, int(self.offsets[-1]), new.data), offsets)
        return RaggedFrames(np.concatenate([np.asarray(self.data), new.data], axis=0), offsets)

    def save(self, path: str | os.PathLike) -> RaggedFrames:
        """Write the frames to the ``.npy`` file ``path`` and return the store on that file, memory-mapped and
        writable: :meth:`extend` then appends to it in place (how a library too large for memory is built)."""
        np.save(path, np.asarray(self.data, dtype=np.float32), allow_pickle=False)
        return RaggedFrames(open_frames(path, len(self.data), writable=True), self.offsets)

    def subset(self, indices: np.ndarray) -> RaggedFrames:
        """The clips ``indices``, in that order, as a new in-memory store (one fancy index of the frames)."""
        indices = np.asarray(indices, dtype=np.int64)
        starts, lengths = self.offsets[indices], self.lengths[indices]
        if isinstance(self.data, np.memmap):
            prefetch(self.data, starts, lengths)
        ends = np.cumsum(lengths)
        # every frame row of every clip without a Python loop: the clip's start, shifted by where it lands, plus the
        # running row number
        rows = np.repeat(starts - (ends - lengths), lengths) + np.arange(int(ends[-1]) if len(ends) else 0)
        return RaggedFrames(np.asarray(self.data[rows], dtype=np.float32), np.concatenate([[0], ends]))

    def kept_subset(self, indices: np.ndarray) -> RaggedFrames:
        """:meth:`subset` of ``indices``, gathered on the first call and kept with this store: for clips every query
        reads (mutual proximity's reference clips). Gathered again when called with another array object; the
        array must not change in place."""
        kept = getattr(self, "_kept", None)
        if kept is None or kept[0] is not indices:
            kept = self._kept = (indices, self.subset(indices))
        return kept[1]

    def chunks(self, max_frames: int) -> list[tuple[int, int]]:
        """``(first, end)`` clip ranges in order, each of at most ``max_frames`` frames (or one longer clip)."""
        out, first = [], 0
        while first < len(self):
            end = int(np.searchsorted(self.offsets, self.offsets[first] + max_frames, side="right")) - 1
            end = max(end, first + 1)
            out.append((first, end))
            first = end
        return out

    def to_state(self, prefix: str) -> dict[str, np.ndarray]:
        """``{prefix_frames, prefix_offsets}`` for a method's ``_state`` (:mod:`mocapkit.retrieval.index` saves
        every ``*_frames`` array as its own ``.npy`` file and opens it memory-mapped)."""
        return {f"{prefix}_frames": self.data, f"{prefix}_offsets": self.offsets}

    @classmethod
    def from_state(cls, prefix: str, state: dict[str, np.ndarray]) -> RaggedFrames:
        """The inverse of :meth:`to_state`; a memory-mapped ``data`` stays memory-mapped."""
        return cls(state[f"{prefix}_frames"], state[f"{prefix}_offsets"])


def open_frames(path: str | os.PathLike, rows: int | None = None, writable: bool = False) -> np.memmap:
    """The first ``rows`` frames (None: all) of the float32 ``[frames, d]`` ``.npy`` file ``path``, memory-mapped
    (read-only, or writable for :meth:`RaggedFrames.extend` to append to). Frames beyond ``rows`` (an append
    interrupted before its index was saved) are not part of the store, and the next append writes over them.

    Raises:
        ValueError: naming ``path``: not a float32 ``[frames, d]`` array, or fewer than ``rows`` frames.
    """
    data = np.load(path, mmap_mode="r+" if writable else "r", allow_pickle=False)
    rows = len(data) if rows is None else int(rows)
    if data.dtype != np.float32 or data.ndim != 2 or len(data) < rows:
        raise ValueError(
            f"{path}: expected float32 frames [at least {rows}, d], found {data.dtype} {data.shape} (a damaged or "
            "truncated file)"
        )
    return data if len(data) == rows else data[:rows]


def mapped_pages(data: np.memmap, starts: np.ndarray, lengths: np.ndarray) -> list[tuple[int, int]]:
    """``(offset, length)`` in bytes within ``data``'s memory map (``data._mmap``), offsets on page boundaries, one
    range per clip of the frames ``starts[i]:starts[i] + lengths[i]`` of the ``[frames, d]`` map ``data``, covering
    its bytes. Empty when ``data`` has no map of its own to advise (numpy keeps one per opened file)."""
    mapping = getattr(data, "_mmap", None)
    if mapping is None or not len(starts):
        return []
    whole = np.frombuffer(mapping, dtype=np.uint8)  # where the map begins, to place ``data`` (a slice or past a header)
    first = data.ctypes.data - whole.ctypes.data
    del whole  # (an export of the map: it must not outlive this call, or the map cannot be closed)
    row_bytes = data.strides[0]
    begin = first + np.asarray(starts, dtype=np.int64) * row_bytes
    end = begin + np.asarray(lengths, dtype=np.int64) * row_bytes
    aligned = begin - begin % mmap.PAGESIZE
    return [(int(a), int(e - a)) for a, e in zip(aligned, end) if e > a]


def prefetch(data: np.memmap, starts: np.ndarray, lengths: np.ndarray) -> None:
    """Ask the kernel to read the clips' frames (``starts``, ``lengths`` in frames) of the memory-mapped ``data``
    from disk now, all at once (``madvise(MADV_WILLNEED)`` on each clip's pages), before they are gathered: the disk
    serves them together. Without it each page fault of the gather waits for its own read (and the device's
    read-ahead around it): a query of a library larger than memory then spends most of its time waiting
    (docs/scaling.md#a-million-clips; the same-run reference in ``bench/bench_retrieval.py --cold``). A clip already
    in the page cache costs a system call of about 2 microseconds."""
    if not hasattr(mmap, "MADV_WILLNEED"):  # (not on every platform)
        return
    mapping = data._mmap
    try:
        for offset, length in mapped_pages(data, starts, lengths):
            mapping.madvise(mmap.MADV_WILLNEED, offset, length)
    except OSError:  # advice only: a file system that refuses it leaves the gather to read as it would have
        return


def _append_npy(path: str | os.PathLike, rows: int, new: np.ndarray) -> np.memmap:
    """``path``'s first ``rows`` frames followed by ``new`` (float32 ``[n, d]``), written in place: the file is cut
    after its first ``rows`` frames, ``new`` appended, and only then the header's frame count rewritten (numpy
    leaves room in a ``.npy`` header for that count to grow), so an interrupted append leaves ``rows`` valid frames.
    Returns the file's frames memory-mapped, writable."""
    fmt = np.lib.format
    with open(path, "r+b") as handle:
        version = fmt.read_magic(handle)
        read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, fortran, dtype = read_header(handle)
        start = handle.tell()
        if fortran or dtype != np.float32 or len(shape) != 2 or shape[1] != new.shape[1] or shape[0] < rows:
            raise ValueError(f"{path}: cannot append [{len(new)}, {new.shape[1]}] float32 frames to {dtype} {shape}")
        handle.truncate(start + rows * shape[1] * 4)
        handle.seek(0, os.SEEK_END)
        handle.write(np.ascontiguousarray(new, dtype=np.float32).tobytes())
        handle.flush()
        handle.seek(0)
        header = {"descr": fmt.dtype_to_descr(dtype), "fortran_order": False, "shape": (rows + len(new), shape[1])}
        (fmt.write_array_header_1_0 if version == (1, 0) else fmt.write_array_header_2_0)(handle, header)
        if handle.tell() != start:  # numpy's header padding did not hold the new count: the file is not usable
            raise ValueError(f"{path}: the .npy header changed size when its frame count grew")
    return open_frames(path, rows + len(new), writable=True)


class CandidateCosts:
    """The frame costs of one query against candidate clips, from which every candidate's lower bound and the exact
    DTW distance of any of them are read (the module docstring).

    Args:
        query: ``[T_q, d]`` frames.
        candidates: the clips, ``[T_k, d]`` each.

    ``costs`` is float32 ``[sum T_k, T_q]``: ``|q_i - c_j|^2 = |q_i - m|^2 + |c_j - m|^2 - 2 (q_i - m).(c_j - m)``,
    the products from one matrix product per block of :attr:`BLOCK_FRAMES` candidate frames. ``m`` is the query's
    mean frame: the sum cancels where frames are near each other, and centring keeps what it cancels small. The
    distances agree with dtaidistance's float64 ones to about 5e-7 of their value (bench_retrieval); a clip's
    distance to itself is rounding, not 0: about 2e-4 on HDM05 clips' features, where the nearest other clip is
    at 0.15 or more.
    """

    #: Candidate frames per matrix product: the block's arrays stay in the CPU's cache.
    BLOCK_FRAMES = 2048

    def __init__(self, query: np.ndarray, candidates: RaggedFrames):
        q = np.asarray(query, dtype=np.float64)
        if q.ndim != 2 or len(q) == 0 or q.shape[1] != candidates.dim:
            raise ValueError(
                f"CandidateCosts: the query must be [T >= 1, {candidates.dim}] like the candidates' frames, got "
                f"{q.shape}"
            )
        self.lengths = candidates.lengths
        if np.any(self.lengths < 1):
            raise ValueError("CandidateCosts: every candidate needs at least one frame")
        self.starts = candidates.offsets[:-1]
        mean = q.mean(axis=0)
        centred = (q - mean).astype(np.float32)
        query_norms = (centred * centred).sum(axis=1)
        minus_twice = -2.0 * centred.T  # the -2 of the expansion inside the product: exact, a power of two
        mean = mean.astype(np.float32)
        self.costs = np.empty((len(candidates.data), len(q)), dtype=np.float32)
        for first, end in candidates.chunks(self.BLOCK_FRAMES):
            a, b = candidates.offsets[first], candidates.offsets[end]
            c = np.asarray(candidates.data[a:b], dtype=np.float32) - mean
            block = self.costs[a:b]
            np.matmul(c, minus_twice, out=block)
            block += query_norms[None, :]
            block += np.einsum("ij,ij->i", c, c)[:, None]
            np.maximum(block, 0.0, out=block)  # rounding can leave a near-zero cost slightly negative

    def distances(self, which: np.ndarray | None = None) -> np.ndarray:
        """float64: the DTW distance (unconstrained, squared Euclidean frame costs, the square root of the cheapest
        path's sum: dtaidistance's ``dtw_ndim.distance``) to the candidates ``which`` (None: all), in that order."""
        which = np.arange(len(self.lengths)) if which is None else np.asarray(which, dtype=np.int64)
        return np.sqrt(_warp_costs(self.costs, self.starts[which], self.lengths[which]))

    def lower_bounds(self) -> np.ndarray:
        """float64 ``[K]``, each at most the candidate's :meth:`distances`: a warping path passes through every frame
        of both clips, so its sum is at least that of each candidate frame's cheapest query frame, and at least that
        of each query frame's cheapest candidate frame (the larger of the two; without a band, the bound LB_Keogh's
        envelope would give is loose, as the envelope is the whole query). One pass over the costs."""
        return np.sqrt(_nearest_frame_sums(self.costs, self.starts, self.lengths))


def candidate_dtw(query: np.ndarray, candidates: RaggedFrames) -> np.ndarray:
    """float64 ``[K]``: the DTW distance of ``query`` ``[T_q, d]`` to each clip of ``candidates``
    (:meth:`CandidateCosts.distances`)."""
    if len(candidates) == 0:
        return np.zeros(0)
    return CandidateCosts(query, candidates).distances()


@njit(cache=True, nogil=True, fastmath=True)
def _nearest_frame_sums(costs, starts, lengths):  # pragma: no cover - compiled by numba
    """float64 ``[K]``: per candidate (rows ``starts[k]:starts[k] + lengths[k]`` of ``costs``), the larger of the
    sum of each of its frames' cheapest cost over the query's frames and the sum of each query frame's cheapest cost
    over its frames. (The costs are finite and non-negative: fastmath's reordered minima are exact.)"""
    n_query = costs.shape[1]
    out = np.empty(len(starts), dtype=np.float64)
    column_min = np.empty(n_query, dtype=np.float32)
    for k in range(len(starts)):
        s, n = starts[k], lengths[k]
        column_min[:] = np.inf
        rows = 0.0
        for j in range(s, s + n):
            row_min = np.float32(np.inf)
            for i in range(n_query):
                cost = costs[j, i]
                row_min = min(row_min, cost)
                column_min[i] = min(column_min[i], cost)
            rows += row_min
        columns = 0.0
        for i in range(n_query):
            columns += column_min[i]
        out[k] = max(rows, columns)
    return out


@njit(cache=True, nogil=True)
def _warp_costs(costs, starts, lengths):  # pragma: no cover - compiled by numba
    """float64 ``[K]``: for each candidate ``k``, the cheapest warping path's summed cost through its rows
    ``starts[k]:starts[k] + lengths[k]`` of ``costs`` ``[frames, T_q]`` (steps: diagonal, along either clip; one
    row of the table kept at a time, over the query's frames)."""
    n_query = costs.shape[1]
    out = np.empty(len(starts), dtype=np.float64)
    row = np.empty(n_query, dtype=np.float64)
    for k in range(len(starts)):
        s, n = starts[k], lengths[k]
        acc = 0.0
        for i in range(n_query):  # the candidate's first frame: only steps along the query reach it
            acc += costs[s, i]
            row[i] = acc
        for j in range(s + 1, s + n):
            diagonal = row[0]
            row[0] = diagonal + costs[j, 0]
            for i in range(1, n_query):
                up = row[i]
                best = diagonal if diagonal < up else up
                if row[i - 1] < best:
                    best = row[i - 1]
                row[i] = best + costs[j, i]
                diagonal = up
        out[k] = row[n_query - 1]
    return out
