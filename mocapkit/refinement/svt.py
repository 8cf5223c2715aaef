"""Singular value thresholding (SVT) matrix completion, Cai, Candès & Shen 2010 ("A singular value thresholding
algorithm for matrix completion", SIAM J. Optim. 20(4)), as a :class:`~mocapkit.refinement.base.MotionRefiner`.

The SVT baseline of Wang 2017 (thesis §3.5, citing Lai et al. 2011 for SVT on motion capture; §4.2.3 Fig. 4.11).
It completes the frames × (3·markers) matrix by approximately minimising the nuclear norm subject to agreeing
with the observed entries; it needs no training data.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from mocapkit.refinement.base import MotionRefiner


def shrink(Y: torch.Tensor, tau: float) -> tuple[torch.Tensor, int]:
    """The singular value shrinkage operator ``D_τ(Y) = U diag((σ_i − τ)_+) Vᵀ`` (Cai, Candès & Shen 2010, §2.1,
    the proximal operator of ``τ‖·‖_*``). Returns the shrunk matrix and its rank."""
    U, s, Vh = torch.linalg.svd(Y, full_matrices=False)
    s = (s - tau).clamp_min(0.0)
    rank = int((s > 0).sum())
    return (U[:, :rank] * s[:rank]) @ Vh[:rank], rank


def svt_complete(
    M: np.ndarray,
    observed: np.ndarray,
    tau: float | None = None,
    delta: float | None = None,
    tol: float = 1e-4,
    max_iter: int = 500,
    device: str = "cpu",
) -> tuple[np.ndarray, dict]:
    """Complete ``M`` (float64 ``[n1, n2]``; values where ``observed`` is False are ignored) by SVT.

    The iteration of Cai, Candès & Shen 2010 (§3, "shrinkage iterations"; parameters of §5.1):

    - ``X^k = D_τ(Y^{k−1})``  and  ``Y^k = Y^{k−1} + δ P_Ω(M − X^k)``;
    - ``τ = 5·sqrt(n1·n2)`` (the paper's ``τ = 5n`` for n × n matrices), ``δ = 1.2 / p`` with ``p = m / (n1·n2)``
      the observed fraction (the paper's recommended step, beyond the ``0 < δ < 2`` of its convergence proof);
    - "kicking": ``Y^0 = k0·δ·P_Ω(M)`` with ``k0 = ⌈τ / (δ‖P_Ω(M)‖_2)⌉`` so that the first iterate is not 0;
    - stop when the relative residual on the observed entries ``‖P_Ω(X^k − M)‖_F / ‖P_Ω(M)‖_F ≤ tol``
      (the paper: 1e-4) or after ``max_iter`` iterations.

    Linear algebra in torch float64 on ``device``.

    Returns:
        ``(X, info)``: the completed float64 ``[n1, n2]`` matrix and ``{"iterations", "residual", "rank",
        "converged", "tau", "delta"}``.
    """
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError(f"SVT: device {device!r} asked for but CUDA is not available")
    dev = torch.device(device)
    n1, n2 = M.shape
    mask = torch.as_tensor(np.asarray(observed, bool), device=dev)
    m = int(mask.sum())
    if m == 0:
        raise ValueError("SVT needs at least one observed entry")
    PM = torch.where(
        mask,
        torch.as_tensor(np.where(observed, M, 0.0), dtype=torch.float64, device=dev),
        torch.zeros((), dtype=torch.float64, device=dev),
    )
    p = m / (n1 * n2)
    tau = 5.0 * math.sqrt(n1 * n2) if tau is None else float(tau)
    delta = 1.2 / p if delta is None else float(delta)
    norm_PM = torch.linalg.norm(PM)
    if norm_PM == 0:
        return np.zeros((n1, n2)), {
            "iterations": 0,
            "residual": 0.0,
            "rank": 0,
            "converged": True,
            "tau": tau,
            "delta": delta,
        }
    k0 = math.ceil(tau / (delta * float(torch.linalg.matrix_norm(PM, ord=2))))
    Y = k0 * delta * PM  # kicking
    X, rank, residual, iterations = torch.zeros_like(PM), 0, float("inf"), 0
    for iterations in range(1, max_iter + 1):
        X, rank = shrink(Y, tau)  # X^k = D_τ(Y^{k−1})
        R = torch.where(mask, PM - X, torch.zeros((), dtype=torch.float64, device=dev))  # P_Ω(M − X^k)
        residual = float(torch.linalg.norm(R) / norm_PM)
        if residual <= tol:  # relative residual on Ω
            break
        Y = Y + delta * R  # Y^k = Y^{k−1} + δ P_Ω(M − X^k)
    return X.cpu().numpy(), {
        "iterations": iterations,
        "residual": residual,
        "rank": rank,
        "converged": residual <= tol,
        "tau": tau,
        "delta": delta,
    }


class SVTCompletion(MotionRefiner):
    """SVT matrix completion of the frames × (3·markers) matrix (Cai, Candès & Shen 2010); see :func:`svt_complete`.

    Preprocessing (not part of the paper, stated): each coordinate column is centred by the mean of its observed
    entries and the matrix is divided by the RMS of the centred observed entries, so that the paper's
    scale-free parameter rules (``τ = 5·sqrt(n1·n2)``, ``δ = 1.2/p``) apply to data in metres; the completion is
    mapped back afterwards. Columns of a marker missing in every frame, and frames with no observed entry, are
    left missing (nothing constrains them; the base class reports them). Observed entries are returned unchanged.

    Args:
        tau: the threshold τ (on the normalised matrix); ``None`` = ``5·sqrt(frames · 3·markers)``.
        delta: the step δ; ``None`` = ``1.2 / p``.
        tol: stopping tolerance on the relative residual over the observed entries (paper: 1e-4).
        max_iter: most iterations.
        center: centre and scale the columns as above (``False``: raw metres, the paper's parameters as is).
        device: ``"cpu"`` or ``"cuda"``.

    After :meth:`refine`, ``info_`` holds the last run's iterations, residual, rank and convergence.
    """

    min_frames = 2

    def __init__(
        self,
        tau: float | None = None,
        delta: float | None = None,
        tol: float = 1e-4,
        max_iter: int = 500,
        center: bool = True,
        device: str = "cpu",
    ):
        self.tau = tau
        self.delta = delta
        self.tol = tol
        self.max_iter = max_iter
        self.center = center
        self.device = device

    def refine(self, motion):
        """See :meth:`MotionRefiner.refine`; also records the solver's ``info_`` in
        ``metadata["refinement"]["solver"]`` (iterations, residual, rank, converged, τ, δ)."""
        out = super().refine(motion)
        out.metadata["refinement"]["solver"] = dict(self.info_)
        return out

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray):
        out = np.where(observed, X, np.nan)
        rows, cols = observed.any(axis=1), observed.any(axis=0)
        if observed[rows][:, cols].all():
            self.info_ = {
                "iterations": 0,
                "residual": 0.0,
                "rank": None,
                "converged": True,
                "tau": self.tau,
                "delta": self.delta,
            }
            return out, None
        M, O = X[rows][:, cols], observed[rows][:, cols]
        if self.center:
            mean = np.where(O, M, 0.0).sum(0) / O.sum(0)
            scale = float(np.sqrt((np.where(O, M - mean, 0.0) ** 2).sum() / O.sum())) or 1.0
        else:
            mean, scale = np.zeros(M.shape[1]), 1.0
        completed, self.info_ = svt_complete(
            (M - mean) / scale, O, self.tau, self.delta, self.tol, self.max_iter, self.device
        )
        block = np.full(out.shape, np.nan)
        block[np.ix_(rows, cols)] = completed * scale + mean
        return np.where(observed, X, block), None
