"""Time-pooled joint statistics: the simple skeleton baseline a user reaches for first.

:class:`PooledJointStatistics` turns each skeleton sequence into one vector: the joints of every body,
centred on body 0's root joint frame by frame, then their mean, standard deviation, minimum and maximum
over the frames where that body is present. With ``StandardScaler`` and ``LogisticRegression`` it is the
baseline the learned models are compared with (``configs/compare/*_recognition.yaml``).
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin

STATISTICS = ("mean", "std", "min", "max")


class PooledJointStatistics(TransformerMixin, BaseEstimator):
    """Sequences → ``[n, bodies · 4 · joints · 3]`` pooled statistics (metres).

    Args:
        bodies: bodies kept per sequence (absent ones give zeros).
        root: index of the joint every frame is centred on (body 0's; 0 = SpineBase / HipCenter).

    ``fit`` learns nothing (stateless); it records ``n_features_out_`` for a consistent width.
    Input: a list of float arrays ``[T, J, 3]`` (one body) or ``[M, T, J, 3]`` (bodies first), metres,
    zeros (or NaN) where a body or joint is absent.
    """

    def __init__(self, bodies: int = 2, root: int = 0):
        self.bodies = bodies
        self.root = root

    def fit(self, X, y=None) -> PooledJointStatistics:
        first = self._as_bodies(X[0]) if len(X) else None
        if first is None:
            raise ValueError("PooledJointStatistics.fit needs at least one sequence")
        self.n_features_out_ = self.bodies * len(STATISTICS) * first.shape[2] * 3
        return self

    def _as_bodies(self, seq) -> np.ndarray:
        seq = np.nan_to_num(np.asarray(seq, dtype=np.float64), nan=0.0)
        if seq.ndim == 3:
            seq = seq[None]
        if seq.ndim != 4 or seq.shape[-1] != 3:
            raise ValueError(f"a sequence must be [T, J, 3] or [M, T, J, 3], got shape {list(seq.shape)}")
        out = np.zeros((self.bodies,) + seq.shape[1:])
        out[: min(self.bodies, len(seq))] = seq[: self.bodies]
        return out

    def transform(self, X) -> np.ndarray:
        rows = []
        for seq in X:
            pos = self._as_bodies(seq)  # [M, T, J, 3]
            present = np.abs(pos).sum(axis=(2, 3)) > 0  # [M, T]
            frames = present[0] if present[0].any() else np.ones(pos.shape[1], bool)
            centred = pos - pos[0, :, self.root : self.root + 1]  # body 0's root, per frame
            parts = []
            for k in range(self.bodies):
                keep = frames & present[k]
                if not keep.any():
                    parts.append(np.zeros(len(STATISTICS) * pos.shape[2] * 3))
                    continue
                rel = centred[k][keep].reshape(int(keep.sum()), -1)
                parts.append(np.concatenate([rel.mean(0), rel.std(0), rel.min(0), rel.max(0)]))
            rows.append(np.concatenate(parts))
        return np.asarray(rows)
