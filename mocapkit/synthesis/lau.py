"""Lau, Bar-Joseph & Kuffner 2009 style baseline: a second-order dynamic Bayesian network whose conditionals are
nonparametric kernel regressions with **frame differences** as outputs (``../shared/spec/thesis-zhou-2014-retrieval-
synthesis.md`` §3.4 "not frame differences as in Lau et al. 2009", §3.7 "Comparisons", §7 gap 22).

**Frames.** Each frame is one vector ``y_t`` of the thesis's representation (:mod:`mocapkit.synthesis.
representation`, ``FeatureClip.flat``: the root's ground-plane step, heading change, height and tilt, then every
bone's exp-map; ``[7 + 3B]``). The network has one node per frame for the **whole body** (no body partitions: the
conditional sees every joint, so limbs stay in phase).

**Conditional** ``p(Δy_t | y_{t−1}, y_{t−2})`` with ``Δy_t = y_t − y_{t−1}``. Its input is written
``x_t = [y_{t−1}, y_{t−1} − y_{t−2}]`` (the same information as ``(y_{t−1}, y_{t−2})``, but the velocity half is
not swamped by the nearly equal poses at 120 fps), each dimension standardised by its sd over the training frames
(floored at 0.1 × the median sd of its half, so that near-constant channels such as fingers do not dominate the
distance). Nadaraya–Watson weights over the training frames ``i``:
``w_i(x) ∝ exp(−‖x − x_i‖² / (2 h² D))`` (``D`` the input dimension, so the width ``h`` is in per-dimension sd
units), and the conditional is the Gaussian with the kernel-weighted mean and **kernel-weighted residual
spread** of the training differences (outputs standardised the same way):
``m(x) = Σ w_i Δ_i``, ``s²(x) = Σ w_i (Δ_i − m)² + s²_min`` per dimension (``s_min = 0.01`` sd: a floor for one
dominant neighbour).

**Width.** ``h`` is the candidate of ``widths`` with the highest leave-one-clip-out log-likelihood of the held-out
clip's frame differences (every training clip in turn held out, the kernel on the other clips' frames; the
mean over all held-out frames of ``log N(Δ_t; m(x_t), s²(x_t))`` in standardised units, per dimension): only
the training clips are used (gap 22). ``width_`` holds the choice, ``cv_log_likelihood_`` every candidate's score.

**Sampling.** Frames 0 and 1 are those of a training clip drawn uniformly, both shifted by one draw of
``N(0, (start_noise · sd)²)`` per dimension (``sd``: across the training clips' first frames); then
``Δy_t ~ N(m(x_t), s²(x_t))`` and ``y_t = y_{t−1} + Δy_t`` for ``t = 2 … n_frames − 1``; the features are decoded
(:func:`~mocapkit.synthesis.representation.decode`) from the drawn clip's start position and heading.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import SMOOTHING_SECONDS
from mocapkit.synthesis.footskate import DEFAULT_ROOT_MOVE
from mocapkit.synthesis.representation import (
    continuous_pieces,
    decode,
    encode,
    root_start,
)

#: Default candidate kernel widths (per-dimension sd units of the standardised input).
WIDTHS = (0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0, 4.0)
#: Floor of the conditional sd, in sd units of the standardised output.
MIN_SPREAD = 0.01


def _scale(values: np.ndarray) -> np.ndarray:
    """Per-column sd of ``[N, d]`` values, floored at 0.1 × the median sd (and at 1e-12)."""
    sd = values.std(axis=0)
    return np.maximum(sd, max(0.1 * float(np.median(sd)), 1e-12))


def _weights(sq_distances: np.ndarray, width: float, dim: int) -> np.ndarray:
    """Normalised Nadaraya–Watson weights ``[n, N]`` from squared distances ``[n, N]``."""
    logits = -sq_distances / (2.0 * width * width * dim)
    logits -= logits.max(axis=1, keepdims=True)
    w = np.exp(logits)
    return w / w.sum(axis=1, keepdims=True)


def _sq_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances ``[len(a), len(b)]``."""
    d = (a * a).sum(axis=1)[:, None] + (b * b).sum(axis=1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d, 0.0)


def conditional(weights: np.ndarray, outputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(mean [n, d], variance [n, d])`` of the kernel-weighted Gaussian conditional (module docstring)."""
    mean = weights @ outputs
    variance = weights @ (outputs * outputs) - mean * mean
    return mean, np.maximum(variance, 0.0) + MIN_SPREAD**2


class LauDBNSynthesizer(MotionSynthesizer):
    """Second-order DBN with kernel-regression conditionals on frame differences (module docstring).

    Args:
        widths: candidate kernel widths ``h`` (per-dimension sd units), chosen by leave-one-clip-out likelihood.
        start_noise: sd of the noise added to the drawn first two frames, in units of the first frames' sd
            across the training clips.
        max_turn_speed: training clips are cut at joint-angle flips faster than this (degrees per second;
            :func:`~mocapkit.synthesis.representation.continuous_pieces`, as for SLFM), so that a flip is not
            learnt as a frame difference; None: no cutting.
        footskate_cleanup, footskate_root: the footskate cleanup after sampling, the same as SLFM's
            (:class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        smoothing_seconds: the Gaussian smoothing of every variant before the cleanup, seconds (0: off;
            :class:`~mocapkit.synthesis.base.MotionSynthesizer`).

    Attributes (after ``fit``):
        width_: the chosen width. cv_log_likelihood_: ``{width: mean held-out log-likelihood per frame and
        dimension}``. inputs_: float64 ``[N, 2F]`` standardised training inputs; outputs_: float64 ``[N, F]``
        standardised training differences (``F = 7 + 3B``); in_mean_, in_scale_, out_mean_, out_scale_: the
        standardisation; starts_: float64 ``[C, 2, F]`` the first two frames of every clip; start_sd_: ``[F]``;
        start_places_: per clip ``(start_xz, start_yaw)``; bones_: the representation's bones; angle_flips_:
        ``(clip, frame, bone, degrees)`` of the flips the clips were cut at.
    """

    min_frames = 4

    def __init__(
        self,
        widths: Sequence[float] = WIDTHS,
        start_noise: float = 0.1,
        max_turn_speed: float | None = 5400.0,
        footskate_cleanup: bool = True,
        footskate_root: str = DEFAULT_ROOT_MOVE,
        smoothing_seconds: float = SMOOTHING_SECONDS,
    ):
        self.widths = widths
        self.start_noise = start_noise
        self.max_turn_speed = max_turn_speed
        self.footskate_cleanup = footskate_cleanup
        self.footskate_root = footskate_root
        self.smoothing_seconds = smoothing_seconds

    @staticmethod
    def _pairs(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(inputs [T − 2, 2F], outputs [T − 2, F])`` of one clip's features ``[T, F]``."""
        inputs = np.concatenate([frames[1:-1], frames[1:-1] - frames[:-2]], axis=1)
        return inputs, frames[2:] - frames[1:-1]

    def _fit_clips(self, clips: list[Motion]) -> None:
        widths = [float(w) for w in np.atleast_1d(self.widths)]
        if not widths or min(widths) <= 0:
            raise ValueError(f"LauDBNSynthesizer: widths={self.widths!r} must be positive numbers")
        if not float(self.start_noise) >= 0:
            raise ValueError(f"LauDBNSynthesizer: start_noise={self.start_noise!r} must be >= 0")
        cut = continuous_pieces(clips, self.fps_, 3, self.max_turn_speed, what="LauDBNSynthesizer.fit")
        self.angle_flips_ = cut.flips
        encoded = [encode(piece) for piece in cut.pieces]
        self.bones_ = encoded[0].bones
        frames = [e.flat() for e in encoded]
        pairs = [self._pairs(f) for f in frames]
        inputs = np.concatenate([p[0] for p in pairs])
        outputs = np.concatenate([p[1] for p in pairs])
        half = frames[0].shape[1]
        self.in_mean_ = inputs.mean(axis=0)
        self.in_scale_ = np.concatenate([_scale(inputs[:, :half]), _scale(inputs[:, half:])])
        self.out_mean_ = outputs.mean(axis=0)
        self.out_scale_ = _scale(outputs)
        self.inputs_ = (inputs - self.in_mean_) / self.in_scale_
        self.outputs_ = (outputs - self.out_mean_) / self.out_scale_
        clip_of = np.concatenate([np.full(len(p[1]), c) for c, p in zip(cut.clip_index, pairs)])
        self.cv_log_likelihood_ = self._cross_validate(widths, clip_of)
        self.width_ = max(widths, key=lambda w: self.cv_log_likelihood_[w])
        self.starts_ = np.stack([f[:2] for f, first in zip(frames, cut.starts_clip) if first])
        self.start_sd_ = self.starts_[:, 0].std(axis=0)
        self.start_places_ = [root_start(piece) for piece, first in zip(cut.pieces, cut.starts_clip) if first]

    def _cross_validate(self, widths: list[float], clip_of: np.ndarray) -> dict[float, float]:
        """Mean held-out log-likelihood (per frame and output dimension) of every width, leaving one clip out."""
        sq = _sq_distances(self.inputs_, self.inputs_)
        dim = self.inputs_.shape[1]
        scores = {}
        for width in widths:
            total = 0.0
            for clip in np.unique(clip_of):
                held, kept = clip_of == clip, clip_of != clip
                mean, variance = conditional(_weights(sq[np.ix_(held, kept)], width, dim), self.outputs_[kept])
                residual = self.outputs_[held] - mean
                total += float(np.sum(-0.5 * (np.log(2 * np.pi * variance) + residual**2 / variance)))
            scores[width] = total / self.outputs_.size
        return scores

    def log_likelihood(self, clips: Sequence[Motion], width: float | None = None) -> float:
        """Mean log-likelihood per frame and dimension (standardised units) of the frame differences of ``clips``
        under the fitted conditional with kernel width ``width`` (default: ``width_``)."""
        inputs, outputs = zip(*(self._pairs(encode(clip).flat()) for clip in clips))
        x = (np.concatenate(inputs) - self.in_mean_) / self.in_scale_
        y = (np.concatenate(outputs) - self.out_mean_) / self.out_scale_
        weights = _weights(_sq_distances(x, self.inputs_), self.width_ if width is None else float(width), x.shape[1])
        mean, variance = conditional(weights, self.outputs_)
        return float(np.mean(-0.5 * (np.log(2 * np.pi * variance) + (y - mean) ** 2 / variance)))

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        chosen = rng.integers(len(self.starts_), size=n_variants)
        shift = rng.normal(size=(n_variants, 1, self.starts_.shape[2])) * float(self.start_noise) * self.start_sd_
        frames = np.zeros((n_variants, max(n_frames, 2), self.starts_.shape[2]))
        frames[:, :2] = self.starts_[chosen] + shift
        dim = self.inputs_.shape[1]
        for t in range(2, n_frames):
            x = np.concatenate([frames[:, t - 1], frames[:, t - 1] - frames[:, t - 2]], axis=1)
            weights = _weights(_sq_distances((x - self.in_mean_) / self.in_scale_, self.inputs_), self.width_, dim)
            mean, variance = conditional(weights, self.outputs_)
            step = mean + np.sqrt(variance) * rng.normal(size=mean.shape)
            frames[:, t] = frames[:, t - 1] + step * self.out_scale_ + self.out_mean_
        out = []
        for k, clip in enumerate(chosen):
            start_xz, start_yaw = self.start_places_[clip]
            out.append(decode(frames[k, :n_frames], self.skeleton_, start_xz=start_xz, start_yaw=start_yaw))
        return out


__all__ = ["MIN_SPREAD", "WIDTHS", "LauDBNSynthesizer", "conditional"]
