"""Classical NMF solvers in torch with a scikit-learn interface: NMF, OrthogonalNMF, GNMF and NMC (thesis §6.3).

Orientation (scikit-learn's, **samples as rows**)::

    X [n_samples, n_features]  ≈  W [n_samples, k]  @  H [k, n_features]
    W = the codes ("transformed data", one row per sample), H = components_ (one basis / cluster centre per row)

The thesis (and most NMF papers) write ``X_thesis [d, n] ≈ Z G`` with samples as columns, so
``X = X_thesisᵀ``, ``W = Gᵀ`` (soft cluster indicators) and ``H = Zᵀ`` (cluster centres).

All solvers are multiplicative updates (MU) on ``device`` in ``dtype`` (float64 by default), with ``eps`` as a floor
on every denominator (``max(denominator, eps)``, which equals scikit-learn's "replace exact zeros" for every
denominator ≥ eps). The objective is evaluated after every iteration (kept in ``objective_``); fitting stops when
its relative change ``|f_{t−1} − f_t| / f_{t−1}`` drops below ``tol`` (``tol=0``: exactly ``max_iter`` iterations).
A non-finite objective raises ``FloatingPointError`` naming the iteration — no NaN is ever returned.

Objectives (``objective_``; note: **no** ½ factor, unlike scikit-learn's internal ½‖·‖²):

* :class:`NMF` Frobenius: ``‖X − WH‖²_F``;  KL: ``Σ X log(X / WH) − X + WH`` (generalised KL).
* :class:`OrthogonalNMF`: ``‖X − WH‖²_F`` with ``H Hᵀ = I`` (Ding et al. 2006).
* :class:`GNMF`: ``‖X − WH‖²_F + λ tr(Wᵀ L W)`` (Cai et al. 2011), ``L = D − S`` over the samples.
* :class:`NMC`: ``‖X − WH‖²_F + λ₁‖W‖²_F + λ₂ tr(Wᵀ L W)`` s.t. ``H Hᵀ = I`` (thesis (6.3), corrected updates).

``reconstruction_err_`` follows scikit-learn: ``‖X − WH‖_F`` for Frobenius; ``sqrt(2 · KL)`` for KL (what
``sklearn.decomposition.NMF`` reports for ``beta_loss="kullback-leibler"``).

Parity: from the same ``W0, H0`` with ``tol=0``, :class:`NMF` reproduces
``sklearn.decomposition.NMF(solver="mu", init="custom", tol=0)`` (same update order: W then H per iteration; same
KL safeguards): W and H agree to ~5e-15 relative after 300 iterations in float64 for Frobenius and KL (tests assert
1e-9). ``init="random"`` draws the same matrices as scikit-learn for the same integer ``random_state``.

Orthogonality: Ding's update keeps the components *near* orthonormal, not exactly: on clusters that own distinct
features ``max|H Hᵀ − I| ≈ 1e-2`` after a default fit (tests assert < 0.02); on clusters with overlapping dense
centres the off-diagonal of the row-normalised Gram plateaus at ~0.15–0.4 (plain NMF: ~0.7).
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
import torch
from sklearn.base import BaseEstimator

from mocapkit.clustering.graphs import (
    check_graph,
    combine_graphs,
    knn_graph,
    label_graph,
    sparse_graph,
)

#: scikit-learn's floor on ``WH`` inside the KL updates and divergence (``np.finfo(np.float32).eps``).
KL_WH_FLOOR = float(np.finfo(np.float32).eps)
#: scikit-learn zeroes H entries below this after every KL H-update (``np.finfo(np.float64).eps``).
KL_H_ZERO = float(np.finfo(np.float64).eps)
#: Added to the one-hot k-means codes so that MU can move every entry (a zero stays zero under MU).
KMEANS_CODE_OFFSET = 0.2


# --------------------------------------------------------------------------- input handling


def _check_nonnegative_matrix(A, name: str) -> np.ndarray | torch.Tensor:
    """Reject non-2-D, empty, NaN, inf and negative inputs with the offending row and column."""
    if sp.issparse(A):
        A = A.toarray()
    if not isinstance(A, torch.Tensor):
        A = np.asarray(A, dtype=np.float64)
    if A.ndim != 2 or A.shape[0] == 0 or A.shape[1] == 0:
        raise ValueError(f"{name} must be a non-empty 2-D array, got shape {tuple(A.shape)}")
    a = A.detach().cpu().numpy() if isinstance(A, torch.Tensor) else A
    for test, what in ((np.isnan, "NaN"), (np.isinf, "infinite")):
        bad = test(a)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(f"{name} has {what} entries ({int(bad.sum())} in total): first at row {i}, column {j}")
    if a.min() < 0:
        i, j = np.unravel_index(int(np.argmin(a)), a.shape)
        raise ValueError(
            f"{name} has negative entries: min {a[i, j]:.4g} at row {i}, column {j} "
            f"(NMF needs non-negative data; shift or split it into positive/negative parts)"
        )
    return A


def _resolve_device(device) -> torch.device:
    if device is None:
        return torch.device("cpu")
    device = torch.device(device)
    if device.type == "cuda" and not torch.cuda.is_available():
        warnings.warn("device='cuda' requested but CUDA is not available; running on CPU", RuntimeWarning, stacklevel=3)
        return torch.device("cpu")
    return device


# --------------------------------------------------------------------------- NMF


class NMF(BaseEstimator):
    """Non-negative matrix factorisation ``X [n, d] ≈ W [n, k] H [k, d]`` by multiplicative updates (Lee & Seung).

    Args:
        n_components: ``k``, the number of components (clusters).
        beta_loss: ``"frobenius"`` (``‖X − WH‖²``) or ``"kullback-leibler"`` (generalised KL divergence).
        init: ``"random"`` (scikit-learn's: ``|N(0,1)| · sqrt(mean(X) / k)``, H drawn before W, so the same
            ``random_state`` gives scikit-learn's random init), ``"nndsvda"`` (Boutsidis & Gallopoulos with zeros
            filled by ``mean(X)``; needs ``k ≤ min(n, d)``; exact SVD where scikit-learn uses a randomised one) or
            ``"kmeans"`` (scikit-learn ``KMeans(n_init=10)`` on the rows: ``W = one-hot + 0.2``,
            ``H = centroids``; a centroid entry that is exactly 0 stays 0 under MU, as in any MU init).
        max_iter: maximum number of iterations (one iteration = one update of each factor).
        tol: stop when the relative change of the objective between iterations is below ``tol``.
        random_state: seed of the random / k-means initialisation.
        eps: floor on every MU denominator.
        device: torch device to compute on (``"cuda"`` falls back to CPU with a warning when unavailable).
        dtype: torch dtype of the computation (float64 default: MU needs it for tight convergence).
        verbose: print the objective every 10 iterations.

    Attributes (after ``fit``):
        components_: ``np.ndarray [k, n_features]``, the H factor.
        labels_: ``np.ndarray [n_samples]``, ``argmax`` of each row of the fitted W.
        n_iter_: iterations run.
        objective_: ``list[float]``, the objective after every iteration (``initial_objective_`` before the first).
        reconstruction_err_: ``‖X − WH‖_F`` (Frobenius) or ``sqrt(2 · KL)`` (KL), as scikit-learn reports it.
    """

    #: losses this class can minimise (subclasses: Frobenius only)
    _supported_losses = ("frobenius", "kullback-leibler")

    def __init__(
        self,
        n_components: int,
        *,
        beta_loss: str = "frobenius",
        init: str = "random",
        max_iter: int = 200,
        tol: float = 1e-4,
        random_state: int | None = None,
        eps: float = 1e-10,
        device=None,
        dtype: torch.dtype = torch.float64,
        verbose: bool = False,
    ):
        self.n_components = n_components
        self.beta_loss = beta_loss
        self.init = init
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.eps = eps
        self.device = device
        self.dtype = dtype
        self.verbose = verbose

    # ------------------------------------------------------------------ public API

    def fit(self, X, y=None, W=None, H=None):
        """Fit ``W`` and ``H`` to ``X [n_samples, n_features]``; ``W``/``H`` (both or neither) = custom init."""
        self._fit(X, y, W, H)
        return self

    def fit_transform(self, X, y=None, W=None, H=None):
        """Fit and return the codes ``W [n_samples, k]`` (numpy for numpy input, torch for torch input)."""
        W_fit = self._fit(X, y, W, H)
        return self._as_output(W_fit, X)

    def transform(self, X):
        """Codes ``W [n_samples, k]`` of new data with ``components_`` fixed, by the same W-updates as ``fit``.

        ``W`` starts at ``sqrt(mean(X) / k)`` everywhere (scikit-learn's ``solver="mu"`` choice). Graph terms of
        :class:`GNMF` / :class:`NMC` are not applied: their graph is over the training samples only.
        """
        self._check_fitted()
        X_in = X
        X = self._to_tensor(_check_nonnegative_matrix(X, "X"))
        if X.shape[1] != self.components_.shape[1]:
            raise ValueError(f"X has {X.shape[1]} features but the model was fitted with {self.components_.shape[1]}")
        H = torch.as_tensor(self.components_, dtype=self.dtype, device=self._device)
        W = torch.full(
            (X.shape[0], H.shape[0]),
            float(np.sqrt(X.mean().item() / H.shape[0])),
            dtype=self.dtype,
            device=self._device,
        )
        W = self._solve_codes(X, W, H)
        return self._as_output(W, X_in)

    def predict(self, X=None) -> np.ndarray:
        """Cluster labels ``[n_samples]`` = argmax of each row of ``W`` (of the fitted data when ``X`` is None)."""
        self._check_fitted()
        if X is None:
            return self.labels_
        W = self.transform(X)
        W = W.detach().cpu().numpy() if isinstance(W, torch.Tensor) else W
        return np.argmax(W, axis=1)

    # ------------------------------------------------------------------ the fitting loop

    def _fit(self, X, y, W, H) -> torch.Tensor:
        self._check_params()
        self._device = _resolve_device(self.device)
        X = self._to_tensor(_check_nonnegative_matrix(X, "X"))
        n, d = X.shape
        k = int(self.n_components)
        self._x_sq_norm = float(torch.sum(X * X))  # ‖X‖², for objectives from cached products
        if (W is None) != (H is None):
            raise ValueError("pass both W and H for a custom initialisation (or neither)")
        if W is not None:
            W = self._to_tensor(_check_nonnegative_matrix(W, "W")).clone()
            H = self._to_tensor(_check_nonnegative_matrix(H, "H")).clone()
            if tuple(W.shape) != (n, k):
                raise ValueError(
                    f"initial W must have shape [n_samples, n_components] = [{n}, {k}], got {list(W.shape)}"
                )
            if tuple(H.shape) != (k, d):
                raise ValueError(
                    f"initial H must have shape [n_components, n_features] = [{k}, {d}], got {list(H.shape)}"
                )
        else:
            W, H = self._initialise(X)
        self._prepare(X, y)
        W, H = self._start(X, W, H)
        self.initial_objective_ = self._objective(X, W, H)
        self._check_finite(self.initial_objective_, 0)
        self.objective_ = []
        previous = self.initial_objective_
        n_iter = 0
        for n_iter in range(1, int(self.max_iter) + 1):
            W, H, value = self._iterate(X, W, H)
            self._check_finite(value, n_iter)
            self.objective_.append(value)
            if self.verbose and n_iter % 10 == 0:
                print(f"{type(self).__name__} iteration {n_iter}: objective {value:.6g}")
            if self.tol > 0 and abs(previous - value) <= self.tol * max(abs(previous), 1e-300):
                break
            previous = value
        W, H = self._finish(X, W, H)
        if not (torch.isfinite(W).all() and torch.isfinite(H).all()):
            raise FloatingPointError(f"{type(self).__name__} produced non-finite factors after iteration {n_iter}")
        self.n_iter_ = n_iter
        self.components_ = H.detach().cpu().numpy()
        self.labels_ = torch.argmax(W, dim=1).cpu().numpy()
        self.reconstruction_err_ = self._reconstruction_error(X, W, H)
        self.n_features_in_ = d
        return W

    def _check_params(self) -> None:
        if not isinstance(self.n_components, (int, np.integer)) or self.n_components < 1:
            raise ValueError(f"n_components must be an integer >= 1, got {self.n_components!r}")
        if self.beta_loss not in self._supported_losses:
            raise ValueError(
                f"{type(self).__name__} beta_loss must be one of {self._supported_losses}, got {self.beta_loss!r}"
            )
        if self.init not in ("random", "nndsvda", "kmeans"):
            raise ValueError(f"init must be 'random', 'nndsvda' or 'kmeans', got {self.init!r}")
        if self.max_iter < 1 or self.tol < 0 or not self.eps > 0:
            raise ValueError(
                f"need max_iter >= 1, tol >= 0, eps > 0; got max_iter={self.max_iter}, tol={self.tol}, eps={self.eps}"
            )

    def _check_finite(self, value: float, iteration: int) -> None:
        if not np.isfinite(value):
            raise FloatingPointError(
                f"{type(self).__name__} diverged at iteration {iteration}: objective is {value} "
                f"(check the data scale, eps and the regularisation weights)"
            )

    def _check_fitted(self) -> None:
        if not hasattr(self, "components_"):
            raise RuntimeError(f"this {type(self).__name__} is not fitted yet; call fit first")

    def _to_tensor(self, A) -> torch.Tensor:
        return torch.as_tensor(A).to(device=self._device, dtype=self.dtype)

    @staticmethod
    def _as_output(W: torch.Tensor, like):
        if isinstance(like, torch.Tensor):
            return W.to(like.device)
        return W.detach().cpu().numpy()

    # ------------------------------------------------------------------ initialisation

    def _initialise(self, X: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(W [n, k], H [k, d])`` from ``init``."""
        n, d = X.shape
        k = int(self.n_components)
        Xn = X.detach().cpu().numpy()
        if self.init == "random":
            avg = np.sqrt(Xn.mean() / k)
            rng = np.random.RandomState(self.random_state)
            H = np.abs(avg * rng.standard_normal(size=(k, d)))
            W = np.abs(avg * rng.standard_normal(size=(n, k)))
        elif self.init == "nndsvda":
            if k > min(n, d):
                raise ValueError(
                    f"init='nndsvda' needs n_components <= min(n_samples, n_features) = {min(n, d)}, "
                    f"got n_components={k}; use init='random' for a larger rank"
                )
            W, H = _nndsvda(Xn, k)
        else:
            if k > n:
                raise ValueError(f"init='kmeans' needs n_components <= n_samples = {n}, got {k}")
            from sklearn.cluster import KMeans

            km = KMeans(n_clusters=k, n_init=10, random_state=self.random_state).fit(Xn)
            W = np.eye(k)[km.labels_] + KMEANS_CODE_OFFSET
            H = np.maximum(km.cluster_centers_, 0.0)
        return self._to_tensor(W), self._to_tensor(H)

    # ------------------------------------------------------------------ hooks the variants override

    def _prepare(self, X: torch.Tensor, y) -> None:
        """Build whatever the updates need besides ``X`` (the graph of GNMF / NMC)."""

    def _start(self, X, W, H):
        """Adjust the initial factors (NMC normalises the rows of H)."""
        return W, H

    def _finish(self, X, W, H):
        """Post-process the converged factors (GNMF normalises the rows of H)."""
        return W, H

    def _iterate(self, X: torch.Tensor, W: torch.Tensor, H: torch.Tensor):
        """One MU iteration (W, then H, as scikit-learn) → ``(W, H, objective)``."""
        eps = self.eps
        if self.beta_loss == "frobenius":
            W = W * (X @ H.T) / torch.clamp(W @ (H @ H.T), min=eps)
            WtX, WtW = W.T @ X, W.T @ W
            H = H * WtX / torch.clamp(WtW @ H, min=eps)
            return W, H, self._frobenius_from_products(X, H, WtX, WtW)
        # generalised KL, with scikit-learn's safeguards (WH floor, W column sums of 0 → 1, tiny H → 0)
        ratio = X / torch.clamp(W @ H, min=KL_WH_FLOOR)
        W = W * (ratio @ H.T) / torch.clamp(H.sum(dim=1)[None, :], min=eps)
        ratio = X / torch.clamp(W @ H, min=KL_WH_FLOOR)
        W_sum = W.sum(dim=0)
        W_sum = torch.where(W_sum == 0, torch.ones_like(W_sum), W_sum)
        H = H * (W.T @ ratio) / torch.clamp(W_sum[:, None], min=eps)
        H = torch.where(H < KL_H_ZERO, torch.zeros_like(H), H)
        return W, H, self._objective(X, W, H)

    def _solve_codes(self, X: torch.Tensor, W: torch.Tensor, H: torch.Tensor) -> torch.Tensor:
        """W-updates only (``transform``), until the relative objective change is below ``tol`` or ``max_iter``."""
        previous = self._objective(X, W, H, with_graph=False)
        XHt, HHt = X @ H.T, H @ H.T
        for _ in range(int(self.max_iter)):
            W = self._codes_step(X, W, H, XHt, HHt)
            value = self._objective(X, W, H, with_graph=False)
            if not np.isfinite(value):
                raise FloatingPointError(f"{type(self).__name__}.transform diverged: objective is {value}")
            if self.tol > 0 and abs(previous - value) <= self.tol * max(abs(previous), 1e-300):
                break
            previous = value
        return W

    def _codes_step(self, X, W, H, XHt, HHt) -> torch.Tensor:
        """One W-update with H fixed (no graph)."""
        if self.beta_loss == "frobenius":
            return W * XHt / torch.clamp(W @ HHt, min=self.eps)
        ratio = X / torch.clamp(W @ H, min=KL_WH_FLOOR)
        return W * (ratio @ H.T) / torch.clamp(H.sum(dim=1)[None, :], min=self.eps)

    # ------------------------------------------------------------------ objectives

    def _objective(self, X, W, H, with_graph: bool = True) -> float:
        """The objective this class minimises (see the module docstring) as a Python float."""
        if self.beta_loss == "frobenius":
            return float(torch.sum((X - W @ H) ** 2))
        return _generalised_kl(X, W @ H)

    def _frobenius_from_products(self, X, H, WtX, WtW) -> float:
        """``‖X − WH‖² = ‖X‖² − 2⟨WᵀX, H⟩ + ⟨WᵀW, HHᵀ⟩`` from the products the H-update already computed."""
        value = self._x_sq_norm - 2.0 * float(torch.sum(WtX * H)) + float(torch.sum(WtW * (H @ H.T)))
        return max(value, 0.0)

    def _reconstruction_error(self, X, W, H) -> float:
        if self.beta_loss == "frobenius":
            return float(torch.linalg.norm(X - W @ H))
        return float(np.sqrt(2.0 * max(_generalised_kl(X, W @ H), 0.0)))


def _generalised_kl(X: torch.Tensor, WH: torch.Tensor) -> float:
    """``Σ X log(X / WH) − X + WH`` computed as scikit-learn does (terms with ``X ≤ float32 eps`` contribute
    only ``WH``; ``WH`` floored at float32 eps)."""
    mask = X > KL_WH_FLOOR
    x = X[mask]
    wh = torch.clamp(WH[mask], min=KL_WH_FLOOR)
    return float(torch.sum(x * torch.log(x / wh)) + WH.sum() - x.sum())


def _nndsvda(X: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """NNDSVD (Boutsidis & Gallopoulos 2008) with zeros filled by ``mean(X)`` — scikit-learn's ``"nndsvda"``
    with an exact truncated SVD. Returns ``W [n, k]``, ``H [k, d]``."""
    U, S, Vt = np.linalg.svd(X, full_matrices=False)
    U, S, Vt = U[:, :k], S[:k], Vt[:k]
    W, H = np.zeros_like(U), np.zeros_like(Vt)
    W[:, 0] = np.sqrt(S[0]) * np.abs(U[:, 0])
    H[0] = np.sqrt(S[0]) * np.abs(Vt[0])
    for j in range(1, k):
        x, y = U[:, j], Vt[j]
        xp, yp, xn, yn = np.maximum(x, 0), np.maximum(y, 0), np.maximum(-x, 0), np.maximum(-y, 0)
        mp = np.linalg.norm(xp) * np.linalg.norm(yp)
        mn = np.linalg.norm(xn) * np.linalg.norm(yn)
        u, v, sigma = (xp, yp, mp) if mp > mn else (xn, yn, mn)
        nu, nv = np.linalg.norm(u), np.linalg.norm(v)
        if nu == 0 or nv == 0:
            continue
        lam = np.sqrt(S[j] * sigma)
        W[:, j] = lam * u / nu
        H[j] = lam * v / nv
    W[W < 1e-6] = 0
    H[H < 1e-6] = 0
    W[W == 0] = X.mean()
    H[H == 0] = X.mean()
    return W, H


# --------------------------------------------------------------------------- orthogonal NMF


class OrthogonalNMF(NMF):
    """Orthogonal NMF (Ding, Li, Peng & Park 2006): ``min ‖X − WH‖²`` s.t. ``W, H ≥ 0``, ``H Hᵀ = I``.

    **Which factor is orthogonal.** The components: ``H Hᵀ = I_k`` is the thesis's ``Zᵀ Z = I_k`` with ``Z = Hᵀ``
    (eq. (6.3) keeps only this constraint and relaxes the one on the indicators ``G = Wᵀ`` "because X is not
    normalised": unnormalised samples cannot have orthonormal indicator rows, while bases can always be unit
    length). Non-negative orthonormal rows have disjoint supports, so every feature belongs to one component.

    **Updates** (per iteration, W then H like :class:`NMF`): the Lee–Seung step
    ``W ← W ∘ (X Hᵀ) / (W H Hᵀ)`` and Ding's orthogonal step, the thesis's Z-step (6.9) transposed,

        ``H ← H ∘ sqrt( (Wᵀ X) / (Wᵀ X Hᵀ H) )``

    (from (6.9) ``Z ← Z ∘ sqrt((X Gᵀ) / (Z Zᵀ X Gᵀ))`` with ``Z = Hᵀ``, ``G = Wᵀ``, ``X_thesis = Xᵀ``; the
    ``Wᵀ W`` of plain NMF is replaced by ``Wᵀ X Hᵀ`` through the Lagrange multiplier of ``H Hᵀ = I``).
    The objective is **not** guaranteed to decrease at every iteration (the H-step is a fixed-point iteration of
    the KKT conditions, not a majorise–minimise step); in practice it decreases overall — see the tests.
    """

    _supported_losses = ("frobenius",)

    def __init__(
        self,
        n_components: int,
        *,
        init: str = "random",
        max_iter: int = 200,
        tol: float = 1e-4,
        random_state: int | None = None,
        eps: float = 1e-10,
        device=None,
        dtype: torch.dtype = torch.float64,
        verbose: bool = False,
    ):
        super().__init__(
            n_components,
            beta_loss="frobenius",
            init=init,
            max_iter=max_iter,
            tol=tol,
            random_state=random_state,
            eps=eps,
            device=device,
            dtype=dtype,
            verbose=verbose,
        )

    def _iterate(self, X, W, H):
        eps = self.eps
        W = W * (X @ H.T) / torch.clamp(W @ (H @ H.T), min=eps)
        WtX, WtW = W.T @ X, W.T @ W
        H = H * torch.sqrt(WtX / torch.clamp((WtX @ H.T) @ H, min=eps))
        return W, H, self._frobenius_from_products(X, H, WtX, WtW)

    def _finish(self, X, W, H):
        """Scale the rows of H to unit ℓ2 norm, W's columns by the norms: ``WH`` and the objective unchanged,
        ``diag(H Hᵀ) = 1`` exactly (Ding's update alone leaves the row norms free)."""
        norms = torch.clamp(torch.linalg.norm(H, dim=1), min=self.eps)
        return W * norms[None, :], H / norms[:, None]


# --------------------------------------------------------------------------- graph-regularised variants


class _GraphRegularised(NMF):
    """Shared graph handling of :class:`GNMF` and :class:`NMC`: the affinity ``S`` and degrees ``D`` as torch."""

    def fit(self, X, y=None, W=None, H=None, graph=None):
        """Fit; ``graph`` (an ``[n, n]`` affinity, dense or scipy sparse) overrides the ``graph`` parameter."""
        self._graph_override = graph
        try:
            return super().fit(X, y, W, H)
        finally:
            self._graph_override = None

    def fit_transform(self, X, y=None, W=None, H=None, graph=None):
        """Fit and return the codes ``W [n_samples, k]``; ``graph`` overrides the ``graph`` parameter."""
        self._graph_override = graph
        try:
            return super().fit_transform(X, y, W, H)
        finally:
            self._graph_override = None

    def _build_affinity(self, X: torch.Tensor, y) -> sp.csr_matrix:
        graph = getattr(self, "_graph_override", None)
        graph = self.graph if graph is None else graph
        n = X.shape[0]
        if isinstance(graph, str):
            Xn = X.detach().cpu().numpy()
            if graph == "knn":
                S = knn_graph(Xn, self.n_neighbors, weight="binary")
            elif graph == "heat":
                S = knn_graph(Xn, self.n_neighbors, weight="heat")
            elif graph == "sparse":
                S = sparse_graph(Xn)
            elif graph == "label":
                if y is None:
                    raise ValueError("graph='label' needs the labels y in fit (y[i] = -1 for unlabelled samples)")
                S = combine_graphs(
                    knn_graph(Xn, self.n_neighbors, weight="binary"), label_graph(y, n), self.label_weight
                )
            else:
                raise ValueError(f"graph must be 'knn', 'heat', 'sparse', 'label' or an [n, n] affinity, got {graph!r}")
        else:
            S = graph
        return check_graph(S, n_samples=n)

    def _prepare(self, X, y) -> None:
        S = self._build_affinity(X, y).tocoo()
        self.affinity_ = S.tocsr()
        indices = torch.as_tensor(np.vstack([S.row, S.col]), dtype=torch.int64)
        values = torch.as_tensor(S.data, dtype=self.dtype)
        self._S = torch.sparse_coo_tensor(
            indices, values, S.shape, device=self._device, check_invariants=True
        ).coalesce()
        self._degree = torch.as_tensor(np.asarray(S.sum(axis=1)).ravel(), dtype=self.dtype, device=self._device)

    def _graph_term(self, W: torch.Tensor, SW: torch.Tensor | None = None) -> float:
        """``tr(Wᵀ L W) = Σ_i D_ii ‖w_i‖² − ⟨W, S W⟩``."""
        SW = torch.sparse.mm(self._S, W) if SW is None else SW
        return float(torch.sum(self._degree[:, None] * W * W) - torch.sum(W * SW))


class GNMF(_GraphRegularised):
    """Graph-regularised NMF (Cai, He, Han & Huang 2011): ``min ‖X − WH‖² + lam · tr(Wᵀ L W)``, ``L = D − S``.

    ``S [n, n]`` is an affinity between the samples (rows of X). Cai's ``U`` is our ``Hᵀ`` and ``V`` our ``W``;
    per iteration (W then H):

        ``W ← W ∘ (X Hᵀ + lam S W) / (W H Hᵀ + lam D W)``,   ``H ← H ∘ (Wᵀ X) / (Wᵀ W H)``

    Both steps are majorise–minimise steps, so the objective is non-increasing. After convergence the rows of H
    are scaled to unit ℓ2 norm and the columns of W multiplied by the norms (Cai et al.; ``WH`` unchanged, the
    graph term changes, so ``objective_`` is recorded before this normalisation).

    Args (besides :class:`NMF`'s, Frobenius only):
        lam: graph weight ``λ``.
        graph: ``"knn"`` (0/1 weights), ``"heat"`` (heat kernel, σ = mean neighbour distance), ``"sparse"``
            (:func:`~mocapkit.clustering.graphs.sparse_graph`), ``"label"`` (kNN + label graph from ``y``), or a
            precomputed ``[n, n]`` affinity (numpy / torch / scipy sparse). ``fit(..., graph=S)`` overrides it.
        n_neighbors: ``p`` of the kNN graph.
        label_weight: weight of the label graph for ``graph="label"``.
    """

    _supported_losses = ("frobenius",)

    def __init__(
        self,
        n_components: int,
        *,
        lam: float = 1.0,
        graph="knn",
        n_neighbors: int = 5,
        label_weight: float = 1.0,
        init: str = "random",
        max_iter: int = 200,
        tol: float = 1e-4,
        random_state: int | None = None,
        eps: float = 1e-10,
        device=None,
        dtype: torch.dtype = torch.float64,
        verbose: bool = False,
    ):
        super().__init__(
            n_components,
            beta_loss="frobenius",
            init=init,
            max_iter=max_iter,
            tol=tol,
            random_state=random_state,
            eps=eps,
            device=device,
            dtype=dtype,
            verbose=verbose,
        )
        self.lam = lam
        self.graph = graph
        self.n_neighbors = n_neighbors
        self.label_weight = label_weight

    def _check_params(self) -> None:
        super()._check_params()
        if self.lam < 0:
            raise ValueError(f"GNMF lam must be >= 0, got {self.lam}")

    def _iterate(self, X, W, H):
        eps, lam = self.eps, float(self.lam)
        SW = torch.sparse.mm(self._S, W)
        W = W * (X @ H.T + lam * SW) / torch.clamp(W @ (H @ H.T) + lam * self._degree[:, None] * W, min=eps)
        WtX, WtW = W.T @ X, W.T @ W
        H = H * WtX / torch.clamp(WtW @ H, min=eps)
        value = self._frobenius_from_products(X, H, WtX, WtW) + lam * self._graph_term(W)
        return W, H, value

    def _objective(self, X, W, H, with_graph: bool = True) -> float:
        value = float(torch.sum((X - W @ H) ** 2))
        return value + float(self.lam) * self._graph_term(W) if with_graph else value

    def _finish(self, X, W, H):
        norms = torch.clamp(torch.linalg.norm(H, dim=1), min=self.eps)
        return W * norms[None, :], H / norms[:, None]


class NMC(_GraphRegularised):
    """The thesis's NMF-based motion clustering (Algorithm 6, §6.3) with corrected updates (below).

    ``min ‖X − WH‖² + lambda1 ‖W‖² + lambda2 tr(Wᵀ L W)``  s.t. ``W, H ≥ 0``, ``H Hᵀ = I``  (thesis (6.3) with
    ``W = Gᵀ``, ``H = Zᵀ``; ``L = D − S`` over the samples). Per iteration, in the thesis's order:

    1. **H-step** (Z-step (6.9), Ding's orthogonal update): ``H ← H ∘ sqrt((Wᵀ X) / (Wᵀ X Hᵀ H))``, then each row
       of H scaled to unit ℓ2 norm ("normalise Z"), the columns of W multiplied by the same norms so that ``WH``
       is unchanged (the spec's optional compensation).
    2. **W-step** (the corrected split-Laplacian G-update, transposed):
       ``W ← W ∘ [(X Hᵀ + lambda2 S W) / (W H Hᵀ + lambda1 W + lambda2 D W)]^eta``. ``S`` plays ``L⁻`` and ``D``
       ``L⁺`` of ``L = L⁺ − L⁻`` (see :func:`~mocapkit.clustering.graphs.split_laplacian`). For ``eta`` in (0, 1]
       this step never increases the objective (MM step of Cai et al.; ``eta = ½`` is Ding's damped form).

    The H-step is not a descent step, so the objective may rise at an iteration (mostly in the first iterations,
    while H moves from the non-orthogonal k-means centroids towards orthogonality). ``objective_h_step_[t]`` holds
    the objective after the H-step of iteration ``t`` (before its W-step), so ``objective_[t] <=
    objective_h_step_[t]`` checks the W-step's descent.
    Labels = argmax of each row of W (the thesis's ``argmax_c G_{c, clip}``).

    Args (besides :class:`NMF`'s, Frobenius only; ``init`` defaults to ``"kmeans"`` as in the thesis):
        lambda1: weight of ``‖W‖²``.
        lambda2: weight of the graph term.
        graph, n_neighbors, label_weight: as :class:`GNMF` (``"label"`` uses ``y`` passed to ``fit``,
            ``-1`` = unlabelled; ``y`` is ignored by every other graph).
        eta: exponent of the W-update, 0.5 (default) or 1.
    """

    _supported_losses = ("frobenius",)

    def __init__(
        self,
        n_components: int,
        *,
        lambda1: float = 1e-3,
        lambda2: float = 1.0,
        graph="knn",
        n_neighbors: int = 5,
        label_weight: float = 1.0,
        eta: float = 0.5,
        init: str = "kmeans",
        max_iter: int = 200,
        tol: float = 1e-4,
        random_state: int | None = None,
        eps: float = 1e-10,
        device=None,
        dtype: torch.dtype = torch.float64,
        verbose: bool = False,
    ):
        super().__init__(
            n_components,
            beta_loss="frobenius",
            init=init,
            max_iter=max_iter,
            tol=tol,
            random_state=random_state,
            eps=eps,
            device=device,
            dtype=dtype,
            verbose=verbose,
        )
        self.lambda1 = lambda1
        self.lambda2 = lambda2
        self.graph = graph
        self.n_neighbors = n_neighbors
        self.label_weight = label_weight
        self.eta = eta

    def _check_params(self) -> None:
        super()._check_params()
        if self.lambda1 < 0 or self.lambda2 < 0:
            raise ValueError(f"NMC lambda1 and lambda2 must be >= 0, got {self.lambda1}, {self.lambda2}")
        if not 0 < self.eta <= 1:
            raise ValueError(f"NMC eta must be in (0, 1] (0.5 or 1), got {self.eta}")

    def _normalise_rows(self, W, H):
        norms = torch.clamp(torch.linalg.norm(H, dim=1), min=self.eps)
        return W * norms[None, :], H / norms[:, None]

    def _start(self, X, W, H):
        self.objective_h_step_ = []  # objective after each H-step (before the W-step)
        return self._normalise_rows(W, H)

    def _iterate(self, X, W, H):
        eps, l1, l2, eta = self.eps, float(self.lambda1), float(self.lambda2), float(self.eta)
        WtX = W.T @ X
        H = H * torch.sqrt(WtX / torch.clamp((WtX @ H.T) @ H, min=eps))
        W, H = self._normalise_rows(W, H)
        XHt, HHt = X @ H.T, H @ H.T
        SW = torch.sparse.mm(self._S, W)
        self.objective_h_step_.append(self._objective_from_products(W, XHt, HHt, SW))
        ratio = (XHt + l2 * SW) / torch.clamp(W @ HHt + l1 * W + l2 * self._degree[:, None] * W, min=eps)
        W = W * (ratio if eta == 1.0 else ratio**eta)
        return W, H, self._objective_from_products(W, XHt, HHt)

    def _objective_from_products(self, W, XHt, HHt, SW=None) -> float:
        """The NMC objective from ``X Hᵀ`` and ``H Hᵀ`` (``‖X − WH‖² = ‖X‖² − 2⟨W, XHᵀ⟩ + ⟨WᵀW, HHᵀ⟩``)."""
        fit = self._x_sq_norm - 2.0 * float(torch.sum(W * XHt)) + float(torch.sum((W.T @ W) * HHt))
        return (
            max(fit, 0.0)
            + float(self.lambda1) * float(torch.sum(W * W))
            + float(self.lambda2) * self._graph_term(W, SW)
        )

    def _objective(self, X, W, H, with_graph: bool = True) -> float:
        value = float(torch.sum((X - W @ H) ** 2)) + float(self.lambda1) * float(torch.sum(W * W))
        return value + float(self.lambda2) * self._graph_term(W) if with_graph else value

    def _codes_step(self, X, W, H, XHt, HHt) -> torch.Tensor:
        ratio = XHt / torch.clamp(W @ HHt + float(self.lambda1) * W, min=self.eps)
        return W * (ratio if self.eta == 1.0 else ratio ** float(self.eta))
