"""The gap-filling baselines of motion-capture practice, as :class:`~mocapkit.refinement.base.MotionRefiner` s.

Interpolation over time, per coordinate of each marker (``[frames]`` trajectories, metres):

- :class:`LinearInterpolation`: straight lines across each gap;
- :class:`PchipInterpolation`: shape-preserving piecewise cubic Hermite (scipy ``PchipInterpolator``): no
  overshoot, C¹;
- :class:`SplineInterpolation`: cubic spline through every observed sample (scipy ``CubicSpline``), C²;
- :class:`HoldLastValue`: the trivial baseline, the last observed value held across the gap.

They fill **interior** gaps only. Leading and trailing gaps (before the first / after the last observation of
a marker) are not extrapolated: they stay missing and are reported in ``metadata["refinement"]["unfilled"]``,
unless ``extrapolate="hold"`` asks to hold the nearest observed value there. A marker missing in every frame
stays missing (reported by name).

Marker inter-correlations:

- :class:`PCAGapFilling`, after Gløersen & Federolf 2016 ("Predicting missing marker trajectories in human
  motion data using marker intercorrelations", PLoS ONE 11(3): e0152616) and Federolf 2013 (PLoS ONE 8(10):
  e78689). It learns from the take itself: no training motions are needed (``fit`` is optional and only adds
  clean frames to the PCA). See the class docstring for the exact steps and where this implementation departs
  from the published one.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.interpolate import CubicSpline, PchipInterpolator

from mocapkit.refinement.base import MotionRefiner, RefinementError


def linear_fill(X: np.ndarray, observed: np.ndarray, empty: float = np.nan) -> np.ndarray:
    """Every column of ``X`` (``[frames, channels]``) linearly interpolated over time through its observed
    frames, the nearest observed value held before the first and after the last; a column with no observed
    frame becomes ``empty``. Observed entries are returned unchanged. The start of the iterative refiners."""
    X = np.asarray(X, dtype=np.float64)
    out = np.where(observed, X, empty)
    t = np.arange(X.shape[0])
    for c in np.flatnonzero((~observed).any(0) & observed.any(0)):
        o = observed[:, c]
        out[~o, c] = np.interp(t[~o], t[o], X[o, c])
    return out


class _TemporalInterpolation(MotionRefiner):
    """Shared machinery: per column, interpolate the missing frames from the observed ones."""

    min_frames = 2
    _min_points = 2

    def __init__(self, extrapolate: str | None = None):
        self.extrapolate = extrapolate

    def _interpolate(self, t_obs: np.ndarray, y_obs: np.ndarray, t_new: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray):
        if self.extrapolate not in (None, "hold"):
            raise ValueError(f"extrapolate must be None or 'hold', got {self.extrapolate!r}")
        frames = X.shape[0]
        filled = np.where(observed, X, np.nan)
        t = np.arange(frames, dtype=np.float64)
        for column in np.flatnonzero(~observed.all(axis=0)):
            seen = np.flatnonzero(observed[:, column])
            if seen.size == 0:
                continue  # missing in every frame: stays missing, reported
            first, last = seen[0], seen[-1]
            inside = np.flatnonzero(~observed[first : last + 1, column]) + first
            if inside.size and seen.size >= self._min_points:
                filled[inside, column] = self._interpolate(t[seen], X[seen, column], t[inside])
            if self.extrapolate == "hold":
                filled[:first, column] = X[first, column]
                filled[last + 1 :, column] = X[last, column]
        return filled, None


class LinearInterpolation(_TemporalInterpolation):
    """Linear interpolation over time across each interior gap (per coordinate).

    Args:
        extrapolate: ``None`` (leading/trailing gaps stay missing and are reported) or ``"hold"``.
    """

    _min_points = 2

    def _interpolate(self, t_obs, y_obs, t_new):
        return np.interp(t_new, t_obs, y_obs)


class PchipInterpolation(_TemporalInterpolation):
    """Piecewise cubic Hermite interpolation (scipy ``PchipInterpolator``) across each interior gap.

    Args:
        extrapolate: ``None`` (leading/trailing gaps stay missing and are reported) or ``"hold"``.
    """

    def _interpolate(self, t_obs, y_obs, t_new):
        return PchipInterpolator(t_obs, y_obs, extrapolate=False)(t_new)


class SplineInterpolation(_TemporalInterpolation):
    """Cubic-spline interpolation (scipy ``CubicSpline``) through all observed samples of a coordinate.

    Args:
        extrapolate: ``None`` (leading/trailing gaps stay missing and are reported) or ``"hold"``.
        bc_type: boundary condition of ``CubicSpline`` (default ``"not-a-knot"``).
    """

    def __init__(self, extrapolate: str | None = None, bc_type: str = "not-a-knot"):
        super().__init__(extrapolate=extrapolate)
        self.bc_type = bc_type

    def _interpolate(self, t_obs, y_obs, t_new):
        return CubicSpline(t_obs, y_obs, bc_type=self.bc_type, extrapolate=False)(t_new)


class HoldLastValue(_TemporalInterpolation):
    """The trivial baseline: every interior gap holds the last observed value before it.

    Args:
        extrapolate: ``None`` (leading/trailing gaps stay missing and are reported) or ``"hold"``.
    """

    _min_points = 1

    def _interpolate(self, t_obs, y_obs, t_new):
        return y_obs[np.searchsorted(t_obs, t_new, side="right") - 1]


#: An iterative PCA update that keeps growing beyond this (metres) is taken as diverging and stopped.
DIVERGING_CHANGE_M = 0.05


class PCAGapFilling(MotionRefiner):
    """PCA gap filling from the correlations between markers, after Gløersen & Federolf 2016.

    Works on the frames × (3·markers) matrix in metres, float64 torch linear algebra. For each marker ``m``
    with gaps (their strategy "R2": one marker at a time):

    1. **Body-fixed coordinates**: subtract, in every frame, the mean position of the reference markers
       (those observed in every frame; all markers, at the current estimate, when no marker is complete).
    2. **Weights**: ``w_j = exp(−d_mj² / (2·weight_scale²))`` for every other marker ``j``, with ``d_mj`` the
       mean distance between ``m`` and ``j`` over the frames where both are observed (``weight_scale`` =
       200 mm, their default); the marker being reconstructed gets ``missing_marker_weight`` (0.02) times the
       largest of the other weights (their 0.02 as such when a neighbour is close, weight ≈ 1), so it barely
       shapes the principal components yet is represented in them. (Relative, not absolute: when every other
       marker is far, an absolute 0.02 would let the marker's own filled values dominate the iterative basis
       and the iteration diverges.)
    3. **Normalise** each coordinate column by its mean and standard deviation over the basis frames, then
       multiply by the weights.
    4. **PCA** (eigen-decomposition of the weighted covariance, ``torch.linalg.eigh``) of the basis frames;
       keep the fewest components whose singular values sum to ``min_cum_sv`` (0.99) of the total.
    5. **Reconstruct**: in every frame where ``m`` is missing, the PC coefficients are the least-squares fit
       to the coordinates observed in that frame; ``m``'s coordinates are read off the fitted frame and the
       weighting, normalisation and body-fixed transform are undone. With ``regularization="ppca"`` (default)
       the least squares carry the probabilistic-PCA prior (coefficient variance = the component's eigenvalue,
       noise = the mean discarded eigenvalue), which keeps frames with few observed markers well posed;
       ``None`` gives plain least squares.

    Basis frames (``method``):

    - ``"complete"``: the frames in which every marker is observed (their method). Needs at least
      ``min_complete_frames`` of them.
    - ``"iterative"`` (default): start from the ``"complete"`` result when the take has ``min_complete_frames``
      complete frames, otherwise from linear interpolation (nearest value held at the ends); then repeat steps
      1–5 with the current estimate as the basis, marker ``m``'s PCA using the frames where ``m`` itself is
      observed (so its own filled values never train its reconstruction), until the filled values change by less
      than ``tol`` metres (at most ``max_iter`` rounds). The usual iterative-PCA extension; it also serves takes
      with no complete frame (random per-frame loss). On a 301-frame HDM05 clip with rgloss it brings the
      one-pass "complete" result of 9–17 cm RMSE down to 0.5–1.3 cm.

    Departures from the published method, stated: step 5 fits the PC coefficients by least squares on the
    coordinates observed in each frame instead of the published transformation between the PCs of the data
    and of the data with the gapped marker zeroed (Federolf 2013); this uses every observed marker of a frame,
    even ones that have gaps elsewhere, where the published "R2" zeroes such markers; the ridge/PPCA prior and
    the iterative basis are additions. Frames in which no marker
    is observed, and markers missing in every frame, are left missing (reported by the base class).

    After :meth:`refine`, ``basis_`` is ``"complete"`` or ``"iterative"`` and ``n_iter_`` the iterative rounds run.

    Training: none needed (``requires_fit = False``). ``fit(motions)`` optionally stores the complete frames of
    clean training motions of the same layout; they are added to the basis frames (after the same body-fixed
    transform).

    Args:
        method: ``"iterative"`` or ``"complete"``.
        min_cum_sv: fraction of the summed singular values the kept components reach (Gløersen: 0.99).
        weight_scale: σ of the distance weights, metres (Gløersen: 200 mm).
        missing_marker_weight: weight of the marker being reconstructed (Gløersen: 0.02).
        min_complete_frames: fewest complete frames for the ``"complete"`` basis.
        max_iter, tol: the iterative basis's stopping rule (rounds; metres).
        ridge: Tikhonov term added to the k×k normal equations of step 5 (relative, on unit-scale PCs).
        device: torch device for the linear algebra (``"cpu"`` or ``"cuda"``).
    """

    min_frames = 2

    def __init__(
        self,
        method: str = "iterative",
        min_cum_sv: float = 0.99,
        weight_scale: float = 0.2,
        missing_marker_weight: float = 0.02,
        min_complete_frames: int = 20,
        max_iter: int = 50,
        tol: float = 1e-5,
        regularization: str | None = "ppca",
        ridge: float = 1e-8,
        device: str = "cpu",
    ):
        self.method = method
        self.min_cum_sv = min_cum_sv
        self.weight_scale = weight_scale
        self.missing_marker_weight = missing_marker_weight
        self.min_complete_frames = min_complete_frames
        self.max_iter = max_iter
        self.tol = tol
        self.regularization = regularization
        self.ridge = ridge
        self.device = device

    # ------------------------------------------------------------------ training (optional)

    def _fit_matrices(self, data):
        frames = [X[observed.all(axis=1)] for X, observed in data]
        self.training_frames_ = np.concatenate(frames) if frames else np.zeros((0, data[0][0].shape[1]))

    # ------------------------------------------------------------------ refinement

    def refine(self, motion):
        """See :meth:`MotionRefiner.refine`; a motion of another layout than the optional training motions is
        rejected (their frames could not join the PCA)."""
        names = getattr(self, "joint_names_", None)
        if names is not None and tuple(motion.joint_names) != tuple(names):
            raise RefinementError(
                f"{motion.source or motion.name}: PCAGapFilling was fitted on another skeleton "
                f"layout; refit on motions of this layout or use an unfitted PCAGapFilling()"
            )
        return super().refine(motion)

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray):
        if self.method not in ("complete", "iterative"):
            raise ValueError(f"method must be 'iterative' or 'complete', got {self.method!r}")
        columns = X.shape[1]
        seen = observed[:, ::3]  # [F, J] marker observed
        active = seen.any(axis=0)  # markers seen at least once
        cols = np.repeat(active, 3)
        out = np.where(observed, X, np.nan)
        gapped = np.flatnonzero(active & ~seen.all(axis=0))
        self.basis_, self.n_iter_ = "none", 0
        if gapped.size == 0:
            return out, None
        Xa, Oa, Sa = X[:, cols], observed[:, cols], seen[:, active]
        train = getattr(self, "training_frames_", np.zeros((0, columns)))[:, cols]
        reference = seen[:, active].all(axis=0)  # reference markers (complete)
        complete = Sa.all(axis=1)
        index = {j: i for i, j in enumerate(np.flatnonzero(active))}
        distances = self._distances(Xa, Sa)
        if self.method == "complete" and complete.sum() < max(2, self.min_complete_frames):
            raise RefinementError(
                f"PCAGapFilling(method='complete'): only {int(complete.sum())} frames have every "
                f"marker, {self.min_complete_frames} needed; use method='iterative'"
            )
        initial = linear_fill(Xa, Oa)  # the iterative start and the fallback
        estimate = initial
        if complete.sum() >= max(2, self.min_complete_frames):
            self.basis_ = "complete"
            estimate = self._pass(
                estimate, Oa, Sa, Xa[complete], train, reference, distances, [index[j] for j in gapped]
            )
        if self.method == "iterative":
            self.basis_ = "iterative"
            changes: list[float] = []
            for iteration in range(1, self.max_iter + 1):
                self.n_iter_ = iteration
                previous = estimate
                estimate = self._pass(
                    estimate, Oa, Sa, estimate, train, reference, distances, [index[j] for j in gapped], own_rows=Sa
                )
                change = float(np.abs(estimate - previous)[~Oa].max())
                if change < self.tol:
                    break
                # diverging: the update grew three times in a row and moves markers by more than 5 cm
                if len(changes) >= 2 and change > changes[-1] > changes[-2] and change > DIVERGING_CHANGE_M:
                    estimate = previous
                    self.basis_ = "iterative (stopped: diverging)"
                    break
                changes.append(change)
        estimate = self._plausible(estimate, Oa, Sa, initial, reference)
        result = np.where(Oa, Xa, estimate)
        result[~Sa.any(axis=1)] = np.nan  # frames with nothing observed
        out[:, cols] = np.where(Oa, Xa, result)
        return out, None

    def _plausible(
        self, estimate: np.ndarray, observed: np.ndarray, seen: np.ndarray, fallback: np.ndarray, reference: np.ndarray
    ) -> np.ndarray:
        """Reconstructed markers farther from the body centre than any observed marker ever is (×1.5) are not
        plausible: they are replaced by the ``fallback`` (linear interpolation over time) and counted in
        ``n_implausible_``. With many markers missing at once the PCA solve can be ill-posed; this keeps a
        diverging reconstruction from inventing positions metres away from the body."""
        P = estimate.reshape(estimate.shape[0], -1, 3)
        centre = self._centres(np.where(observed, estimate, fallback), reference)[:, None]  # [F, 1, 3]
        radius = np.linalg.norm(P - centre, axis=2)  # [F, J]
        reach = 1.5 * radius[seen].max() if seen.any() else np.inf
        bad = (radius > reach) & ~seen
        self.n_implausible_ = int(bad.sum())
        if not bad.any():
            return estimate
        out = estimate.copy().reshape(P.shape)
        out[bad] = fallback.reshape(P.shape)[bad]
        return out.reshape(estimate.shape)

    @staticmethod
    def _distances(X: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """Mean distance between markers over the frames where both are observed, ``[J, J]`` metres (inf if never)."""
        P = X.reshape(X.shape[0], -1, 3)
        J = P.shape[1]
        total, count = np.zeros((J, J)), np.zeros((J, J))
        for start in range(0, P.shape[0], 512):
            p, s = P[start : start + 512], seen[start : start + 512]
            d = np.linalg.norm(p[:, :, None] - p[:, None], axis=3)
            both = s[:, :, None] & s[:, None]
            total += np.where(both, d, 0.0).sum(0)
            count += both.sum(0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, total / np.maximum(count, 1), np.inf)

    def _centres(self, X: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """Per-frame mean position of the reference markers, ``[frames, 3]``."""
        P = X.reshape(X.shape[0], -1, 3)
        ref = reference if reference.any() else np.ones(P.shape[1], bool)
        return P[:, ref].mean(axis=1)

    def _pass(self, X, observed, seen, basis, train, reference, distances, gapped, own_rows=None) -> np.ndarray:
        """One reconstruction of every gapped marker from the basis frames; ``X`` is finite everywhere (observed
        values, and the current estimate elsewhere, which only enters the body-fixed centre). ``own_rows``
        (bool ``[basis frames, markers]``): per marker, the basis frames its PCA may use (training frames always)."""
        dev = torch.device(self.device)
        columns = X.shape[1]
        J = columns // 3
        centre = np.tile(self._centres(X, reference), J)  # [F, C]
        basis_all = (
            np.concatenate(
                [
                    basis - np.tile(self._centres(basis, reference), J),
                    train - np.tile(self._centres(train, reference), J),
                ]
            )
            if len(train)
            else basis - np.tile(self._centres(basis, reference), J)
        )
        B = torch.as_tensor(basis_all, dtype=torch.float64, device=dev)
        mean, std = B.mean(0), B.std(0)
        std = torch.where(std > 1e-9, std, torch.ones_like(std))
        Z0 = (B - mean) / std  # [n, C]
        if own_rows is None:
            cov = (Z0.T @ Z0 / max(Z0.shape[0] - 1, 1))[None].expand(len(gapped), -1, -1)
        else:
            keep = np.concatenate([own_rows[:, gapped], np.ones((len(train), len(gapped)), bool)])  # [n, G]
            K = torch.as_tensor(keep, dtype=torch.float64, device=dev)
            cov = torch.einsum("ng,nc,nd->gcd", K, Z0, Z0) / (K.sum(0) - 1).clamp_min(1)[:, None, None]
        data = torch.as_tensor(X - centre, dtype=torch.float64, device=dev)
        obs = torch.as_tensor(observed, device=dev)
        out = X.copy()
        # distance weights of every gapped marker (rows) over all markers, then the weighted covariances
        d = np.where(np.isfinite(distances[gapped]), distances[gapped], 1e3)  # [G, J]
        w_markers = np.exp(-(d**2) / (2.0 * self.weight_scale**2))
        w_markers[np.arange(len(gapped)), gapped] = 0.0
        w_markers[np.arange(len(gapped)), gapped] = self.missing_marker_weight * w_markers.max(axis=1)
        W = torch.as_tensor(np.repeat(np.maximum(w_markers, 1e-12), 3, axis=1), dtype=torch.float64, device=dev)
        evals, evecs = torch.linalg.eigh(cov * W[:, :, None] * W[:, None, :])  # [G, C], [G, C, C]
        evals, evecs = evals.flip(-1).clamp_min(0.0), evecs.flip(-1)  # descending
        sv = evals.sqrt()
        counts = torch.searchsorted(torch.cumsum(sv, -1), (self.min_cum_sv * sv.sum(-1))[:, None]).squeeze(-1) + 1
        for g, m in enumerate(gapped):
            rows = np.flatnonzero(~seen[:, m] & seen.any(axis=1))
            if rows.size == 0:
                continue
            k = min(int(counts[g]), columns)
            V, lam, w = evecs[g, :, :k], evals[g, :k], W[g]  # [C, k], [k], [C]
            r = torch.as_tensor(rows, device=dev)
            o = obs[r].to(torch.float64)  # [f, C]
            z = (data[r] - mean) / std * w * o  # observed coords only
            gram = (V.T[None] * o[:, None, :]) @ V  # Vᵀ diag(o_f) V, [f, k, k]
            if self.regularization == "ppca":  # Gaussian prior on the coefficients, variance = eigenvalues
                noise = evals[g, k:].mean() if k < columns else evals[g, -1]
                prior = noise / lam.clamp_min(1e-12 * float(evals[g, 0]))
            else:
                prior = torch.zeros_like(lam)
            gram = gram + torch.diag_embed(prior + self.ridge)[None]
            coef = torch.linalg.solve(gram, (z @ V).unsqueeze(-1)).squeeze(-1)  # [f, k]
            block = slice(3 * m, 3 * m + 3)
            zm = coef @ V[block].T  # weighted, normalised
            xm = zm / w[block] * std[block] + mean[block]
            out[rows, block] = xm.cpu().numpy() + centre[rows, block]
        return out
