"""The low-rank refiners of Wang 2017 ch. 4: LRMF (§4.1, Algorithm 2) and TrNN (§4.2, Algorithm 3).

Synthetic checks of the corrected ALM updates (constraint residuals → 0, RPCA and completion recovery), the DCT
smoothness solve, the refiner contract (observed entries bit-identical unless flagged), a real HDM05 clip with
10 markers × 60-frame gaps against linear interpolation, and the errors for inputs the methods cannot handle.
"""

import numpy as np
import pytest
import scipy.fft
import torch
from sklearn.base import clone

from mocapkit.motion.container import Motion
from mocapkit.refinement.base import RefinementError
from mocapkit.refinement.gap_filling import linear_fill
from mocapkit.refinement.lrmf import (
    CMU_UNIT,
    LRMF,
    _dct_fft,
    _idct_fft,
    apply_second_difference,
    dct,
    idct,
    lrmf,
    lsj_rank,
    second_difference,
    smooth_solve,
)
from mocapkit.refinement.trnn import TrNN, trnn
from tests.shared_data import SHARED, needs

HDM_BD = SHARED / "data" / "hdm05_cuts11" / "bd"


def smooth_low_rank(frames=300, features=93, rank=3, scale=10.0, seed=0) -> np.ndarray:
    """``[frames, features]`` = smooth temporal factors (slow sinusoids) × random loadings, rank ``rank``."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, frames)[:, None]
    A = np.sin(2 * np.pi * rng.uniform(0.5, 3, rank) * t + rng.uniform(0, 2 * np.pi, rank))
    return scale * A @ rng.standard_normal((rank, features)) / np.sqrt(rank)


def relative_error(estimate, truth) -> float:
    return float(np.linalg.norm(estimate - truth) / np.linalg.norm(truth))


def synthetic_motion(frames=240, joints=12, seed=0) -> Motion:
    X = smooth_low_rank(frames, 3 * joints, rank=5, scale=0.3, seed=seed)
    X += np.tile([0.0, 1.0, 0.0], joints)  # standing about 1 m up
    return Motion(X.reshape(frames, joints, 3), [f"m{j}" for j in range(joints)], 120.0)


# --------------------------------------------------------------------------- numerical pieces


def test_dct_matches_scipy_and_diagonalises_the_second_difference():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 8, 101):
        x = rng.standard_normal((n, 4))
        ref = scipy.fft.dct(x, axis=0, norm="ortho")
        assert np.allclose(dct(torch.tensor(x)).numpy(), ref, atol=1e-12)
        assert np.allclose(_dct_fft(torch.tensor(x)).numpy(), ref, atol=1e-12)  # the non-CPU path
        assert np.allclose(_idct_fft(torch.tensor(ref)).numpy(), x, atol=1e-12)
        assert np.allclose(idct(dct(torch.tensor(x.T.copy()), dim=1), dim=1).numpy(), x.T, atol=1e-12)
    n = 60
    O = second_difference(n)
    assert O[0, :2].tolist() == [-1, 1] and O[-1, -2:].tolist() == [1, -1]  # eq. 4.22, not 4.2
    xi = np.sort(2 * np.cos(np.pi * np.arange(n) / n) - 2)
    assert np.allclose(np.linalg.eigvalsh(O), xi, atol=1e-10)  # eigenvalues of eq. 4.25
    T = rng.standard_normal((n, 5))
    dense = np.linalg.solve(0.7 * np.eye(n) + 30.0 * O @ O, T)
    assert np.allclose(smooth_solve(torch.tensor(T), 0.7, 30.0).numpy(), dense, atol=1e-10)
    assert np.allclose(smooth_solve(torch.tensor(T.T.copy()), 0.7, 30.0, dim=1).numpy(), dense.T, atol=1e-10)
    assert np.allclose(apply_second_difference(torch.tensor(T)).numpy(), O @ T)


def test_interpolation_and_lsj_rank_rules():
    X = np.arange(10.0)[:, None] * [1.0, 2.0]
    observed = np.ones_like(X, bool)
    observed[3:6, 0] = observed[0, 1] = observed[9, 1] = False
    filled = linear_fill(np.where(observed, X, 0), observed, empty=0.0)
    assert np.allclose(filled[:, 0], X[:, 0])  # interior gap: exact for a line
    assert filled[0, 1] == 2.0 and filled[9, 1] == 16.0  # ends held
    s = np.array([100.0, 10.0, 9.0, 3.0, 2.95, 0.01])
    assert lsj_rank(s, 0.1, "absolute") == 5  # last gap >= 0.1 is σ5 − σ6
    assert lsj_rank(s, 0.1, "normalised") == 1  # only σ1 − σ2 is >= 0.1·σ1
    assert lsj_rank(s, 0.1, "largest") == 1
    with pytest.raises(ValueError, match="rule"):
        lsj_rank(s, 0.1, "median")


# --------------------------------------------------------------------------- the ALM solvers


def test_trnn_solves_synthetic_rpca_and_residual_vanishes():
    """Thesis §4.2.3 synthetic protocol (smaller): D = X* + S*, 10 % of entries replaced by U[−10, 10]."""
    rng = np.random.default_rng(1)
    m, n, r0 = 300, 150, 5
    truth = rng.standard_normal((m, r0)) @ rng.standard_normal((r0, n))
    D = truth.copy()
    hit = rng.random(D.shape) < 0.1
    D[hit] = rng.uniform(-10, 10, hit.sum())
    res = trnn(
        D.T,
        np.ones((n, m), bool),
        truncation=r0,
        width=6,
        lam=1 / np.sqrt(max(m, n)),
        mu=0.0,
        rho=1.5,
        eta=1.25 / np.linalg.norm(D, 2),
        tol=1e-7,
    )
    assert res.converged and res.n_iter < 100
    assert relative_error(res.low_rank.T, truth) < 1e-5  # NRE
    residuals = [h["residual"] for h in res.history]
    assert residuals[-1] < 1e-6 < residuals[0]
    assert (np.abs(res.sparse.T) > 1e-3)[hit].mean() > 0.95  # the outliers sit in S


@pytest.mark.parametrize("truncation", [0, 3])
def test_trnn_recovers_a_smooth_rank3_matrix_from_60_percent(truncation):
    X = smooth_low_rank(rank=3)
    observed = np.random.default_rng(2).random(X.shape) < 0.6
    res = trnn(np.where(observed, X, 0), observed, truncation=truncation, width=5)
    assert res.converged
    assert relative_error(res.low_rank, X) < 1e-2
    assert res.history[-1]["residual"] < 1e-4  # constraints hold at the end


def test_lrmf_residuals_vanish_and_recover_a_smooth_rank3_matrix():
    X = smooth_low_rank(rank=3, seed=3)
    observed = np.random.default_rng(4).random(X.shape) < 0.6
    res = lrmf(np.where(observed, X, 0), observed, width=4)
    assert res.converged
    assert relative_error(res.low_rank, X) < 1e-2
    residuals = [h["residual"] for h in res.history]
    assert residuals[-1] < 1e-4 and residuals[0] > 1e-1
    assert np.all(np.diff(np.log([h["penalty"] for h in res.history])) >= 0)  # λ schedule never decreases


def test_lrmf_puts_gross_outliers_in_the_sparse_term():
    X = smooth_low_rank(rank=3, seed=5)
    rng = np.random.default_rng(6)
    observed = rng.random(X.shape) < 0.8
    hit = observed & (rng.random(X.shape) < 0.02)
    D = X + np.where(hit, rng.choice([-1, 1], X.shape) * rng.uniform(5, 10, X.shape), 0)
    res = lrmf(np.where(observed, D, 0), observed, width=4)
    assert res.converged
    big = np.abs(res.sparse) > 2.0
    assert big[hit].mean() > 0.95 and big[~hit].mean() < 1e-3
    assert relative_error(res.low_rank, X) < 2e-2


# --------------------------------------------------------------------------- the refiner contract


@pytest.mark.parametrize("refiner", [TrNN(truncation=5), TrNN(truncation=0), LRMF()], ids=["trnn", "tsmc", "lrmf"])
def test_refine_fills_gaps_and_keeps_observed_entries(refiner):
    clean = synthetic_motion()
    missing = np.zeros_like(clean.missing)
    missing[50:90, [1, 4, 7]] = True
    missing[::7, 2] = True
    missing[:, 11] = True  # never observed: stays missing
    positions = clean.positions.copy()
    spikes = [(30, 3), (120, 5), (200, 9)]
    for f, j in spikes:
        positions[f, j] += [0.25, 0.0, 0.0]  # 25 cm outliers
    corrupted = Motion(positions, clean.joint_names, clean.fps, missing=missing)
    out = refiner.refine(corrupted)
    report = out.metadata["refinement"]
    assert report["unfilled"] == {"m11": 240}
    assert out.missing[:, 11].all() and not out.missing[:, :11].any()
    gap = missing[:, :11]
    err = np.linalg.norm(out.positions[:, :11] - clean.positions[:, :11], axis=2)
    X = np.nan_to_num(corrupted.positions.reshape(240, -1).astype(np.float64))
    linear = linear_fill(X, np.repeat(~missing, 3, axis=1), empty=0.0).reshape(240, 12, 3)[:, :11]
    assert err[gap].mean() < 0.75 * np.linalg.norm(linear - clean.positions[:, :11], axis=2)[gap].mean()
    # observed entries: bit-identical unless flagged, and the flagged ones are the spikes
    changed = ~(out.positions == corrupted.positions).all(axis=2) & ~corrupted.missing
    assert report["repaired"] == int(changed.sum())
    assert all(changed[f, j] for f, j in spikes) and changed.sum() <= len(spikes) + 2
    assert all(np.linalg.norm(out.positions[f, j] - clean.positions[f, j]) < 0.02 for f, j in spikes)
    # no flagging: every observed entry bit-identical
    keep = clone(refiner).set_params(outlier_threshold=None).refine(corrupted)
    assert keep.metadata["refinement"]["repaired"] == 0
    assert np.array_equal(keep.positions[~corrupted.missing], corrupted.positions[~corrupted.missing])


def test_parameters_stored_untouched_and_cloneable():
    t = TrNN(truncation=7, rank=20, lam=None, mu=50.0, device="cpu", dtype="float64")
    assert clone(t).get_params() == t.get_params()
    assert t.get_params()["rank"] == 20 and t.get_params()["dtype"] == "float64"
    assert LRMF(rank="auto").get_params()["rank"] == "auto"


@needs(HDM_BD)
def test_trnn_beats_linear_interpolation_on_hdm05_gaps():
    from mocapkit.datasets import read_motion
    from mocapkit.refinement.corruptions import corrupt
    from mocapkit.refinement.metrics import score_refinement

    clean = read_motion(HDM_BD / "HDM_bd_depositFloorR_001_120.amc", asf=HDM_BD / "HDM_bd.asf")
    corruption = corrupt(clean, "continuous_missing", 60, seed=0)  # 10 markers × 60 frames
    assert corruption.removed.sum() == 600
    refiner = TrNN()
    out = refiner.refine(corruption.motion)
    assert refiner.converged_ and refiner.width_ > refiner.truncation
    frames = clean.num_frames
    X = np.nan_to_num(corruption.motion.positions.reshape(frames, -1).astype(np.float64))
    observed = np.repeat(~corruption.motion.missing, 3, axis=1)
    linear = Motion(linear_fill(X, observed, empty=0.0).reshape(frames, -1, 3), clean.joint_names, clean.fps)
    ours, baseline = score_refinement(out, clean, corruption), score_refinement(linear, clean, corruption)
    assert ours.coverage == 1.0 and ours.changed_clean == 0
    assert ours.rmse_cm < 0.8 * baseline.rmse_cm, (ours.rmse_cm, baseline.rmse_cm)


# --------------------------------------------------------------------------- errors


def test_clear_errors_for_inputs_the_methods_cannot_handle():
    motion = synthetic_motion(frames=15)
    with pytest.raises(RefinementError, match=r"15 frames, TrNN needs at least 16"):
        TrNN().refine(motion)  # r = 15 < d <= frames
    with pytest.raises(RefinementError, match=r"truncation r=15 needs at least 16 frames"):
        TrNN()._refine_matrix(np.ones((15, 36)), np.ones((15, 36), bool))
    assert TrNN().refine(synthetic_motion(frames=16)).num_frames == 16
    TrNN(truncation=3).refine(motion)  # fine with a smaller r
    with pytest.raises(RefinementError, match="2 frames, LRMF needs at least 3"):
        LRMF().refine(synthetic_motion(frames=2))
    few = synthetic_motion(frames=100, joints=5)  # 15 coordinates < r + 1
    with pytest.raises(RefinementError, match=r"needs at least 16 observed coordinates"):
        TrNN().refine(few)
    with pytest.raises(ValueError, match="factor width"):
        trnn(np.ones((50, 9)), np.ones((50, 9), bool), truncation=4, width=4)
    with pytest.raises(ValueError, match="factor width"):
        lrmf(np.ones((50, 9)), np.ones((50, 9), bool), width=10)
    with pytest.raises(ValueError, match="rank must be"):
        TrNN(rank="big").refine(synthetic_motion())
    with pytest.raises(ValueError, match="unit"):
        LRMF(unit=0).refine(synthetic_motion())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    X = smooth_low_rank(rank=3)
    observed = np.random.default_rng(2).random(X.shape) < 0.6
    a = trnn(np.where(observed, X, 0), observed, truncation=3, width=5)
    b = trnn(np.where(observed, X, 0), observed, truncation=3, width=5, device="cuda")
    assert abs(a.n_iter - b.n_iter) <= 2 and relative_error(b.low_rank, a.low_rank) < 1e-3  # same to ~tol
    c = lrmf(np.where(observed, X, 0), observed, width=4, device="cuda")
    assert relative_error(c.low_rank, X) < 1e-2
    assert CMU_UNIT == pytest.approx(0.056444)
