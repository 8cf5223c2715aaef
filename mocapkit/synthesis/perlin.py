"""The training-clip baselines of motion-variation synthesis: copies of the training clips, and the same copies
with Perlin noise added to every DOF curve (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §3.7,
"Comparisons", and §7 gap 22).

Both draw, for every variant, one training clip: the clips in a random order, cycled (variant ``k`` is clip
``order[k mod n_clips]``), so every clip is used equally often and ``n_clips`` variants are all different clips.
A clip whose length differs from the requested ``n_frames`` is **time-warped by linear resampling**
(:func:`~mocapkit.synthesis.clips.time_warp`: every AMC channel interpolated linearly at ``n_frames`` evenly spaced times from its first
to its last frame, angles unwrapped first so that a 179° → −179° step is not swept through 0°). Variants are
posed on the reference skeleton by their AMC angles (:mod:`mocapkit.synthesis.base`).

- :class:`CopyTrainingClips` returns the (time-warped) clips unchanged: the **training-set reference row** of the
  benchmark (its variation is about the training set's own).
- :class:`PerlinNoiseSynthesizer` adds noise to every DOF curve of the thesis's representation (§3.1: each joint
  an exponential map, 3 DOFs; the root as :mod:`mocapkit.synthesis.representation` makes it relative: ground-plane
  step, heading change, height, tilt), not to the AMC Euler curves: adding noise to Euler angles near gimbal lock
  (the HDM05 root, whose ``RX``/``RZ`` swing by tens of degrees when a take faces sideways) would turn small
  noise into large rotations, and the absolute root position and heading differ between takes for no reason of
  the motion. The copy is encoded (:func:`~mocapkit.synthesis.representation.encode`), every channel ``k`` gets
  an independent 1-D Perlin gradient noise curve (:func:`perlin_noise`, Perlin 1995 as cited in §3.7, one octave) of
  frequency ``frequency`` Hz (lattice points ``1/frequency`` s apart, a random phase per channel) scaled so
  that its peak is ``amplitude · σ_k``, and the result is decoded from the copy's start position and heading
  (noise on the off-axis components of a bone with fewer than 3 dofs is projected away there). ``σ_k`` is the
  channel's **within-class sd across the training clips** (:func:`within_class_sd`): the sd over clips at the
  same normalised time, after time-warping every clip to the mean length, root-mean-squared over time. The
  thesis does not give the noise parameters (gap 22 asks for an amplitude comparable to that sd); the defaults
  ``amplitude=1`` (noise up to ±1 within-class sd, i.e. as large as the differences between two real
  performances) and ``frequency=2`` Hz (about the rate of the movement phases of the HDM05 motion types: a hop,
  a squat or a kick lasts 0.5–1.5 s) are our choice.
"""

from __future__ import annotations

import numpy as np

from mocapkit.datasets.formats.asf_amc import amc_motion
from mocapkit.motion.container import Motion
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import SMOOTHING_SECONDS, dof_matrix, dof_values, rotation_columns, time_warp
from mocapkit.synthesis.footskate import DEFAULT_ROOT_MOVE
from mocapkit.synthesis.representation import decode, encode, root_start


def perlin_noise(x: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """1-D Perlin gradient noise at positions ``x`` (``[n]``, lattice units, ``0 ≤ x < len(gradients) − 1``), with
    slopes ``gradients`` at the integer lattice points; scaled by 2 so that it lies in ``[-1, 1]`` for gradients
    in ``[-1, 1]`` (it is 0 at every lattice point; the quintic fade ``6f⁵ − 15f⁴ + 10f³`` keeps its first and
    second derivatives continuous)."""
    x = np.asarray(x, dtype=np.float64)
    cell = np.floor(x).astype(np.int64)
    f = x - cell
    fade = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    left = gradients[cell] * f
    right = gradients[cell + 1] * (f - 1.0)
    return 2.0 * (left + fade * (right - left))


def within_class_sd(features: list[np.ndarray]) -> np.ndarray:
    """float64 ``[channels]``: per channel of per-frame feature matrices ``[T, channels]`` of clips of one type that
    all have the same length, the sd across clips at each frame, root-mean-squared over the frames."""
    return np.sqrt(np.stack(features).var(axis=0).mean(axis=0))


class CopyTrainingClips(MotionSynthesizer):
    """The training clips themselves, time-warped to ``n_frames`` (the benchmark's reference row; module docstring).

    Attributes (after ``fit``): ``train_matrices_``: the clips' AMC values, one float64 ``[T_i, channels]`` per clip
    (:func:`~mocapkit.synthesis.clips.dof_matrix`); ``angles_``: bool ``[channels]``, the angle columns.
    """

    def _fit_clips(self, clips: list[Motion]) -> None:
        self.train_matrices_ = [dof_matrix(clip)[0] for clip in clips]
        self.angles_ = rotation_columns(self.layout_)

    def _copies(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[np.ndarray]:
        """The time-warped training clip of every variant (balanced draws: module docstring)."""
        order = rng.permutation(len(self.train_matrices_))
        return [
            time_warp(self.train_matrices_[order[k % len(order)]], n_frames, self.angles_) for k in range(n_variants)
        ]

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        return [dof_values(m, self.layout_) for m in self._copies(n_variants, n_frames, rng)]


class PerlinNoiseSynthesizer(CopyTrainingClips):
    """A training clip per variant plus 1-D Perlin noise on every DOF curve (module docstring).

    Args:
        amplitude: peak of the noise in units of each channel's within-class sd (``>= 0``; 0: plain copies).
        frequency: noise frequency, Hz (lattice points ``1/frequency`` seconds apart; ``> 0``).
        footskate_cleanup, footskate_root: the footskate cleanup after sampling, the same as SLFM's
            (:class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        smoothing_seconds: the Gaussian smoothing of every variant before the cleanup, seconds (0: off;
            :class:`~mocapkit.synthesis.base.MotionSynthesizer`).

    Attributes (after ``fit``): those of :class:`CopyTrainingClips`, and ``sigma_``: float64 ``[7 + 3B]``
    within-class sd of every channel of the :mod:`~mocapkit.synthesis.representation` features (ASF units per
    frame / radians per frame for the root's ``dx, dz, dyaw``, ASF units for its height, radians otherwise).
    """

    def __init__(
        self,
        amplitude: float = 1.0,
        frequency: float = 2.0,
        footskate_cleanup: bool = True,
        footskate_root: str = DEFAULT_ROOT_MOVE,
        smoothing_seconds: float = SMOOTHING_SECONDS,
    ):
        self.amplitude = amplitude
        self.frequency = frequency
        self.footskate_cleanup = footskate_cleanup
        self.footskate_root = footskate_root
        self.smoothing_seconds = smoothing_seconds

    def _encoded(self, matrix: np.ndarray):
        """``(flat features [T, 7 + 3B], start_xz, start_yaw)`` of AMC values ``[T, channels]`` on the reference
        skeleton (:func:`~mocapkit.synthesis.representation.encode`, ``root_start``)."""
        motion = amc_motion(self.skeleton_, dof_values(matrix, self.layout_), fps=self.fps_, angle_unit="deg")
        start_xz, start_yaw = root_start(motion)
        return encode(motion).flat(), start_xz, start_yaw

    def _fit_clips(self, clips: list[Motion]) -> None:
        if not float(self.amplitude) >= 0.0:
            raise ValueError(f"PerlinNoiseSynthesizer: amplitude={self.amplitude!r} must be >= 0")
        if not float(self.frequency) > 0.0:
            raise ValueError(f"PerlinNoiseSynthesizer: frequency={self.frequency!r} must be > 0 Hz")
        super()._fit_clips(clips)
        warped = [time_warp(m, self.mean_frames_, self.angles_) for m in self.train_matrices_]
        self.sigma_ = within_class_sd([self._encoded(m)[0] for m in warped])

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        lattice = np.arange(n_frames) / self.fps_ * float(self.frequency)  # [n_frames] lattice units
        channels = len(self.sigma_)
        points = int(np.floor(lattice[-1])) + 3
        out = []
        for copy in self._copies(n_variants, n_frames, rng):
            gradients = rng.uniform(-1.0, 1.0, size=(channels, points))
            phase = rng.uniform(0.0, 1.0, size=channels)
            noise = np.stack([perlin_noise(lattice + phase[k], gradients[k]) for k in range(channels)], axis=1)
            features, start_xz, start_yaw = self._encoded(copy)
            noisy = features + float(self.amplitude) * self.sigma_ * noise
            out.append(decode(noisy, self.skeleton_, start_xz=start_xz, start_yaw=start_yaw))
        return out


__all__ = ["CopyTrainingClips", "PerlinNoiseSynthesizer", "perlin_noise", "within_class_sd"]
