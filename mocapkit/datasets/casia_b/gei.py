"""Gait Energy Images (GEIs): the mean of aligned binary silhouettes over a gait cycle.

A GEI (Han & Bhanu, "Individual recognition using gait energy image", TPAMI 2006) is
``G(x, y) = 1/N · Σ_t B_t(x, y)`` over the ``N`` size-normalised, horizontally centred
silhouettes ``B_t`` of one gait cycle: 1 where the body always is, 0 where it never is,
grey where the limbs swing. Three steps, one function each:

:func:`normalize_silhouettes`
    OpenGait's pretreatment (``datasets/pretreatment.py``) without OpenCV: drop empty
    frames, crop the rows to the silhouette's vertical extent, scale to a fixed height
    keeping the aspect ratio, centre the horizontal *median column* (the first column
    where the cumulative column mass exceeds half the total) and cut or zero-pad to the
    output width. All frames are resampled at once with a box (area) filter, first the
    rows, then the columns; each output pixel is a weighted sum of the few input pixels it
    covers (the taps), gathered for all frames in one numpy operation per tap.
:func:`gait_period`
    the gait cycle length in frames from the autocorrelation of the lower-body width
    (:func:`leg_width_signal`): legs apart twice per cycle make it oscillate once per step;
    the cycle is the autocorrelation peak in a plausible range of cycle lengths that also
    correlates at half its lag (:func:`period_from_signal`). Frames cut by the picture's side
    are left out of the signal. On synthetic CASIA-B renders (level cameras, an earlier
    version of the renderer) it was within one frame for 20–24 of 24 walks per oblique or side
    view, but only 7–9 of 24 in the frontal views (0°, 180°), where the legs hardly change the
    silhouette's width; on the current renderer's 16-subject set, 52 of 1,760 sequences (24 of
    them frontal) have no detectable period.
:func:`gait_energy_images`
    one GEI per whole gait cycle (``per="cycle"``) or one per sequence
    (``per="sequence"``); cycles are cut back to back on the sequence's own frame clock.

Sizes: ``(64, 44)`` is OpenGait's convention (64 px high, 64 px wide around the median
column, then 10 columns cut from each side); ``(124, 124)`` is the thesis network's square
input (silhouette 124 px high, centred in 124 columns). Any ``(height, width)`` works: the
window is always ``width`` columns centred on the median column.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: OpenGait's GEI size (height, width).
OPENGAIT_SIZE = (64, 44)
#: The thesis network's input size (height, width).
THESIS_SIZE = (124, 124)
PER_CHOICES = ("cycle", "sequence")


class GaitSequenceError(ValueError):
    """A silhouette sequence from which no GEI can be built.

    Attributes:
        reason: short code: ``"no_frames"`` (no non-empty silhouette, or fewer than
            ``min_frames``), ``"no_period"`` (no gait cycle found in the leg-area signal),
            ``"too_short"`` (fewer frames than one gait cycle).
    """

    def __init__(self, message: str, reason: str):
        self.reason = reason
        super().__init__(message)

    def __reduce__(self):  # picklable, so worker processes can send it back
        return (type(self), (str(self), self.reason))


# --------------------------------------------------------------------------- normalisation


def _box_taps(starts: np.ndarray, scales: np.ndarray, n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-resampling taps: int64 indices and float32 weights, both ``[T, n_out, K]``.

    Output pixel ``i`` of frame ``t`` covers the input interval ``[starts[t] + i / s, starts[t] + (i + 1) / s)``
    (``s = scales[t]`` output pixels per input pixel); its weight on input pixel ``k`` is the overlap of
    ``[k, k + 1)`` with that interval times ``s``. The ``K`` taps are the input pixels the interval can
    touch; taps outside ``[0, n_in)`` get weight 0 (zero padding), so rows inside the image sum to 1.
    """
    lo = starts[:, None] + np.arange(n_out)[None, :] / scales[:, None]  # [T, n_out]
    hi = lo + 1.0 / scales[:, None]
    first = np.floor(lo).astype(np.int64)
    taps = int(np.ceil(1.0 / scales.min())) + 1
    index = first[..., None] + np.arange(taps)  # [T, n_out, K]
    overlap = np.minimum(hi[..., None], index + 1) - np.maximum(lo[..., None], index)
    weight = np.clip(overlap, 0.0, None) * scales[:, None, None]
    outside = (index < 0) | (index >= n_in)
    weight[outside] = 0.0
    return np.clip(index, 0, n_in - 1), weight.astype(np.float32)


def normalize_silhouettes(
    frames: np.ndarray, height: int = 64, width: int | None = 44, min_foreground: float = 0.001, chunk: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """Crop, scale and centre binary silhouettes (OpenGait's pretreatment).

    Args:
        frames: uint8 ``[T, H, W]`` silhouettes, 0 = background, 255 = foreground (intermediate
            values are treated as partial coverage), or bool.
        height: output height in pixels: the silhouette's vertical extent is scaled to it.
        width: output width in pixels (None: ``height``, a square image). The scaled silhouette's
            median column lands on output column ``width / 2``; columns beyond the frame are zeros.
        min_foreground: frames whose foreground mass is below this fraction of the frame's
            pixels are dropped as empty (OpenGait drops frames with a pixel sum ≤ 10000 at
            255 scale, i.e. ≤ 0.05 % of a 240×320 frame).
        chunk: frames resampled at once (bounds the temporary memory).

    Returns:
        ``(aligned, kept)``: float32 ``[T', height, width]`` in [0, 1], and int64 ``[T']`` indices
        (into ``frames``) of the frames kept, in order.
    """
    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise ValueError(f"frames must be [T, H, W], got shape {frames.shape}")
    if frames.dtype not in (np.uint8, np.bool_):
        raise ValueError(f"frames must be uint8 (0/255) or bool silhouettes, got dtype {frames.dtype}")
    if width is None:
        width = height
    if height < 1 or width < 1:
        raise ValueError(f"height and width must be >= 1, got {height}x{width}")
    if not 0.0 <= min_foreground < 1.0:
        raise ValueError(f"min_foreground must be a fraction in [0, 1), got {min_foreground}")
    _, rows, cols = frames.shape
    scale_to_unit = 1.0 if frames.dtype == np.bool_ else 1.0 / 255.0
    narrow = np.uint16 if rows * 255 < 2**16 else np.uint32  # exact, and faster than summing in float
    col_mass = frames.sum(axis=1, dtype=narrow).astype(np.float64) * scale_to_unit  # [T, W]
    mass = col_mass.sum(axis=1)
    kept = np.flatnonzero((mass > 0) & (mass >= min_foreground * rows * cols)).astype(np.int64)
    aligned = np.zeros((len(kept), height, width), dtype=np.float32)
    if not len(kept):
        return aligned, kept

    occupied = frames.any(axis=2)[kept]  # [T', H]
    top = occupied.argmax(axis=1)
    bottom = rows - 1 - occupied[:, ::-1].argmax(axis=1)
    scale = height / (bottom - top + 1.0)  # output pixels per input pixel, same on both axes
    cumulative = np.cumsum(col_mass[kept], axis=1)
    median_col = (cumulative > mass[kept, None] / 2).argmax(axis=1)  # first column past half the mass
    left = median_col - (width / 2) / scale  # input x of output column 0's left edge

    for start in range(0, len(kept), chunk):
        part = slice(start, start + chunk)
        frame_of = kept[part, None]
        row_index, row_weight = _box_taps(top[part].astype(np.float64), scale[part], height, rows)  # [t, h, K]
        col_index, col_weight = _box_taps(left[part], scale[part], width, cols)  # [t, w, K]
        # Only the columns under the output window matter: gather rows of a per-frame window of
        # `span` columns (clipped inside the frame; taps outside the frame have weight 0 anyway).
        span = int(np.ceil(width / scale[part].min())) + 2
        if span < cols:
            offset = np.clip(np.floor(left[part]).astype(np.int64), 0, cols - span)
            windows = np.lib.stride_tricks.sliding_window_view(frames, span, axis=2)  # [T, H, cols - span + 1, span]
            source, column = windows, (offset[:, None],)
            col_index = np.clip(col_index - offset[:, None, None], 0, span - 1)
        else:
            source, column, span = frames, (), cols
        scaled_rows = np.zeros((len(frame_of), height, span), dtype=np.float32)
        term = np.empty_like(scaled_rows)
        for k in range(row_index.shape[2]):  # few taps: vectorised over frames and pixels
            np.multiply(row_weight[:, :, k, None], source[(frame_of, row_index[:, :, k]) + column], out=term)
            scaled_rows += term
        by_column = np.ascontiguousarray(scaled_rows.transpose(0, 2, 1))  # [t, span, h]: columns gather as rows
        chunk_of = np.arange(len(frame_of))[:, None]
        scaled = np.zeros((len(frame_of), width, height), dtype=np.float32)
        term = np.empty_like(scaled)
        for k in range(col_index.shape[2]):
            np.multiply(col_weight[:, :, k, None], by_column[chunk_of, col_index[:, :, k]], out=term)
            scaled += term
        aligned[part] = scaled.transpose(0, 2, 1)
    aligned *= np.float32(scale_to_unit)
    np.clip(aligned, 0.0, 1.0, out=aligned)
    return aligned, kept


# --------------------------------------------------------------------------- gait period


def lag_correlation(signal: np.ndarray, max_lag: int) -> np.ndarray:
    """Pearson correlation of ``signal[:-k]`` with ``signal[k:]`` for ``k = 0..max_lag``, float64 ``[max_lag + 1]``.

    Each lag is normalised by the means and spreads of its own two overlapping segments, so
    long lags (short overlaps) are not damped as in the biased autocorrelation. A lag whose
    segments are constant gets 0.
    """
    x = np.asarray(signal, dtype=np.float64)
    n = len(x)
    if not 0 <= max_lag < n:
        raise ValueError(f"max_lag must be in [0, {n - 1}] for a signal of {n} samples, got {max_lag}")
    lags = np.arange(max_lag + 1)
    count = n - lags
    csum, csq = np.concatenate([[0.0], np.cumsum(x)]), np.concatenate([[0.0], np.cumsum(x * x)])
    head_sum, head_sq = csum[count], csq[count]  # x[0 : n - k]
    tail_sum, tail_sq = csum[n] - csum[lags], csq[n] - csq[lags]  # x[k : n]
    cross = np.correlate(x, x, mode="full")[n - 1 : n + max_lag]  # Σ x[t] x[t + k]
    cov = cross - head_sum * tail_sum / count
    var = (head_sq - head_sum**2 / count) * (tail_sq - tail_sum**2 / count)
    scale = np.sqrt(np.clip(var, 0.0, None))
    tiny = 1e-12 * max(1.0, float(np.abs(x).max()) ** 2) * count
    return np.where(scale > tiny, cov / np.where(scale > tiny, scale, 1.0), 0.0)


def leg_width_signal(aligned: np.ndarray, lower_fraction: float = 0.25) -> np.ndarray:
    """Horizontal spread of the lower body per frame, float64 ``[T]`` (pixels).

    The standard deviation of the column position of the foreground in the bottom
    ``lower_fraction`` of the rows: large with the legs apart, small with them together, so it
    oscillates once per step. (The plain foreground *area* of the same rows, Sarkar et al.'s
    signal, is much noisier on rendered walks: the area hardly changes when legs cross.)
    A frame with no foreground there gets 0.
    """
    aligned = np.asarray(aligned)
    if aligned.ndim != 3:
        raise ValueError(f"aligned must be [T, h, w], got shape {aligned.shape}")
    if not 0.0 < lower_fraction <= 1.0:
        raise ValueError(f"lower_fraction must be in (0, 1], got {lower_fraction}")
    first_row = aligned.shape[1] - max(1, round(lower_fraction * aligned.shape[1]))
    columns = aligned[:, first_row:].sum(axis=1, dtype=np.float64)  # [T, w]
    mass = columns.sum(axis=1)
    x = np.arange(aligned.shape[2], dtype=np.float64)
    safe = np.where(mass > 0, mass, 1.0)
    mean = (columns * x).sum(axis=1) / safe
    spread = np.sqrt(np.clip((columns * (x - mean[:, None]) ** 2).sum(axis=1) / safe, 0.0, None))
    return np.where(mass > 0, spread, 0.0)


def _parabolic_peak(r: np.ndarray, k: int) -> float:
    """Sub-sample position of the local maximum ``r[k]`` from the parabola through ``r[k-1..k+1]``."""
    curvature = r[k - 1] - 2 * r[k] + r[k + 1]
    return k + (0.5 * (r[k - 1] - r[k + 1]) / curvature if curvature < 0 else 0.0)


def period_from_signal(
    signal: np.ndarray,
    min_cycle: int = 18,
    max_cycle: int = 34,
    min_correlation: float = 0.2,
    smooth: int = 5,
    min_overlap: int = 4,
) -> int | None:
    """The gait cycle in frames from a per-frame leg signal sampled once per frame.

    1. Median-filter the signal over ``smooth`` frames (removes single-frame segmentation
       glitches), remove its least-squares line and take :func:`lag_correlation` up to the longest
       lag that leaves ``min_overlap`` frames overlapping.
    2. Candidates are the local maxima with lag in ``[min_cycle, max_cycle]`` and correlation
       ≥ ``min_correlation``. A leg signal repeats every *step* (half a cycle) and, better, every
       cycle (near and far leg differ in most views), so the cycle ``C`` is the candidate with the
       highest ``r(C) + r(C / 2)``: a true cycle also correlates at half its lag, while three steps
       (``1.5 C``) is anti-correlated at half its lag. Keep ``max_cycle < 2 · min_cycle`` so that
       two cycles are never a candidate.
    3. The peak is refined to sub-frame precision (parabola) and rounded.

    Returns None when the signal is too short for a lag of ``min_cycle + 1`` or no candidate passes.
    """
    from scipy.signal import detrend, medfilt  # here: scipy.signal takes half a second to import, every command

    x = np.asarray(signal, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"signal must be 1-D, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("signal holds NaN or infinite values")
    if not 2 <= min_cycle <= max_cycle:
        raise ValueError(f"need 2 <= min_cycle <= max_cycle, got {min_cycle}, {max_cycle}")
    max_lag = len(x) - min_overlap
    if max_lag < min_cycle + 1:
        return None
    if smooth > 1:
        x = medfilt(x, smooth | 1)  # odd kernel
    r = lag_correlation(detrend(x), max_lag)
    lags = np.arange(len(r), dtype=np.float64)
    best, best_score = None, -np.inf
    for k in range(min_cycle, min(max_cycle, max_lag - 1) + 1):
        if r[k] >= min_correlation and r[k] >= r[k - 1] and r[k] > r[k + 1]:
            score = r[k] + np.interp(k / 2, lags, r)
            if score > best_score:
                best, best_score = k, score
    return None if best is None else round(float(_parabolic_peak(r, best)))


def gait_period(
    aligned: np.ndarray,
    kept: np.ndarray | None = None,
    complete: np.ndarray | None = None,
    lower_fraction: float = 0.25,
    min_cycle: int = 18,
    max_cycle: int = 34,
    min_correlation: float = 0.2,
    smooth: int = 5,
) -> int | None:
    """Gait cycle length in frames (two steps) of aligned silhouettes ``[T, h, w]``, or None if none is found.

    Args:
        aligned: from :func:`normalize_silhouettes`.
        kept: frame numbers of ``aligned`` (its ``kept``); dropped frames are filled by linear
            interpolation so the signal keeps the sequence's clock. None: consecutive frames.
        complete: bool ``[T]``, frames whose silhouette is whole (not cut by the image's side);
            the signal uses only those (walkers entering or leaving the picture distort it), or
            all frames when fewer than ``min_cycle + 5`` are complete. None: all.
        lower_fraction: rows used by :func:`leg_width_signal`.
        min_cycle, max_cycle, min_correlation, smooth: see :func:`period_from_signal`. The defaults
            suit CASIA-B's 25 fps (cycles of 0.72–1.36 s).
    """
    signal = leg_width_signal(aligned, lower_fraction)
    times = np.arange(len(signal)) if kept is None else np.asarray(kept, dtype=np.int64)
    if len(times) != len(signal):
        raise ValueError(f"kept has {len(times)} entries for {len(signal)} frames")
    if complete is not None:
        complete = np.asarray(complete, dtype=bool)
        if len(complete) != len(signal):
            raise ValueError(f"complete has {len(complete)} entries for {len(signal)} frames")
        if complete.sum() >= min_cycle + 5:
            signal, times = signal[complete], times[complete]
    if len(times) < 2:
        return None
    clock = np.arange(times[0], times[-1] + 1)
    return period_from_signal(
        np.interp(clock, times, signal),
        min_cycle=min_cycle,
        max_cycle=max_cycle,
        min_correlation=min_correlation,
        smooth=smooth,
    )


# --------------------------------------------------------------------------- GEIs


@dataclass
class GEIInfo:
    """How :func:`gait_energy_images` built its GEIs.

    Attributes:
        per: ``"cycle"`` or ``"sequence"``.
        period: the gait cycle in frames (None with ``per="sequence"`` unless given).
        kept: int64 ``[T']`` numbers of the non-empty frames that were aligned.
        spans: int64 ``[K, 2]``: GEI ``k`` covers frames ``spans[k, 0] <= t < spans[k, 1]`` of the
            input (one period each with ``per="cycle"``, back to back from the first non-empty
            frame; frames after the last whole cycle are left out).
        frames_per_gei: int64 ``[K]``: non-empty silhouettes averaged into each GEI.
        period_detected: the period came from :func:`gait_period` (not given, not the fallback).
    """

    per: str
    period: int | None
    kept: np.ndarray
    spans: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    frames_per_gei: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    period_detected: bool = False


def _touches_sides(frames: np.ndarray) -> np.ndarray:
    """bool ``[T]``: the silhouette reaches the first or last column (cut by the picture's side)."""
    return (frames[:, :, 0] > 0).any(axis=1) | (frames[:, :, -1] > 0).any(axis=1)


def gait_energy_images(
    frames: np.ndarray,
    size: tuple[int, int] = OPENGAIT_SIZE,
    per: str = "cycle",
    min_foreground: float = 0.001,
    min_frames: int = 1,
    period: int | None = None,
    fallback_period: int | None = None,
    lower_fraction: float = 0.25,
    min_cycle: int = 18,
    max_cycle: int = 34,
    min_correlation: float = 0.2,
) -> tuple[np.ndarray, GEIInfo]:
    """GEIs of one silhouette sequence.

    Args:
        frames: uint8 ``[T, H, W]`` silhouettes (0/255).
        size: ``(height, width)`` of the GEIs, e.g. :data:`OPENGAIT_SIZE` or :data:`THESIS_SIZE`.
        per: ``"cycle"``: one GEI per whole gait cycle of the detected (or given) period, cut back to
            back from the first non-empty frame; leftover frames are unused; ``"sequence"``: one GEI,
            the mean of all non-empty frames.
        min_foreground: see :func:`normalize_silhouettes`.
        min_frames: fewest non-empty frames for ``per="sequence"``, and for a cycle's GEI (a cycle
            with fewer, e.g. a run of empty frames, is left out; at least half the period is needed).
        period: cycle length in frames to use instead of detecting it.
        fallback_period: cycle length used when none is detected (``info.period_detected`` is then
            False); None: raise. Detection is least reliable in frontal views (0°, 180°).
        lower_fraction, min_cycle, max_cycle, min_correlation: see :func:`gait_period`.

    Returns:
        ``(geis, info)``: float32 ``[K, height, width]`` in [0, 1] and a :class:`GEIInfo`.

    Raises:
        GaitSequenceError: no non-empty frame (or fewer than ``min_frames``), no detectable period,
            or fewer frames than one cycle (``per="cycle"``).
    """
    if per not in PER_CHOICES:
        raise ValueError(f"per must be one of {PER_CHOICES}, got {per!r}")
    height, width = (int(v) for v in size)
    aligned, kept = normalize_silhouettes(frames, height, width, min_foreground=min_foreground)
    total = len(frames)
    if per == "sequence":
        if len(kept) < max(1, min_frames):
            raise GaitSequenceError(
                f"{len(kept)} non-empty silhouettes of {total} frames, need at least {max(1, min_frames)}",
                reason="no_frames",
            )
        spans = np.array([[kept[0], kept[-1] + 1]], dtype=np.int64)
        info = GEIInfo(per, period, kept, spans, np.array([len(kept)], dtype=np.int64))
        return aligned.mean(axis=0, keepdims=True), info

    if not len(kept):
        raise GaitSequenceError(f"no non-empty silhouette in {total} frames", reason="no_frames")
    detected = period is None
    if period is None:
        period = gait_period(
            aligned,
            kept,
            complete=~_touches_sides(frames[kept]),
            lower_fraction=lower_fraction,
            min_cycle=min_cycle,
            max_cycle=max_cycle,
            min_correlation=min_correlation,
        )
        if period is None and fallback_period is not None:
            period, detected = int(fallback_period), False
        if period is None:
            raise GaitSequenceError(
                f"no gait period found in {len(kept)} non-empty silhouettes of {total} frames "
                f"(the lower-body width has no autocorrelation peak for cycles of "
                f"{min_cycle}-{max_cycle} frames)",
                reason="no_period",
            )
    if period < 1:
        raise ValueError(f"period must be >= 1, got {period}")
    first, stop = int(kept[0]), int(kept[-1]) + 1
    cycles = (stop - first) // period
    if cycles == 0:
        raise GaitSequenceError(
            f"{stop - first} frames from the first to the last non-empty silhouette are "
            f"shorter than one gait cycle of {period} frames",
            reason="too_short",
        )
    starts = first + np.arange(cycles, dtype=np.int64) * period
    spans = np.stack([starts, starts + period], axis=1)
    lo, hi = np.searchsorted(kept, spans[:, 0]), np.searchsorted(kept, spans[:, 1])
    counts = hi - lo
    enough = counts >= max(min_frames, (period + 1) // 2)
    if not enough.any():
        raise GaitSequenceError(
            f"no gait cycle of {period} frames holds {max(min_frames, (period + 1) // 2)} non-empty silhouettes",
            reason="no_frames",
        )
    geis = np.stack([aligned[a:b].mean(axis=0) for a, b in zip(lo[enough], hi[enough])])
    return geis, GEIInfo(per, period, kept, spans[enough], counts[enough].astype(np.int64), detected)
