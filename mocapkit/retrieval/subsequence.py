"""Search inside long takes: where in these takes does something like the query happen (``mocapkit search --within``).

A query clip ``Q`` (``[m, d]`` per-frame features) is looked for in each take ``X`` (``[n, d]``, same features) in
two stages:

1. **prefilter on windowed descriptors**: every window of ``m`` frames of every take, every ``stride`` frames
   (``m / 4`` by default), becomes a descriptor: its frames at ``points`` evenly spaced times (``[points, d]``,
   flattened). Windows are ranked by the Euclidean distance of their descriptor to the query's; after suppressing
   windows that overlap a better one by more than half, the best ``candidates`` windows (over all takes) go on.
   This is a handful of array operations per take whatever its length;
2. **subsequence DTW** (open begin and end; dtaidistance's C ``warping_paths_fast`` with ``psi`` relaxation on the
   take's side) on each candidate window widened by ``m / 2`` frames each side: the best end frame whose matched
   segment lasts between ``min_length`` and ``max_length`` times the query, the start by backtracking the warping
   path. The distance is that of :class:`~mocapkit.retrieval.dtw.DTWRetrieval` (the square root of the warped sum
   of squared frame distances), divided by ``sqrt(m + segment length)`` as its ``length_normalised`` does.

Matches that overlap a better one (intersection over union above ``overlap``) are dropped; the ``k`` best are
returned as :class:`Match` ``(take, start, end, distance)``, frames ``[start, end)``.

The features are those of the index's DTW method (its stored per-frame positions, ``[T, 60]`` normalised
landmarks for ``dtw_positions`` and the default, every joint for ``dtw_plain``), so an index built once answers
both whole-clip and ``--within`` queries. Evaluation (precision of the returned segments at IoU 0.5, seconds per
hour of motion searched): ``scripts/results/retrieval_within.py``, docs/results/retrieval.md#search-inside-long-takes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Match:
    """A matched segment: take index, frames ``[start, end)`` of that take, distance (smaller = nearer)."""

    take: int
    start: int
    end: int
    distance: float


def window_descriptors(x: np.ndarray, length: int, stride: int, points: int) -> tuple[np.ndarray, np.ndarray]:
    """``(starts int64 [W], descriptors float64 [W, points * d])``: every window ``[s, s + length)`` of ``x``
    (``[n, d]``) with ``s`` a multiple of ``stride`` (and the last window flush with the end), sampled at ``points``
    evenly spaced frames. A take shorter than ``length`` gives one window, the whole take."""
    n = len(x)
    length = min(int(length), n)
    starts = np.arange(0, n - length + 1, max(1, int(stride)), dtype=np.int64)
    if starts[-1] != n - length:
        starts = np.append(starts, n - length)
    offsets = np.round(np.linspace(0, length - 1, int(points))).astype(np.int64)
    return starts, x[starts[:, None] + offsets[None, :]].reshape(len(starts), -1).astype(np.float64)


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


def best_subsequence(
    query: np.ndarray, series: np.ndarray, min_length: int, max_length: int, penalty: float = 0.0
) -> tuple[int, int, float] | None:
    """``(start, end, distance)`` of the best match of all of ``query`` (``[m, d]``) to a segment
    ``series[start:end]`` (``[n, d]``) lasting ``min_length`` to ``max_length`` frames, by subsequence DTW (open
    begin and end); distance as :class:`~mocapkit.retrieval.dtw.DTWRetrieval` with ``length_normalised``. None
    when no segment has an allowed length. ``penalty`` is added to the squared cost of every non-diagonal step
    (dtaidistance's ``penalty``), in units of the query's mean squared frame distance to its mean frame."""
    from dtaidistance import dtw_ndim

    m, n = len(query), len(series)
    q = np.ascontiguousarray(query, dtype=np.float64)
    x = np.ascontiguousarray(series, dtype=np.float64)
    scale = float(((q - q.mean(axis=0)) ** 2).sum(axis=1).mean()) if penalty else 0.0
    _, paths = dtw_ndim.warping_paths_fast(
        q, x, psi=(0, 0, n, n), penalty=penalty * scale, compact=False, psi_neg=False, keep_int_repr=True
    )
    last = paths[m, 1:]  # squared cost of the whole query ending at each series frame
    for end in np.argsort(last, kind="stable")[: max(8, n // 4)]:
        if not np.isfinite(last[end]) or end + 1 < min_length:
            continue
        start = _backtrack_start(paths, int(end))
        length = int(end) + 1 - start
        if min_length <= length <= max_length:
            return start, int(end) + 1, float(np.sqrt(last[end]) / np.sqrt(m + length))
    return None


def _backtrack_start(paths: np.ndarray, end: int) -> int:
    """The series frame where the optimal warping path ending at query's last frame and series frame ``end``
    begins (``paths`` is dtaidistance's ``[m + 1, n + 1]`` accumulated-cost matrix)."""
    i, j = paths.shape[0] - 1, end + 1
    while i > 1:
        steps = (paths[i - 1, j - 1], paths[i - 1, j], paths[i, j - 1]) if j > 1 else (np.inf, paths[i - 1, j], np.inf)
        step = int(np.argmin(steps))
        if step == 0:
            i, j = i - 1, j - 1
        elif step == 1:
            i -= 1
        else:
            j -= 1
    return j - 1


def search_within(
    query: np.ndarray,
    takes: list[np.ndarray],
    k: int = 10,
    candidates: int | None = None,
    stride: float = 0.25,
    points: int = 8,
    min_length: float = 0.5,
    max_length: float = 2.0,
    overlap: float = 0.5,
    penalty: float = 0.0,
) -> list[Match]:
    """The ``k`` best non-overlapping matches of ``query`` (``[m, d]``) inside ``takes`` (each ``[n, d]``, the same
    features), best first (the module docstring).

    Args:
        k: matches returned (``k <= 0``: every candidate's).
        candidates: windows passed from the prefilter to DTW (None: ``max(4 k, 20)``).
        stride: window step, a fraction of the query's length.
        points: frames per window descriptor.
        min_length, max_length: a match lasts this many times the query's frames, at least / at most.
        overlap: matches (and prefilter windows) overlapping a better one by more IoU than this are dropped.
        penalty: cost of a non-diagonal warping step (:func:`best_subsequence`).
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
    wanted = max(4 * k, 20) if candidates is None else int(candidates)
    step = max(1, int(round(stride * m)))
    q_desc = window_descriptors(query, m, m, points)[1][0]
    intervals, scores = [], []
    for t, take in enumerate(takes):
        starts, desc = window_descriptors(take, m, step, points)
        d = np.sqrt(((desc - q_desc) ** 2).sum(axis=1))
        width = min(m, len(take))
        intervals += [(t, int(s), int(s) + width) for s in starts]
        scores.append(d)
    scores = np.concatenate(scores)
    chosen = _suppress(np.argsort(scores, kind="stable"), intervals, 0.5, wanted)
    lo_len, hi_len = max(2, int(np.floor(min_length * m))), int(np.ceil(max_length * m))
    matches: list[Match] = []
    for i in chosen:
        t, start, end = intervals[i]
        take = takes[t]
        a, b = max(0, start - m // 2), min(len(take), end + m // 2)
        found = best_subsequence(query, take[a:b], lo_len, hi_len, penalty)
        if found is not None:
            matches.append(Match(t, a + found[0], a + found[1], found[2]))
    order = np.argsort([mt.distance for mt in matches], kind="stable")
    kept = _suppress(order, [(mt.take, mt.start, mt.end) for mt in matches], overlap, len(matches))
    out = [matches[i] for i in kept]
    return out if k <= 0 else out[: int(k)]


__all__ = ["Match", "best_subsequence", "search_within", "segment_iou", "window_descriptors"]
