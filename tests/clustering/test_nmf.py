"""Classical NMF solvers (mocapkit.clustering.nmf): descent, sklearn parity, orthogonality, clustering, errors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.optimize import linear_sum_assignment
from sklearn.decomposition import NMF as SklearnNMF

from mocapkit.clustering.graphs import knn_graph
from mocapkit.clustering.nmf import GNMF, NMC, NMF, OrthogonalNMF

#: relative slack allowed on "non-increasing" (round-off of the objective itself)
MONOTONE_RTOL = 1e-9
#: our factors vs scikit-learn's, max |difference| / max |sklearn|, same init and iterations, float64
PARITY_RTOL = 1e-9


def clustering_accuracy(y_true, y_pred) -> float:
    """Best one-to-one match of predicted to true labels (Hungarian), as a fraction."""
    counts = np.zeros((y_pred.max() + 1, y_true.max() + 1))
    np.add.at(counts, (y_pred, y_true), 1)
    rows, cols = linear_sum_assignment(-counts)
    return counts[rows, cols].sum() / len(y_true)


def blobs(seed, n_per=40, k=4, d=30, noise=0.1):
    """Non-negative blobs around dense random centres (overlapping feature supports)."""
    rng = np.random.default_rng(seed)
    centres = 2 * rng.random((k, d))
    y = np.repeat(np.arange(k), n_per)
    return np.abs(centres[y] + noise * rng.standard_normal((len(y), d))), y


def parts_blobs(seed, n_per=40, k=4, d=32, noise=0.1):
    """Non-negative blobs whose centres each own a block of features (plus a low background)."""
    rng = np.random.default_rng(seed)
    centres = 0.1 * rng.random((k, d))
    block = d // k
    for c in range(k):
        centres[c, c * block : (c + 1) * block] += 1 + rng.random(block)
    y = np.repeat(np.arange(k), n_per)
    return np.abs(centres[y] + noise * rng.standard_normal((len(y), d))), y


def max_relative_increase(objective) -> float:
    o = np.asarray(objective)
    return float(np.max(np.diff(o) / np.abs(o[:-1])))


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    X = rng.random((60, 25))
    W0, H0 = rng.random((60, 5)), rng.random((5, 25))
    return X, W0, H0


# ---------------------------------------------------------------------------- descent


@pytest.mark.parametrize(
    "model",
    [
        NMF(5, beta_loss="frobenius", max_iter=150, tol=0, random_state=0),
        NMF(5, beta_loss="kullback-leibler", max_iter=150, tol=0, random_state=0),
        GNMF(5, lam=1.0, max_iter=150, tol=0, random_state=0),
        GNMF(5, lam=10.0, graph="heat", max_iter=150, tol=0, random_state=0),
    ],
    ids=["nmf-frobenius", "nmf-kl", "gnmf-knn", "gnmf-heat"],
)
def test_objective_never_increases(model, data):
    X, _, _ = data
    model.fit(X)
    assert len(model.objective_) == model.n_iter_ == 150
    assert model.objective_[0] <= model.initial_objective_
    assert max_relative_increase(model.objective_) <= MONOTONE_RTOL
    assert model.objective_[-1] < 0.5 * model.initial_objective_


@pytest.mark.parametrize("eta", [0.5, 1.0])
def test_nmc_w_step_descends_and_objective_ends_lower(eta):
    # Ding's H-step is not a descent step: on overlapping blobs the objective rises in the first iterations
    # (H leaves the k-means centroids for near-orthogonal rows). What is guaranteed is the W-step:
    X, _ = blobs(0)
    model = NMC(4, eta=eta, max_iter=100, tol=0, random_state=0).fit(X)
    after_h, after_w = np.asarray(model.objective_h_step_), np.asarray(model.objective_)
    assert len(after_h) == len(after_w) == 100
    assert np.all(after_w <= after_h * (1 + MONOTONE_RTOL))
    assert after_w[-1] < model.initial_objective_
    # on data with an orthogonal-friendly structure the whole iteration descends in practice (observed, asserted)
    X, _ = parts_blobs(0)
    model = NMC(4, eta=eta, max_iter=100, tol=0, random_state=0).fit(X)
    assert max_relative_increase(model.objective_) <= MONOTONE_RTOL


def test_orthogonal_nmf_ends_lower_but_is_not_monotone():
    X, _ = parts_blobs(0)
    model = OrthogonalNMF(4, max_iter=200, tol=0, random_state=0).fit(X)
    assert model.objective_[-1] < 0.05 * model.initial_objective_
    assert model.objective_[-1] < min(model.objective_[:10])
    # documented behaviour: Ding's update does raise the objective at some iterations from a random start
    assert max_relative_increase(model.objective_) > 0


# ---------------------------------------------------------------------------- parity with scikit-learn


@pytest.mark.parametrize("beta_loss", ["frobenius", "kullback-leibler"])
@pytest.mark.parametrize("n_iter", [1, 50, 300])
def test_parity_with_sklearn_mu(data, beta_loss, n_iter):
    X, W0, H0 = data
    ref = SklearnNMF(n_components=5, solver="mu", beta_loss=beta_loss, init="custom", max_iter=n_iter, tol=0)
    W_ref = ref.fit_transform(X, W=W0.copy(), H=H0.copy())
    ours = NMF(5, beta_loss=beta_loss, max_iter=n_iter, tol=0)
    W = ours.fit_transform(X, W=W0, H=H0)
    assert ours.n_iter_ == ref.n_iter_ == n_iter
    assert np.abs(W - W_ref).max() <= PARITY_RTOL * np.abs(W_ref).max()
    assert np.abs(ours.components_ - ref.components_).max() <= PARITY_RTOL * np.abs(ref.components_).max()
    assert ours.reconstruction_err_ == pytest.approx(ref.reconstruction_err_, rel=1e-9)


def test_random_init_and_transform_match_sklearn(data):
    X, _, _ = data
    ref = SklearnNMF(n_components=5, solver="mu", init="random", random_state=3, max_iter=40, tol=0)
    W_ref = ref.fit_transform(X)
    ours = NMF(5, init="random", random_state=3, max_iter=40, tol=0)
    assert np.abs(ours.fit_transform(X) - W_ref).max() <= PARITY_RTOL * np.abs(W_ref).max()
    X_new = np.random.default_rng(1).random((7, 25))
    assert np.allclose(ours.transform(X_new), ref.transform(X_new), rtol=1e-9, atol=1e-12)
    assert np.array_equal(ours.predict(X_new), ref.transform(X_new).argmax(axis=1))


def test_torch_in_torch_out_and_numpy_in_numpy_out(data):
    X, W0, H0 = data
    W_np = NMF(5, max_iter=20, tol=0).fit_transform(X, W=W0, H=H0)
    W_t = NMF(5, max_iter=20, tol=0).fit_transform(torch.from_numpy(X), W=torch.from_numpy(W0), H=H0)
    assert isinstance(W_np, np.ndarray) and isinstance(W_t, torch.Tensor)
    assert np.allclose(W_t.numpy(), W_np, rtol=1e-12)


def test_convergence_stops_on_relative_change(data):
    X, _, _ = data
    model = NMF(5, max_iter=5000, tol=1e-4, random_state=0).fit(X)
    assert model.n_iter_ < 5000
    o = model.objective_
    assert abs(o[-2] - o[-1]) <= 1e-4 * o[-2]
    assert all(abs(a - b) > 1e-4 * a for a, b in itertools.pairwise(o[:-1]))


# ---------------------------------------------------------------------------- orthogonality


@pytest.mark.parametrize(
    "make", [lambda: OrthogonalNMF(4, random_state=0), lambda: NMC(4, random_state=0)], ids=["onmf", "nmc"]
)
def test_components_are_near_orthonormal(make):
    X, _ = parts_blobs(0)
    model = make().fit(X)
    gram = model.components_ @ model.components_.T
    assert np.allclose(np.diag(gram), 1.0, atol=1e-12)  # rows normalised
    assert np.abs(gram - np.eye(4)).max() < 0.02  # Ding's update: near, not exactly, orthogonal
    # on overlapping blobs orthogonality is only approximate, but much closer than plain NMF's
    X, _ = blobs(0)
    H_nmf = NMF(4, random_state=0).fit(X).components_
    H_nmf = H_nmf / np.linalg.norm(H_nmf, axis=1, keepdims=True)
    H = make().fit(X).components_
    assert np.abs(H @ H.T - np.eye(4)).max() < 0.5 * np.abs(H_nmf @ H_nmf.T - np.eye(4)).max()


def test_gnmf_rows_of_components_are_unit_norm_and_wh_kept(data):
    X, W0, H0 = data
    model = GNMF(5, max_iter=50, tol=0)
    W = model.fit_transform(X, W=W0, H=H0)
    assert np.allclose(np.linalg.norm(model.components_, axis=1), 1.0)
    assert np.linalg.norm(X - W @ model.components_) == pytest.approx(model.reconstruction_err_, rel=1e-12)
    assert model.reconstruction_err_**2 <= model.objective_[-1]


# ---------------------------------------------------------------------------- clustering


@pytest.mark.parametrize(
    "make",
    [
        lambda s: NMC(4, random_state=s),
        lambda s: NMC(4, eta=1.0, random_state=s),
        lambda s: GNMF(4, random_state=s),
        lambda s: NMC(4, graph="heat", random_state=s),
    ],
    ids=["nmc", "nmc-eta1", "gnmf", "nmc-heat"],
)
@pytest.mark.parametrize("seed", [0, 1])
def test_clusters_well_separated_blobs(make, seed):
    for X, y in (blobs(seed), parts_blobs(seed)):
        model = make(seed).fit(X)
        assert clustering_accuracy(y, model.labels_) > 0.9
        assert np.array_equal(model.predict(), model.labels_)


def test_nmc_label_graph_and_precomputed_graph():
    X, y = blobs(0)
    y_partial = np.where(np.arange(len(y)) % 4 == 0, y, -1)
    model = NMC(4, graph="label", random_state=0).fit(X, y_partial)
    assert clustering_accuracy(y, model.labels_) > 0.9
    assert model.affinity_[0, 4] >= 1.0  # same label, both labelled
    S = knn_graph(X, 5)
    a = GNMF(4, max_iter=30, tol=0, random_state=0).fit(X)
    b = GNMF(4, graph=S.toarray(), max_iter=30, tol=0, random_state=0).fit(X)
    c = GNMF(4, graph="heat", max_iter=30, tol=0, random_state=0).fit(X, graph=sp.csr_matrix(S))
    assert np.allclose(a.components_, b.components_) and np.allclose(a.components_, c.components_)
    with pytest.raises(ValueError, match="needs the labels"):
        NMC(4, graph="label").fit(X)


def test_transform_of_training_data_recovers_labels():
    X, y = parts_blobs(0)
    for model in (NMC(4, random_state=0), GNMF(4, random_state=0), OrthogonalNMF(4, random_state=0)):
        model.fit(X)
        assert clustering_accuracy(y, model.predict(X)) > 0.9
        assert np.array_equal(model.predict(X[::3]), model.predict(X)[::3])  # other n: no training graph used


# ---------------------------------------------------------------------------- bad input


def test_bad_input_errors(data):
    X, W0, H0 = data
    bad = X.copy()
    bad[3, 7] = -0.3
    with pytest.raises(ValueError, match=r"negative entries: min -0.3 at row 3, column 7"):
        NMF(5).fit(bad)
    bad = X.copy()
    bad[2, 4] = np.nan
    with pytest.raises(ValueError, match="NaN entries .* row 2, column 4"):
        NMF(5).fit(bad)
    bad[2, 4] = np.inf
    with pytest.raises(ValueError, match="infinite entries"):
        NMF(5).fit(bad)
    with pytest.raises(ValueError, match="2-D"):
        NMF(5).fit(X[0])
    with pytest.raises(ValueError, match="nndsvda"):
        NMF(26, init="nndsvda").fit(X)
    assert NMF(26, init="random", max_iter=5).fit(X).components_.shape == (26, 25)  # as sklearn: allowed
    with pytest.raises(ValueError, match=r"initial W must have shape \[n_samples, n_components\] = \[60, 5\]"):
        NMF(5).fit(X, W=W0[:, :4], H=H0)
    with pytest.raises(ValueError, match="initial H"):
        NMF(5).fit(X, W=W0, H=H0.T)
    with pytest.raises(ValueError, match="both W and H"):
        NMF(5).fit(X, W=W0)
    with pytest.raises(ValueError, match="n_components"):
        NMF(0).fit(X)
    with pytest.raises(ValueError, match="beta_loss"):
        NMF(5, beta_loss="itakura-saito").fit(X)
    with pytest.raises(ValueError, match="graph is empty"):
        GNMF(5).fit(X, graph=np.zeros((60, 60)))
    with pytest.raises(ValueError, match="graph is empty"):
        NMC(5, graph=sp.eye(60)).fit(X)
    with pytest.raises(ValueError, match=r"expected \[60, 60\]"):
        NMC(5, graph=np.ones((59, 59))).fit(X)
    with pytest.raises(ValueError, match="eta"):
        NMC(5, eta=2.0).fit(X)
    with pytest.raises(RuntimeError, match="not fitted"):
        NMF(5).transform(X)


def test_divergence_raises_instead_of_returning_nan(data):
    X, W0, H0 = data
    W_huge = W0 * 1e300
    with pytest.raises(FloatingPointError, match="iteration"):
        NMF(5, max_iter=10).fit(X, W=W_huge, H=H0 * 1e300)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu(data):
    X, W0, H0 = data
    for cls in (NMF, NMC):
        cpu = cls(5, max_iter=50, tol=0).fit(X, W=W0, H=H0)
        gpu = cls(5, max_iter=50, tol=0, device="cuda").fit(X, W=W0, H=H0)
        assert np.allclose(cpu.components_, gpu.components_, rtol=1e-8, atol=1e-10)
