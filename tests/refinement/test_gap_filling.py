"""Gap-filling baselines (interpolation, PCA after Gløersen & Federolf 2016) and SVT completion."""

import numpy as np
import pytest
import torch
from sklearn.base import clone

from mocapkit.motion.container import Motion
from mocapkit.refinement import RefinementError, corrupt
from mocapkit.refinement.gap_filling import (
    HoldLastValue,
    LinearInterpolation,
    PCAGapFilling,
    PchipInterpolation,
    SplineInterpolation,
)
from mocapkit.refinement.metrics import score_refinement
from mocapkit.refinement.svt import SVTCompletion, svt_complete
from tests.shared_data import SHARED, needs

HDM05_CLIP = SHARED / "data" / "hdm05_cuts11" / "bd" / "HDM_bd_depositFloorR_001_120.amc"

FAST = [
    LinearInterpolation(),
    PchipInterpolation(),
    SplineInterpolation(),
    HoldLastValue(),
    PCAGapFilling(max_iter=5),
    SVTCompletion(max_iter=100),
]
NAMES = [type(r).__name__ for r in FAST]


def latent_motion(frames=240, joints=12, fps=120.0, seed=0):
    """Markers that are fixed linear mixtures of 3 smooth latent signals plus their rest offsets (rank ≤ 4)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    latent = np.stack([np.sin(2 * np.pi * 0.8 * t), np.cos(2 * np.pi * 0.5 * t), np.sin(2 * np.pi * 1.3 * t + 1)])
    mixing = rng.normal(scale=0.1, size=(joints * 3, 3))
    positions = (rng.normal(scale=0.4, size=joints * 3) + (mixing @ latent).T).reshape(frames, joints, 3)
    return Motion(positions=positions, joint_names=[f"m{j}" for j in range(joints)], fps=fps, name="latent")


def with_missing(motion, mask):
    positions = motion.positions.copy()
    positions[mask] = np.nan
    return Motion(positions=positions, joint_names=motion.joint_names, fps=motion.fps, name=motion.name)


@pytest.mark.parametrize("refiner", FAST, ids=NAMES)
def test_observed_entries_are_bit_identical_and_interior_gaps_filled(refiner):
    clean = latent_motion()
    c = corrupt(clean, "continuous_missing", 30, seed=1)
    out = refiner.refine(c.motion)
    observed = ~c.motion.missing
    assert np.array_equal(out.positions[observed], c.motion.positions[observed])
    assert not out.missing.any() and np.isfinite(out.positions).all()
    assert out.metadata["refinement"]["filled"] == c.removed.sum()
    assert out.metadata["refinement"]["unfilled"] == {}


@pytest.mark.parametrize("cls", [LinearInterpolation, PchipInterpolation, SplineInterpolation, HoldLastValue])
def test_leading_and_trailing_gaps_are_reported_not_extrapolated(cls):
    clean = latent_motion(joints=4)
    mask = np.zeros(clean.missing.shape, bool)
    mask[:10, 1] = mask[-7:, 2] = mask[50:60, 3] = True
    out = cls().refine(with_missing(clean, mask))
    assert out.metadata["refinement"]["unfilled"] == {"m1": 10, "m2": 7}
    assert out.missing[:10, 1].all() and out.missing[-7:, 2].all() and not out.missing[:, 3].any()
    held = cls(extrapolate="hold").refine(with_missing(clean, mask))
    assert not held.missing.any()
    assert np.array_equal(held.positions[:10, 1], np.repeat(clean.positions[10:11, 1], 10, axis=0))
    assert np.array_equal(held.positions[-7:, 2], np.repeat(clean.positions[-8:-7, 2], 7, axis=0))


def test_interpolants_are_exact_on_what_they_can_represent():
    frames = np.arange(100, dtype=np.float64)
    line = np.stack([0.01 * frames, -0.02 * frames + 1, np.full(100, 0.5)], axis=1)[:, None]
    cubic = np.stack([(frames / 100) ** 3, (frames / 100) ** 2, frames / 100], axis=1)[:, None]
    motion = Motion(positions=np.concatenate([line, cubic], axis=1), joint_names=["line", "cubic"], fps=100.0)
    mask = np.zeros((100, 2), bool)
    mask[30:60] = True
    holey = with_missing(motion, mask)
    for refiner in (LinearInterpolation(), PchipInterpolation(), SplineInterpolation()):
        assert np.allclose(refiner.refine(holey).positions[:, 0], motion.positions[:, 0], atol=1e-6)
    assert np.allclose(SplineInterpolation().refine(holey).positions[:, 1], motion.positions[:, 1], atol=1e-5)


def test_pca_recovers_a_long_gap_from_correlated_markers_where_interpolation_cannot():
    clean = latent_motion(frames=400)
    mask = np.zeros(clean.missing.shape, bool)
    mask[100:300, 3] = True  # 200 frames = 1.7 s on one marker
    holey = with_missing(clean, mask)
    linear = np.abs(LinearInterpolation().refine(holey).positions[mask] - clean.positions[mask]).max()
    assert linear > 0.02
    for method in ("complete", "iterative"):  # the published one pass, and the default
        pca = PCAGapFilling(method=method)
        error = np.abs(pca.refine(holey).positions[mask] - clean.positions[mask]).max()
        assert pca.basis_ == method and error < 1e-3


def test_pca_iterative_basis_when_no_frame_is_complete():
    clean = latent_motion(frames=300)
    c = corrupt(clean, "random_missing", 0.3, seed=0)  # every frame misses 4 of 12 markers
    pca = PCAGapFilling(max_iter=30, weight_scale=100.0)  # no distance weighting: plain iterative PCA
    out = pca.refine(c.motion)
    assert pca.basis_ == "iterative" and 1 <= pca.n_iter_ <= 30
    observed = ~c.motion.missing
    assert np.array_equal(out.positions[observed], c.motion.positions[observed])
    assert score_refinement(out, clean, c).mean_error_mm < 0.01  # converges to the exact low-rank fill
    with pytest.raises(RefinementError, match="complete"):
        PCAGapFilling(method="complete").refine(c.motion)


def test_pca_needs_no_training_but_may_use_it():
    clean = latent_motion(frames=400)
    assert PCAGapFilling.requires_fit is False
    mask = np.zeros(clean.missing.shape, bool)
    mask[100:300, 3] = True
    fitted = PCAGapFilling().fit([latent_motion(frames=300, seed=0)])
    assert fitted.training_frames_.shape == (300, 36)
    out = fitted.refine(with_missing(clean, mask))
    assert np.abs(out.positions[mask] - clean.positions[mask]).max() < 1e-3
    assert clone(fitted).get_params() == fitted.get_params()
    with pytest.raises(RefinementError, match="another skeleton layout"):
        fitted.refine(with_missing(latent_motion(joints=5), np.eye(240, 5, dtype=bool)))


def test_svt_recovers_an_exactly_low_rank_matrix_from_half_its_entries():
    rng = np.random.default_rng(0)
    M = rng.normal(size=(300, 3)) @ rng.normal(size=(3, 60))
    observed = rng.random(M.shape) < 0.5
    X, info = svt_complete(M, observed)
    assert info["converged"] and info["rank"] == 3
    assert np.linalg.norm(X - M) / np.linalg.norm(M) < 1e-3
    assert info["tau"] == pytest.approx(5 * np.sqrt(300 * 60)) and info["delta"] == pytest.approx(1.2 / observed.mean())


def test_svt_refiner_on_a_low_rank_motion_reports_its_solver():
    clean = latent_motion()
    c = corrupt(clean, "missing_ratio", 0.3, seed=2)
    short, longer = SVTCompletion(max_iter=50).refine(c.motion), SVTCompletion(max_iter=300).refine(c.motion)
    s_short, s_long = (out.metadata["refinement"]["solver"] for out in (short, longer))
    assert s_short["iterations"] == 50 and not s_short["converged"]
    assert s_long["residual"] < s_short["residual"] < 0.1
    assert score_refinement(longer, clean, c).mean_error_mm < min(5.0, score_refinement(short, clean, c).mean_error_mm)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message when CUDA is absent")
def test_svt_cuda_without_cuda_is_a_clear_error():
    c = corrupt(latent_motion(), "missing_ratio", 0.1)
    with pytest.raises(RuntimeError, match="CUDA"):
        SVTCompletion(device="cuda").refine(c.motion)


@pytest.mark.parametrize("refiner", FAST, ids=NAMES)
def test_clear_errors_and_reports(refiner):
    clean = latent_motion(joints=5, frames=120)
    with pytest.raises(RefinementError, match="every entry is missing"):
        refiner.refine(with_missing(clean, np.ones(clean.missing.shape, bool)))
    inf = clean.positions.copy()
    inf[7, 2, 1] = np.inf  # an array input: a non-finite coordinate is a gap, filled like any other
    gapped = Motion(positions=inf, joint_names=clean.joint_names, fps=clean.fps)
    assert gapped.missing[7, 2] and gapped.missing.sum() == 1
    assert np.isfinite(refiner.refine(gapped).positions[7, 2]).all()
    written_later = Motion(positions=clean.positions.copy(), joint_names=clean.joint_names, fps=clean.fps)
    written_later.positions[7, 2, 1] = np.inf  # into an observed entry after the Motion was built
    with pytest.raises(RefinementError, match=r"non-finite value at frame 7 of marker 'm2'"):
        refiner.refine(written_later)
    mask = np.zeros(clean.missing.shape, bool)
    mask[:, 4] = True  # marker m4 missing in every frame
    mask[40:50, 1] = True
    out = refiner.refine(with_missing(clean, mask))
    assert out.metadata["refinement"]["unfilled"] == {"m4": 120}
    assert out.missing[:, 4].all() and not out.missing[:, :4].any()


@needs(HDM05_CLIP)
def test_short_gaps_on_real_hdm05_beat_holding_the_last_value():
    from mocapkit.datasets.formats.motion_io import read_motion

    clip = read_motion(HDM05_CLIP)
    c = corrupt(clip, "continuous_missing", 20, seed=0)  # 10 markers × 20 frames (0.17 s at 120 fps)
    hold = score_refinement(HoldLastValue().refine(c.motion), clip, c)
    for refiner in (
        LinearInterpolation(),
        PchipInterpolation(),
        SplineInterpolation(),
        PCAGapFilling(max_iter=10),
        SVTCompletion(max_iter=300),
    ):
        out = refiner.refine(c.motion)
        score = score_refinement(out, clip, c)
        assert score.coverage == 1.0 and score.changed_clean == 0
        assert score.rmse_cm < 0.5 * hold.rmse_cm, (type(refiner).__name__, score.rmse_cm, hold.rmse_cm)


@needs(HDM05_CLIP)
def test_iterative_pca_improves_on_its_interpolation_start_on_real_hdm05():
    from mocapkit.datasets.formats.motion_io import read_motion

    clip = read_motion(HDM05_CLIP)
    c = corrupt(clip, "rgloss", seed=0)  # 10 markers × 60 frames, few complete frames
    linear = score_refinement(LinearInterpolation().refine(c.motion), clip, c)
    pca = PCAGapFilling(max_iter=20)
    score = score_refinement(pca.refine(c.motion), clip, c)
    assert pca.basis_ == "iterative" and score.coverage == 1.0
    assert score.rmse_cm < 0.6 * linear.rmse_cm, (score.rmse_cm, linear.rmse_cm)


DIVERGING_CLIP = SHARED / "data" / "hdm05_cuts11" / "bk" / "HDM_bk_kickLFront1Reps_012_120.amc"


@needs(DIVERGING_CLIP)
def test_pca_gap_filling_does_not_diverge_when_many_markers_are_gone_at_once():
    """20 gaps of 100 frames in 250 frames: the iterative PCA once invented markers metres from the body
    (183 cm RMSE against 28 cm for linear interpolation); it now stops a diverging iteration and falls back
    to interpolation for implausible reconstructions."""
    from dataclasses import replace

    from mocapkit.datasets import read_motion

    clip = read_motion(DIVERGING_CLIP)
    start = max(0, (clip.num_frames - 250) // 2)
    clip = replace(
        clip, positions=clip.positions[start : start + 250], missing=clip.missing[start : start + 250], rotations=None
    )
    corruption = corrupt(clip, "long_gaps", "20x100", seed=3467547118)
    pca = score_refinement(PCAGapFilling().refine(corruption.motion), clip, corruption).rmse_cm
    linear = score_refinement(LinearInterpolation().refine(corruption.motion), clip, corruption).rmse_cm
    assert pca < 1.2 * linear
