"""PSC (Wang 2017 ch. 3), robust filter bases (Lou 2012 ch. 2) and DynaMMo (Li et al. 2009) as refiners.

Small dictionaries / few iterations throughout so that the file runs in well under a minute on one core.
"""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from mocapkit.motion.container import Motion
from mocapkit.refinement import RefinementError, corrupt
from mocapkit.refinement.dynammo import DynaMMo
from mocapkit.refinement.filter_bases import FilterBasesRefiner
from mocapkit.refinement.gap_filling import LinearInterpolation
from mocapkit.refinement.metrics import matrix_rmse
from mocapkit.refinement.psc import PSCRefiner
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
FPS = 120.0


def synthetic(frames: int = 420, joints: int = 8, seed: int = 0, mixing_seed: int = 0) -> Motion:
    """Smooth multi-marker take: 3·joints channels mixing three sinusoids (0.8, 1.3, 2.1 Hz), metres.

    ``mixing_seed`` fixes the "body" (the mixing matrix and the rest pose); ``seed`` the phases/amplitudes.
    """
    body = np.random.default_rng(mixing_seed)
    mixing = body.normal(scale=0.08, size=(6, 3 * joints))
    rest = body.uniform(-0.5, 0.5, size=3 * joints) + np.tile([0.0, 1.0, 0.0], joints)
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / FPS
    phases, amps = rng.uniform(0, 2 * np.pi, 3), rng.uniform(0.7, 1.3, 3)
    latent = np.concatenate(
        [
            [a * np.sin(2 * np.pi * f * t + p), a * np.cos(2 * np.pi * f * t + p)]
            for f, p, a in zip((0.8, 1.3, 2.1), phases, amps, strict=True)
        ]
    ).T  # [frames, 6]
    positions = (latent @ mixing + rest).reshape(frames, joints, 3)
    return Motion(
        positions=positions, joint_names=tuple(f"m{j}" for j in range(joints)), fps=FPS, name=f"synthetic{seed}"
    )


def with_gap(motion: Motion, joints=(2, 5), start: int = 200, length: int = 30) -> Motion:
    missing = np.zeros(motion.missing.shape, bool)
    missing[start : start + length, list(joints)] = True
    return Motion(
        positions=motion.positions, joint_names=motion.joint_names, fps=motion.fps, missing=missing, name=motion.name
    )


def assert_observed_kept(out: Motion, corrupted: Motion) -> np.ndarray:
    """Observed entries come back bit-identical unless the method reports them repaired; returns the changed mask."""
    observed = ~corrupted.missing
    changed = observed & (out.positions != corrupted.positions).any(axis=2)
    assert int(changed.sum()) == out.metadata["refinement"]["repaired"]
    assert not out.missing.any()
    return changed


def small_filter_bases(**kw) -> FilterBasesRefiner:
    return FilterBasesRefiner(**{"max_iter": 60, **kw})


def small_psc(**kw) -> PSCRefiner:
    return PSCRefiner(**{"n_atoms": 96, "n_neighbors": 10, "max_iter": 6, "max_train_windows": 3000, **kw})


# ---------------------------------------------------------------------------------------- contract


@pytest.mark.parametrize("make", [small_psc, small_filter_bases])
def test_refine_before_fit_raises_not_fitted(make):
    with pytest.raises(NotFittedError):
        make().refine(with_gap(synthetic()))


@pytest.mark.parametrize("make", [small_psc, small_filter_bases])
def test_layout_mismatch_names_the_missing_joints(make):
    refiner = make().fit([synthetic(seed=1)])
    other = synthetic(seed=2)
    renamed = Motion(positions=other.positions, joint_names=other.joint_names[:-1] + ("elsewhere",), fps=FPS)
    with pytest.raises(RefinementError, match="m7"):
        refiner.refine(renamed)


def test_psc_poselet_joints_absent_from_layout_are_named():
    with pytest.raises(RefinementError, match="lwrist"):
        small_psc(poselets={"arm": ("m0", "m1", "lwrist")}).fit([synthetic()])


# ---------------------------------------------------------------------------------------- DynaMMo


def test_dynammo_fills_gap_of_correlated_sinusoids_and_keeps_observed():
    clean = synthetic(seed=3)
    gapped = with_gap(clean)
    out = DynaMMo(hidden_dim=8, max_iter=60).refine(gapped)  # 6 latent sinusoid states + slack for the means
    changed = assert_observed_kept(out, gapped)
    assert not changed.any()  # a pure gap filler flags nothing
    linear = LinearInterpolation().refine(gapped)
    err, lin = matrix_rmse(clean, out, gapped.missing), matrix_rmse(clean, linear, gapped.missing)
    assert err < 0.1 * lin, (err, lin)


def test_dynammo_log_likelihood_never_decreases():
    clean = synthetic(seed=4, frames=300)
    gapped = corrupt(clean, "random_missing", 0.3, seed=0).motion
    model = DynaMMo(hidden_dim=8, max_iter=40, tol=0.0)
    model.refine(gapped)
    ll = np.asarray(model.log_likelihood_)
    assert len(ll) == model.n_iter_ == 40
    assert (np.diff(ll) >= -1e-8 * np.abs(ll[1:])).all(), np.diff(ll).min()
    assert ll[-1] > ll[0]


def test_dynammo_leaves_never_observed_marker_missing():
    gapped = synthetic(seed=5, frames=200)
    missing = np.zeros(gapped.missing.shape, bool)
    missing[:, 3] = True
    missing[50:80, 1] = True
    gapped = Motion(positions=gapped.positions, joint_names=gapped.joint_names, fps=FPS, missing=missing)
    out = DynaMMo(hidden_dim=4, max_iter=10).refine(gapped)
    assert out.missing[:, 3].all() and not out.missing[:, 1].any()
    assert out.metadata["refinement"]["unfilled"] == {"m3": 200}


# ---------------------------------------------------------------------------------------- filter bases


def test_filter_bases_fill_gap_better_than_linear():
    train = [synthetic(seed=s) for s in (10, 11, 12)]
    refiner = small_filter_bases().fit(train)
    clean = synthetic(seed=13)
    gapped = with_gap(clean)
    out = refiner.refine(gapped)
    assert_observed_kept(out, gapped)
    err = matrix_rmse(clean, out, gapped.missing)
    lin = matrix_rmse(clean, LinearInterpolation().refine(gapped), gapped.missing)
    assert err < 0.5 * lin, (err, lin)


def test_filter_bases_flag_and_repair_a_20cm_spike():
    refiner = small_filter_bases().fit([synthetic(seed=s) for s in (20, 21)])
    clean = synthetic(seed=22)
    positions = clean.positions.copy()
    positions[150, 4] += np.float32(0.2) * np.array([0.6, 0.0, 0.8], np.float32)
    spiked = Motion(positions=positions, joint_names=clean.joint_names, fps=FPS)
    out = refiner.refine(spiked)
    changed = assert_observed_kept(out, spiked)
    assert changed[150, 4]
    assert changed.sum() <= 3  # the spike, at most its neighbours
    assert np.linalg.norm(out.positions[150, 4] - clean.positions[150, 4]) < 0.02
    assert refiner.weights_[150, 4] < refiner.outlier_weight


def test_filter_bases_training_needs_a_full_window():
    with pytest.raises(RefinementError, match="no fully observed training window"):
        FilterBasesRefiner().fit([synthetic(frames=40)])


# ---------------------------------------------------------------------------------------- PSC


def test_psc_fills_synthetic_gap_better_than_linear():
    refiner = small_psc(tdd_threshold=None).fit([synthetic(seed=s) for s in (30, 31, 32, 33)])
    clean = synthetic(seed=34)
    gapped = with_gap(clean, joints=(2, 6))
    out = refiner.refine(gapped)
    assert not assert_observed_kept(out, gapped).any()
    err = matrix_rmse(clean, out, gapped.missing)
    lin = matrix_rmse(clean, LinearInterpolation().refine(gapped), gapped.missing)
    assert err < 0.5 * lin, (err, lin)


def test_psc_trust_data_detection_flags_a_spike():
    refiner = small_psc().fit([synthetic(seed=s) for s in (40, 41)])
    clean = synthetic(seed=42)
    positions = clean.positions.copy()
    positions[100, 3, 1] += 0.2
    spiked = Motion(positions=positions, joint_names=clean.joint_names, fps=FPS)
    out = refiner.refine(spiked)
    changed = assert_observed_kept(out, spiked)
    assert changed[100, 3] and changed.sum() == 1
    assert np.linalg.norm(out.positions[100, 3] - clean.positions[100, 3]) < 0.05


@needs(HDM05)
def test_psc_trained_on_two_hdm05_performers_beats_linear_on_the_third():
    from mocapkit.datasets import read_motion

    def clips(actor, step):
        return [read_motion(p) for p in sorted((HDM05 / actor).glob("*.amc"))[::step]]

    train = clips("bd", 4) + clips("bk", 4)
    test = clips("mm", 6)
    refiner = PSCRefiner(n_atoms=128, n_neighbors=20, llc_lambda=1e-3, max_iter=5, max_train_windows=4000).fit(train)
    errors, linear = [], []
    for k, clean in enumerate(test):
        c = corrupt(clean, "continuous_missing", 30, seed=k)
        out = refiner.refine(c.motion)
        assert_observed_kept(out, c.motion)
        errors.append(matrix_rmse(clean, out, c.removed))
        linear.append(matrix_rmse(clean, LinearInterpolation().refine(c.motion), c.removed))
    assert np.mean(errors) < np.mean(linear), (errors, linear)
