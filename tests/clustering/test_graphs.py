"""Sample graphs for GNMF / NMC (mocapkit.clustering.graphs)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import torch

from mocapkit.clustering.graphs import (
    check_graph,
    combine_graphs,
    knn_graph,
    label_graph,
    laplacian,
    sparse_graph,
    split_laplacian,
)


@pytest.fixture(scope="module")
def X():
    return np.random.default_rng(0).random((40, 6))


def _is_symmetric(S):
    return abs(S - S.T).max() < 1e-15


def test_knn_graph_binary_neighbours_symmetry(X):
    S = knn_graph(X, n_neighbors=5)
    assert isinstance(S, sp.csr_matrix) and S.shape == (40, 40)
    assert _is_symmetric(S) and np.all(S.diagonal() == 0)
    assert set(np.unique(S.data)) == {1.0}
    dense = S.toarray()
    distances = np.linalg.norm(X[:, None] - X[None], axis=-1)
    np.fill_diagonal(distances, np.inf)
    nearest = np.argsort(distances, axis=1)[:, :5]
    for i in range(40):
        assert np.all(dense[i, nearest[i]] == 1)  # its own 5 neighbours are in
        assert set(np.flatnonzero(dense[i])) == set(nearest[i]) | set(
            np.flatnonzero((nearest == i).any(axis=1))
        )  # plus exactly those who chose i
    assert (dense.sum(axis=1) >= 5).all()
    assert np.allclose(knn_graph(torch.from_numpy(X), 5).toarray(), dense)


def test_knn_graph_heat_weights(X):
    S = knn_graph(X, n_neighbors=4, weight="heat", sigma=0.3)
    B = knn_graph(X, n_neighbors=4)
    assert _is_symmetric(S) and (S != 0).toarray().tolist() == (B != 0).toarray().tolist()
    i, j = S.nonzero()
    d2 = ((X[i] - X[j]) ** 2).sum(axis=1)
    assert np.allclose(np.asarray(S[i, j]).ravel(), np.exp(-d2 / (2 * 0.3**2)))
    # default sigma = mean distance to the 4 nearest neighbours
    distances = np.sort(np.linalg.norm(X[:, None] - X[None], axis=-1), axis=1)[:, 1:5]
    S_default = knn_graph(X, n_neighbors=4, weight="heat")
    sigma = distances.mean()
    assert np.allclose(np.asarray(S_default[i, j]).ravel(), np.exp(-d2 / (2 * sigma**2)))


def test_knn_graph_errors(X):
    with pytest.raises(ValueError, match="n_neighbors"):
        knn_graph(X, n_neighbors=40)
    with pytest.raises(ValueError, match="weight"):
        knn_graph(X, weight="cosine")
    with pytest.raises(ValueError, match="non-finite"):
        knn_graph(np.full((5, 2), np.nan))


def test_label_graph_and_combine():
    y = np.array([0, 1, 0, -1, 1, 0, -1])
    S = label_graph(y)
    expected = np.zeros((7, 7))
    for a in (0, 2, 5):
        for b in (0, 2, 5):
            expected[a, b] = a != b
    expected[1, 4] = expected[4, 1] = 1
    assert np.array_equal(S.toarray(), expected)
    assert label_graph(np.array([0, 1, -1]), 3).nnz == 0
    with pytest.raises(ValueError, match="n_samples"):
        label_graph(y, n_samples=8)
    C = combine_graphs(sp.eye(7, k=1) + sp.eye(7, k=-1), S, weight=0.5)
    assert C[0, 1] == 1 and C[0, 2] == 0.5 and C[1, 4] == 0.5
    with pytest.raises(ValueError, match="shapes"):
        combine_graphs(sp.eye(3), S)


def test_sparse_graph(X):
    # two far-apart groups: the sparse codes (restricted to the 8 nearest candidates) never cross groups
    rng = np.random.default_rng(1)
    Z = np.vstack([rng.random((15, 6)), 10 + rng.random((15, 6))])
    S = sparse_graph(Z, beta=0.01, n_neighbors=8)
    assert _is_symmetric(S) and np.all(S.diagonal() == 0) and S.data.min() > 0
    assert S[:15, 15:].nnz == 0
    assert (np.diff(S.indptr) <= 16).all() and S.nnz > 0
    # larger beta → sparser codes
    assert sparse_graph(X, beta=0.2).nnz < sparse_graph(X, beta=0.005).nnz
    with pytest.raises(ValueError, match="beta"):
        sparse_graph(X, beta=0)


def test_laplacian_and_split(X):
    S = knn_graph(X, 3, weight="heat")
    L, D = laplacian(S)
    assert np.allclose(L.toarray().sum(axis=1), 0)
    assert np.allclose(D.diagonal(), S.toarray().sum(axis=1))
    eigenvalues = np.linalg.eigvalsh(L.toarray())
    assert eigenvalues.min() > -1e-10  # positive semi-definite
    plus, minus = split_laplacian(L)
    assert np.allclose((plus - minus).toarray(), L.toarray())
    assert plus.data.min() >= 0 and minus.data.min() >= 0
    assert np.allclose(plus.toarray(), D.toarray()) and np.allclose(minus.toarray(), S.toarray())


def test_graph_validation_errors():
    with pytest.raises(ValueError, match="square"):
        laplacian(np.ones((3, 4)))
    with pytest.raises(ValueError, match="empty"):
        laplacian(np.eye(4))
    with pytest.raises(ValueError, match="negative weights: min -1 at row 0, column 1"):
        check_graph(np.array([[0, -1.0], [-1.0, 0]]))
    with pytest.warns(RuntimeWarning, match="not symmetric"):
        S = check_graph(np.array([[0, 1.0], [0, 0]]))
    assert S[0, 1] == S[1, 0] == 0.5
