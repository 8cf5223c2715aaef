"""The SLFM (linear model of coregionalisation) and the Zhou 2014 ch. 4 synthesiser (mocapkit.synthesis.slfm),
the ``synthesize`` library function and ``mocapkit synthesize``."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from mocapkit.cli import main
from mocapkit.datasets.formats.asf_amc import amc_motion, read_amc, write_amc
from mocapkit.synthesis.clips import SynthesisInputError, dof_matrix
from mocapkit.synthesis.representation import encode
from mocapkit.synthesis.slfm import (
    SLFMParams,
    SLFMPosterior,
    SLFMRegressor,
    SLFMSynthesizer,
    StackedSLFM,
    fit_slfm_hyperparameters,
    slfm_covariance,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
HOPS = [
    HDM05 / actor / f"HDM_{actor}_hopBothLegs1hops_{n:03d}_120.amc"
    for actor, n in (("bd", 1), ("bd", 2), ("bk", 13), ("dg", 22), ("mm", 31))
]
TINY = {"frame_stride": 8, "n_fit": 24, "n_inducing": 10, "max_iter": 2}


def _params(D: int = 3, seed: int = 0) -> SLFMParams:
    rng = np.random.default_rng(seed)
    return SLFMParams(
        lengthscale=rng.uniform(0.5, 2.0, D),
        bias=rng.uniform(0.0, 0.3, D),
        mixing=rng.normal(size=(D, D)),
        noise=rng.uniform(0.01, 0.1, D),
    )


def test_full_cross_covariance_is_sum_of_kronecker_products():
    params = _params()
    rng = np.random.default_rng(1)
    X1, X2 = rng.normal(size=(5, 2)), rng.normal(size=(4, 2))
    expected = np.zeros((15, 12))
    for p in range(3):
        K = np.array(
            [
                [np.exp(-np.sum((a - b) ** 2) / (2 * params.lengthscale[p] ** 2)) + params.bias[p] for b in X2]
                for a in X1
            ]
        )
        expected += np.kron(np.outer(params.mixing[:, p], params.mixing[:, p]), K)
    np.testing.assert_allclose(slfm_covariance(params, X1, X2), expected, rtol=1e-12)


def test_gpytorch_lcm_kernel_is_the_same_model():
    import torch

    from mocapkit.synthesis.slfm import _gpytorch_model

    params = _params()
    X = np.random.default_rng(2).normal(size=(6, 2))
    model = _gpytorch_model(torch.as_tensor(X), torch.zeros(6, 3, dtype=torch.float64), 3, 1e-4)
    with torch.no_grad():
        for p, multitask in enumerate(model.covar_module.covar_module_list):
            rbf, constant = multitask.data_covar_module.kernels
            rbf.lengthscale = float(params.lengthscale[p])
            constant.constant = torch.tensor(params.bias[p], dtype=torch.float64)
            multitask.task_covar_module.covar_factor.copy_(torch.as_tensor(params.mixing[:, p : p + 1]))
        dense = model.covar_module(torch.as_tensor(X)).to_dense().numpy()
    output_major = np.arange(18).reshape(6, 3).T.reshape(-1)  # GPyTorch interleaves: row n·D + i
    np.testing.assert_allclose(dense[np.ix_(output_major, output_major)], slfm_covariance(params, X, X), atol=1e-6)


def test_posterior_with_all_inducing_inputs_is_the_exact_gp_and_interpolates():
    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, (25, 2))
    Y = np.stack([np.sin(X[:, 0]), np.cos(X[:, 1]), X[:, 0] * X[:, 1] / 3], axis=1)
    params = _params()
    params.lengthscale[:] = 1.0
    params.noise[:] = 1e-6
    posterior = SLFMPosterior(params, X, Y, X)
    mean, cov = posterior.predict(X)
    np.testing.assert_allclose(mean, Y, atol=2e-3)  # low noise: the mean goes through the training outputs
    assert np.all(np.linalg.eigvalsh(cov) > -1e-8)
    # against the exact GP written out: Cov(f*, y) (K + noise)⁻¹ y
    Xq = rng.uniform(-2, 2, (4, 2))
    params.noise[:] = 0.05
    K = slfm_covariance(params, X, X) + np.kron(np.diag(params.noise), np.eye(len(X)))
    cross = slfm_covariance(params, Xq, X)
    exact_mean = (cross @ np.linalg.solve(K, Y.T.reshape(-1))).reshape(3, -1).T
    exact_cov = slfm_covariance(params, Xq, Xq) - cross @ np.linalg.solve(K, cross.T)
    mean, cov = SLFMPosterior(params, X, Y, X).predict(Xq)
    np.testing.assert_allclose(mean, exact_mean, atol=1e-4)
    for v in range(4):
        np.testing.assert_allclose(cov[v], exact_cov[v::4, v::4], atol=1e-4)


def test_hyperparameter_fit_and_stacked_prediction():
    rng = np.random.default_rng(4)
    X = rng.normal(size=(40, 3))
    Y = np.stack([np.sin(X[:, 0]) + 0.5 * X[:, 1], np.cos(X[:, 1]), np.zeros(40) + 2.0], axis=1)
    Y[:, :2] += 0.01 * rng.standard_normal((40, 2))
    params = fit_slfm_hyperparameters(
        (X - X.mean(0)) / X.std(0), (Y[:, :2] - Y[:, :2].mean(0)) / Y[:, :2].std(0), max_iter=15
    )
    assert np.all(np.isfinite(params.mixing)) and np.all(params.noise >= 1e-4) and np.all(params.noise < 0.5)
    a = SLFMRegressor(n_fit=30, n_inducing=20, max_iter=5).fit(X, Y, np.random.default_rng(0))
    b = SLFMRegressor(n_fit=30, n_inducing=12, max_iter=5, mean_function="zero").fit(
        X[:, :2], Y[:, :2], np.random.default_rng(1)
    )
    mean_a, cov_a = a.predict(X[:5], noise=True)
    assert np.allclose(mean_a[:, 2], 2.0) and np.allclose(cov_a[:, 2], 0.0)  # a constant output is not modelled
    assert np.abs(mean_a[:, :2] - Y[:5, :2]).max() < 0.2
    stacked = StackedSLFM([a, b])
    padded = np.zeros((2, 5, 3))
    padded[0], padded[1, :, :2] = X[:5], X[:5, :2]
    mean, cov = stacked.predict(padded, noise=True)
    mean_b, cov_b = b.predict(X[:5, :2], noise=True)
    np.testing.assert_allclose(mean[0], mean_a, atol=1e-9)
    np.testing.assert_allclose(cov[0], cov_a, atol=1e-9)
    np.testing.assert_allclose(mean[1, :, :2], mean_b, atol=1e-9)
    np.testing.assert_allclose(cov[1, :, :2, :2], cov_b, atol=1e-9)
    draws = stacked.sample(padded, np.random.default_rng(0))
    assert draws.shape == (2, 5, 3) and np.all(np.isfinite(draws))


# --------------------------------------------------------------------------- the synthesiser on real clips


@pytest.fixture(scope="module")
def hops():
    return [read_amc(path) for path in HOPS]


@pytest.fixture(scope="module")
def fitted(hops):
    return SLFMSynthesizer(**TINY, random_state=0).fit(hops)


@needs(HDM05)
def test_variants_are_new_finite_motions_in_range(hops, fitted, tmp_path):
    variants = fitted.sample(3, n_frames=60, seed=5)
    skeleton = hops[0].metadata["asf"]
    assert len(variants) == 3
    for v in variants:
        assert v.positions.shape == (60, len(skeleton.joint_names), 3)
        assert v.metadata["asf"] is skeleton and np.all(np.isfinite(v.positions))
    path = tmp_path / "variant.amc"
    write_amc(path, variants[0])
    again = read_amc(path, asf=skeleton)
    np.testing.assert_allclose(again.positions, variants[0].positions, atol=1e-5)

    # different from each other and from every training clip (root-relative joint positions)
    def pose(m, n=60):
        p = m.positions[:n].astype(float)
        return p - p[:, :1]

    for i in range(3):
        for j in range(i + 1, 3):
            assert np.abs(pose(variants[i]) - pose(variants[j])).mean() > 0.005
        for clip in hops:
            n = min(60, len(clip.positions))
            assert np.abs(pose(variants[i], n) - pose(clip, n)).mean() > 0.005
    # in range: root height and every feature within the training range ± half of it (+ 0.2 rad)
    train = np.concatenate([encode(c).flat() for c in hops])
    low, high = train.min(0), train.max(0)
    margin = 0.5 * (high - low) + 0.2
    for v in variants:
        f = encode(v).flat()
        assert np.all(f[:, 3:] >= (low - margin)[3:]) and np.all(f[:, 3:] <= (high + margin)[3:])
    heights = np.concatenate([dof_matrix(v)[0][:, 1] for v in variants])
    train_heights = np.concatenate([dof_matrix(c)[0][:, 1] for c in hops])
    spread = np.ptp(train_heights)
    assert train_heights.min() - 0.5 * spread < heights.min() and heights.max() < train_heights.max() + 0.5 * spread


@needs(HDM05)
def test_sampling_options(fitted):
    params = fitted.get_params()
    assert params["frame_stride"] == 8 and params["footskate_cleanup"] is True
    a = fitted.sample(2, n_frames=20, seed=1)
    assert len(fitted.footskate_reports_) == 2
    again = fitted.sample(2, n_frames=20, seed=1)
    np.testing.assert_array_equal(a[0].positions, again[0].positions)
    clone = copy.deepcopy(fitted).set_params(sample_noise=False, footskate_cleanup=False)
    b = clone.sample(2, n_frames=20, seed=1)
    assert not np.allclose(a[0].positions, b[0].positions)
    assert len(fitted.sample(1, seed=0)[0].positions) == fitted.mean_frames_


@needs(HDM05)
def test_correlated_noise_gives_smoother_variants_than_independent_draws(fitted):
    from mocapkit.synthesis.metrics import mean_jerk

    def jerk(rho):
        model = copy.deepcopy(fitted).set_params(
            noise_correlation=rho, footskate_cleanup=False, smoothing_seconds=0.0
        )  # the draws alone
        return np.mean([mean_jerk(v) for v in model.sample(4, n_frames=60, seed=3)])

    assert jerk(0.9) < 0.8 * jerk(0.0)


def test_given_standard_normals_are_mapped_through_the_covariance():
    from mocapkit.synthesis.slfm import gaussian_samples

    mean = np.array([[1.0, -1.0]])
    cov = np.array([[[4.0, 0.0], [0.0, 9.0]]])
    z = np.array([[0.5, -2.0]])
    out = gaussian_samples(mean, cov, np.random.default_rng(0), z)
    np.testing.assert_allclose(np.sort(np.abs(out - mean)[0]), np.sort([2 * 0.5, 3 * 2.0]))


@needs(HDM05)
def test_scf_difference_dynamic_feature(hops):
    model = SLFMSynthesizer(**TINY, dynamic_feature="scf_difference", footskate_cleanup=False).fit(hops[:2])
    (variant,) = model.sample(1, n_frames=10, seed=0)
    assert np.all(np.isfinite(variant.positions))
    with pytest.raises(ValueError, match="dynamic_feature"):
        SLFMSynthesizer(dynamic_feature="angles").fit(hops[:2])


@needs(HDM05)
def test_bad_training_sets(hops):
    with pytest.raises(SynthesisInputError, match="at least 2"):
        SLFMSynthesizer(**TINY).fit(hops[:1])
    skeleton = hops[0].metadata["asf"]
    short = amc_motion(skeleton, {b: v[:3] for b, v in hops[1].metadata["amc_values"].items()}, source="short_clip.amc")
    with pytest.raises(SynthesisInputError, match="short_clip.amc has 3 frames"):
        SLFMSynthesizer(**TINY).fit([hops[0], short])
    other = copy.deepcopy(skeleton)
    other.bone("lfemur").dof = ("rx", "ry")
    values = {b: np.array(v) for b, v in hops[1].metadata["amc_values"].items()}
    values["lfemur"] = values["lfemur"][:, :2]
    mismatched = amc_motion(other, values, source="other_skeleton.amc")
    with pytest.raises(SynthesisInputError, match="other_skeleton.amc has a different skeleton"):
        SLFMSynthesizer(**TINY).fit([hops[0], mismatched])


@needs(HDM05)
def test_cli_end_to_end(tmp_path, capsys):
    out = tmp_path / "variants"
    settings = [f"--set={k}={v}" for k, v in TINY.items()]
    code = main(
        [
            "synthesize",
            str(HDM05 / "bd"),
            "--type",
            "hopBothLegs1hops",
            "--max-clips",
            "3",
            "--out",
            str(out),
            "--variants",
            "2",
            "--frames",
            "30",
            "--seed",
            "3",
            "--quiet",
            *settings,
        ]
    )
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert len(report["training_clips"]) == 3 and report["variants"] == ["variant_000.amc", "variant_001.amc"]
    assert report["fit_seconds"] > 0 and report["sample_seconds_per_motion_second"] > 0
    assert report["parameters"]["n_fit"] == TINY["n_fit"] and "footskate_sliding_m_per_s" in report
    assert len(report["footskate_root_shift_m"]["horizontal_max"]) == 2
    assert report["noise_scale"] == float(list(report["variation_by_noise_scale"])[-1])
    assert "angle_flips" not in report  # the three bd hops have none
    variant = read_amc(out / "variant_001.amc", asf=out / "HDM_bd.asf")
    assert variant.positions.shape[0] == 30 and np.all(np.isfinite(variant.positions))


def test_cli_errors(tmp_path, capsys):
    assert main(["synthesize", str(tmp_path), "--type", "noSuchMotion", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no AMC or BVH clips matching *noSuchMotion*.amc / *noSuchMotion*.bvh" in err and str(tmp_path) in err
    assert main(["synthesize", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file or folder" in capsys.readouterr().err


DEEP_SQUAT = HDM05 / "dg" / "HDM_dg_squat1Reps_025_120.amc"


@needs(HDM05)
def test_angle_flips_of_a_real_deep_squat_and_none_in_hops(hops):
    from mocapkit.synthesis.representation import angle_flips

    squat = read_amc(DEEP_SQUAT)
    flips = angle_flips(squat)
    # the knee passes 180°: lfemur turns 180° in one frame while the joint positions move by millimetres
    assert (83, "lfemur") in {(frame, bone) for frame, bone, _ in flips}
    assert all(degrees > 45 for _, _, degrees in flips)
    step = np.linalg.norm(squat.positions[83] - squat.positions[82], axis=1).max()
    assert step < 0.06
    assert all(angle_flips(clip) == [] for clip in hops)
    assert angle_flips(squat, max_turn_speed=1e6) == []


@needs(HDM05)
def test_clip_segment_is_the_frames_of_the_clip(hops):
    from mocapkit.synthesis.clips import clip_segment

    piece = clip_segment(hops[0], 10, 30)
    assert piece.num_frames == 20 and piece.fps == hops[0].fps and piece.source.endswith("[10:30]")
    np.testing.assert_allclose(piece.positions, hops[0].positions[10:30], atol=1e-9)


@needs(HDM05)
def test_fit_cuts_training_clips_at_angle_flips_and_says_so(hops):
    squat = read_amc(DEEP_SQUAT)
    with pytest.warns(
        UserWarning, match=r"HDM_dg_squat1Reps_025_120.amc: joint-angle flips \(.*lfemur 180° at frame 83"
    ):
        model = SLFMSynthesizer(**TINY, footskate_cleanup=False).fit([squat, hops[0]])
    assert ("lfemur", 83) in {(bone, frame) for _, frame, bone, _ in model.angle_flips_}
    assert all(label.endswith("HDM_dg_squat1Reps_025_120.amc") for label, *_ in model.unused_pieces_)
    # the pieces' first frames are not clip starts: the first-frame statistics come from the two clips only
    assert np.all(np.isfinite(model.sample(1, n_frames=20, seed=0)[0].positions))
    kept = SLFMSynthesizer(**TINY, footskate_cleanup=False, max_turn_speed=None).fit([squat, hops[0]])
    assert kept.angle_flips_ == [] and kept.unused_pieces_ == []


@needs(HDM05)
def test_noise_scale_shrinks_the_spread_of_the_variants(fitted):
    from mocapkit.synthesis.metrics import variation

    def spread(scale):
        model = copy.deepcopy(fitted).set_params(noise_scale=scale, footskate_cleanup=False)
        return variation(model.sample(4, n_frames=40, seed=5)).v

    # the variants also differ by their drawn first frames, so the spread does not vanish at scale 0
    assert spread(0.0) < spread(0.5) < spread(1.0)


@needs(HDM05)
def test_output_margin_keeps_draws_in_the_training_range(fitted):
    sampler = fitted.samplers_["t>3"]
    G, D = sampler.stack.y_mean.shape
    context = np.full((3, sampler.gather.max() + 1), 50.0)
    context[:, -1] = 0.0
    huge = np.full((G, 3, D), 40.0)
    _, draws = sampler.draw(context, np.random.default_rng(0), True, huge, output_margin=0.0)
    low = sampler.stack.y_low.reshape(-1)[sampler.slots]
    high = sampler.stack.y_high.reshape(-1)[sampler.slots]
    assert np.all(draws >= low - 1e-9) and np.all(draws <= high + 1e-9)
    _, free = sampler.draw(context, np.random.default_rng(0), True, huge)
    assert np.any((free < low - 1e-6) | (free > high + 1e-6))


@needs(HDM05)
def test_auto_noise_scale_is_the_smallest_reaching_the_target_variation(fitted, hops):
    from mocapkit.synthesis.slfm import NOISE_SCALES

    tried = fitted.variation_by_noise_scale_
    assert list(tried) == list(NOISE_SCALES[: len(tried)]) and fitted.noise_scale_ == list(tried)[-1]
    ratios = list(tried.values())
    assert all(r < fitted.target_variation for r in ratios[:-1])
    assert ratios[-1] >= fitted.target_variation or fitted.noise_scale_ == NOISE_SCALES[-1]
    # a higher target needs at least as much noise
    wider = SLFMSynthesizer(**TINY, random_state=0, target_variation=ratios[-1] + 0.5).fit(hops)
    assert wider.noise_scale_ >= fitted.noise_scale_
    fixed = SLFMSynthesizer(**TINY, noise_scale=0.4).fit(hops[:2])
    assert fixed.noise_scale_ == 0.4 and fixed.variation_by_noise_scale_ == {}
    with pytest.raises(ValueError, match="noise_scale"):
        SLFMSynthesizer(**TINY, noise_scale="large").fit(hops[:2])


@needs(HDM05)
def test_cross_partition_gives_the_limbs_the_roots_pose_and_step(hops):
    def inputs(model, node):
        (found,) = [m for m in model.models_ if m.node == node and m.case == "t>3"]
        return {(state, back): set(columns.tolist()) for state, back, columns in found.inputs}

    literal = SLFMSynthesizer(**TINY, footskate_cleanup=False, noise_scale=0.5, cross_partition=False).fit(hops[:2])
    coupled = SLFMSynthesizer(**TINY, footskate_cleanup=False, noise_scale=0.5).fit(hops[:2])
    root_pose, root_step = (set(c.tolist()) for c in coupled._columns("root"))
    for node in ("ltibia", "rhumerus"):
        before, after = inputs(literal, node), inputs(coupled, node)
        for back in (1, 2):
            assert (
                not before[("flat", back)] & root_pose and after[("flat", back)] == before[("flat", back)] | root_pose
            )
            assert after[("dynamic", back)] == before[("dynamic", back)] | root_step
    assert inputs(literal, "lowerback") == inputs(coupled, "lowerback")  # TH holds the root already
    with pytest.raises(ValueError, match="cross_partition must be True or False, got 'false'"):
        SLFMSynthesizer(**TINY, cross_partition="false").fit(hops[:2])
    with pytest.raises(ValueError, match="footskate_root must be one of"):
        SLFMSynthesizer(**TINY, footskate_root="sideways").fit(hops[:2])
    (variant,) = coupled.sample(1, n_frames=20, seed=0)
    assert np.all(np.isfinite(variant.positions))
