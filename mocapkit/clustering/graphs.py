"""Sample graphs for graph-regularised NMF (GNMF, NMC): affinities ``S [n, n]`` and their Laplacians.

Every builder returns a symmetric ``scipy.sparse.csr_matrix`` of shape ``[n_samples, n_samples]`` with
non-negative weights and a zero diagonal (no self loops). Samples are the rows of ``X [n_samples, n_features]``,
as everywhere in :mod:`mocapkit.clustering`.

* :func:`knn_graph` — the GNMF graph of Cai et al. 2011: ``p``-nearest neighbours, 0/1 or heat-kernel weights.
* :func:`sparse_graph` — a locally weighted sparse (ℓ1) graph, **our reading** of Feng et al. 2015
  (the thesis, §6.3.1, names it but gives no construction).
* :func:`label_graph` — semi-supervised: 1 between labelled samples of the same class.
* :func:`combine_graphs` — ``a + weight · b``.
* :func:`laplacian` / :func:`split_laplacian` — ``L = D − S`` and ``L = L⁺ − L⁻`` for multiplicative updates.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
import torch


def _as_numpy_2d(X, name: str = "X") -> np.ndarray:
    """``X`` (numpy, torch or a nested list) as a finite float64 ``[n, d]`` array, or a clear error."""
    if isinstance(X, torch.Tensor):
        X = X.detach().cpu().numpy()
    if sp.issparse(X):
        X = X.toarray()
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[0] == 0 or X.shape[1] == 0:
        raise ValueError(f"{name} must be a non-empty 2-D array [n_samples, n_features], got shape {X.shape}")
    bad = ~np.isfinite(X)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(
            f"{name} has non-finite entries ({int(bad.sum())} in total): first {X[i, j]} at row {i}, column {j}"
        )
    return X


def check_graph(S, n_samples: int | None = None, name: str = "graph") -> sp.csr_matrix:
    """Validate an affinity matrix and return it as float64 CSR ``[n, n]``.

    Accepts a dense numpy / torch array or any scipy sparse matrix. Raises ``ValueError`` for a non-square
    matrix, a size other than ``n_samples``, non-finite or negative weights, and a graph with no edges
    (``S`` all zero off the diagonal: the graph term would then do nothing). An asymmetric ``S`` is symmetrised
    as ``(S + Sᵀ) / 2`` with a warning (``tr(Wᵀ L W)`` only sees the symmetric part).
    """
    if isinstance(S, torch.Tensor):
        S = S.detach().cpu().numpy()
    S = sp.csr_matrix(S, dtype=np.float64) if not sp.issparse(S) else S.tocsr().astype(np.float64)
    if S.ndim != 2 or S.shape[0] != S.shape[1]:
        raise ValueError(f"{name} must be a square [n_samples, n_samples] affinity matrix, got shape {S.shape}")
    if n_samples is not None and S.shape[0] != n_samples:
        raise ValueError(
            f"{name} has shape {S.shape} but X has {n_samples} samples (rows); expected [{n_samples}, {n_samples}]"
        )
    if S.nnz and not np.isfinite(S.data).all():
        raise ValueError(f"{name} has non-finite weights")
    if S.nnz and S.data.min() < 0:
        k = int(np.argmin(S.data))
        i = int(np.searchsorted(S.indptr, k, side="right") - 1)
        raise ValueError(
            f"{name} has negative weights: min {S.data[k]:.4g} at row {i}, column {S.indices[k]} "
            f"(affinities must be >= 0; pass a signed Laplacian through split_laplacian instead)"
        )
    off_diagonal = S - sp.diags(S.diagonal())
    off_diagonal.eliminate_zeros()
    if off_diagonal.nnz == 0:
        raise ValueError(f"{name} is empty: no edges between distinct samples (all off-diagonal weights are 0)")
    if abs(S - S.T).max() > 1e-12 * max(abs(S).max(), 1.0):
        warnings.warn(f"{name} is not symmetric; using (S + S^T) / 2", RuntimeWarning, stacklevel=2)
        S = ((S + S.T) * 0.5).tocsr()
    return S


def knn_graph(X, n_neighbors: int = 5, weight: str = "binary", sigma: float | None = None) -> sp.csr_matrix:
    """The GNMF ``p``-nearest-neighbour graph (Cai et al. 2011) over the rows of ``X [n, d]``.

    ``S_ij > 0`` when ``j`` is among the ``n_neighbors`` nearest (Euclidean) neighbours of ``i`` **or** vice versa
    (symmetrised as ``max(A, Aᵀ)``, so a row may have more than ``n_neighbors`` edges); zero diagonal.

    Args:
        X: samples ``[n_samples, n_features]`` (numpy or torch).
        n_neighbors: ``p``, the neighbours per sample, ``1 <= p < n_samples`` (Cai et al. use 5).
        weight: ``"binary"`` (0/1 weights) or ``"heat"``: ``exp(−d² / (2σ²))``. Cai et al. write the heat kernel
            as ``exp(−d² / t)``, i.e. ``t = 2σ²``.
        sigma: kernel width in the units of ``X``; default: the mean distance to the ``p`` nearest neighbours.

    Returns:
        ``scipy.sparse.csr_matrix [n_samples, n_samples]`` float64.
    """
    from sklearn.neighbors import kneighbors_graph

    X = _as_numpy_2d(X)
    n = X.shape[0]
    if not 1 <= int(n_neighbors) < n:
        raise ValueError(f"n_neighbors must be in [1, n_samples - 1] = [1, {n - 1}], got {n_neighbors}")
    if weight not in ("binary", "heat"):
        raise ValueError(f"knn_graph weight must be 'binary' or 'heat', got {weight!r}")
    if weight == "binary":
        A = kneighbors_graph(X, int(n_neighbors), mode="connectivity", include_self=False)
    else:
        A = kneighbors_graph(X, int(n_neighbors), mode="distance", include_self=False)  # explicit 0 for duplicates
        if sigma is None:
            sigma = float(A.data.mean())
        if not sigma > 0:
            raise ValueError(
                f"heat kernel sigma must be > 0, got {sigma} (all neighbours at distance 0? pass sigma explicitly)"
            )
        A.data = np.exp(-(A.data**2) / (2.0 * float(sigma) ** 2))
    A = A.tocsr().astype(np.float64)
    S = A.maximum(A.T).tocsr()
    S.setdiag(0.0)
    S.eliminate_zeros()
    return S


def sparse_graph(X, beta: float = 0.05, n_neighbors: int | None = None, max_iter: int = 2000) -> sp.csr_matrix:
    """A locally weighted sparse graph: every sample coded as a locality-weighted ℓ1 combination of the others.

    **Our reading of Feng et al. 2015** ("A locally weighted sparse graph regularized NMF", Neurocomputing 169),
    which the thesis (§6.3.1) names without giving a construction. For each sample ``x_i``:

        ``a_i = argmin_a ½‖x_i − X_N a‖² + β_i ‖p_i ∘ a‖₁``

    over its ``m = n_neighbors`` nearest samples ``N`` (the candidates; all others get 0), with locality weights
    ``p_ij = d(x_i, x_j) / mean_{j∈N} d(x_i, x_j)`` (far candidates cost more; dimensionless, mean 1) and
    ``β_i = beta · ‖x_i‖²`` (so ``beta`` is scale-free: the gradient of the fit term at ``a = 0`` is ``~‖x_i‖²``).
    The weighted lasso is solved by rescaling: ``b = p ∘ a`` turns it into a plain lasso on the columns
    ``x_j / p_ij``, solved with ``sklearn.linear_model.Lasso(alpha=β_i / n_features, fit_intercept=False)``
    (sklearn divides the squared error by ``2 · n_rows``), then ``a = b / p``. Finally ``S = (|A| + |A|ᵀ) / 2``.

    Args:
        X: samples ``[n_samples, n_features]``.
        beta: sparsity relative to ``‖x_i‖²``; larger → fewer edges.
        n_neighbors: candidates per sample ``m`` (default ``min(n − 1, 30)``), the speed knob: n lassos of size m.
        max_iter: lasso coordinate-descent iterations.

    Returns:
        ``scipy.sparse.csr_matrix [n_samples, n_samples]`` float64, symmetric, zero diagonal.
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import Lasso
    from sklearn.neighbors import NearestNeighbors

    X = _as_numpy_2d(X)
    n, d = X.shape
    m = min(n - 1, 30) if n_neighbors is None else int(n_neighbors)
    if not 1 <= m < n:
        raise ValueError(f"n_neighbors must be in [1, n_samples - 1] = [1, {n - 1}], got {n_neighbors}")
    if not beta > 0:
        raise ValueError(f"sparse_graph beta must be > 0, got {beta}")
    distances, neighbours = NearestNeighbors(n_neighbors=m + 1).fit(X).kneighbors(X)
    rows, cols, vals = [], [], []
    for i in range(n):
        keep = neighbours[i] != i  # drop the sample itself (wherever ties put it)
        cand, dist = neighbours[i][keep][:m], distances[i][keep][:m]
        sq_norm = float(X[i] @ X[i])
        if sq_norm == 0.0:  # an all-zero sample is coded by nothing
            continue
        mean_dist = dist.mean()
        p = dist / mean_dist if mean_dist > 0 else np.ones_like(dist)
        p = np.maximum(p, 1e-3)  # duplicates (distance 0) must not get a free ride
        lasso = Lasso(alpha=beta * sq_norm / d, fit_intercept=False, max_iter=max_iter)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            lasso.fit(X[cand].T / p[None, :], X[i])
        a = lasso.coef_ / p
        nz = np.flatnonzero(a)
        rows.extend([i] * len(nz))
        cols.extend(cand[nz].tolist())
        vals.extend(np.abs(a[nz]).tolist())
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n), dtype=np.float64)
    S = ((A + A.T) * 0.5).tocsr()
    S.setdiag(0.0)
    S.eliminate_zeros()
    if S.nnz == 0:
        raise ValueError(f"sparse_graph found no edges with beta={beta}: every lasso code is zero; lower beta")
    return S


def label_graph(y, n_samples: int | None = None) -> sp.csr_matrix:
    """Semi-supervised label graph: ``S_ij = 1`` when ``i ≠ j`` are both labelled (``y ≥ 0``) with the same label.

    Args:
        y: ``[n_samples]`` integer labels, ``-1`` (any negative value) = unlabelled.
        n_samples: expected length of ``y`` (checked), default ``len(y)``.

    Returns:
        ``scipy.sparse.csr_matrix [n_samples, n_samples]``; all zero when no class has two labelled samples
        (:func:`check_graph` then calls it empty).
    """
    if isinstance(y, torch.Tensor):
        y = y.detach().cpu().numpy()
    y = np.asarray(y)
    if y.ndim != 1:
        raise ValueError(f"labels y must be 1-D [n_samples], got shape {y.shape}")
    if n_samples is not None and len(y) != n_samples:
        raise ValueError(f"labels y has {len(y)} entries but n_samples is {n_samples}")
    if not np.issubdtype(y.dtype, np.integer):
        if not np.all(np.isfinite(y)) or np.any(y != np.round(y)):
            raise ValueError("labels y must be integers (-1 = unlabelled)")
        y = y.astype(np.int64)
    rows, cols = [], []
    for label in np.unique(y[y >= 0]):
        members = np.flatnonzero(y == label)
        r, c = np.meshgrid(members, members, indexing="ij")
        off = r != c
        rows.append(r[off])
        cols.append(c[off])
    n = len(y)
    if not rows:
        return sp.csr_matrix((n, n), dtype=np.float64)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n), dtype=np.float64)


def combine_graphs(a, b, weight: float = 1.0) -> sp.csr_matrix:
    """``a + weight · b`` for two ``[n, n]`` affinities (e.g. a kNN graph plus a label graph), as CSR."""
    a = sp.csr_matrix(a, dtype=np.float64)
    b = sp.csr_matrix(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"cannot combine graphs of shapes {a.shape} and {b.shape}")
    if weight < 0:
        raise ValueError(f"combine_graphs weight must be >= 0, got {weight}")
    return (a + float(weight) * b).tocsr()


def laplacian(S) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Graph Laplacian ``L = D − S`` with ``D = diag(Σ_j S_ij)`` (thesis Ch. 2.7). Returns ``(L, D)``, both CSR.

    ``S`` is validated by :func:`check_graph` (square, non-negative, finite, at least one edge).
    """
    S = check_graph(S)
    D = sp.diags(np.asarray(S.sum(axis=1)).ravel()).tocsr()
    return (D - S).tocsr(), D


def split_laplacian(L) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Split a signed matrix into non-negative parts ``L = L⁺ − L⁻`` (Gu & Zhou style), ``L± = max(±L, 0)``.

    In a multiplicative update the gradient term ``λ L W`` becomes ``λ L⁺ W`` in the denominator and ``λ L⁻ W``
    in the numerator. For ``L = D − S`` this gives ``L⁺ = D`` (minus self loops) and ``L⁻ = S`` off the diagonal.
    """
    L = sp.csr_matrix(L, dtype=np.float64)
    if L.shape[0] != L.shape[1]:
        raise ValueError(f"Laplacian must be square, got shape {L.shape}")
    plus = L.maximum(0).tocsr()
    minus = (-L).maximum(0).tocsr()
    return plus, minus
