"""Clips' per-frame features stored end to end, and the exact DTW of one query against many of them.

:class:`RaggedFrames` is how a DTW method keeps its database: every clip's ``[T_i, d]`` frames in one float32
array ``data [sum T_i, d]`` with ``offsets [n + 1]`` (clip ``i`` is ``data[offsets[i]:offsets[i + 1]]``). One array
instead of ``n`` small ones halves the memory of float64 lists, gathers candidates with one fancy index, and can be a
memory map: :mod:`mocapkit.retrieval.index` saves it as its own ``.npy`` file and opens it memory-mapped, so the
frames of a large library stay on disk and only the clips a query compares against are read.

:func:`candidate_dtw` is the second stage of a prefiltered search: the DTW distance of one query to ``K`` candidate
clips. It computes every frame-to-frame cost of the ``K`` clips in one matrix product (BLAS, float32), then runs the
dynamic programme on those costs in compiled code (numba), one candidate after the other. dtaidistance computes
each cell's cost inside its loop, about 40 times slower per cost on this machine's CPU; the distances are the same
(squared Euclidean frame costs, the square root of the cheapest warping path's sum, no band) to float32 rounding.
"""

from __future__ import annotations

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
        """A new store with ``arrays`` appended (in memory, even when this one is a memory map)."""
        new = RaggedFrames.from_list(arrays, dim=self.dim)
        data = np.concatenate([np.asarray(self.data), new.data], axis=0)
        return RaggedFrames(data, np.concatenate([self.offsets, self.offsets[-1] + new.offsets[1:]]))

    def subset(self, indices: np.ndarray) -> RaggedFrames:
        """The clips ``indices``, in that order, as a new in-memory store (one fancy index of the frames)."""
        indices = np.asarray(indices, dtype=np.int64)
        starts, lengths = self.offsets[indices], self.lengths[indices]
        ends = np.cumsum(lengths)
        # every frame row of every clip without a Python loop: the clip's start, shifted by where it lands, plus the
        # running row number
        rows = np.repeat(starts - (ends - lengths), lengths) + np.arange(int(ends[-1]) if len(ends) else 0)
        return RaggedFrames(np.asarray(self.data[rows], dtype=np.float32), np.concatenate([[0], ends]))

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


def candidate_dtw(
    query: np.ndarray, frames: np.ndarray, lengths: np.ndarray, frame_norms: np.ndarray | None = None
) -> np.ndarray:
    """float64 ``[K]``: the DTW distance (unconstrained, squared Euclidean frame costs, square root of the path's
    sum; dtaidistance's ``dtw_ndim.distance``) of ``query`` ``[T_q, d]`` to each of ``K`` clips given end to end as
    ``frames`` ``[sum T, d]`` with ``lengths`` ``[K]`` (a :class:`RaggedFrames`' ``data`` and ``lengths``).
    ``frame_norms`` ``[sum T]``, the frames' squared norms, may be passed when many queries share ``frames``."""
    q = np.asarray(query, dtype=np.float64)
    c = np.asarray(frames, dtype=np.float64)
    lengths = np.asarray(lengths, dtype=np.int64)
    if len(lengths) == 0:
        return np.zeros(0)
    if q.ndim != 2 or c.ndim != 2 or q.shape[1] != c.shape[1] or len(q) == 0 or int(lengths.sum()) != len(c):
        raise ValueError(
            f"candidate_dtw: query [T, d] and frames [sum T, d] with lengths summing to their rows, got query "
            f"{q.shape}, frames {c.shape}, lengths summing to {int(lengths.sum())}"
        )
    if np.any(lengths < 1):
        raise ValueError("candidate_dtw: every candidate needs at least one frame")
    # |q - c|^2 = |q|^2 + |c|^2 - 2 q.c: the products in one [T_q, sum T] matrix product, the sums in the kernel.
    # float64, because in float32 the cancellation leaves a clip about 1 % of a near copy's distance from itself
    dots = q @ c.T
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    if frame_norms is None:
        frame_norms = (c * c).sum(axis=1)
    return np.sqrt(_warp_costs(dots, (q * q).sum(axis=1), np.asarray(frame_norms, np.float64), starts, lengths))


@njit(cache=True, nogil=True)
def _warp_costs(dots, query_norms, frame_norms, starts, lengths):  # pragma: no cover - compiled by numba
    """float64 ``[K]``: for each candidate ``k``, the cheapest warping path's summed cost through the frame costs
    ``query_norms[i] + frame_norms[j] - 2 dots[i, j]`` of its columns ``starts[k]:starts[k] + lengths[k]`` (steps:
    diagonal, down, right; one row of the table kept at a time)."""
    n_query = dots.shape[0]
    out = np.empty(len(starts), dtype=np.float64)
    for k in range(len(starts)):
        s, n = starts[k], lengths[k]
        row = np.empty(n, dtype=np.float64)
        acc = 0.0
        for j in range(n):  # the first query frame: only horizontal steps reach it
            acc += max(query_norms[0] + frame_norms[s + j] - 2.0 * dots[0, s + j], 0.0)
            row[j] = acc
        for i in range(1, n_query):
            diagonal = row[0]
            row[0] = diagonal + max(query_norms[i] + frame_norms[s] - 2.0 * dots[i, s], 0.0)
            for j in range(1, n):
                up = row[j]
                best = diagonal if diagonal < up else up
                if row[j - 1] < best:
                    best = row[j - 1]
                # rounding can make a cost slightly negative
                row[j] = best + max(query_norms[i] + frame_norms[s + j] - 2.0 * dots[i, s + j], 0.0)
                diagonal = up
        out[k] = row[n - 1]
    return out
