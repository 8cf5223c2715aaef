"""Gap filling by a moving average: each missing sample becomes the mean of its joint's observed samples within
``half_window`` frames on either side (an example refiner; docs/extending.md#add-a-method)."""

from __future__ import annotations

import numpy as np

from mocapkit.refinement.base import MotionRefiner


class MovingAverageRefiner(MotionRefiner):
    """Fill each gap with the mean of the observed samples within ``half_window`` frames.

    Args:
        half_window: frames searched on each side of a missing sample (>= 1). A sample with no observed
            neighbour that close stays missing, and the refine report lists it as unfilled.
    """

    def __init__(self, half_window: int = 5):
        self.half_window = half_window  # stored untouched: a scikit-learn estimator checks in fit / refine

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, None]:
        # X: float64 [frames, 3·joints] metres, 0 where not observed; observed: bool, the same shape
        if int(self.half_window) < 1:
            raise ValueError(f"half_window must be >= 1, got {self.half_window}")
        w = int(self.half_window)
        frames = X.shape[0]
        # windowed sums along the frames, from cumulative sums with a zero row in front
        sums = np.vstack([np.zeros((1, X.shape[1])), np.cumsum(np.where(observed, X, 0.0), axis=0)])
        counts = np.vstack([np.zeros((1, X.shape[1])), np.cumsum(observed, axis=0)])
        start = np.clip(np.arange(frames) - w, 0, frames)
        stop = np.clip(np.arange(frames) + w + 1, 0, frames)
        total, n = sums[stop] - sums[start], counts[stop] - counts[start]
        with np.errstate(invalid="ignore", divide="ignore"):
            filled = np.where(n > 0, total / n, np.nan)  # NaN: nothing observed that close, left missing
        return filled, None  # None: no observed sample is flagged as an outlier
