"""TrNN: motion completion by truncated-nuclear-norm RPCA with temporal smoothness (Wang 2017 §4.2 "Model B";
Hu et al. 2017a), Algorithm 3 of the thesis with the corrections listed below.

Orientation. Here the thesis's own orientation is kept: ``D ∈ R^{m×n}`` with ``m = 3·joints`` rows and one
column per frame, i.e. the transpose of the ``[frames, 3·joints]`` matrix of
:func:`mocapkit.refinement.base.motion_matrix`. :func:`trnn` takes and returns ``[frames, features]`` arrays
and transposes internally (time is the contiguous axis of every ``m×n`` array). ``Ω`` is the observed set; ``P_Ω`` zeroes the unobserved entries.

Model (eq. 4.21)::

    min ½(‖L‖²_F + ‖R‖²_F) − tr(U L Rᵀ Vᵀ) + λ‖P_Ω(S)‖₁ + (μ/2)‖L Rᵀ O‖²_F
    s.t.  L Rᵀ + S = P_Ω(D),  U Uᵀ = V Vᵀ = I_r

with ``L ∈ R^{m×d}``, ``R ∈ R^{n×d}``, ``U ∈ R^{r×m}``, ``V ∈ R^{r×n}`` and ``O`` the second-difference
operator of eq. 4.22. ``½(‖L‖² + ‖R‖²) − tr(U L Rᵀ Vᵀ)`` minimised over the factors is the truncated nuclear
norm ``‖X‖_r = Σ_{i>r} σ_i(X)`` of ``X = L Rᵀ`` (eq. 4.20): the ``r`` largest singular values are free,
only the tail is shrunk.

``truncation = 0`` (``r = 0``, no ``U, V``) leaves the factorised *nuclear* norm ``‖X‖_*``: the model of
Feng et al. 2014b ("TSMC": low rank + sparse + temporal stability) that the thesis's Table 4.1 compares with.
It is that *model* solved by this ALM, not Feng et al.'s own partial-SVD solver, so its timings are not
TSMC's.

Only small matrices are ever decomposed: the U- and V-steps (eq. 4.26) take economy SVDs of the ``m×r`` and
``n×r`` products ``L Rᵀ Vᵀ`` and ``R Lᵀ Uᵀ``; the smoothness step (eq. 4.25) is one DCT and one inverse DCT
along time; the L- and R-steps invert ``d×d`` matrices. Cost per iteration ``O(m n d + m n log n)``.

Corrections of the printed algorithm (each marked ``[fix]`` in the code):

* eq. 4.25: ``Γ_ii = 1 / (η + μ ξ_i²)``; the thesis prints ``Y1`` for the penalty ``η``;
* eq. 4.22, not 4.2: ``O`` ends with the row ``[1 −1]``, which makes it diagonal in the DCT-II basis;
* Algorithm 3 line 1: ``R¹ = randn(n, d) / ‖·‖_F`` (the thesis prints ``randn(m, n)``);
* ``U¹, V¹`` (not given by the thesis): the top-``r`` left/right singular vectors of the gap-interpolated
  data (:func:`mocapkit.refinement.gap_filling.linear_fill`), one SVD before the loop;
* the ``E^k`` of the ϑ stopping rule is ``S^k``; the multipliers are unsigned (the thesis says ``Y1, Y2 > 0``);
* the factor width ``d = min(round(1.2 · rank(X)), m, n)`` (§4.2.3) is raised to at least ``r + 1`` so that
  ``r ≤ rank(X) ≤ d`` (eq. 4.20) can hold.

Stopping rule (§4.2.3)::

    ϑ = max{ ‖P_Ω(D) − L Rᵀ − S‖_F / ‖P_Ω(D)‖_F,  ‖L Rᵀ − L₋ R₋ᵀ‖_F / ‖L Rᵀ‖_F } < ε.

Thesis MoCap settings (§4.2.3, used as defaults): ``r = 15``, ``λ = 100/√max(m, n)``, ``μ = 100``,
``ρ = 1.4``, ``η¹ = 1e−5``, ``η_max = 1e6``, ``ε = 1e−4``; synthetic RPCA settings: ``λ = 1/√max(m, n)``,
``μ = 0``, ``ρ = 1.5``, ``η¹ = 1.25/‖D‖₂``, ``ε = 1e−7``. The parameters are in the thesis's CMU units; the
refiner rescales (``unit``, see :mod:`mocapkit.refinement.lrmf`).

Rank. ``rank(X)`` is estimated by the LSJ rule of §4.2.3 on the singular values of the linearly interpolated
data, ``argmax{i : σ_i − σ_{i+1} ≥ 0.1}``, taken literally on the singular values in CMU units
(:func:`mocapkit.refinement.lrmf.lsj_rank`, rule ``"absolute"``). Normalising by ``σ₁`` first gives 1–2 on
real motion (the mean pose dominates ``σ₁``), which contradicts the thesis's ``r = 15 ≤ rank(X)``; that rule
is available as ``rank_rule="normalised"``.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from mocapkit.refinement.base import MotionRefiner, RefinementError
from mocapkit.refinement.gap_filling import linear_fill
from mocapkit.refinement.lrmf import (
    CMU_UNIT,
    LowRankResult,
    _solve_right,
    dct,
    drop_empty_columns,
    flag_outliers,
    ialm_multipliers,
    idct,
    lsj_rank,
    resolve_device,
    resolve_dtype,
    soft,
)


def _orthonormal_maximiser(A: torch.Tensor) -> torch.Tensor:
    """``argmax_W tr(W A)`` s.t. ``W Wᵀ = I_r`` for ``A [k, r]``: ``W = Q Pᵀ`` with ``A = P Σ Qᵀ`` the economy
    SVD (Wang 2017 Appendix .1, after Hong et al. 2016). Returns ``W [r, k]``."""
    P, _, Qh = torch.linalg.svd(A, full_matrices=False)  # P: k×r, Qh = Qᵀ: r×r
    return (P @ Qh).mT  # Q Pᵀ = (P Qᵀ)ᵀ


def trnn(
    X: np.ndarray,
    observed: np.ndarray,
    truncation: int = 15,
    width: int | None = None,
    lam: float | None = None,
    mu: float = 100.0,
    rho: float = 1.4,
    eta: float = 1e-5,
    eta_max: float = 1e6,
    max_iter: int = 500,
    tol: float = 1e-4,
    random_state: int | None = 0,
    device="cpu",
    dtype=torch.float64,
    init: np.ndarray | None = None,
) -> LowRankResult:
    """Algorithm 3 of Wang 2017 (corrected, see the module docstring).

    Args:
        X: float ``[frames n, features m]`` (``Dᵀ``); values at unobserved entries are ignored.
        observed: bool ``[n, m]`` (``Ωᵀ``).
        truncation: ``r``, the number of leading singular values left unpenalised (0: nuclear norm).
        width: factor width ``d`` (``r < d ≤ min(m, n)``); None: ``min(m, n)``.
        lam: weight of ``‖P_Ω(S)‖₁``; None: ``100 / √max(m, n)`` (thesis MoCap setting).
        mu: weight of the smoothness term ``(μ/2)‖LRᵀO‖²`` (0: plain TrNN-RPCA).
        rho, eta, eta_max: penalty growth factor, initial penalty ``η¹`` and its cap.
        max_iter, tol: iteration cap and ϑ threshold ``ε``.
        random_state: seed of ``R¹ = randn(n, d)``.
        init: ``[n, m]`` matrix whose top-``r`` singular vectors start ``U, V``; None: the gap-interpolated data.

    Returns:
        :class:`~mocapkit.refinement.lrmf.LowRankResult` with ``low_rank = (L Rᵀ)ᵀ`` and ``sparse = P_Ω(S)ᵀ``
        (``[n, m]``); ``history[k]["objective"]`` is the value of eq. 4.21's objective at ``(L, R, S, M, U, V)``
        with ``M`` in the smoothness term.
    """
    device, dtype = resolve_device(device), resolve_dtype(dtype)
    n, m = X.shape
    r = int(truncation)
    if r < 0:
        raise ValueError(f"truncation must be >= 0, got {truncation}")
    d = min(m, n) if width is None else int(width)
    if not (r < d <= min(m, n)) and not (r == 0 and 1 <= d <= min(m, n)):
        raise ValueError(
            f"factor width d={d} must satisfy truncation r={r} < d <= min(frames, features) = "
            f"{min(m, n)} (eq. 4.20 needs r <= rank(X) <= d)"
        )
    lam = 100.0 / math.sqrt(max(m, n)) if lam is None else float(lam)
    obs_np = np.asarray(observed, bool)
    Om = torch.as_tensor(np.ascontiguousarray(obs_np.T), device=device)  # Ω, m×n (time contiguous)
    PD = torch.as_tensor(np.ascontiguousarray(np.where(obs_np, X, 0.0).T), device=device, dtype=dtype)  # P_Ω(D)
    norm_PD = float(torch.linalg.matrix_norm(PD))
    if norm_PD == 0:
        raise ValueError("TrNN: every observed entry is 0, nothing to complete")
    # Algorithm 3 line 1: Y1 = Y2 = D / max(‖D‖₂, ‖D‖_∞/λ); S = M = 0; R = randn(n, d)/‖·‖_F  [fix: not randn(m, n)]
    Y1, Y2 = ialm_multipliers(PD, lam)
    S = torch.zeros_like(PD)
    M = torch.zeros_like(PD)
    gen = torch.Generator().manual_seed(0 if random_state is None else int(random_state))
    R = torch.randn(n, d, generator=gen, dtype=torch.float64).to(device=device, dtype=dtype)
    R = R / torch.linalg.matrix_norm(R)
    if r > 0:  # [fix: U, V start not given] top-r singular vectors of the interpolated data
        start = linear_fill(X, obs_np, empty=0.0) if init is None else np.asarray(init, dtype=np.float64)
        P, _, Qh = torch.linalg.svd(torch.as_tensor(start.T, device=device, dtype=dtype), full_matrices=False)
        U, V = P[:, :r].mT.contiguous(), Qh[:r].contiguous()  # U: r×m, V: r×n
    else:
        U = torch.zeros(0, m, device=device, dtype=dtype)
        V = torch.zeros(0, n, device=device, dtype=dtype)
    eye = torch.eye(d, device=device, dtype=dtype)
    xi2 = (2 * torch.cos(math.pi * torch.arange(n, device=device, dtype=dtype) / n) - 2) ** 2  # ξ_i², eq. 4.25
    X_prev = torch.zeros_like(PD)
    history: list[dict] = []
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        # T1 = Uᵀ V + Y1 + Y2 + η (M + P_Ω(D) − S), m×n                                  T1 of (4.24)
        T1 = (Y1 + Y2).add_(M, alpha=eta).add_(PD, alpha=eta).sub_(S, alpha=eta)
        if r > 0:
            T1.addmm_(U.mT, V)
        L = _solve_right(T1 @ R, eye + 2 * eta * (R.mT @ R))  # (4.24) L = T1 R T2⁻¹
        R = _solve_right(T1.mT @ L, eye + 2 * eta * (L.mT @ L))  # (4.24) R = T1ᵀ L T3⁻¹ (new L)
        del T1
        LR = L @ R.mT
        Ts = (PD - LR).add_(Y2, alpha=1 / eta)  # T_s of (4.24)
        S = torch.where(Om, soft(Ts, lam / eta), Ts)  # (4.24) S = P_Ωc(Ts) + P_Ω(T(Ts))
        del Ts
        # (4.25) [fix: Γ_ii = 1/(η + μξ_i²), the thesis prints Y1 for η]: Mᵀ = IDCT(Γ DCT(Tmᵀ)), Tm = η L Rᵀ − Y1,
        # with the DCT along time (axis 1 here, i.e. along the columns of Tmᵀ)
        C = dct((LR * eta).sub_(Y1), dim=1).mul_(1.0 / (eta + mu * xi2))  # DCT coefficients of M
        M = idct(C, dim=1)
        if r > 0:
            U = _orthonormal_maximiser(L @ (V @ R).mT)  # (4.26) SVD of L Rᵀ Vᵀ (m×r)
            V = _orthonormal_maximiser(R @ (U @ L).mT)  # (4.26) SVD of R Lᵀ Uᵀ (n×r)
        R1 = M - LR
        R2 = (PD - LR).sub_(S)
        Y1.add_(R1, alpha=eta)  # Algorithm 3 line 6
        Y2.add_(R2, alpha=eta)  # Algorithm 3 line 6
        norm_LR = float(torch.linalg.matrix_norm(LR))
        residual = float(torch.linalg.matrix_norm(R2)) / norm_PD
        change = float(torch.linalg.matrix_norm(X_prev.sub_(LR))) / max(norm_LR, 1e-300)
        theta = max(residual, change)  # ϑ of §4.2.3 [fix: E^k is S^k]
        # objective of (4.21) with M in the smoothness term; ‖MO‖² = Σ_i ξ_i² ‖DCT coefficient i‖² (Parseval)
        objective = (
            0.5 * float(L.square().sum() + R.square().sum())
            - float(((U @ L) * (V @ R)).sum())
            + lam * float(torch.where(Om, S, 0.0).abs_().sum())
            + 0.5 * mu * float((C.square().sum(0) * xi2).sum())
        )
        history.append(
            {
                "theta": theta,
                "residual": max(residual, float(torch.linalg.matrix_norm(R1)) / norm_PD),
                "objective": objective,
                "penalty": eta,
            }
        )
        if not math.isfinite(theta):
            raise FloatingPointError(f"TrNN diverged at iteration {it} (non-finite residual)")
        X_prev = LR
        eta = min(rho * eta, eta_max)  # Algorithm 3 line 7
        if theta < tol:
            converged = True
            break
    sparse = torch.where(Om, S, torch.zeros_like(S))
    return LowRankResult(
        LR.mT.cpu().numpy().astype(np.float64), sparse.mT.cpu().numpy().astype(np.float64), it, converged, d, history
    )


class TrNN(MotionRefiner):
    """Motion completion by truncated-nuclear-norm RPCA with temporal smoothness (Wang 2017 §4.2, Algorithm 3).

    Fills every missing entry of a marker observed somewhere in the sequence; a marker missing in every frame
    stays missing (``unfilled``). Like :class:`~mocapkit.refinement.lrmf.LRMF` it is robust: an observed joint is
    replaced by the low-rank estimate only when the Euclidean norm of its sparse component ``S`` exceeds
    ``outlier_threshold`` metres (``repaired``; the threshold is discussed in :mod:`mocapkit.refinement.lrmf`);
    every other observed entry comes back bit-identical.

    Args:
        truncation: ``r``, leading singular values left unpenalised (thesis MoCap setting 15). ``0`` gives the
            nuclear-norm model of Feng et al. 2014b (TSMC-style baseline of the thesis's Table 4.1).
        rank: ``"auto"`` (LSJ estimate of ``rank(X)``, then ``d = min(round(1.2·rank), m, n)``, at least ``r + 1``)
            or the factor width ``d`` as an int.
        rank_threshold, rank_rule: LSJ threshold and rule (:func:`~mocapkit.refinement.lrmf.lsj_rank`), in ``unit``s.
        lam: ℓ1 weight; None: ``100/√max(m, n)``.
        mu: smoothness weight (thesis 100).
        rho, eta, eta_max: ALM penalty growth (1.4), start (1e-5) and cap (1e6).
        outlier_threshold: metres; None never flags.
        unit: metres per solver unit (default: the CMU unit the thesis's parameters were tuned in).
        max_iter, tol: iteration cap and ϑ threshold (1e-4).
        random_state: seed of ``R¹``.
        device, dtype: torch device (``"cpu"``, ``"cuda"``) and dtype.

    Attributes (after :meth:`refine`): ``rank_`` (estimated ``rank(X)``), ``width_`` (``d``), ``n_iter_``,
    ``converged_``, ``history_``.

    Needs at least ``max(3, truncation + 1)`` frames and ``truncation + 1`` observed coordinates (the factor
    width must satisfy ``r < d ≤ min(frames, coordinates)``).
    """

    def __init__(
        self,
        truncation: int = 15,
        rank: int | str = "auto",
        rank_threshold: float = 0.1,
        rank_rule: str = "absolute",
        lam: float | None = None,
        mu: float = 100.0,
        rho: float = 1.4,
        eta: float = 1e-5,
        eta_max: float = 1e6,
        outlier_threshold: float | None = 0.03,
        unit: float = CMU_UNIT,
        max_iter: int = 500,
        tol: float = 1e-4,
        random_state: int | None = 0,
        device="cpu",
        dtype=torch.float64,
    ):
        self.truncation = truncation
        self.rank = rank
        self.rank_threshold = rank_threshold
        self.rank_rule = rank_rule
        self.lam = lam
        self.mu = mu
        self.rho = rho
        self.eta = eta
        self.eta_max = eta_max
        self.outlier_threshold = outlier_threshold
        self.unit = unit
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.device = device
        self.dtype = dtype

    @property
    def min_frames(self) -> int:
        """Fewest frames: ``r + 1`` (``r < d ≤ frames``), and 3 for the second differences of ``O``."""
        return max(3, int(self.truncation) + 1)

    def _width(self, Xs: np.ndarray, observed: np.ndarray, filled: np.ndarray) -> int:
        n, m = Xs.shape
        r = int(self.truncation)
        if self.rank == "auto":
            self.rank_ = lsj_rank(np.linalg.svd(filled, compute_uv=False), self.rank_threshold, self.rank_rule)
            d = min(round(1.2 * self.rank_), m, n)
        elif isinstance(self.rank, (int, np.integer)) and self.rank >= 1:
            self.rank_ = d = min(int(self.rank), m, n)
        else:
            raise ValueError(f"rank must be 'auto' or a positive int, got {self.rank!r}")
        return max(d, r + 1)  # [fix] r <= rank(X) <= d

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Fill ``X`` (float64 ``[frames, 3·joints]`` metres, 0 where not ``observed``); see the class docstring."""
        r = int(self.truncation)
        if r < 0:
            raise ValueError(f"truncation must be >= 0, got {self.truncation}")
        if not self.unit > 0:
            raise ValueError(f"unit must be positive (metres per solver unit), got {self.unit!r}")
        n = X.shape[0]
        if n < self.min_frames:
            raise RefinementError(
                f"TrNN with truncation r={r} needs at least {self.min_frames} frames (r < d <= frames), got {n}"
            )
        keep = drop_empty_columns(X, observed)
        if keep.sum() < r + 1:
            raise RefinementError(
                f"TrNN with truncation r={r} needs at least {r + 1} observed coordinates "
                f"({(r + 3) // 3} markers; r < d <= coordinates), got {int(keep.sum())}"
            )
        Xs, obs = X[:, keep] / self.unit, observed[:, keep]
        filled = linear_fill(Xs, obs, empty=0.0)
        width = self._width(Xs, obs, filled)
        result = trnn(
            Xs,
            obs,
            r,
            width,
            self.lam,
            self.mu,
            self.rho,
            self.eta,
            self.eta_max,
            self.max_iter,
            self.tol,
            self.random_state,
            self.device,
            self.dtype,
            init=filled,
        )
        self.width_, self.n_iter_, self.converged_, self.history_ = (
            width,
            result.n_iter,
            result.converged,
            result.history,
        )
        out = np.full(X.shape, np.nan)
        out[:, keep] = result.low_rank * self.unit
        sparse = np.zeros(X.shape)
        sparse[:, keep] = result.sparse * self.unit
        return out, flag_outliers(sparse, observed, self.outlier_threshold)
