"""LRMF: low-rank motion refinement by bilinear factorisation, sparse noise and temporal smoothness (Wang 2017,
§4.1 "Model A"; Hu et al. 2017b), solved by the augmented Lagrangian method (ALM, Lin et al. 2010).

Orientation. The thesis writes a motion as ``X ∈ R^{d×n}`` (one column per frame, ``d = 3·joints``) and then
solves the *transposed* problem (its eq. 4.5–4.6) on ``Xᵀ ∈ R^{n×d}``. That transposed matrix is exactly the
frames × (3·joints) matrix of :func:`mocapkit.refinement.base.motion_matrix`, so every array below is
``[frames, features]`` and the thesis's ``Xᵀ, U ∈ R^{n×k}, V ∈ R^{d×k}, E, M, Y1, Y2 ∈ R^{n×d}`` appear
untransposed. ``observed`` (``Ω`` of §4.1, 1 = observed) is a bool array of the same shape.

Model (eq. 4.3, in the factorised, transposed form 4.6–4.7)::

    min ½(‖U‖²_F + ‖V‖²_F) + α‖Ω∘E‖₁ + (β/2)‖O M‖²_F   s.t.  X = U Vᵀ + E,  M = U Vᵀ

with ``O`` the ``n×n`` second-difference operator of eq. 4.22 (first row ``[−1 1]``, last row ``[1 −1]``).
Missing entries (``Ω = 0``) carry no ℓ1 cost, so ``E`` absorbs ``X − UVᵀ`` there and the low-rank, smooth
``UVᵀ`` fills them; on observed entries ``E`` is the sparse noise/outlier estimate.

The ALM updates are the thesis's Algorithm 2 with its printed equations corrected (each correction is marked
``[fix]`` in the code):

* (4.10) ``V ← Zᵀ U [I + (λ1+λ2) UᵀU]⁻¹`` (the thesis prints ``Z_v U``; ``V`` is ``d×k``);
* (4.11)/(4.12) the E-step uses **element-wise** soft-thresholding (the thesis defines ``S_τ`` as the
  nuclear-norm prox);
* (4.14) ``Y1 ← Y1 + λ1(M − UVᵀ)``, ``Y2 ← Y2 + λ2(Xᵀ − UVᵀ − E)`` (the thesis swaps the residuals);
* Algorithm 2's multiplier start ``Xᵀ / max(‖Xᵀ‖_F², ‖Xᵀ‖_∞)`` is replaced by IALM's scale-consistent
  ``Xᵀ / max(‖Xᵀ‖₂, ‖Xᵀ‖_∞/α)``;
* ``O`` ends with ``[1 −1]`` (eq. 4.22, not 4.2), which makes the M-step (4.13) diagonal in the DCT-II basis;
  it is solved with the DCT of §4.2 (eq. 4.25), ``O(n log n)`` per column instead of an ``n×n`` inverse.

Stopping rule (the thesis gives none for Algorithm 2; this is the ϑ rule of its §4.2.3, extended to both
constraints)::

    ϑ = max{ ‖Xᵀ − UVᵀ − E‖_F / ‖Xᵀ‖_F,  ‖M − UVᵀ‖_F / ‖Xᵀ‖_F,  ‖UVᵀ − U₋V₋ᵀ‖_F / ‖UVᵀ‖_F } < tol.

Rank (§4.1.2): "last significant jump" (LSJ, after Wang & Yin 2010) on the singular values of the linearly
interpolated data, then the factor width ``κ = min(round(1.1 r), 3J, n)`` (eq. 4.15); see :func:`estimate_rank`.

Units. Parameters ``α, β`` (and TrNN's ``λ, μ``) are not scale-free: ``‖·‖_*`` and ``‖·‖₁`` grow linearly with
the data, ``‖OM‖²`` quadratically. The thesis tuned them on CMU data in CMU length units
(1 unit = 1/0.45 inch = 0.056444 m). The refiners therefore divide the metre matrix by
``unit`` (default 0.056444) before solving and multiply the result back, so that the thesis's values apply
as printed; ``unit=1`` solves in metres. (On HDM05 clips with 10 markers × 60-frame gaps, TrNN in metres with
the thesis's values had about twice the RMSE it has in CMU units: 9.6 against 5.0 cm, mean of 10 cases.)

Outliers. The refiners flag an observed joint as an outlier, and replace it by the low-rank estimate, when the
Euclidean norm of its sparse component (``E`` here, ``S`` in TrNN) exceeds ``outlier_threshold`` (default
0.03 m). Measured on HDM05 clips: the sparse component of clean observed joints stays under ~1 cm (99th
percentile; a few isolated joints reach 3–8 cm on fast motions), joints with σ = 2 cm noise per coordinate have
a median of ~3 cm, and 10–30 cm single-frame spikes are all above 10 cm. At 3 cm about half of the noisy joints
and essentially none of the clean ones (0–12 per clip) are flagged, and a flagged noisy joint's error drops from
~3 cm to ~0.2–0.5 cm. Every other observed entry comes back bit-identical; ``outlier_threshold=None`` flags
nothing.

This module also holds the pieces LRMF shares with :mod:`mocapkit.refinement.trnn`: the orthonormal DCT-II
(:func:`dct`, :func:`idct`: scipy on the CPU, a torch FFT on other devices), the smoothness solve
(:func:`smooth_solve`), gap interpolation and the rank estimate.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import torch

from mocapkit.motion.container import all_coordinates
from mocapkit.refinement.base import MotionRefiner, RefinementError
from mocapkit.refinement.gap_filling import linear_fill

#: Length of the CMU ASF/AMC unit in metres: the unit the thesis's parameters were tuned in.
CMU_UNIT = 0.056444


# ----------------------------------------------------------------------------- shared numerical pieces


def resolve_device(device) -> torch.device:
    """``"cpu"`` / ``"cuda"`` / a torch device; ``"cuda"`` without CUDA falls back to CPU with a warning."""
    device = torch.device("cpu" if device is None else device)
    if device.type == "cuda" and not torch.cuda.is_available():
        warnings.warn("device='cuda' requested but CUDA is not available; running on CPU", RuntimeWarning, stacklevel=3)
        return torch.device("cpu")
    return device


def resolve_dtype(dtype) -> torch.dtype:
    """A torch floating dtype from a torch dtype or its name (``"float64"``, ``"float32"``)."""
    if isinstance(dtype, str):
        dtype = getattr(torch, dtype, None)
    if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
        raise ValueError(f"dtype must be a torch floating dtype or its name, got {dtype!r}")
    return dtype


def second_difference(n: int) -> np.ndarray:
    """The ``n×n`` second-difference matrix ``O`` of Wang 2017 eq. 4.22 (rows ``[−1 1 …]``, ``[1 −2 1 …]``, …,
    ``[… 1 −1]``; needs ``n ≥ 2``). Its eigenvectors are the DCT-II basis, eigenvalues ``2cos(πk/n) − 2``."""
    if n < 2:
        raise ValueError(f"the second-difference operator needs n >= 2, got {n}")
    O = np.diag(np.full(n, -2.0)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1)
    O[0, 0] = O[-1, -1] = -1.0
    return O


def apply_second_difference(M: torch.Tensor) -> torch.Tensor:
    """``O M`` for ``M [n, …]`` (``O`` of eq. 4.22 acting along the first, time, axis) without forming ``O``."""
    out = torch.empty_like(M)
    out[1:-1] = M[:-2] - 2 * M[1:-1] + M[2:]
    out[0] = M[1] - M[0]
    out[-1] = M[-2] - M[-1]
    return out


def _dct_fft(x: torch.Tensor) -> torch.Tensor:
    """Orthonormal DCT-II along the first axis of ``x [n, …]`` by one length-``n`` FFT (Makhoul 1980)."""
    n = x.shape[0]
    v = torch.cat([x[0::2], x[1::2].flip(0)], 0)
    V = torch.fft.fft(v, dim=0)
    k = torch.arange(n, device=x.device, dtype=x.dtype)
    w = torch.polar(torch.ones_like(k), -math.pi * k / (2 * n)).reshape((n,) + (1,) * (x.dim() - 1))
    y = 2 * (V * w).real
    scale = torch.full((n,), math.sqrt(1 / (2 * n)), device=x.device, dtype=x.dtype)
    scale[0] = math.sqrt(1 / (4 * n))
    return y * scale.reshape(w.shape)


def _idct_fft(y: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`_dct_fft` along the first axis."""
    n = y.shape[0]
    shape = (n,) + (1,) * (y.dim() - 1)
    scale = torch.full((n,), math.sqrt(1 / (2 * n)), device=y.device, dtype=y.dtype)
    scale[0] = math.sqrt(1 / (4 * n))
    c = y / scale.reshape(shape)  # unnormalised DCT-II coefficients c_k = 2 Re(w_k V_k)
    c_rev = torch.cat([torch.zeros_like(c[:1]), c[1:].flip(0)], 0)  # c_{n−k}, with c_n = 0
    k = torch.arange(n, device=y.device, dtype=y.dtype)
    w_conj = torch.polar(torch.ones_like(k), math.pi * k / (2 * n)).reshape(shape)
    V = w_conj * torch.complex(c, -c_rev) / 2  # w_k V_k = (c_k − i c_{n−k}) / 2
    v = torch.fft.ifft(V, dim=0).real
    x = torch.empty_like(v)
    half = (n + 1) // 2
    x[0::2] = v[:half]
    x[1::2] = v[half:].flip(0)
    return x


def dct(x: torch.Tensor, dim: int = 0) -> torch.Tensor:
    """Orthonormal DCT-II of ``x`` along ``dim`` (``scipy.fft.dct(x, axis=dim, norm="ortho")``).

    On the CPU it is scipy's (pocketfft, the faster one for lengths with large prime factors); on other devices
    a torch FFT implementation (:func:`_dct_fft`). Same dtype and device as ``x``."""
    if x.device.type == "cpu":
        return torch.from_numpy(scipy.fft.dct(x.numpy(), axis=dim, norm="ortho"))
    return _dct_fft(x.movedim(dim, 0)).movedim(0, dim)


def idct(y: torch.Tensor, dim: int = 0) -> torch.Tensor:
    """Inverse of :func:`dct` along ``dim`` (``scipy.fft.idct(y, axis=dim, norm="ortho")``)."""
    if y.device.type == "cpu":
        return torch.from_numpy(scipy.fft.idct(y.numpy(), axis=dim, norm="ortho"))
    return _idct_fft(y.movedim(dim, 0)).movedim(0, dim)


def smoothness_gains(n: int, eta: float, mu: float, device=None, dtype=torch.float64) -> torch.Tensor:
    """``Γ_ii = 1 / (η + μ ξ_i²)``, ``ξ_i = −2 + 2cos((i−1)π/n)``, ``i = 1 … n`` (Wang 2017 eq. 4.25 with ``η``
    in place of the printed ``Y1``), as a float ``[n]`` vector."""
    xi = 2 * torch.cos(math.pi * torch.arange(n, device=device, dtype=dtype) / n) - 2
    return 1.0 / (eta + mu * xi**2)


def smooth_solve(T: torch.Tensor, eta: float, mu: float, dim: int = 0) -> torch.Tensor:
    """``(η I_n + μ O²)⁻¹`` applied along the time axis ``dim`` of ``T`` (``n`` frames there), by
    ``IDCT(Γ · DCT(T))`` (eq. 4.25): ``O = Φ Λ Φᵀ`` with ``Φ`` the orthonormal DCT-II basis."""
    n = T.shape[dim]
    gains = smoothness_gains(n, eta, mu, T.device, T.dtype)
    shape = [1] * T.dim()
    shape[dim] = n
    return idct(gains.reshape(shape) * dct(T, dim), dim)


def soft(x: torch.Tensor, tau: float) -> torch.Tensor:
    """Element-wise soft thresholding ``sign(x) max(|x| − τ, 0) = x − clamp(x, −τ, τ)``."""
    return x - x.clamp(-tau, tau)


def lsj_rank(singular_values: np.ndarray, threshold: float = 0.1, rule: str = "absolute") -> int:
    """Rank by the "last significant jump" of decreasing ``singular_values`` (Wang 2017 §4.1.2 and §4.2.3).

    Rules (the thesis is ambiguous: §4.1.2 writes ``|λ_k0 − λ_k0+1| > ε·m`` with ``m`` undefined, §4.2.3 "the
    largest index where the jump is beyond a threshold" but also "the largest jump"):

    * ``"absolute"``: the largest ``i`` (1-based) with ``σ_i − σ_{i+1} ≥ threshold``, on the singular values as
      given: the literal formula of §4.2.3, ``argmax{i : |σ_i − σ_{i+1}| ≥ 0.1}``, which is meaningful in the
      thesis's (CMU) units. Default. Singular values grow like √frames, so so does this rank: 11–20 on
      HDM05 clips of 76–721 frames, all 93 coordinates beyond ~2,000 frames of CMU motion.
    * ``"normalised"``: the same on ``σ / σ₁`` (as the thesis's Fig. 4.5 plots them). On real motion the mean pose makes
      ``σ₁`` dominate, so this gives ranks of 1–2 (see the module docstring of :mod:`mocapkit.refinement.trnn`).
    * ``"largest"``: the index of the largest gap ``argmax_i (σ_i − σ_{i+1})``.

    ``σ_{k+1} = 0`` past the last value, so a full-rank spectrum can return ``k``. At least 1.
    """
    s = np.sort(np.asarray(singular_values, dtype=np.float64))[::-1]
    if s.size == 0 or s[0] <= 0:
        return 1
    if rule == "normalised":
        s = s / s[0]
    elif rule not in ("absolute", "largest"):
        raise ValueError(f"rule={rule!r}: expected 'absolute', 'normalised' or 'largest'")
    gaps = s - np.append(s[1:], 0.0)
    if rule == "largest":
        return int(np.argmax(gaps)) + 1
    big = np.flatnonzero(gaps >= threshold)
    return int(big[-1]) + 1 if big.size else 1


def estimate_rank(X: np.ndarray, observed: np.ndarray, threshold: float = 0.1, rule: str = "absolute") -> int:
    """LSJ rank of ``X [frames, features]`` (same units as ``threshold``) after linear interpolation of its gaps
    (Wang 2017 §4.1.2 steps 1–3); see :func:`lsj_rank` for ``rule``."""
    filled = linear_fill(X, observed, empty=0.0)
    return lsj_rank(np.linalg.svd(filled, compute_uv=False), threshold, rule)


@dataclass
class LowRankResult:
    """What :func:`lrmf` and :func:`mocapkit.refinement.trnn.trnn` return.

    Attributes:
        low_rank: float64 ``[frames, features]``, the recovered low-rank matrix (``UVᵀ`` / ``(LRᵀ)ᵀ``), same units
            as the input.
        sparse: float64 ``[frames, features]``, the sparse component on observed entries (``E`` / ``Sᵀ``), 0 on
            unobserved ones.
        n_iter: iterations run.
        converged: whether ``ϑ < tol`` was reached within ``max_iter``.
        width: factor width used (``κ`` / ``d``).
        history: one dict per iteration: ``theta`` (ϑ), ``residual`` (relative norm of the constraint residuals),
            ``objective`` (the model's objective at the current iterate) and ``penalty`` (λ1 / η).
    """

    low_rank: np.ndarray
    sparse: np.ndarray
    n_iter: int
    converged: bool
    width: int
    history: list[dict] = field(default_factory=list)


def _solve_right(A: torch.Tensor, G: torch.Tensor) -> torch.Tensor:
    """``A G⁻¹`` for a small symmetric positive-definite ``G``."""
    return torch.linalg.solve(G, A.mT).mT


# ----------------------------------------------------------------------------- the solver


def ialm_multipliers(D: torch.Tensor, weight: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The two Lagrange multipliers' start of the inexact ALM (Lin, Chen & Ma 2010), used by both thesis models:
    ``Y1 = Y2 = D / max(‖D‖₂, ‖D‖_∞ / weight)`` (Algorithm 2 line 1 with α, Algorithm 3 line 1 with λ)."""
    scale = max(float(torch.linalg.matrix_norm(D, ord=2)), float(D.abs().max()) / weight)
    Y1 = D / scale
    return Y1, Y1.clone()


def lrmf(
    X: np.ndarray,
    observed: np.ndarray,
    width: int,
    alpha: float = 1.0,
    beta: float = 100.0,
    lambda1: float = 1e-5,
    lambda2: float = 1e-5,
    gamma: float = 1.4,
    lambda_max: float = 1e10,
    max_iter: int = 500,
    tol: float = 1e-4,
    random_state: int | None = 0,
    device="cpu",
    dtype=torch.float64,
) -> LowRankResult:
    """Algorithm 2 of Wang 2017 (corrected, see the module docstring) on ``X`` (the thesis's ``Xᵀ``).

    Args:
        X: float ``[frames n, features d]``; values at unobserved entries are ignored.
        observed: bool ``[n, d]``, True where observed (``Ω``).
        width: factor width ``κ`` (``U: n×κ``, ``V: d×κ``), an upper bound on the rank.
        alpha, beta: weights of ``‖Ω∘E‖₁`` and ``(1/2)‖OM‖²`` (eq. 4.6).
        lambda1, lambda2, gamma, lambda_max: initial penalties, their growth factor and cap (Algorithm 2 line 8).
        max_iter, tol: iteration cap and ϑ threshold.
        random_state: seed of ``V⁰ = rand(d, κ)``.

    Returns:
        :class:`LowRankResult` with ``low_rank = UVᵀ`` and ``sparse = Ω∘E``.
    """
    device, dtype = resolve_device(device), resolve_dtype(dtype)
    n, d = X.shape
    if n < 2:
        raise ValueError(f"LRMF needs at least 2 frames, got {n}")
    width = int(width)
    if not 1 <= width <= min(n, d):
        raise ValueError(f"factor width must be in [1, min(frames, features) = {min(n, d)}], got {width}")
    Om = torch.as_tensor(np.asarray(observed, bool), device=device)
    Xt = torch.as_tensor(np.where(observed, X, 0.0), device=device, dtype=dtype)
    norm_X = float(torch.linalg.matrix_norm(Xt))
    if norm_X == 0:
        raise ValueError("LRMF: every observed entry is 0, nothing to factorise")
    # Algorithm 2 line 1: Y1 = Y2 = Xᵀ / max(‖Xᵀ‖₂, ‖Xᵀ‖_∞/α)   [fix: IALM's scaling, not max(‖Xᵀ‖²_F, ‖Xᵀ‖_∞)]
    Y1, Y2 = ialm_multipliers(Xt, alpha)
    gen = torch.Generator().manual_seed(0 if random_state is None else int(random_state))
    V = torch.rand(d, width, generator=gen, dtype=torch.float64).to(device=device, dtype=dtype)
    V = V / torch.linalg.matrix_norm(V)  # V⁰ = rand(d, κ) / ‖·‖_F
    E = torch.zeros_like(Xt)
    M = torch.zeros_like(Xt)
    eye = torch.eye(width, device=device, dtype=dtype)
    xi2 = (2 * torch.cos(math.pi * torch.arange(n, device=device, dtype=dtype) / n) - 2) ** 2  # eigenvalues² of O
    l1, l2 = float(lambda1), float(lambda2)
    UV_prev = torch.zeros_like(Xt)
    history: list[dict] = []
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        Z = (Y1 + Y2).add_(M, alpha=l1).add_(Xt, alpha=l2).sub_(E, alpha=l2)  # Z_u = Z_v = Y1+Y2+λ1M+λ2(Xᵀ−E), n×d
        U = _solve_right(Z @ V, eye + (l1 + l2) * (V.mT @ V))  # (4.9)
        V = _solve_right(Z.mT @ U, eye + (l1 + l2) * (U.mT @ U))  # (4.10) [fix: Zᵀ U, not Z_v U]
        del Z
        UV = U @ V.mT
        Ze = (Xt - UV).add_(Y2, alpha=1 / l2)  # Z_e of (4.11)
        E = torch.where(Om, soft(Ze, alpha / l2), Ze)  # (4.11) [fix: element-wise S_τ]
        del Ze
        # (4.13) M = (λ1 I + β O²)⁻¹ (λ1 UVᵀ − Y1), diagonal in the DCT-II basis along time (the trick of 4.25)
        C = dct((UV * l1).sub_(Y1), dim=0).mul_((1.0 / (l1 + beta * xi2)).unsqueeze(1))
        M = idct(C, dim=0)
        R1 = M - UV
        R2 = (Xt - UV).sub_(E)
        Y1.add_(R1, alpha=l1)  # (4.14) [fix: Y1 ↔ M − UVᵀ]
        Y2.add_(R2, alpha=l2)  # (4.14) [fix: Y2 ↔ Xᵀ − UVᵀ − E]
        norm_UV = float(torch.linalg.matrix_norm(UV))
        r1 = float(torch.linalg.matrix_norm(R1)) / norm_X
        r2 = float(torch.linalg.matrix_norm(R2)) / norm_X
        change = float(torch.linalg.matrix_norm(UV_prev.sub_(UV))) / max(norm_UV, 1e-300)
        theta = max(r1, r2, change)
        # objective of (4.7); ‖OM‖²_F = Σ_i ξ_i² ‖DCT coefficient row i of M‖² (Parseval)
        objective = (
            0.5 * float(U.square().sum() + V.square().sum())
            + alpha * float(torch.where(Om, E, 0.0).abs_().sum())
            + 0.5 * beta * float((C.square().sum(1) * xi2).sum())
        )
        history.append({"theta": theta, "residual": max(r1, r2), "objective": objective, "penalty": l1})
        if not math.isfinite(theta):
            raise FloatingPointError(f"LRMF diverged at iteration {it} (non-finite residual)")
        UV_prev = UV
        l1, l2 = min(gamma * l1, lambda_max), min(gamma * l2, lambda_max)  # Algorithm 2 line 8
        if theta < tol:
            converged = True
            break
    sparse = torch.where(Om, E, torch.zeros_like(E))
    return LowRankResult(
        UV.cpu().numpy().astype(np.float64), sparse.cpu().numpy().astype(np.float64), it, converged, width, history
    )


# ----------------------------------------------------------------------------- shared refiner plumbing


def flag_outliers(sparse: np.ndarray, observed: np.ndarray, threshold: float | None) -> np.ndarray | None:
    """Joints to repair: observed entries whose per-joint sparse component ``‖(s_x, s_y, s_z)‖₂`` exceeds
    ``threshold`` (metres). ``sparse, observed [frames, 3·joints]`` → bool ``[frames, joints]``; None when
    ``threshold`` is None."""
    if threshold is None:
        return None
    frames, features = sparse.shape
    size = np.sqrt((np.where(observed, sparse, 0.0) ** 2).reshape(frames, features // 3, 3).sum(axis=2))
    return (size > threshold) & all_coordinates(observed.reshape(frames, features // 3, 3))


def drop_empty_columns(X: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Columns (coordinates) with at least one observed entry; the others cannot be filled by a low-rank model."""
    keep = observed.any(axis=0)
    if not keep.any():
        raise RefinementError("no observed entry at all, nothing to refine from")
    return keep


class LRMF(MotionRefiner):
    """Low-rank + sparse + smooth motion refinement by bilinear factorisation (Wang 2017 §4.1, Algorithm 2).

    A robust method: it fills every missing entry of a marker observed somewhere in the sequence, and it
    replaces an observed joint (all three coordinates) when the Euclidean norm of its sparse component
    ``E`` exceeds ``outlier_threshold`` metres (listed in ``repaired``); other observed entries come back
    bit-identical. A marker missing in every frame stays missing (``unfilled``).

    Args:
        alpha: weight of ``‖Ω∘E‖₁`` (thesis 1.0).
        beta: weight of the smoothness term ``(β/2)‖OM‖²`` (thesis 100).
        lambda1, lambda2: initial ALM penalties (thesis 1e-5 each).
        gamma: penalty growth per iteration (thesis 1.4).
        lambda_max: penalty cap (thesis 1e10).
        rank: ``"auto"`` (LSJ estimate ``r`` of §4.1.2, then ``κ = min(round(rank_inflation·r), 3J, n)``, eq. 4.15)
            or the factor width ``κ`` as an int.
        rank_threshold, rank_rule: LSJ threshold and rule (:func:`lsj_rank`), applied in ``unit``s.
        rank_inflation: the 1.1 of eq. 4.15.
        outlier_threshold: metres; None never flags (observed entries always kept).
        unit: metres per solver unit; the matrix is divided by it before solving (see the module docstring).
        max_iter, tol: ALM iteration cap and ϑ threshold.
        random_state: seed of the ``V`` initialisation.
        device, dtype: torch device (``"cpu"``, ``"cuda"``) and dtype of the computation.

    Attributes (after :meth:`refine`): ``rank_`` (estimated ``r``), ``width_`` (``κ``), ``n_iter_``,
    ``converged_``, ``history_`` (see :class:`LowRankResult`).
    """

    min_frames = 3

    def __init__(
        self,
        alpha: float = 1.0,
        beta: float = 100.0,
        lambda1: float = 1e-5,
        lambda2: float = 1e-5,
        gamma: float = 1.4,
        lambda_max: float = 1e10,
        rank: int | str = "auto",
        rank_threshold: float = 0.1,
        rank_rule: str = "absolute",
        rank_inflation: float = 1.1,
        outlier_threshold: float | None = 0.03,
        unit: float = CMU_UNIT,
        max_iter: int = 500,
        tol: float = 1e-4,
        random_state: int | None = 0,
        device="cpu",
        dtype=torch.float64,
    ):
        self.alpha = alpha
        self.beta = beta
        self.lambda1 = lambda1
        self.lambda2 = lambda2
        self.gamma = gamma
        self.lambda_max = lambda_max
        self.rank = rank
        self.rank_threshold = rank_threshold
        self.rank_rule = rank_rule
        self.rank_inflation = rank_inflation
        self.outlier_threshold = outlier_threshold
        self.unit = unit
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.device = device
        self.dtype = dtype

    def _width(self, X: np.ndarray, observed: np.ndarray) -> int:
        n, d = X.shape
        if self.rank == "auto":
            r = estimate_rank(X, observed, self.rank_threshold, self.rank_rule)
            self.rank_ = r
            return max(1, min(round(self.rank_inflation * r), d, n))  # (4.15)
        if not isinstance(self.rank, (int, np.integer)) or self.rank < 1:
            raise ValueError(f"rank must be 'auto' or a positive int, got {self.rank!r}")
        self.rank_ = int(self.rank)
        return min(int(self.rank), d, n)

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Fill ``X`` (float64 ``[frames, 3·joints]`` metres, 0 where not ``observed``); see the class docstring."""
        n = X.shape[0]
        if n < self.min_frames:
            raise RefinementError(f"LRMF needs at least {self.min_frames} frames (second differences in time), got {n}")
        if not self.unit > 0:
            raise ValueError(f"unit must be positive (metres per solver unit), got {self.unit!r}")
        keep = drop_empty_columns(X, observed)
        Xs, obs = X[:, keep] / self.unit, observed[:, keep]
        width = self._width(Xs, obs)
        result = lrmf(
            Xs,
            obs,
            width,
            self.alpha,
            self.beta,
            self.lambda1,
            self.lambda2,
            self.gamma,
            self.lambda_max,
            self.max_iter,
            self.tol,
            self.random_state,
            self.device,
            self.dtype,
        )
        self.width_, self.n_iter_, self.converged_, self.history_ = (
            width,
            result.n_iter,
            result.converged,
            result.history,
        )
        filled = np.full(X.shape, np.nan)
        filled[:, keep] = result.low_rank * self.unit
        sparse = np.zeros(X.shape)
        sparse[:, keep] = result.sparse * self.unit
        return filled, flag_outliers(sparse, observed, self.outlier_threshold)
