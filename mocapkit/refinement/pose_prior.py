"""Gap filling with a pose prior: a temporal cubic guess fused, frame by frame, with a Gaussian model of poses.

Why: a joint missing for a second or more cannot be interpolated in time (the cubic bridge between the gap's
ends misses everything the joint did in between), but in every frame its neighbours still say where it is — a
hand sits centimetres from its wrist. On fold bd's validation clips of HDM05 (training performers only) the
learned refiners' correction of missing entries was ≈ 0 (their gap error equalled their cubic first guess's to
0.1 mm), while a per-frame linear regression of a joint on the other joints, fitted on training frames, had a
quarter of that error (docs/results/refinement.md#why-the-networks-do-not-fill-long-gaps). This method makes that
regression the prior of a fusion:

1. **Temporal guess** ``g``: the cubic Hermite fill of :func:`~mocapkit.models.refiners.cubic_fill` (a curve
   between the nearest observed samples before and after each gap; the last observed step continued for a few
   frames and then held at a take's ends).
2. **Pose frame**: every frame of ``g`` is centred on its root and turned about the up axis so that its hip line
   lies along the first horizontal axis (the frames of the training poses were treated the same way).
3. **Prior**: probabilistic PCA of the training poses in that frame — mean ``μ`` [3J], loadings ``W`` [3J, K]
   (the ``K`` leading eigenvectors scaled by the square roots of their eigenvalues), isotropic noise ``σ²`` (the
   mean discarded eigenvalue).
4. **Fusion** per frame ``t``: every coordinate of ``g_t`` is a soft observation of the pose with variance
   ``v = σ_obs² + σ² + (drift · d / fps)²``, ``d`` the distance in frames from the entry to the nearest observed
   sample of its joint (0 for observed entries: the temporal guess is trusted next to a sample, less and less
   inside a long gap; a joint never observed in the take has ``v = ∞``). The posterior mean of the PPCA
   coefficients ``c_t = (I + Wᵀ V⁻¹ W)⁻¹ Wᵀ V⁻¹ (g_t − μ)`` gives the subspace pose ``s_t = μ + W c_t``; the
   posterior mean of the PPCA noise adds back the fraction ``σ² / (σ² + v_temporal)`` of the guess's residual
   ``g_t − s_t`` (``v_temporal = v − σ²``: next to a sample most of the guess is kept, far from one none), and
   the pose, turned back to the take's frame, fills the missing entries. Observed entries come back untouched (a gap filler: it does not
   denoise; put :class:`~mocapkit.refinement.screening.MedianScreen` in front for noisy takes).
5. **Short gaps**: interior gaps of a joint up to ``short_gap_seconds`` (0.2 s) take the not-a-knot cubic spline
   through the joint's samples instead (:func:`~mocapkit.refinement.learned.spline_fill`, the learned refiners'
   hand-over): there it beats the fusion, whose prior pulls a well-bracketed sample towards the training poses.

Cost: ``fit`` is one ``[3J, 3J]`` eigen-decomposition; ``refine`` is a ``[K, K]`` solve per frame
(``O(T · 3J · K²)``). Frames in which every joint is missing are filled inside the take up to
``max_empty_frames`` in a row and left missing beyond it and before the first / after the last observed frame
(reported as unfilled), as the learned refiners do.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import hip_line_heading, turn_about_up
from mocapkit.motion.layouts import hip_joints
from mocapkit.refinement.base import MotionRefiner, RefinementError


def nearest_sample_distance(observed: np.ndarray) -> np.ndarray:
    """Frames from every entry of ``observed`` (bool ``[T, J]``) to the nearest True of its column: 0 on a True,
    ``inf`` in a column without one. float64 ``[T, J]``."""
    frames = np.arange(observed.shape[0])[:, None].astype(np.float64)
    last = np.where(observed, frames, -np.inf)
    last = np.maximum.accumulate(last, axis=0)  # latest sample at or before t
    following = np.where(observed, frames, np.inf)[::-1]
    following = np.minimum.accumulate(following, axis=0)[::-1]  # next sample at or after t
    return np.minimum(frames - last, following - frames)


class PosePriorRefiner(MotionRefiner):
    """Temporal cubic guess fused with a PPCA prior of training poses; see the module docstring.

    Parameters:
        n_components: PPCA components ``K`` (at most ``3·joints − 1``: 90 of HDM05's 93 coordinates is nearly
            the full covariance). Default 90, chosen with ``drift`` on the validation clips of HDM05's training
            performers (K ∈ {30, 60, 90} × drift ∈ {0.04, 0.12, 0.2, 0.38} m/s;
            docs/decisions.md#pose-prior-components-and-drift).
        drift: metres per second by which the temporal guess's standard deviation grows with the distance to
            the nearest observed sample of the joint. Default 0.2 (chosen with ``n_components``).
        observation_noise: standard deviation (metres) of an observed sample. Default 0.002.
        noise_floor: the least standard deviation (metres) of the PPCA noise: ``σ² = max(mean discarded
            eigenvalue, noise_floor²)``. With ``K`` near ``3J`` the discarded eigenvalues are ~0 and a prior
            fitted on few clips is overconfident in its smallest directions (it then overrides the temporal
            guess even next to a sample); the floor keeps every direction uncertain by at least this much.
            Default 0.005 (chosen on the validation clips with the prior fitted on 10 clips per performer, as
            the benchmark fits it: 0, 0.002, 0.005, 0.01 m; docs/decisions.md#pose-prior-noise-floor).
        short_gap_seconds: interior gaps of a joint up to this long are filled by the cubic spline through its
            observed samples (:func:`~mocapkit.refinement.learned.spline_fill`, as the learned refiners hand short
            gaps over) instead of the fusion; 0: none. Default 0.2 (24 frames at 120 fps; chosen on the validation
            clips of HDM05's training performers among 0, 12, 24, 48, 72, 96 frames,
            docs/decisions.md#pose-prior-short-gaps; in
            seconds so that a 30 fps take hands over 6 frames, not 0.8 s).
        max_empty_frames: interior runs of frames with no observed joint longer than this stay missing, as do
            such frames before the first / after the last observed frame. Default 12.
        max_frames: training frames used (a seeded random subset above it). Default 200,000.
        random_state: seed of that subset.

    Attributes after ``fit``: ``mean_`` [3J], ``loadings_`` [3J, K], ``noise_variance_`` (m²),
    ``eigenvalues_`` [3J], ``root_``, ``hips_`` (joint indices; None: no heading alignment), ``n_frames_``.
    """

    requires_fit = True
    fixed_sampling = True

    def __init__(
        self,
        n_components: int = 90,
        drift: float = 0.2,
        observation_noise: float = 0.002,
        noise_floor: float = 0.005,
        short_gap_seconds: float = 0.2,
        max_empty_frames: int = 12,
        max_frames: int = 200_000,
        random_state: int | None = 0,
    ):
        self.n_components = n_components
        self.drift = drift
        self.noise_floor = noise_floor
        self.observation_noise = observation_noise
        self.short_gap_seconds = short_gap_seconds
        self.max_empty_frames = max_empty_frames
        self.max_frames = max_frames
        self.random_state = random_state

    # ------------------------------------------------------------------ fit

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> PosePriorRefiner:
        """Learn the pose prior from clean ``motions`` (one layout, frame rate and up axis; frames with a missing
        joint are left out)."""
        if not (int(self.n_components) >= 1):
            raise ValueError(f"n_components must be ≥ 1, got {self.n_components!r}")
        if not (float(self.drift) > 0 and float(self.observation_noise) > 0 and float(self.noise_floor) >= 0):
            raise ValueError(
                f"drift and observation_noise must be positive and noise_floor ≥ 0, got {self.drift!r}, "
                f"{self.observation_noise!r}, {self.noise_floor!r}"
            )
        if not (float(self.short_gap_seconds) >= 0):
            raise ValueError(f"short_gap_seconds must be ≥ 0, got {self.short_gap_seconds!r}")
        motions = list(motions or [])
        if motions:
            first = motions[0]
            self.root_ = first.parents.index(-1) if first.parents and -1 in first.parents else 0
            self.hips_ = hip_joints(first.joint_names, first.layout_name)
        return super().fit(motions, y)

    def _fit_matrices(self, data: list[tuple[np.ndarray, np.ndarray]]) -> None:
        frames = [X[observed.all(axis=1)] for X, observed in data]
        F = np.concatenate(frames) if frames else np.empty((0, data[0][0].shape[1]))
        if len(F) < 2:
            raise RefinementError(f"{type(self).__name__}.fit: fewer than 2 training frames with every joint observed")
        if len(F) > int(self.max_frames):
            F = F[np.random.default_rng(self.random_state).choice(len(F), int(self.max_frames), replace=False)]
        poses = self._to_pose_frame(F.reshape(len(F), -1, 3))[0].reshape(len(F), -1)
        self.mean_ = poses.mean(axis=0)
        evals, evecs = np.linalg.eigh(np.cov(poses - self.mean_, rowvar=False))
        evals, evecs = evals[::-1].clip(min=0), evecs[:, ::-1]
        K = min(int(self.n_components), len(evals) - 1)
        self.eigenvalues_ = evals
        self.noise_variance_ = max(float(evals[K:].mean()), float(self.noise_floor) ** 2)
        self.loadings_ = evecs[:, :K] * np.sqrt(evals[:K])
        self.n_frames_ = len(F)

    # ------------------------------------------------------------------ pose frame

    def _to_pose_frame(self, P: np.ndarray):
        """``[N, J, 3]`` → (root-centred, heading-turned ``[N, J, 3]``, root ``[N, 3]``, heading ``[N]`` rad): the
        hip line turned onto the first horizontal axis (:func:`~mocapkit.motion.geometry.hip_line_heading`)."""
        root = P[:, self.root_].copy()
        Q = P - root[:, None]
        if self.hips_ is None:
            angle = np.zeros(len(P))
        else:
            angle = hip_line_heading(Q, self.hips_[0], self.hips_[1], self.up_axis_)
        return turn_about_up(Q, angle, self.up_axis_), root, angle

    def _from_pose_frame(self, L: np.ndarray, root: np.ndarray, angle: np.ndarray) -> np.ndarray:
        return turn_about_up(L, angle, self.up_axis_, inverse=True) + root[:, None]

    # ------------------------------------------------------------------ refine

    def temporal_guess(self, positions: np.ndarray, observed: np.ndarray) -> np.ndarray:
        """The cubic fill of ``positions`` (float ``[T, J, 3]``, ignored where not ``observed`` ``[T, J]``):
        float64 ``[T, J, 3]``."""
        import torch

        from mocapkit.models.refiners import cubic_fill

        x = torch.from_numpy(np.where(observed[..., None], positions, 0.0)[None])
        return cubic_fill(x, torch.from_numpy(observed[None]))[0].numpy()

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, None]:
        from mocapkit.refinement.learned import (
            empty_frames_kept,
            short_gaps,
            spline_fill,
        )

        T, L = X.shape
        seen = observed[:, ::3]  # [T, J]
        guess = self.temporal_guess(X.reshape(T, -1, 3), seen)
        out = guess.copy()
        anchors = [self.root_] + list(self.hips_ or ())
        framed = bool(seen[:, anchors].any(axis=0).all())  # the pose frame needs the root and the hips somewhere
        if framed:
            distance = nearest_sample_distance(seen)
            step = float(self.drift) / self.fps_
            temporal = np.repeat(float(self.observation_noise) ** 2 + (step * distance) ** 2, 3, axis=1)  # [T, 3J]
            noise = self.noise_variance_
            precision = np.where(np.isfinite(temporal), 1.0 / (temporal + noise), 0.0)
            local, root, angle = self._to_pose_frame(guess)
            g = local.reshape(T, L)
            W = self.loadings_
            WtV = W.T[None] * precision[:, None, :]  # [T, K, 3J]
            A = np.eye(W.shape[1])[None] + WtV @ W  # [T, K, K]
            b = WtV @ (g - self.mean_)[..., None]  # [T, K, 1]
            subspace = self.mean_ + (np.linalg.solve(A, b)[..., 0] @ W.T)  # [T, 3J]
            # the posterior mean of the PPCA noise term keeps the part of the guess the subspace cannot hold,
            # in proportion to how far the guess is trusted (all of it next to a sample, none of it far away)
            keep = np.where(np.isfinite(temporal), noise / (noise + temporal), 0.0)
            pose = subspace + keep * (np.where(np.isfinite(g), g, 0.0) - subspace)
            out = self._from_pose_frame(pose.reshape(T, -1, 3), root, angle)
        longest = round(float(self.short_gap_seconds) * self.fps_)
        if longest > 0:
            short = short_gaps(~seen, longest)
            out[short] = spline_fill(X.reshape(T, -1, 3), ~seen, short)[short]
        out = out.reshape(T, L)
        never = ~seen.any(axis=0)
        if not framed:  # no prior: a joint never observed has no temporal guess either
            out[:, np.repeat(never, 3)] = np.nan
        out[empty_frames_kept(~seen, int(self.max_empty_frames))] = np.nan  # frames left missing
        return out, None
