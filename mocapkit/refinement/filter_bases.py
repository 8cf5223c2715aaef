"""Robust spatial-temporal filter bases (Lou & Chai, IEEE TVCG 2010; Lou 2012 PhD thesis, ch. 2).

Learning (thesis eqs. 2.1–2.6). Every training window of ``M`` frames of the ``L = 3·joints`` marker
channels is stacked **channel-major** (the ``M`` lags of channel 1, then of channel 2, …; eq. 2.2) into a row
of ``D`` [windows, M·L]; the filter bases are the leading eigenvectors ``E`` [M·L, K] of the lag moment
matrix ``C_D = Dᵀ D / S_N`` (eq. 2.3), ``K`` the fewest that hold ``energy`` (99 %) of its trace.

Filtering (eqs. 2.8–2.16). The refined take ``z`` minimises

    Σ_t Σ_l α_l(t) ρ(z_l(t) − y_l(t)) + λ Σ_s ‖z_s − E c_s‖²,     ρ(r) = (p²/2)(1 − exp(−r²/p²))  (Welsch, eq. 2.9)

over all sliding windows ``z_s``, with ``α`` = 1 where observed, 0 where missing (eq. 2.16). Block-coordinate
descent with IRLS (eqs. 2.12–2.15): ``c_s = Eᵀ z_s`` for every window, then per entry in closed form

    z_l(t) = (λ R_l(t) + α w y_l(t)) / (λ n_t + α w),      w = exp(−(z_l(t) − y_l(t))² / p²) at the previous z,

``R`` the overlap-add of the window reconstructions ``E c_s`` and ``n_t`` the number of windows covering
frame ``t`` (the thesis's ``w r²`` data term with ``λ = 0.1``; the printed eq. 2.15 lacks the parentheses of
``w = ψ(r)/r``). Observed markers whose final Welsch weight, the product over their three coordinates
``exp(−‖z − y‖²/p²)``, falls below ``outlier_weight`` are reported as outliers and replaced by ``z``; missing
entries are filled with ``z``; every other observed entry is returned untouched.

Cost: ``fit`` is ``O(windows · (M·L)²)`` for the moment matrix plus ``O((M·L)³)`` for its eigenvectors
(``M·L`` = 1,860 for 31 joints); ``refine`` is ``O(iterations · T · M·L · K)``.

Adaptations to marker positions in metres (the thesis filters joint angles or CMU markers captured by the
same subject in one room), all documented on the parameters:

* **Frame rate**: the thesis downsamples to 30 fps and uses ``M = 20``. Here the lags are dilated instead
  (``dilation`` = round(fps / 30), 4 at 120 fps), so a window spans the same 0.67 s at the original rate.
* **Invariance**: the raw (uncentred) moment matrix ties the bases to where in the room and which way the
  training performers moved. With ``invariance="heading"`` (default) each window is centred (its mean
  position per axis over markers and lags removed; the three constant-translation vectors are added back
  to the basis, so ``E`` spans every translate of the learnt windows) and ``C_D`` is averaged in closed form
  over all rotations about the vertical axis (as if the training set held every heading). ``"translation"``
  only centres; ``"none"`` is the thesis as written.
* **Number of bases**: the thesis keeps 99 % of the energy of the *uncentred* moment matrix, most of which
  is the mean pose; of the centred, heading-averaged one, 99 % leaves about 46 bases on HDM05 (three
  performers), too few for a fourth (median residual above the outlier threshold). The default keeps
  99.99 % (about 270 bases; measured below).
* **Welsch scale**: ``p = 3`` is in the data's units in the thesis (degrees); here ``p = 0.03`` m (3 cm).
* **Boundary frames**: ``(M − 1)·δ`` unobserved frames are padded at both ends, so every real frame lies in
  ``M`` windows (in the thesis the first and last ``M − 1`` frames are covered by fewer) and takes
  shorter than one window can be refined.
* **Initialisation**: the thesis starts from ``z = y``, undefined where missing; gaps start from linear
  interpolation, a never-observed marker from the centroid of the observed ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mocapkit.motion.container import AXES, Motion
from mocapkit.refinement.base import MotionRefiner, RefinementError
from mocapkit.refinement.gap_filling import linear_fill

#: Frame rate at which the thesis processes all data (120 fps downsampled to 30 fps).
THESIS_FPS = 30.0


class FilterBasesRefiner(MotionRefiner):
    """Robust M-SSA filter with learnt spatial-temporal bases: fill-in, outlier removal (Lou 2012, ch. 2).

    Parameters:
        window: lag-window length ``M`` in (dilated) frames. Default 20 (thesis §2.2.1).
        energy: fraction of the moment matrix's trace the kept bases hold. Default 0.9999 (the thesis's 0.99
            applies to the uncentred matrix, see the module docstring). Measured, trained on HDM05 bd, bk,
            dg and filling ``continuous_missing`` 30-frame gaps in 11 mm clips: 0.99 → K = 46, 5.7 cm RMSE
            (linear interpolation 2.8 cm); 0.999 → 127, 1.8 cm; 0.9999 → 270, 0.8 cm; 0.99999 → 528, 0.7 cm
            at twice the cost.
        n_bases: fixed number of bases ``K`` instead of the energy rule (None = energy rule).
        welsch_p: Welsch scale ``p`` in metres. Default 0.03 (thesis p = 3, read as centimetres).
        prior_weight: ``λ`` of the subspace term. Default 0.1 (thesis).
        max_iter: most block-coordinate iterations. Default 50: the thesis's 10–20 suffice for outliers;
            filling a gap through the subspace term converges geometrically (measured as above: 15
            iterations 0.96 cm, 30 → 0.84 cm, 100 → 0.80 cm).
        tol: stop when the cost changes by less than ``tol`` relative. Default 1e-5 (my choice).
        outlier_weight: observed markers whose final Welsch weight ``exp(−‖z − y‖²/p²)`` is below this are
            flagged and repaired. Default 0.01, i.e. a 3-D residual above ``p·sqrt(ln 100)`` ≈ 6.4 cm (my
            choice: about the 6 cm trust-data threshold of Wang 2017, eq. 3.13).
        dilation: frames between lags; None = round(training fps / 30).
        invariance: ``"heading"`` (default), ``"translation"`` or ``"none"`` (module docstring).
        max_windows: training windows used to build ``C_D`` (a seeded random subset when there are more).
            Default 30000 (my choice; ``C_D`` is ``O(windows · (M·L)²)``).
        random_state: seed of that subset.

    Attributes (after ``fit``): ``bases_`` [M·L, K'] orthonormal (K' = K, plus 3 translation vectors for
    the invariant variants), ``n_bases_`` (K), ``eigenvalues_`` (of ``C_D``, m², descending),
    ``dilation_``, ``fps_``, ``up_axis_``, ``joint_names_``. After ``refine``: ``weights_`` [T, joints] final
    Welsch weights of the markers (1 where missing), ``cost_`` per-iteration cost (eq. 2.16), ``n_iter_``.
    """

    requires_fit = True
    fixed_sampling = True

    def __init__(
        self,
        window: int = 20,
        energy: float = 0.9999,
        n_bases: int | None = None,
        welsch_p: float = 0.03,
        prior_weight: float = 0.1,
        max_iter: int = 50,
        tol: float = 1e-5,
        outlier_weight: float = 0.01,
        dilation: int | None = None,
        invariance: str = "heading",
        max_windows: int = 30000,
        random_state: int | None = 0,
    ):
        self.window = window
        self.energy = energy
        self.n_bases = n_bases
        self.welsch_p = welsch_p
        self.prior_weight = prior_weight
        self.max_iter = max_iter
        self.tol = tol
        self.outlier_weight = outlier_weight
        self.dilation = dilation
        self.invariance = invariance
        self.max_windows = max_windows
        self.random_state = random_state

    # ------------------------------------------------------------------ fit

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> FilterBasesRefiner:
        """Learn the bases from clean ``motions`` (one layout, one frame rate, one up axis)."""
        if self.invariance not in ("heading", "translation", "none"):
            raise ValueError(f"invariance must be 'heading', 'translation' or 'none', got {self.invariance!r}")
        return super().fit(motions, y)

    def _fit_matrices(self, data: list[tuple[np.ndarray, np.ndarray]]) -> None:
        self.dilation_ = int(self.dilation) if self.dilation else max(1, round(self.fps_ / THESIS_FPS))
        M, delta = int(self.window), self.dilation_
        L = data[0][0].shape[1]
        rows = []
        for X, observed in data:
            if X.shape[0] < (M - 1) * delta + 1:
                continue
            ok = _unfold(observed.astype(np.float64), M, delta).min(axis=(1, 2)) > 0  # fully observed windows
            rows.append(_unfold(X, M, delta)[ok].reshape(-1, L * M))
        Dm = np.concatenate(rows) if rows else np.empty((0, L * M))
        if len(Dm) < 2:
            raise RefinementError(
                f"{type(self).__name__}.fit: no fully observed training window of {(M - 1) * delta + 1} frames"
            )
        if len(Dm) > self.max_windows:
            Dm = Dm[np.random.default_rng(self.random_state).choice(len(Dm), int(self.max_windows), replace=False)]
        shift = self._translation_basis(L, M)
        if self.invariance != "none":
            Dm = Dm - (Dm @ shift) @ shift.T  # centre every window (per axis)
        C = Dm.T @ Dm / len(Dm)  # eq. 2.3
        if self.invariance == "heading":
            C = _average_heading(C, L // 3, M, AXES[self.up_axis_])
        evals, evecs = np.linalg.eigh(C)
        evals, evecs = evals[::-1].clip(min=0), evecs[:, ::-1]
        if self.n_bases:
            K = int(self.n_bases)
        else:
            K = int(np.searchsorted(np.cumsum(evals) / evals.sum(), float(self.energy)) + 1)
        K = max(1, min(K, int((evals > 1e-12 * evals[0]).sum())))
        E = evecs[:, :K]
        if self.invariance != "none":
            E = np.concatenate([shift, E], axis=1)  # centred bases ⟂ translations
        self.bases_, self.n_bases_, self.eigenvalues_ = E, K, evals

    def _translation_basis(self, L: int, M: int) -> np.ndarray:
        """[M·L, 3] orthonormal: a constant offset along x, y, z of every marker at every lag (channel-major)."""
        S = np.zeros((L, M, 3))
        for a in range(3):
            S[a::3, :, a] = 1.0
        return S.reshape(L * M, 3) / np.sqrt(L * M / 3)

    # ------------------------------------------------------------------ refine

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        T0, L = X.shape
        M, delta, E = int(self.window), self.dilation_, self.bases_
        lam, p2 = float(self.prior_weight), float(self.welsch_p) ** 2
        # pad (M-1)·δ unobserved frames at both ends: every real frame is then covered by M windows
        # and takes shorter than one window work too
        pad = (M - 1) * delta
        observed = np.pad(observed, ((pad, pad), (0, 0)))
        X = np.pad(X, ((pad, pad), (0, 0)))
        T = X.shape[0]
        alpha = observed.astype(np.float64)
        y = np.where(observed, X, 0.0)
        z = _initial(X, observed)
        n = _unfold_counts(T, M, delta)[:, None]  # windows covering each frame
        cost_history: list[float] = []
        for _ in range(max(1, int(self.max_iter))):
            Z = _unfold(z, M, delta).reshape(-1, L * M)  # [S, L·M] windows (channel-major)
            recon = (Z @ E) @ E.T  # E c_s, c_s = Eᵀ z_s (eqs. 2.12–2.13)
            w = np.exp(-((z - y) ** 2) / p2)  # IRLS weight ψ(r)/r at the previous z
            cost_history.append(float((alpha * 0.5 * p2 * (1.0 - w)).sum()) + lam * float(((Z - recon) ** 2).sum()))
            R = _fold(recon.reshape(-1, L, M), T, delta)
            z = (lam * R + alpha * w * y) / (lam * n + alpha * w)  # eq. 2.15, closed form per entry
            if len(cost_history) > 1 and abs(cost_history[-2] - cost_history[-1]) <= self.tol * cost_history[-1]:
                break
        z, y, observed = z[pad : T - pad], y[pad : T - pad], observed[pad : T - pad]
        r2 = np.where(observed, (z - y) ** 2, 0.0).reshape(T0, L // 3, 3).sum(2)
        marker_weight = np.exp(-r2 / p2)  # product of the marker's 3 coordinate weights
        repaired = (marker_weight < float(self.outlier_weight)) & observed[:, ::3]
        self.weights_, self.cost_, self.n_iter_ = marker_weight, cost_history, len(cost_history)
        return z, repaired


def _initial(X: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """``y`` where observed, linear interpolation in gaps, the per-frame centroid (per axis) of the observed
    markers for a marker never observed (and for frames with no observed marker, its interpolation)."""
    z = linear_fill(X, observed)
    never = ~observed.any(0)
    if never.any():
        T, L = X.shape
        obs3 = observed.reshape(T, L // 3, 3)
        X3 = np.where(obs3, X.reshape(T, L // 3, 3), 0.0)
        cnt = obs3.sum(1)
        centroid = np.where(cnt > 0, X3.sum(1) / np.maximum(cnt, 1), np.nan)  # [T, 3]
        centroid = linear_fill(np.nan_to_num(centroid), cnt > 0)
        for c in np.flatnonzero(never):
            z[:, c] = centroid[:, c % 3]
    return z


def _unfold(z: np.ndarray, M: int, delta: int) -> np.ndarray:
    """Windows ``[S, L, M]`` of ``z`` ``[T, L]``: window s holds frames ``s, s+δ, …, s+(M−1)δ``."""
    T = z.shape[0]
    S = T - (M - 1) * delta
    idx = np.arange(S)[:, None] + delta * np.arange(M)[None, :]  # [S, M]
    return np.swapaxes(z[idx], 1, 2)


def _fold(windows: np.ndarray, T: int, delta: int) -> np.ndarray:
    """Overlap-add of ``[S, L, M]`` windows back to ``[T, L]`` (the inverse bookkeeping of :func:`_unfold`)."""
    S, L, M = windows.shape
    out = np.zeros((T, L))
    for m in range(M):
        out[m * delta : m * delta + S] += windows[:, :, m]
    return out


def _unfold_counts(T: int, M: int, delta: int) -> np.ndarray:
    return _fold(np.ones((T - (M - 1) * delta, 1, M)), T, delta)[:, 0]


def _average_heading(C: np.ndarray, J: int, M: int, up: int) -> np.ndarray:
    """``C`` [(J·3·M)², channel-major] averaged over all rotations about axis ``up``.

    For the two horizontal axes (h1, h2) of two entries: ``E[R a bᵀ Rᵀ] = ½(a·b) I + ½(a₁b₂ − a₂b₁)[[0, 1], [−1, 0]]``
    (rotation by a uniform angle); vertical–horizontal cross moments average to zero.
    """
    h1, h2 = [a for a in range(3) if a != up]
    C6 = C.reshape(J, 3, M, J, 3, M)
    out = np.zeros_like(C6)
    out[:, up, :, :, up, :] = C6[:, up, :, :, up, :]
    same = 0.5 * (C6[:, h1, :, :, h1, :] + C6[:, h2, :, :, h2, :])
    cross = 0.5 * (C6[:, h1, :, :, h2, :] - C6[:, h2, :, :, h1, :])
    out[:, h1, :, :, h1, :] = same
    out[:, h2, :, :, h2, :] = same
    out[:, h1, :, :, h2, :] = cross
    out[:, h2, :, :, h1, :] = -cross
    return out.reshape(C.shape)
