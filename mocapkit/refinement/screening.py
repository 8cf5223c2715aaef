"""A robust outlier screen in front of any refiner: observed samples far from the running median of their joint are
hidden and refilled.

Noise on individual samples (the theses' ``rdcrypt`` / ``mxcrypt``: σ = 2 cm on 30 % of the entries, white in time)
and single-frame spikes are what a running median is made for: at 120 fps a joint moves a few millimetres from one
frame to the next, so a sample several millimetres away from the median of its neighbours is very likely corrupted.
:func:`median_outliers` flags those samples; :class:`MedianScreen` marks them missing, lets the refiner it wraps
(classical or learned, the one contract of :mod:`mocapkit.refinement.base`) fill them with the gaps, and reports
them as repaired. numpy only, so it also runs in front of :class:`~mocapkit.refinement.learned.OnnxRefiner`.

The median of a joint's sample ``i`` is taken per coordinate over its ``half_window`` observed neighbours on each
side (the same number on both sides, so that a steady trend has no bias), fewer where ``half_window`` of them would
span more than ``max_span`` frames (beside a gap) and near a joint's first and last observed sample; a sample with
no such window (those two, one beside a gap longer than ``max_span − 2`` frames) is not judged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from sklearn.base import clone

from mocapkit.motion.container import Motion, point_distance
from mocapkit.refinement.base import MotionRefiner, check_motion

#: Default ``half_window`` and ``threshold`` (metres) of :class:`MedianScreen` and ``mocapkit refine --screen-outliers``:
#: two observed neighbours on each side, 5 mm. Chosen on HDM05 validation clips at 120 fps (training performers
#: only; K ∈ {2, 3, 5} × {5, 7.5, 10, 15 mm}; mean RMS over noise, random loss and gaps): the choice of PCHIP, the
#: BiGRU and the transformer (LRMF chose 10 mm); ``scripts/selection/refiner_inference_settings.py --setting screen``,
#: docs/decisions.md#median-screen. ``n_sigmas`` None: the fixed threshold alone (the Hampel rule, tried on the same
#: clips, spares fast clean motion but missed most of the noise with two neighbours a side).
SCREEN_HALF_WINDOW = 2
SCREEN_THRESHOLD = 0.005
SCREEN_N_SIGMAS = None


def median_outliers(
    positions: np.ndarray,
    missing: np.ndarray,
    half_window: int = SCREEN_HALF_WINDOW,
    threshold: float = SCREEN_THRESHOLD,
    max_span: int | None = None,
    n_sigmas: float | None = None,
) -> np.ndarray:
    """bool ``[T, J]``: the observed samples farther than ``threshold`` (the positions' units, metres for
    everything ``read_motion`` returns) from the per-coordinate median of the ``half_window`` observed samples
    on each side of them, same joint (see the module docstring).

    Args:
        positions: ``[T, J, 3]``; missing entries are ignored (NaN allowed there).
        missing: bool ``[T, J]``.
        half_window: observed neighbours on each side (≥ 1).
        threshold: distance beyond which a sample is flagged.
        max_span: the most frames a window may span, first to last sample (None: ``4 · half_window``).
        n_sigmas: None: ``threshold`` alone. A number: the Hampel rule, flagged beyond
            ``max(threshold, n_sigmas · 1.4826 · MAD)`` where MAD is the median of the window's distances to its
            median (the window's own spread: fast motion and low frame rates raise the bar).
    """
    positions = np.asarray(positions)
    missing = np.asarray(missing, dtype=bool)
    if positions.ndim != 3 or positions.shape[2] != 3 or missing.shape != positions.shape[:2]:
        raise ValueError(
            f"median_outliers: positions [T, J, 3] and missing [T, J] expected, got "
            f"{positions.shape} and {missing.shape}"
        )
    k = int(half_window)
    if k < 1:
        raise ValueError(f"median_outliers: half_window must be ≥ 1, got {half_window}")
    span = 4 * k if max_span is None else int(max_span)
    # every joint's observed samples in one array, joint after joint (windows never cross a joint's ends)
    joint, frame = np.nonzero(~missing.T)  # [N] each, by joint then frame
    x = positions[frame, joint].astype(np.float64)  # [N, 3]
    index = np.arange(joint.size)
    first = np.searchsorted(joint, joint, side="left")  # the joint's first sample
    last = np.searchsorted(joint, joint, side="right") - 1  # and its last
    half = np.zeros(joint.size, dtype=np.int64)  # per sample, the widest symmetric window within the span
    for h in range(1, k + 1):
        inside = np.flatnonzero((index - first >= h) & (last - index >= h))
        half[inside[frame[inside + h] - frame[inside - h] <= span]] = h
    deviation = np.zeros(joint.size)
    for h in np.unique(half[half > 0]):
        at = index[half == h]
        window = at[:, None] + np.arange(-h, h + 1)[None]  # [m, 2h+1]
        centre = np.median(x[window], axis=1)  # [m, 3]
        deviation[at] = point_distance(x[at], centre)
        if n_sigmas is not None:
            spread = np.median(point_distance(x[window], centre[:, None]), axis=1)  # MAD, [m]
            deviation[at] *= deviation[at] > float(n_sigmas) * 1.4826 * spread
    flags = np.zeros(missing.shape, dtype=bool)
    flags[frame[deviation > threshold], joint[deviation > threshold]] = True
    return flags


class MedianScreen(MotionRefiner):
    """Any refiner behind :func:`median_outliers`: the flagged samples are marked missing, ``refiner`` fills them
    with the take's gaps, and they come back as repaired (``metadata["refinement"]["screened"]`` counts them; one
    the refiner cannot fill keeps its observed value). Every other observed sample comes back bit-identical.

    Args:
        refiner: the refiner that fills (any :class:`~mocapkit.refinement.base.MotionRefiner`); ``fit`` fits a
            clone of it (``refiner_``); ``refine`` before ``fit`` uses it as given.
        half_window, threshold, max_span, n_sigmas: those of :func:`median_outliers` (threshold in metres).
    """

    def __init__(
        self,
        refiner: MotionRefiner,
        half_window: int = SCREEN_HALF_WINDOW,
        threshold: float = SCREEN_THRESHOLD,
        max_span: int | None = None,
        n_sigmas: float | None = SCREEN_N_SIGMAS,
    ):
        self.refiner = refiner
        self.half_window = half_window
        self.threshold = threshold
        self.max_span = max_span
        self.n_sigmas = n_sigmas

    @property
    def requires_fit(self) -> bool:
        return bool(self.refiner.requires_fit)

    @property
    def min_frames(self) -> int:
        return int(self.refiner.min_frames)

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> MedianScreen:
        """Fit a clone of ``refiner`` on ``motions`` (clean training motions: they are not screened)."""
        self.refiner_ = clone(self.refiner).fit(motions)
        return self

    def refine(self, motion: Motion) -> Motion:
        """``motion`` with its median outliers hidden and refilled by the refiner, and its gaps filled."""
        check_motion(motion, self.min_frames, what=type(self).__name__)
        refiner = getattr(self, "refiner_", self.refiner)
        flags = median_outliers(
            motion.positions, motion.missing, self.half_window, self.threshold, self.max_span, self.n_sigmas
        )
        hidden = replace(
            motion,
            positions=np.where(flags[..., None], np.float32(np.nan), motion.positions),
            missing=motion.missing | flags,
        )
        done = refiner.refine(hidden)
        kept = flags & done.missing  # flagged, but the refiner could not fill them: as observed
        positions = done.positions.copy()
        positions[kept] = motion.positions[kept]
        missing = done.missing & ~kept
        inner = done.metadata.get("refinement", {})
        report = {
            **inner,
            "method": f"{type(self).__name__}({inner.get('method', type(refiner).__name__)})",
            "screened": int(flags.sum()),
            "filled": int((motion.missing & ~missing).sum()),
            "repaired": int(inner.get("repaired", 0)) + int((flags & ~kept).sum()),
        }
        return replace(motion, positions=positions, missing=missing, metadata={**motion.metadata, "refinement": report})
