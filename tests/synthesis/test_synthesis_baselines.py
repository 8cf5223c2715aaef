"""The baselines of motion-variation synthesis on real HDM05 hops: training-clip copies, Perlin noise
(mocapkit/synthesis/perlin.py), the Lau et al. kernel-regression DBN (lau.py) and the autoregressive CVAE (cvae.py,
mocapkit/models/motion_vae.py, mocapkit/synthesis/module.py)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from mocapkit.datasets.formats.asf_amc import read_amc
from mocapkit.datasets.formats.bvh import read_bvh
from mocapkit.motion.container import Motion
from mocapkit.synthesis.clips import SynthesisInputError, dof_matrix, dof_values, smooth_values, time_warp
from mocapkit.synthesis.cvae import CVAESynthesizer
from mocapkit.synthesis.lau import LauDBNSynthesizer
from mocapkit.synthesis.perlin import (
    CopyTrainingClips,
    PerlinNoiseSynthesizer,
    perlin_noise,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
HOPS = sorted(HDM05.glob("*/HDM_*_hopBothLegs1hops_*_120.amc"))
FAST_CVAE = {"hidden": 64, "latent": 8, "steps": 150, "batch_size": 128}


def _methods():
    return {
        "copy": CopyTrainingClips(),
        "perlin": PerlinNoiseSynthesizer(),
        "lau": LauDBNSynthesizer(widths=(0.05, 0.2, 0.35, 0.5, 4.0)),
        "cvae": CVAESynthesizer(**FAST_CVAE),
    }


@pytest.fixture(scope="module")
def hops():
    """Five hops of three performers for training, three others held out (the clips are 56–151 frames)."""
    clips = [read_amc(path) for path in HOPS[::4]]
    return clips[:5], clips[5:8]


@pytest.fixture(scope="module")
def fitted(hops):
    train, _ = hops
    return {name: method.fit(train) for name, method in _methods().items()}


@needs(HDM05)
@pytest.mark.parametrize("name", ["copy", "perlin", "lau", "cvae"])
def test_samples_finite_variants_on_the_reference_skeleton(fitted, hops, name):
    synthesizer = fitted[name]
    variants = synthesizer.sample(3, n_frames=40, seed=1)
    assert len(variants) == 3
    for v in variants:
        assert v.num_frames == 40 and np.isfinite(v.positions).all()
        assert v.metadata["asf"] is hops[0][0].metadata["asf"] and v.fps == 120.0
        assert np.isfinite(dof_matrix(v)[0]).all()
    again = synthesizer.sample(3, n_frames=40, seed=1)
    other = synthesizer.sample(3, n_frames=40, seed=2)
    np.testing.assert_array_equal(variants[0].positions, again[0].positions)
    assert any(not np.allclose(a.positions, b.positions) for a, b in zip(variants, other))
    assert synthesizer.sample(2, seed=0)[0].num_frames == synthesizer.mean_frames_


@needs(HDM05)
def test_copies_are_the_training_clips(fitted, hops):
    train, _ = hops
    variants = fitted["copy"].sample(5, n_frames=None, seed=0)
    originals = {c.name: dof_matrix(c)[0] for c in train}
    matrix = dof_matrix(variants[0])[0]
    warped = [time_warp(m, len(matrix), fitted["copy"].angles_) for m in originals.values()]
    assert min(np.abs(matrix - w).max() for w in warped) < 1e-9
    assert len({tuple(dof_matrix(v)[0][0]) for v in variants}) == 5  # five variants, five different clips


@needs(HDM05)
def test_perlin_deviation_scales_with_its_amplitude(hops):
    train, _ = hops
    positions = {
        a: np.stack(
            [
                v.positions
                for v in PerlinNoiseSynthesizer(amplitude=a, footskate_cleanup=False, smoothing_seconds=0.0)
                .fit(train)
                .sample(4, 60, seed=3)
            ]
        )
        for a in (0.0, 0.25, 0.5)
    }
    copies = np.stack([v.positions for v in CopyTrainingClips().fit(train).sample(4, 60, seed=3)])
    np.testing.assert_allclose(positions[0.0], copies, atol=1e-4)  # amplitude 0: the copies
    small = np.abs(positions[0.25] - copies).mean()
    large = np.abs(positions[0.5] - copies).mean()
    assert small > 1e-3 and large / small == pytest.approx(2.0, rel=0.15)


def test_perlin_noise_is_bounded_smooth_and_zero_on_the_lattice():
    gradients = np.random.default_rng(0).uniform(-1, 1, 12)
    x = np.linspace(0, 10, 2001)
    noise = perlin_noise(x, gradients)
    assert np.abs(noise).max() <= 1.0 and noise.std() > 0.05
    np.testing.assert_allclose(perlin_noise(np.arange(11.0), gradients), 0.0, atol=1e-12)
    assert np.abs(np.diff(noise, 2)).max() < 1e-3  # no kinks at this sampling


@needs(HDM05)
def test_lau_width_is_chosen_by_held_out_likelihood(fitted):
    lau = fitted["lau"]
    widths = (0.05, 0.2, 0.35, 0.5, 4.0)
    assert lau.width_ in widths and set(lau.cv_log_likelihood_) == set(widths)
    assert lau.cv_log_likelihood_[lau.width_] == max(lau.cv_log_likelihood_.values())
    assert lau.cv_log_likelihood_[lau.width_] > max(lau.cv_log_likelihood_[0.05], lau.cv_log_likelihood_[4.0])


@needs(HDM05)
def test_lau_chosen_width_beats_the_extremes_on_unseen_clips():
    clips = [read_amc(path) for path in HOPS[:20]]  # 10 to fit on (as the thesis), 10 unseen
    lau = LauDBNSynthesizer(widths=(0.05, 0.35, 4.0)).fit(clips[::2])
    unseen = clips[1::2]
    chosen = lau.log_likelihood(unseen)
    assert chosen > lau.log_likelihood(unseen, width=0.05) and chosen > lau.log_likelihood(unseen, width=4.0)


@needs(HDM05)
def test_cvae_trains_quickly_and_its_loss_falls(fitted):
    cvae = fitted["cvae"]
    assert len(cvae.loss_curve_) == FAST_CVAE["steps"] and cvae.train_seconds_ < 60
    assert cvae.loss_curve_[-10:].mean() < 0.5 * cvae.loss_curve_[:10].mean()


@needs(HDM05)
def test_cvae_is_seeded(hops):
    train, _ = hops
    small = {**FAST_CVAE, "steps": 20}
    a, b = CVAESynthesizer(**small).fit(train), CVAESynthesizer(**small).fit(train)
    np.testing.assert_array_equal(a.loss_curve_, b.loss_curve_)
    c = CVAESynthesizer(**small, random_state=5).fit(train)
    assert not np.array_equal(a.loss_curve_, c.loss_curve_)


@needs(HDM05)
def test_cvae_latent_scale_widens_the_variants_and_auto_reaches_the_target(fitted, hops):
    import copy

    def departure(scale):
        """Mean distance (m) of the variants from those of scale 0 drawn with the same seed (same start frames,
        same normals): what the latent scale adds."""

        def variants(s):
            model = copy.deepcopy(fitted["cvae"]).set_params(noise_scale=s, footskate_cleanup=False)
            return np.stack([v.positions for v in model.sample(4, n_frames=40, seed=5)])

        return float(np.linalg.norm(variants(scale) - variants(0.0), axis=-1).mean())

    assert 0.0 < departure(1.0) < departure(6.0)
    assert fitted["cvae"].noise_scale_ == 1.0 and fitted["cvae"].variation_by_noise_scale_ == {}

    train, _ = hops
    auto = CVAESynthesizer(**FAST_CVAE, noise_scale="auto", target_variation=1.1).fit(train)
    tried = auto.variation_by_noise_scale_
    assert list(tried) == list(CVAESynthesizer.noise_scales[: len(tried)]) and auto.noise_scale_ == list(tried)[-1]
    ratios = list(tried.values())
    assert all(r < 1.1 for r in ratios[:-1])
    assert ratios[-1] >= 1.1 or auto.noise_scale_ == CVAESynthesizer.noise_scales[-1]
    with pytest.raises(ValueError, match="CVAESynthesizer: noise_scale"):
        CVAESynthesizer(**FAST_CVAE, noise_scale=-1.0).fit(train)


@pytest.mark.parametrize("name", ["copy", "perlin", "lau", "cvae"])
def test_not_fitted(name):
    with pytest.raises(NotFittedError):
        _methods()[name].sample(2, 10, seed=0)


@needs(HDM05)
@pytest.mark.parametrize("name", ["copy", "perlin", "lau", "cvae"])
def test_bad_training_clips_are_rejected(hops, name):
    train, _ = hops
    with pytest.raises(SynthesisInputError, match="at least"):
        _methods()[name].fit(train[:1])
    positions_only = Motion(positions=train[0].positions, joint_names=train[0].joint_names, fps=120.0, name="pos")
    with pytest.raises(SynthesisInputError, match="pos is not an ASF/AMC motion"):
        _methods()[name].fit([positions_only, train[1]])


@needs(HDM05)
@pytest.mark.parametrize(
    "method, message",
    [
        (PerlinNoiseSynthesizer(amplitude=-1.0), "amplitude"),
        (PerlinNoiseSynthesizer(frequency=0.0), "frequency"),
        (LauDBNSynthesizer(widths=(0.0, 1.0)), "widths"),
        (CVAESynthesizer(fps=0.0), "fps"),
        (LauDBNSynthesizer(footskate_root="sideways"), "footskate_root"),
        (CVAESynthesizer(footskate_cleanup="yes"), "footskate_cleanup"),
        (PerlinNoiseSynthesizer(smoothing_seconds=-0.1), "smoothing_seconds"),
        (LauDBNSynthesizer(smoothing_seconds="0.1"), "smoothing_seconds"),
    ],
)
def test_bad_parameters_are_rejected(hops, method, message):
    with pytest.raises(ValueError, match=message):
        method.fit(hops[0])


@needs(HDM05)
def test_synthesize_command_runs_a_baseline(tmp_path, capsys):
    from mocapkit.cli import main

    out = tmp_path / "perlin"
    assert (
        main(
            [
                "synthesize",
                *map(str, HOPS[:4]),
                "--method",
                "perlin",
                "--out",
                str(out),
                "--variants",
                "2",
                "--seed",
                "3",
                "--quiet",
            ]
        )
        == 0
    )
    assert "wrote 2 variants of 4 training clips" in capsys.readouterr().out
    variants = sorted(out.glob("variant_*.amc"))
    assert len(variants) == 2
    motion = read_amc(variants[0], asf=next(out.glob("*.asf")))
    assert np.isfinite(motion.positions).all() and motion.num_frames > 10
    # the same variants as self-contained BVH: the same joints, positions and frame rate
    assert (
        main(
            [
                "synthesize",
                *map(str, HOPS[:4]),
                "--method",
                "perlin",
                "--out",
                str(tmp_path / "bvh"),
                "--variants",
                "2",
                "--seed",
                "3",
                "--quiet",
                "--format",
                "bvh",
            ]
        )
        == 0
    )
    assert sorted(p.name for p in (tmp_path / "bvh").iterdir()) == ["report.json", "variant_000.bvh", "variant_001.bvh"]
    as_bvh = read_bvh(tmp_path / "bvh" / "variant_000.bvh")
    assert as_bvh.joint_names == motion.joint_names and as_bvh.fps == motion.fps
    np.testing.assert_allclose(as_bvh.positions, motion.positions, atol=1e-4)
    assert (
        main(
            ["synthesize", *map(str, HOPS[:3]), "--method", "lau", "--out", str(tmp_path / "x"), "--set", "amplitude=2"]
        )
        == 2
    )  # a Perlin parameter, not Lau's
    assert "amplitude" in capsys.readouterr().err


@needs(HDM05)
def test_synthesize_trains_on_windows_of_long_takes(tmp_path):
    from mocapkit.synthesis.synthesize import synthesize

    lengths = [read_amc(f).num_frames for f in HOPS[:3]]
    window = min(lengths) // 2  # frames; two windows from the shortest clip
    report = synthesize(
        HOPS[:3], tmp_path, n_variants=2, method="perlin", max_clips=5, progress=False, window_seconds=window / 120.0
    )
    assert report["window_seconds"] == window / 120.0
    expected = []
    for f, n in zip(HOPS[:3], lengths):
        expected += [f"{f.resolve()}[{s}:{s + window}]" for s in range(0, n - window + 1, window)]
    assert report["training_clips"] == expected[:5]
    first = str(HOPS[0].resolve())
    assert report["frames_left_out"][first] == lengths[0] - window * (lengths[0] // window)
    assert report["frames_per_variant"] == window
    assert report["skeleton"] == "HDM_bd.asf" and (tmp_path / "HDM_bd.asf").is_file()  # the takes' own ASF
    with pytest.raises(ValueError, match="at least 4 frames"):
        synthesize(HOPS[:3], tmp_path, method="perlin", progress=False, window_seconds=0.01)


@needs(HDM05)
@pytest.mark.parametrize("name", ["lau", "cvae"])
def test_frame_to_frame_models_cut_training_clips_at_angle_flips(hops, name):
    squat = read_amc(HDM05 / "dg" / "HDM_dg_squat1Reps_025_120.amc")  # lfemur turns 180° at frame 83
    train, _ = hops
    with pytest.warns(UserWarning, match=r"HDM_dg_squat1Reps_025_120.amc: joint-angle flips"):
        model = _methods()[name].fit([squat, train[0]])
    assert ("lfemur", 83) in {(bone, frame) for _, frame, bone, _ in model.angle_flips_}
    assert len(model.starts_) == 2 == len(model.start_places_)  # pieces after a flip are not starting poses
    variant = model.sample(1, n_frames=30, seed=0)[0]
    assert np.all(np.isfinite(variant.positions))
    kept = _methods()[name].set_params(max_turn_speed=None).fit([squat, train[0]])
    assert kept.angle_flips_ == []


@needs(HDM05)
@pytest.mark.parametrize("name", ["perlin", "lau", "cvae"])
def test_every_generator_gets_the_same_footskate_cleanup(fitted, hops, name):
    from mocapkit.synthesis.metrics import foot_skating

    synthesizer = fitted[name]
    names = hops[0][0].joint_names
    ankles = [names.index("ltibia"), names.index("rtibia")]
    assert synthesizer.floor_ == pytest.approx(np.mean([c.positions[:, ankles, 1].min() for c in hops[0]]))
    cleaned = synthesizer.sample(3, n_frames=80, seed=4)
    assert len(synthesizer.footskate_reports_) == 3
    try:
        raw = synthesizer.set_params(footskate_cleanup=False).sample(3, n_frames=80, seed=4)
        assert synthesizer.footskate_reports_ == []
    finally:
        synthesizer.set_params(footskate_cleanup=True)
    skating = [np.nanmean([foot_skating(v) for v in variants]) for variants in (raw, cleaned)]
    assert skating[1] < skating[0]
    fitted["copy"].sample(2, seed=0)
    assert fitted["copy"].footskate_reports_ == []  # the reference is never cleaned


@needs(HDM05)
def test_smoothing_low_passes_the_values_and_unwraps_angles_first(hops):
    clip = hops[0][0]
    matrix, layout = dof_matrix(clip)
    rng = np.random.default_rng(0)
    noisy = matrix + rng.normal(0.0, 2.0, matrix.shape)
    smoothed = np.concatenate(list(smooth_values(dof_values(noisy, layout), layout, 120.0, 0.02).values()), axis=1)
    jitter = lambda m: np.abs(np.diff(m, n=2, axis=0)).mean()
    assert jitter(smoothed) < 0.2 * jitter(noisy)
    assert np.abs(smoothed - matrix).mean() < 0.7 * np.abs(noisy - matrix).mean()  # closer to the clean curve
    np.testing.assert_array_equal(
        np.concatenate(list(smooth_values(dof_values(noisy, layout), layout, 120.0, 0.0).values()), axis=1), noisy
    )
    # an angle turning steadily through ±180° (wrapped into [-180, 180)) stays a steady turn, not a spin back
    turning = matrix.copy()
    column = int(np.flatnonzero([name.lower().startswith("r") for dofs in layout.dofs for name in dofs])[0])
    steady = np.linspace(150.0, 210.0, len(turning))
    turning[:, column] = (steady + 180.0) % 360.0 - 180.0
    out = np.concatenate(list(smooth_values(dof_values(turning, layout), layout, 120.0, 0.02).values()), axis=1)
    np.testing.assert_allclose(out[12:-12, column], steady[12:-12], atol=1e-6)  # a ramp, away from the ends


@needs(HDM05)
@pytest.mark.parametrize("name", ["perlin", "lau", "cvae"])
def test_every_generator_gets_the_same_smoothing(fitted, name):
    from mocapkit.synthesis.metrics import mean_jerk

    synthesizer = fitted[name]
    before = synthesizer.smoothing_seconds
    try:
        raw = synthesizer.set_params(smoothing_seconds=0.0, footskate_cleanup=False).sample(3, n_frames=80, seed=4)
        smooth = synthesizer.set_params(smoothing_seconds=0.05).sample(3, n_frames=80, seed=4)
    finally:
        synthesizer.set_params(smoothing_seconds=before, footskate_cleanup=True)
    jerk = [np.mean([mean_jerk(v) for v in variants]) for variants in (raw, smooth)]
    assert jerk[1] < 0.5 * jerk[0]
