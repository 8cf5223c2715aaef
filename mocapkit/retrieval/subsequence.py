"""Search inside long takes: where in these takes does something like the query happen (``mocapkit search --within``).

A query clip ``Q`` (``[m, d]`` per-frame features) is looked for in each take ``X`` (``[n, d]``, same features) by
**subsequence DTW** (open begin and end on the take's side) in one pass over every frame of the take
(:func:`subsequence_profile`): for every end frame ``j``, the cheapest warping path of the whole query onto a
segment of ``X`` ending at ``j``, its squared cost and the frame where it begins (carried along the dynamic
programme, as SPRING does; Sakurai et al. 2007). Frame costs are squared Euclidean distances from matrix products
(BLAS, in blocks of columns); the programme is compiled with numba and keeps two columns, so memory does not grow
with the take.

Every end frame's segment is scored by the distance of :class:`~mocapkit.retrieval.dtw.DTWRetrieval` (the square
root of the warped sum of squared frame distances) divided by ``sqrt(m + segment length)``, as its
``length_normalised`` does; segments shorter than ``min_length`` or longer than ``max_length`` times the query are
dropped, and an end frame is a candidate when its distance is the smallest within a quarter of the query's length
either side. Candidates that overlap a better one (intersection over union above ``overlap``) are dropped; the
``k`` best are returned as :class:`Match` ``(take, start, end, distance)``, frames ``[start, end)``.

The cost is ``m * n * d`` per take: about 0.1-0.2 s per query per hour of takes on one core of this project's
machine (docs/results/retrieval.md#search-inside-long-takes). There is no prefilter: at that speed one would save
little and would miss matches (docs/decisions.md#within-search-features).

The features are those of the index's DTW method (its stored per-frame positions, ``[T, 60]`` normalised
landmarks for ``dtw_positions`` and the default, every joint for ``dtw_plain``), so an index built once answers
both whole-clip and ``--within`` queries. Evaluation (precision of the returned segments at IoU 0.5, seconds per
hour of motion searched): ``scripts/results/retrieval_within.py``, docs/results/retrieval.md#search-inside-long-takes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.ndimage import minimum_filter1d
from tqdm import tqdm

#: Columns of frame costs computed per matrix product (``[m, BLOCK]`` float64).
BLOCK = 4096
#: Frames searched above which a progress bar shows on a terminal (ten hours at 30 fps: a few seconds a query).
PROGRESS_FRAMES = 10 * 3600 * 30


@dataclass(frozen=True)
class Match:
    """A matched segment: take index, frames ``[start, end)`` of that take, distance (smaller = nearer)."""

    take: int
    start: int
    end: int
    distance: float


def segment_iou(a: tuple[int, int], b: tuple[int, int]) -> float:
    """Intersection over union of two frame intervals ``[start, end)``."""
    inter = max(0, min(a[1], b[1]) - max(a[0], b[0]))
    union = max(a[1], b[1]) - min(a[0], b[0])
    return inter / union if union > 0 else 0.0


def _suppress(order: np.ndarray, intervals: list[tuple[int, int, int]], overlap: float, keep: int) -> list[int]:
    """Indices in ``order`` (best first) whose ``(take, start, end)`` overlaps no kept one by IoU above
    ``overlap``, at most ``keep`` of them."""
    kept: list[int] = []
    for i in order:
        take, start, end = intervals[i]
        if all(intervals[j][0] != take or segment_iou((start, end), intervals[j][1:]) <= overlap for j in kept):
            kept.append(int(i))
            if len(kept) == keep:
                break
    return kept


@njit(cache=True, nogil=True)
def _subsequence_columns(costs, first, previous, previous_start, out_cost, out_start):  # pragma: no cover - numba
    """Advance the subsequence DTW over the columns of ``costs`` (``[m, w]`` frame costs of the query against
    series frames ``first .. first + w - 1``). ``previous`` / ``previous_start`` (``[m]``) hold the column before's
    accumulated costs and path starts and are updated in place; ``out_cost`` / ``out_start`` (``[w]``) receive the
    last query frame's. A cell is reached from the diagonal, from the previous query frame at the same series frame,
    or from the previous series frame at the same query frame; ties go to the first of these."""
    m, w = costs.shape
    column = np.empty(m)
    column_start = np.empty(m, dtype=np.int64)
    for c in range(w):
        column[0] = costs[0, c]  # open begin: the query may start at any series frame
        column_start[0] = first + c
        for i in range(1, m):
            best, begin = previous[i - 1], previous_start[i - 1]
            if column[i - 1] < best:
                best, begin = column[i - 1], column_start[i - 1]
            if previous[i] < best:
                best, begin = previous[i], previous_start[i]
            column[i] = costs[i, c] + best
            column_start[i] = begin
        out_cost[c] = column[m - 1]
        out_start[c] = column_start[m - 1]
        previous[:] = column
        previous_start[:] = column_start


def subsequence_profile(query: np.ndarray, series: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cost float64 [n], start int64 [n])``: for every frame ``j`` of ``series`` (``[n, d]``), the squared cost
    of the cheapest warping path of all of ``query`` (``[m, d]``) onto a segment ``series[start[j]:j + 1]``
    (squared Euclidean frame costs summed along the path; open begin and end)."""
    q = np.ascontiguousarray(query, dtype=np.float64)
    m, n = len(q), len(series)
    previous, previous_start = np.full(m, np.inf), np.zeros(m, dtype=np.int64)  # before the first frame: no path
    out_cost, out_start = np.empty(n), np.empty(n, dtype=np.int64)
    q_norms = (q * q).sum(axis=1)[:, None]
    for first in range(0, n, BLOCK):
        block = np.asarray(series[first : first + BLOCK], dtype=np.float64)  # a block at a time: no copy of the take
        costs = q_norms + (block * block).sum(axis=1)[None, :] - 2.0 * (q @ block.T)
        np.maximum(costs, 0.0, out=costs)  # rounding of the expansion can dip below 0
        last = first + len(block)
        _subsequence_columns(costs, first, previous, previous_start, out_cost[first:last], out_start[first:last])
    return out_cost, out_start


def subsequence_candidates(
    query: np.ndarray, series: np.ndarray, min_length: int, max_length: int, radius: int
) -> list[tuple[int, int, float]]:
    """``(start, end, distance)`` of every end frame of ``series`` whose segment (:func:`subsequence_profile`) lasts
    ``min_length`` to ``max_length`` frames and whose distance (module docstring) is the smallest within ``radius``
    end frames either side."""
    cost, start = subsequence_profile(query, series)
    end = np.arange(1, len(series) + 1)
    length = end - start
    distance = np.sqrt(cost / (len(query) + length))
    distance[(length < min_length) | (length > max_length)] = np.inf
    local = np.isfinite(distance) & (distance <= minimum_filter1d(distance, 2 * radius + 1, mode="nearest"))
    return [(int(start[j]), int(end[j]), float(distance[j])) for j in np.flatnonzero(local)]


def search_within(
    query: np.ndarray,
    takes: list[np.ndarray],
    k: int = 10,
    min_length: float = 0.5,
    max_length: float = 2.0,
    overlap: float = 0.5,
) -> list[Match]:
    """The ``k`` best non-overlapping matches of ``query`` (``[m, d]``) inside ``takes`` (each ``[n, d]``, the same
    features), best first (the module docstring).

    Args:
        k: matches returned (``k <= 0``: every candidate's).
        min_length, max_length: a match lasts this many times the query's frames, at least / at most.
        overlap: matches overlapping a better one by more IoU than this are dropped.
    """
    query = np.asarray(query, dtype=np.float64)
    m = len(query)
    if m < 2:
        raise ValueError(f"a query of {m} frame(s): at least 2 are needed")
    if not takes:
        raise ValueError("no takes to search")
    dims = {t.shape[1] for t in takes}
    if dims != {query.shape[1]}:
        raise ValueError(f"the query has {query.shape[1]} features per frame, the takes {sorted(dims)}")
    # a NaN would spread through the dynamic programme and hide every later match of its take
    if not np.isfinite(query).all():
        raise ValueError("the query's features hold NaN or infinite values")
    bad = [t for t, take in enumerate(takes) if not np.isfinite(take).all()]
    if bad:
        raise ValueError(f"the features of take(s) {bad[:10]} hold NaN or infinite values")
    lo_len, hi_len = max(2, int(np.floor(min_length * m))), int(np.ceil(max_length * m))
    radius = max(1, m // 4)
    matches: list[Match] = []
    frames = sum(len(take) for take in takes)
    quiet = True if frames <= PROGRESS_FRAMES else None  # (None: tqdm shows the bar on a terminal only)
    with tqdm(total=frames, desc="search --within", unit="frame", unit_scale=True, disable=quiet, leave=False) as bar:
        for t, take in enumerate(takes):
            for start, end, distance in subsequence_candidates(query, take, lo_len, hi_len, radius):
                matches.append(Match(t, start, end, distance))
            bar.update(len(take))
    order = np.argsort([mt.distance for mt in matches], kind="stable")
    keep = len(matches) if k <= 0 else int(k)
    kept = _suppress(order, [(mt.take, mt.start, mt.end) for mt in matches], overlap, keep)
    return [matches[i] for i in kept]


__all__ = [
    "Match",
    "search_within",
    "segment_iou",
    "subsequence_candidates",
    "subsequence_profile",
]
