"""Unsupervised feature selection over several feature views: AMFS (Wang 2017, ch. 5) and its baselines, the
Laplacian Score, SPEC and UDFS.

Every estimator here takes **views**: a list of arrays ``[N, d_v]`` (samples in rows, one array per feature type; a
single 2-D array is one view), stack them into ``X [N, D]``, ``D = Σ d_v``, z-score every feature (fitted, kept in
``mean_`` / ``scale_``; ``standardize=False`` keeps the raw values) and select ``n_features`` columns of the stacked
features: ``selected_`` (int64 indices into the stacked features, best first), ``view_slices_`` (the columns of
each view), ``transform(views) -> [N, n_features]``.

**AMFS**, adaptive multi-view feature selection (``../shared/spec/thesis-wang-2017-mocap-processing.md`` §4,
with the sort-order fix of §8 item 29). In the spec's column notation (``X ∈ R^{D×N}``):

* per view ``v``, the local-regression Laplacian (5.2–5.17): the ``k`` nearest neighbours of each sample in the
  view (Euclidean, on the standardised view features, the sample itself included), ``K_i = X_iᵀX_i`` (k×k),
  ``L_i = μ H (H K_i H + μ I)⁻¹`` (the push-through form of ``H − H X_iᵀ(X_i H X_iᵀ + μI)⁻¹ X_i H``, so only k×k
  inverses), ``L^(v) = Σ_i S_i L_i S_iᵀ`` (never formed: only ``diag(X L^(v) Xᵀ)`` is needed, as
  ``Σ_i Σ_pq (L_i)_pq x_{i_p} ∘ x_{i_q}``);
* ``A = X (Σ_v α_v^r L^(v)) Xᵀ``, ``B = X H_X Xᵀ`` (``H_X = I − 11ᵀ/N``), objective (5.22)
  ``tr(WᵀAW) / tr(WᵀBW)`` over selections ``W`` and weights ``α`` on the simplex;
* **Algorithm 4** (W given α; the trace-ratio method): ``λ = tr(WᵀAW)/tr(WᵀBW)``, scores
  ``A_ii − λ B_ii``, keep the ``n_features`` **smallest** (``order="ascending"``, the fix: the ratio then never
  increases; ``"descending"`` is the thesis as printed, for comparison), until the selection stops changing;
* **Algorithm 5** (α given W, 5.24): ``f_v = tr(Wᵀ X L^(v) Xᵀ W)^{−1/(r−1)}``, ``α_v = f_v / Σ_u f_u`` (the exact
  minimiser of the numerator over the simplex, so the ratio never increases in this step either);
* start from ``α_v = 1/M`` and a random selection; alternate until the selection stops changing or ``max_iter``.

Features that are constant on the training data (``B_ii = 0``) are never selected (unless nothing else is left).
With ``standardize=True`` every other ``B_ii`` equals ``N``, so the W step keeps the features of smallest
``A_ii``: the trace ratio then only decides how the views are weighted.

**LaplacianScore** (He, Cai & Niyogi 2005): a heat-kernel ``k``-nearest-neighbour graph on the stacked
(standardised) features, ``S_ij = exp(−‖x_i − x_j‖² / t)`` for neighbours (either way), ``t`` = the mean squared
neighbour distance unless given, ``L = D − S``; the score of feature ``f`` is ``f̃ᵀ L f̃ / f̃ᵀ D f̃`` with
``f̃ = f − (fᵀD1 / 1ᵀD1) 1``; the ``n_features`` **smallest** scores are selected.

**SPEC**, spectral feature selection (Zhao & Liu 2007; one of AMFS's baselines in the thesis, spec §4), on the
same heat-kernel graph: with the normalised Laplacian ``𝓛 = D^{-1/2} (D − S) D^{-1/2}`` (eigenpairs
``λ_1 = 0 ≤ λ_2 ≤ …``, ``ξ_1 = D^{1/2}1 / ‖D^{1/2}1‖``) and ``f̂ = D^{1/2} f / ‖D^{1/2} f‖``, a feature scores
``φ1 = f̂ᵀ𝓛f̂`` (smaller is better), ``φ2 = f̂ᵀ𝓛f̂ / (1 − (f̂ᵀξ_1)²)`` (smaller is better) or
``φ3 = Σ_{j=2..c} (2 − λ_j)(f̂ᵀξ_j)²`` (larger is better; the default). ``φ2`` **is** the Laplacian Score on the
same graph (expand ``f̂`` and ``ξ_1``: both are ``fᵀLf / (fᵀDf − (fᵀD1)²/1ᵀD1)``; Zhao & Liu note it), so the
default is ``φ3``, the ranking SPEC adds: how much of a feature lies on the graph's ``c − 1`` smoothest
non-trivial eigenvectors.

**UDFS**, ℓ2,1-regularised discriminative feature selection (Yang et al. 2011; the thesis's other baseline):
``min tr(WᵀMW) + γ‖W‖_{2,1}`` s.t. ``WᵀW = I`` (``W`` ``[D, c]``), in rows-as-samples form
``M = Σ_i X_{N_i}ᵀ B_i X_{N_i}`` (``X_{N_i}`` the rows of sample ``i``'s neighbourhood), ``B_i = H (H K_i H + μI)⁻¹ H`` over each sample's ``k`` nearest neighbours (the
local-regression matrix of AMFS divided by ``μ``: :func:`local_regression_laplacians`), solved by the paper's
iteration: ``W`` = the ``c`` eigenvectors of ``M + γ diag(1 / 2‖w^i‖)`` of smallest eigenvalue, until the
selection stops changing; features ranked by ``‖w^i‖`` (largest first).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.exceptions import NotFittedError
from sklearn.neighbors import NearestNeighbors
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_array

ORDERS = ("ascending", "descending")


def _check_views(views, n_views: int | None = None, dims: Sequence[int] | None = None) -> list[np.ndarray]:
    """A list of float64 ``[N, d_v]`` arrays with one ``N`` (a single 2-D array is one view)."""
    if isinstance(views, np.ndarray) and views.ndim == 2:
        views = [views]
    views = [check_array(v, dtype=np.float64, ensure_min_samples=1) for v in views]
    if not views:
        raise ValueError("no views: pass a list of [N, d_v] arrays")
    if len({v.shape[0] for v in views}) != 1:
        raise ValueError(f"views disagree on the number of samples: {[v.shape[0] for v in views]}")
    if n_views is not None and len(views) != n_views:
        raise ValueError(f"fitted on {n_views} views, got {len(views)}")
    if dims is not None and [v.shape[1] for v in views] != list(dims):
        raise ValueError(f"fitted on views of widths {list(dims)}, got {[v.shape[1] for v in views]}")
    return views


class _ViewSelector(TransformerMixin, BaseEstimator):
    """Shared fit preamble (stack, standardise) and ``transform`` of the view feature selectors."""

    def _prepare(self, views) -> tuple[list[np.ndarray], np.ndarray]:
        views = _check_views(views)
        dims = [v.shape[1] for v in views]
        X = np.concatenate(views, axis=1)
        D = X.shape[1]
        if not 1 <= int(self.n_features) <= D:
            raise ValueError(f"n_features={self.n_features} must be in [1, {D}] (the stacked feature count)")
        stops = np.cumsum(dims)
        self.view_slices_ = [slice(int(a), int(b)) for a, b in zip(stops - dims, stops, strict=True)]
        self.n_features_in_ = D
        self.view_dims_ = np.array(dims, dtype=np.int64)
        if self.standardize:
            self.mean_ = X.mean(0)
            std = X.std(0)
            self.scale_ = np.where(std > 1e-12 * np.maximum(1.0, np.abs(self.mean_)), std, 1.0)
        else:
            self.mean_, self.scale_ = np.zeros(D), np.ones(D)
        Xs = (X - self.mean_) / self.scale_
        return [Xs[:, s] for s in self.view_slices_], Xs

    def transform(self, views) -> np.ndarray:
        """``[N, n_features]``: the selected (standardised) stacked features, best first."""
        if not hasattr(self, "selected_"):
            raise NotFittedError(f"{type(self).__name__} is not fitted: call fit(views) first")
        views = _check_views(views, len(self.view_slices_), self.view_dims_.tolist())
        X = np.concatenate(views, axis=1)
        return (X[:, self.selected_] - self.mean_[self.selected_]) / self.scale_[self.selected_]


def _knn(X: np.ndarray, k: int) -> np.ndarray:
    """int64 ``[N, k]``: the ``k`` nearest rows of each row of ``X`` (Euclidean), the row itself always included."""
    N = X.shape[0]
    nbrs = NearestNeighbors(n_neighbors=k).fit(X).kneighbors(X, return_distance=False).astype(np.int64)
    own = np.arange(N)
    has_self = (nbrs == own[:, None]).any(1)
    nbrs[~has_self, -1] = own[~has_self]  # exact duplicates can push a point out of its own list
    return nbrs


def local_regression_laplacians(X: np.ndarray, nbrs: np.ndarray, mu: float) -> np.ndarray:
    """``[N, k, k]``: ``L_i = μ H (H K_i H + μ I)⁻¹`` of each neighbourhood, ``K_i`` the Gram matrix of the rows
    ``X[nbrs[i]]`` (spec eq. 5.14 in its push-through form); symmetric, positive semi-definite, ``L_i 1 = 0``."""
    N, k = nbrs.shape
    H = np.eye(k) - 1.0 / k
    out = np.empty((N, k, k))
    chunk = max(1, int(2**24 // max(1, k * X.shape[1])))
    for a in range(0, N, chunk):
        Xn = X[nbrs[a : a + chunk]]  # [c, k, d]
        HX = Xn - Xn.mean(1, keepdims=True)  # H X_i (rows centred)
        M = HX @ HX.transpose(0, 2, 1) + mu * np.eye(k)  # H K H + μI
        L = mu * np.linalg.solve(M, np.broadcast_to(H, M.shape))  # μ M⁻¹ H = μ H M⁻¹ (they commute)
        out[a : a + chunk] = 0.5 * (L + L.transpose(0, 2, 1))
    return out


def laplacian_quadratic_diag(X: np.ndarray, nbrs: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``[D]``: ``diag(Xᵀ (Σ_i S_i L_i S_iᵀ) X)`` for rows-as-samples ``X [N, D]`` without forming N×N or D×D:
    ``Σ_i Σ_pq (L_i)_pq X[nbrs_ip] ∘ X[nbrs_iq]``."""
    N, k = nbrs.shape
    out = np.zeros(X.shape[1])
    chunk = max(1, int(2**24 // max(1, k * X.shape[1])))
    for a in range(0, N, chunk):
        G = X[nbrs[a : a + chunk]]  # [c, k, D]
        out += np.einsum("ckd,ckd->d", G, L[a : a + chunk] @ G)
    return out


class AMFS(_ViewSelector):
    """Adaptive multi-view feature selection (Wang 2017 ch. 5; the module docstring gives the algorithm).

    Args:
        n_features: number of stacked features to select (``d``).
        r: exponent of the view weights (``α_v^r``, ``r > 1``; large r → uniform weights).
        mu: ridge ``μ`` of the local regressions.
        n_neighbors: neighbourhood size ``k`` (the sample included), capped at ``N``.
        max_iter: most alternations of Algorithm 4 and Algorithm 5.
        order: ``"ascending"`` (select the smallest ``A_ii − λB_ii``: the corrected minimisation) or
            ``"descending"`` (the thesis as printed).
        standardize: z-score every stacked feature first (fitted).
        random_state: seed of the initial random selection.

    Fitted attributes: ``selected_`` int64 ``[n_features]`` (best first), ``alphas_`` ``[M]`` (on the simplex),
    ``objective_`` float64 (the ratio at the random start, then after every W update and every α update, in
    order: non-increasing for ``order="ascending"``), ``n_iter_`` (alternations), ``scores_`` ``[D]`` (the final
    ``A_ii − λB_ii``), ``view_diagonals_`` ``[M, D]`` (``diag(X L^(v) Xᵀ)``), ``b_`` ``[D]``
    (``diag(X H_X Xᵀ)``), ``view_slices_``, ``mean_``, ``scale_``.
    """

    max_inner_iter = 100

    def __init__(
        self,
        n_features: int,
        r: float = 4.0,
        mu: float = 0.1,
        n_neighbors: int = 10,
        max_iter: int = 20,
        order: str = "ascending",
        standardize: bool = True,
        random_state=0,
    ):
        self.n_features = n_features
        self.r = r
        self.mu = mu
        self.n_neighbors = n_neighbors
        self.max_iter = max_iter
        self.order = order
        self.standardize = standardize
        self.random_state = random_state

    def fit(self, views, y=None) -> AMFS:
        """Select features from ``views`` (list of ``[N, d_v]``); ``y`` is ignored (unsupervised)."""
        if self.order not in ORDERS:
            raise ValueError(f"order must be one of {ORDERS}, got {self.order!r}")
        if not float(self.r) > 1.0:
            raise ValueError(f"r must be > 1 (r = 1 puts all the weight on one view), got {self.r}")
        if not float(self.mu) > 0.0:
            raise ValueError(f"mu must be > 0, got {self.mu}")
        view_data, Xs = self._prepare(views)
        N, D = Xs.shape
        if N < 2:
            raise ValueError("AMFS needs at least 2 samples")
        k = int(min(max(int(self.n_neighbors), 2), N))
        diag = np.empty((len(view_data), D))
        for v, Xv in enumerate(view_data):
            nbrs = _knn(Xv, k)
            diag[v] = laplacian_quadratic_diag(Xs, nbrs, local_regression_laplacians(Xv, nbrs, float(self.mu)))
        b = ((Xs - Xs.mean(0)) ** 2).sum(0)
        usable = b > 1e-12 * max(1.0, b.max())
        if usable.sum() < int(self.n_features):
            usable[:] = True
        d, r, M = int(self.n_features), float(self.r), len(view_data)
        alphas = np.full(M, 1.0 / M)
        rng = check_random_state(self.random_state)
        candidates = np.flatnonzero(usable)
        selected = np.sort(rng.choice(candidates, d, replace=False))

        def ratio(sel, a):
            return float((a**r) @ diag[:, sel].sum(1) / max(b[sel].sum(), 1e-300))

        history = [ratio(selected, alphas)]

        scores = np.zeros(D)
        n_iter = 0
        for _ in range(int(self.max_iter)):
            n_iter += 1
            previous = selected
            A = (alphas**r) @ diag  # diag of A
            for _ in range(self.max_inner_iter):  # Algorithm 4
                lam = float(A[selected].sum() / max(b[selected].sum(), 1e-300))
                scores = A - lam * b
                if self.order == "ascending":
                    ranked = np.argsort(np.where(usable, scores, np.inf), kind="stable")
                else:
                    ranked = np.argsort(-np.where(usable, scores, -np.inf), kind="stable")
                new = ranked[:d]
                if np.array_equal(np.sort(new), np.sort(selected)):
                    selected = new
                    break
                selected = new
                history.append(ratio(selected, alphas))
            t = np.maximum(diag[:, selected].sum(1), 1e-300)  # Algorithm 5
            f = t ** (-1.0 / (r - 1.0))
            f = np.where(np.isfinite(f), f, np.finfo(float).max / (4 * M))
            alphas = f / f.sum()
            history.append(ratio(selected, alphas))
            if np.array_equal(np.sort(selected), np.sort(previous)):
                break
        self.selected_ = np.asarray(selected, dtype=np.int64)
        self.alphas_ = alphas
        self.objective_ = np.asarray(history, dtype=np.float64)
        self.n_iter_ = n_iter
        self.scores_ = scores
        self.view_diagonals_ = diag
        self.b_ = b
        return self


def heat_kernel_graph(X: np.ndarray, n_neighbors: int, t: float | None = None) -> tuple[sp.csr_matrix, float]:
    """The symmetric ``k``-nearest-neighbour heat-kernel graph of the rows of ``X`` and its width:
    ``S_ij = exp(−‖x_i − x_j‖² / t)`` where ``j`` is among the ``k`` nearest other rows of ``i`` or the reverse,
    ``t`` the mean squared neighbour distance unless given (``k`` capped at ``N − 1``)."""
    N = X.shape[0]
    k = int(min(max(int(n_neighbors), 1), N - 1))
    dist, nbrs = NearestNeighbors(n_neighbors=k + 1).fit(X).kneighbors(X)
    not_self = nbrs != np.arange(N)[:, None]
    keep = np.zeros_like(not_self)
    keep[np.arange(N)[:, None], np.argsort(~not_self, axis=1, kind="stable")[:, :k]] = True  # k non-self
    keep &= not_self
    rows = np.repeat(np.arange(N), keep.sum(1))
    cols, d2 = nbrs[keep], dist[keep] ** 2
    t = float(t) if t is not None else float(d2.mean())
    t = t if t > 0 else 1.0
    S = sp.csr_matrix((np.exp(-d2 / t), (rows, cols)), shape=(N, N))
    return S.maximum(S.T), t


class LaplacianScore(_ViewSelector):
    """Laplacian Score feature selection (He, Cai & Niyogi 2005) on the stacked views (module docstring).

    Args:
        n_features: number of stacked features to select (those of smallest score).
        n_neighbors: ``k`` of the k-nearest-neighbour graph (capped at ``N − 1``).
        t: heat-kernel width; ``None``: the mean squared distance to the ``k`` neighbours.
        standardize: z-score every stacked feature first (fitted; the graph is built on the result).

    Fitted attributes: ``selected_`` int64 ``[n_features]`` (smallest score first), ``scores_`` ``[D]`` (``inf``
    for a constant feature), ``t_``, ``view_slices_``, ``mean_``, ``scale_``.
    """

    def __init__(self, n_features: int, n_neighbors: int = 5, t: float | None = None, standardize: bool = True):
        self.n_features = n_features
        self.n_neighbors = n_neighbors
        self.t = t
        self.standardize = standardize

    def fit(self, views, y=None) -> LaplacianScore:
        """Score and select the features of ``views`` (list of ``[N, d_v]``); ``y`` is ignored."""
        _, X = self._prepare(views)
        if X.shape[0] < 2:
            raise ValueError("LaplacianScore needs at least 2 samples")
        S, t = heat_kernel_graph(X, self.n_neighbors, self.t)
        deg = np.asarray(S.sum(1)).ravel()
        F = X - (deg @ X) / max(deg.sum(), 1e-300)
        den = (deg[:, None] * F * F).sum(0)
        num = den - (F * (S @ F)).sum(0)
        scores = np.full(X.shape[1], np.inf)
        ok = den > 1e-12 * max(1.0, den.max())
        scores[ok] = num[ok] / den[ok]
        self.scores_ = scores
        self.t_ = t
        self.selected_ = np.argsort(scores, kind="stable")[: int(self.n_features)].astype(np.int64)
        return self


class SPEC(_ViewSelector):
    """Spectral feature selection (Zhao & Liu 2007) on the stacked views' heat-kernel graph (module docstring).

    Args:
        n_features: number of stacked features to select.
        ranking: ``"phi1"``, ``"phi2"`` (= the Laplacian Score) or ``"phi3"`` (default).
        n_components: ``c`` of ``φ3`` (eigenvectors 2..c of the normalised Laplacian).
        n_neighbors, t: the graph (:func:`heat_kernel_graph`).
        standardize: z-score every stacked feature first (fitted).

    Fitted attributes: ``selected_`` int64 ``[n_features]`` (best first), ``scores_`` ``[D]`` (the ranking's values;
    a constant-zero feature gets the worst), ``t_``, ``view_slices_``, ``mean_``, ``scale_``.
    """

    rankings = ("phi1", "phi2", "phi3")

    def __init__(
        self,
        n_features: int,
        ranking: str = "phi3",
        n_components: int = 10,
        n_neighbors: int = 5,
        t: float | None = None,
        standardize: bool = True,
    ):
        self.n_features = n_features
        self.ranking = ranking
        self.n_components = n_components
        self.n_neighbors = n_neighbors
        self.t = t
        self.standardize = standardize

    def fit(self, views, y=None) -> SPEC:
        """Score and select the features of ``views`` (list of ``[N, d_v]``); ``y`` is ignored."""
        if self.ranking not in self.rankings:
            raise ValueError(f"ranking must be one of {self.rankings}, got {self.ranking!r}")
        _, X = self._prepare(views)
        N = X.shape[0]
        if N < 3:
            raise ValueError("SPEC needs at least 3 samples")
        S, self.t_ = heat_kernel_graph(X, self.n_neighbors, self.t)
        root = np.sqrt(np.maximum(np.asarray(S.sum(1)).ravel(), 1e-300))  # D^{1/2}
        normalised = sp.identity(N, format="csr") - sp.diags(1 / root) @ S @ sp.diags(1 / root)
        F = root[:, None] * X  # D^{1/2} f per column
        norms = np.linalg.norm(F, axis=0)
        ok = norms > 1e-12 * max(1.0, norms.max())
        F = F / np.where(ok, norms, 1.0)
        if self.ranking == "phi3":
            c = int(min(max(int(self.n_components), 2), N))
            lam, xi = np.linalg.eigh(normalised.toarray())
            scores = ((2.0 - lam[1:c]) * (xi[:, 1:c].T @ F).T ** 2).sum(1)
            scores = np.where(ok, scores, -np.inf)
            order = np.argsort(-scores, kind="stable")
        else:
            scores = (F * (normalised @ F)).sum(0)
            if self.ranking == "phi2":
                xi1 = root / np.linalg.norm(root)
                scores = scores / np.maximum(1.0 - (xi1 @ F) ** 2, 1e-12)
            scores = np.where(ok, scores, np.inf)
            order = np.argsort(scores, kind="stable")
        self.scores_ = scores
        self.selected_ = order[: int(self.n_features)].astype(np.int64)
        return self


class UDFS(_ViewSelector):
    """ℓ2,1-regularised discriminative feature selection (Yang et al. 2011) on the stacked views (module docstring).

    Args:
        n_features: number of stacked features to select.
        n_components: ``c``, the columns of ``W`` (the paper: the number of clusters).
        gamma: weight ``γ`` of the ℓ2,1 norm.
        mu: ridge of the local regressions (the paper's ``λ``).
        n_neighbors: neighbourhood size ``k`` (the sample included), capped at ``N``.
        max_iter: most reweighting iterations.
        standardize: z-score every stacked feature first (fitted).

    Fitted attributes: ``selected_`` int64 ``[n_features]`` (largest ``‖w^i‖`` first), ``scores_`` ``[D]``
    (``‖w^i‖``), ``W_`` ``[D, c]``, ``objective_`` (``tr(WᵀMW) + γ‖W‖_{2,1}`` after every iteration), ``n_iter_``,
    ``view_slices_``, ``mean_``, ``scale_``. Cost: one ``D × D`` eigenproblem per iteration.

    With more features than samples (``D > N``, e.g. 3,256 HOD + GPF features of ~170 clips) ``M = XᵀLX`` has rank
    at most ``N``: every ``W`` inside the null space of ``X`` makes ``tr(WᵀMW) = 0``, so the ℓ2,1 term alone picks
    the rows and the selection says little about the data's structure. Reduce ``D`` first (fewer views, or PCA)
    where that matters.
    """

    def __init__(
        self,
        n_features: int,
        n_components: int = 10,
        gamma: float = 1.0,
        mu: float = 1.0,
        n_neighbors: int = 5,
        max_iter: int = 20,
        standardize: bool = True,
    ):
        self.n_features = n_features
        self.n_components = n_components
        self.gamma = gamma
        self.mu = mu
        self.n_neighbors = n_neighbors
        self.max_iter = max_iter
        self.standardize = standardize

    def fit(self, views, y=None) -> UDFS:
        """Select features from ``views`` (list of ``[N, d_v]``); ``y`` is ignored (unsupervised)."""
        from scipy.linalg import eigh

        if not float(self.mu) > 0.0 or not float(self.gamma) >= 0.0:
            raise ValueError(f"mu must be > 0 and gamma >= 0, got mu={self.mu}, gamma={self.gamma}")
        _, X = self._prepare(views)
        N, D = X.shape
        if N < 2:
            raise ValueError("UDFS needs at least 2 samples")
        c = int(min(max(int(self.n_components), 1), D))
        nbrs = _knn(X, int(min(max(int(self.n_neighbors), 2), N)))
        B = local_regression_laplacians(X, nbrs, float(self.mu)) / float(self.mu)  # H (H K_i H + μI)⁻¹ H
        k = nbrs.shape[1]
        rows = np.repeat(nbrs, k, axis=1).ravel()
        cols = np.tile(nbrs, (1, k)).ravel()
        total = sp.csr_matrix((B.ravel(), (rows, cols)), shape=(N, N))  # Σ_i S_i B_i S_iᵀ (duplicates add)
        M = X.T @ (total @ X)
        M = 0.5 * (M + M.T)
        weights = np.ones(D)
        history, selected, W = [], None, None
        n_iter = 0
        for _ in range(int(self.max_iter)):
            n_iter += 1
            W = eigh(M + float(self.gamma) * np.diag(weights), subset_by_index=[0, c - 1], driver="evr")[1]
            norms = np.linalg.norm(W, axis=1)
            history.append(float(np.trace(W.T @ M @ W) + float(self.gamma) * norms.sum()))
            weights = 1.0 / (2.0 * np.maximum(norms, 1e-12))
            previous, selected = selected, np.argsort(-norms, kind="stable")[: int(self.n_features)]
            if previous is not None and np.array_equal(np.sort(previous), np.sort(selected)):
                break
        self.W_ = W
        self.scores_ = np.linalg.norm(W, axis=1)
        self.selected_ = np.asarray(selected, dtype=np.int64)
        self.objective_ = np.asarray(history, dtype=np.float64)
        self.n_iter_ = n_iter
        return self
