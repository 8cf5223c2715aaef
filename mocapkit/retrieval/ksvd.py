"""K-SVD dictionary learning with a batched orthogonal matching pursuit (Aharon, Elad & Bruckstein 2006).

Orientation (scikit-learn's, **samples as rows**)::

    Y [n_samples, d]  ≈  X [n_samples, n_atoms]  @  D [n_atoms, d]      ‖x_i‖₀ ≤ n_nonzero, ‖D_k‖₂ = 1

``components_`` is ``D`` (one unit-norm atom per row); the thesis (Zhou 2014 eq. 3.4) writes the transpose
``Y_thesis [d, n] ≈ D_thesis [d, q] X_thesis [q, n]``.

Fitting alternates, for at most ``max_iter`` iterations:

1. **sparse coding** of every (sub-sampled) row by OMP with the current dictionary, ``n_nonzero`` atoms per row;
2. the **exact K-SVD atom update**: for each atom ``k`` in turn (Gauss-Seidel: later atoms see the updated
   earlier ones), the residual restricted to the rows that use it, ``E = Y_ω − X_ω D + x_ωk d_k``, is replaced by
   its best rank-1 approximation ``x_ωk d_k`` (the leading right singular vector of ``E``, computed as the top
   eigenvector of the ``d × d`` matrix ``EᵀE``, with ``x_ωk = E d_k``). An atom no row uses is replaced by the
   normalised residual of the worst-represented row not already used for a replacement.

Initialisation: ``n_atoms`` distinct random rows of the data (``random_state``), unit-normed (an all-zero row
is replaced by a random Gaussian direction). ``error_`` holds the RMS reconstruction error
``‖Y − XD‖_F / sqrt(n·d)`` after each iteration's atom update; fitting stops early when its relative decrease
falls below ``tol``.

OMP (:func:`batch_omp`) is vectorised over rows rather than looping in Python per row as
``sklearn.linear_model.orthogonal_mp_gram`` does (about 2.6 ms per row at 700 atoms / 35 non-zeros, too slow for
tens of thousands of frames): the selected atoms of every row are orthonormalised incrementally (Gram–Schmidt,
applied twice for stability), the residual is updated in data space, and the coefficients come from one
triangular back-substitution at the end. It selects the same atoms and gives the same least-squares
coefficients as ``orthogonal_mp_gram`` (tests check it). A row stops early (fewer than ``n_nonzero`` non-zeros)
when its residual vanishes or the next atom is numerically in the span of the chosen ones, as scikit-learn does.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

#: Rows coded at once by :func:`batch_omp` (bounds the ``[batch, n_atoms]`` correlation matrix).
OMP_BATCH = 4096
#: A new atom whose component orthogonal to the chosen ones is shorter than this (atoms are unit norm) is
#: treated as linearly dependent: the row stops there.
DEPENDENCE_TOL = 1e-7


def _check_matrix(Y, name: str) -> np.ndarray:
    Y = np.asarray(Y, dtype=np.float64)
    if Y.ndim != 2 or Y.shape[0] == 0 or Y.shape[1] == 0:
        raise ValueError(f"{name} must be a non-empty 2-D array [n_samples, n_features], got shape {Y.shape}")
    if not np.isfinite(Y).all():
        i, j = np.argwhere(~np.isfinite(Y))[0]
        raise ValueError(f"{name} has non-finite entries: first at row {i}, column {j}")
    return Y


def batch_omp(Y: np.ndarray, D: np.ndarray, n_nonzero: int, batch: int = OMP_BATCH) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal matching pursuit of every row of ``Y [n, d]`` on the unit-norm atoms ``D [q, d]``.

    Returns:
        ``(indices int64 [n, m], coefs float64 [n, m])`` with ``m = min(n_nonzero, q, d)``: the atoms each row
        selected, in selection order, and their least-squares coefficients; a row that stopped early has
        ``coef == 0`` in its remaining slots (their index repeats an already selected atom and must be ignored).
    """
    Y = np.asarray(Y, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64)
    n, d = Y.shape
    q = D.shape[0]
    m = int(min(n_nonzero, q, d))
    indices = np.zeros((n, m), dtype=np.int64)
    coefs = np.zeros((n, m), dtype=np.float64)
    D32, G = D.astype(np.float32), D @ D.T
    for start in range(0, n, batch):
        stop = min(start + batch, n)
        indices[start:stop], coefs[start:stop] = _omp_block(Y[start:stop], D, m, D32, G)
    return indices, coefs


def _omp_block(Y: np.ndarray, D: np.ndarray, m: int, D32: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # step-major layouts ([m, n, ...]) keep every per-step slice contiguous
    n, d = Y.shape
    rows = np.arange(n)
    Q = np.zeros((m, n, d))  # orthonormal basis of the chosen atoms (Gram–Schmidt), per row
    L = np.zeros((m, m, n))  # Cholesky factor of the chosen atoms' Gram matrix: D_S = L Q
    z = np.zeros((m, n))  # Q y
    idx = np.zeros((m, n), dtype=np.int64)
    active = np.ones(n, dtype=bool)
    residual = Y.copy()
    floor = 1e-12 * np.maximum(np.linalg.norm(Y, axis=1), 1e-300)
    for k in range(m):
        corr = residual.astype(np.float32) @ D32.T
        np.abs(corr, out=corr)
        if k:
            corr[rows[None, :], idx[:k]] = -1.0  # never re-select (the residual is orthogonal to them)
        new = np.argmax(corr, axis=1)
        active &= np.einsum("nd,nd->n", residual, residual) > floor**2
        idx[k] = np.where(active, new, idx[k - 1] if k else new)
        # w = L⁻¹ G[S, new] (forward substitution): the new atom's coordinates on the current basis
        g = G[idx[:k], idx[k][None, :]]
        w = np.empty((k, n))
        for j in range(k):
            w[j] = (g[j] - np.einsum("jn,jn->n", L[j, :j], w[:j])) / L[j, j]
        v = D[idx[k]] - np.einsum("kn,knd->nd", w, Q[:k])
        norm = np.sqrt(np.einsum("nd,nd->n", v, v))
        active &= norm > DEPENDENCE_TOL
        safe = np.where(active, norm, 1.0)
        Q[k] = v * (active / safe)[:, None]
        L[k, :k] = w * active
        L[k, k] = safe
        z[k] = np.einsum("nd,nd->n", Q[k], Y)
        residual -= z[k][:, None] * Q[k]
    # coefficients: D_S^T γ = Q^T L^T γ ≈ y  →  L^T γ = Q y = z  (back-substitution; inactive slots give 0)
    gamma = np.zeros((m, n))
    for k in range(m - 1, -1, -1):
        gamma[k] = (z[k] - np.einsum("jn,jn->n", L[k + 1 :, k], gamma[k + 1 :])) / L[k, k]
    return idx.T, gamma.T


def codes_to_dense(indices: np.ndarray, coefs: np.ndarray, n_atoms: int) -> np.ndarray:
    """The dense ``[n, n_atoms]`` codes of :func:`batch_omp`'s ``(indices, coefs)``."""
    X = np.zeros((indices.shape[0], n_atoms), dtype=np.float64)
    np.add.at(X, (np.repeat(np.arange(indices.shape[0]), indices.shape[1]), indices.ravel()), coefs.ravel())
    return X


def _reconstruct(D: np.ndarray, indices: np.ndarray, coefs: np.ndarray) -> np.ndarray:
    return np.einsum("nk,nkd->nd", coefs, D[indices])


class KSVD(BaseEstimator):
    """K-SVD dictionary learning (see the module docstring).

    Args:
        n_atoms: ``q``, the number of atoms (may exceed the dimension: an overcomplete dictionary).
        n_nonzero: ``m``, the non-zeros of each row's code (at most ``min(n_atoms, d)`` are used).
        max_iter: the most (sparse coding + atom update) iterations.
        tol: stop when the relative decrease of the RMS error between iterations is below ``tol``.
        random_state: seed of the initialisation, the row sub-sampling and atom replacement.
        max_samples: fit on at most this many randomly chosen rows (``None``: all).

    Attributes (after ``fit``):
        components_: ``[n_atoms, d]`` unit-norm atoms.
        error_: ``list[float]``, RMS reconstruction error after each iteration.
        n_iter_: iterations run.
        n_replaced_: atoms replaced because no row used them (summed over iterations).
    """

    def __init__(
        self,
        n_atoms: int = 700,
        n_nonzero: int = 35,
        max_iter: int = 10,
        tol: float = 1e-6,
        random_state=0,
        max_samples: int | None = None,
    ):
        self.n_atoms = n_atoms
        self.n_nonzero = n_nonzero
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.max_samples = max_samples

    def fit(self, Y, y=None) -> KSVD:
        Y = _check_matrix(Y, "Y")
        q, m = int(self.n_atoms), int(self.n_nonzero)
        if q < 1 or m < 1 or int(self.max_iter) < 1:
            raise ValueError(f"n_atoms, n_nonzero and max_iter must be >= 1, got {q}, {m}, {self.max_iter}")
        rng = np.random.default_rng(self.random_state)
        if self.max_samples is not None and len(Y) > int(self.max_samples):
            Y = Y[np.sort(rng.choice(len(Y), int(self.max_samples), replace=False))]
        n, d = Y.shape
        D = Y[rng.choice(n, q, replace=q > n)].copy()
        norms = np.linalg.norm(D, axis=1)
        zero = norms < 1e-12
        D[zero] = rng.standard_normal((int(zero.sum()), d))
        D /= np.linalg.norm(D, axis=1, keepdims=True)
        self.error_, self.n_replaced_ = [], 0
        for it in range(int(self.max_iter)):
            indices, coefs = batch_omp(Y, D, m)
            D, replaced = self._update_atoms(Y, D, indices, coefs, rng)
            self.n_replaced_ += replaced
            self.error_.append(float(np.sqrt(np.mean((Y - _reconstruct(D, indices, coefs)) ** 2))))
            self.n_iter_ = it + 1
            if it and self.error_[-2] > 0 and (self.error_[-2] - self.error_[-1]) / self.error_[-2] < self.tol:
                break
        self.components_ = D
        return self

    @staticmethod
    def _update_atoms(Y, D, indices, coefs, rng) -> tuple[np.ndarray, int]:
        """One Gauss-Seidel sweep of exact rank-1 atom updates; ``coefs`` is updated in place."""
        D = D.copy()
        q = D.shape[0]
        m = indices.shape[1]
        residual = Y - _reconstruct(D, indices, coefs)
        used = coefs.ravel() != 0
        flat = np.where(used, indices.ravel(), -1)
        order = np.argsort(flat, kind="stable")
        bounds = np.searchsorted(flat[order], np.arange(q + 1))
        taken = np.zeros(len(Y), dtype=bool)
        replaced = []
        for k in range(q):
            pos = order[bounds[k] : bounds[k + 1]]
            if len(pos) == 0:
                replaced.append(k)
                continue
            rws, slots = pos // m, pos % m
            x = coefs[rws, slots]
            E = residual[rws] + np.outer(x, D[k])
            _, V = np.linalg.eigh(E.T @ E)
            atom = V[:, -1]
            new_x = E @ atom
            D[k] = atom
            coefs[rws, slots] = new_x
            residual[rws] = E - np.outer(new_x, atom)
        if replaced:
            err = np.einsum("nd,nd->n", residual, residual)
            for k in replaced:
                err[taken] = -1.0
                s = int(np.argmax(err))
                if err[s] <= 1e-24:
                    v = rng.standard_normal(D.shape[1])
                else:
                    v = residual[s]
                    taken[s] = True
                D[k] = v / np.linalg.norm(v)
        return D, len(replaced)

    def _check_fitted(self):
        if not hasattr(self, "components_"):
            raise NotFittedError("KSVD is not fitted: call fit(Y) first")

    def sparse_codes(self, Y) -> tuple[np.ndarray, np.ndarray]:
        """``(indices int64 [n, m], coefs float64 [n, m])`` of every row (see :func:`batch_omp`)."""
        self._check_fitted()
        Y = _check_matrix(Y, "Y")
        if Y.shape[1] != self.components_.shape[1]:
            raise ValueError(f"Y has {Y.shape[1]} features, the dictionary {self.components_.shape[1]}")
        return batch_omp(Y, self.components_, int(self.n_nonzero))

    def transform(self, Y) -> np.ndarray:
        """Dense codes ``[n_samples, n_atoms]`` by OMP with ``n_nonzero`` atoms per row."""
        indices, coefs = self.sparse_codes(Y)
        return codes_to_dense(indices, coefs, self.components_.shape[0])

    def inverse_transform(self, codes) -> np.ndarray:
        self._check_fitted()
        return np.asarray(codes, dtype=np.float64) @ self.components_
