"""The pose-prior gap filler (mocapkit.refinement.pose_prior): fusion of the cubic guess with a PPCA pose model."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import CMU31
from mocapkit.refinement.base import RefinementError
from mocapkit.refinement.corruptions import corrupt
from mocapkit.refinement.pose_prior import PosePriorRefiner, nearest_sample_distance

ARM = ("lhumerus", "lradius", "lwrist", "lhand", "lfingers", "lthumb")


def swinging_body(frames: int, seed: int, fps: float = 120.0) -> Motion:
    """A CMU31 body with fixed joint offsets whose left arm swings (one phase for the whole chain, so the hand
    follows the wrist) while the body turns about the vertical and walks: in a pose frame every joint is a linear
    function of the swing, in time the hand's path is a curve no gap-end interpolation can guess."""
    rng = np.random.default_rng(0)  # the same body in every take
    offsets = rng.normal(0.0, 0.1, (CMU31.num_joints, 3))
    swing_dirs = rng.normal(0.0, 1.0, (CMU31.num_joints, 3))
    take = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    swing = 0.25 * np.sin(2 * np.pi * take.uniform(0.6, 1.2) * t + take.uniform(0, 2 * np.pi))  # [T]
    local = np.zeros((frames, CMU31.num_joints, 3))
    for j, p in enumerate(CMU31.parents):
        if p >= 0:
            depth = ARM.index(CMU31.joint_names[j]) + 1 if CMU31.joint_names[j] in ARM else 0
            local[:, j] = local[:, p] + offsets[j] + (depth > 0) * 0.1 * depth * swing[:, None] * swing_dirs[j]
    local[..., 1] += 0.9
    heading = take.uniform(0, 2 * np.pi) + 0.8 * t
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    world = local.copy()
    world[..., 0], world[..., 2] = c * local[..., 0] + s * local[..., 2], -s * local[..., 0] + c * local[..., 2]
    world[..., 0] += 0.4 * t[:, None]
    return Motion(world, CMU31.joint_names, fps, parents=CMU31.parents, layout_name="cmu31", name=f"swing{seed}")


@pytest.fixture(scope="module")
def fitted():
    # the fusion itself: no short-gap hand-over to the spline (that has its own test)
    return PosePriorRefiner(n_components=8, short_gap_seconds=0).fit([swinging_body(300, s) for s in range(4)])


def test_nearest_sample_distance():
    observed = np.array([[0, 1, 0], [0, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1, 0]], bool)
    d = nearest_sample_distance(observed)
    assert d[:, 0].tolist() == [2, 1, 0, 1, 2, 3]
    assert d[:, 1].tolist() == [0, 1, 2, 2, 1, 0]
    assert np.isinf(d[:, 2]).all()


def test_a_long_gap_is_filled_from_the_pose_where_the_cubic_guess_misses(fitted):
    clean = swinging_body(300, 11)
    hand = CMU31.joint_names.index("lhand")
    missing = np.zeros((300, CMU31.num_joints), bool)
    missing[40:260, hand] = True  # 1.8 s
    gappy = Motion(
        np.where(missing[..., None], np.nan, clean.positions),
        clean.joint_names,
        clean.fps,
        parents=clean.parents,
        layout_name="cmu31",
    )
    filled = fitted.refine(gappy)
    cubic = fitted.temporal_guess(gappy.positions, ~gappy.missing)
    error = np.linalg.norm(filled.positions[missing] - clean.positions[missing], axis=-1).mean()
    cubic_error = np.linalg.norm(cubic[missing] - clean.positions[missing], axis=-1).mean()
    assert cubic_error > 0.05 and error < 0.1 * cubic_error  # the swing is recovered, not bridged
    assert not filled.missing.any()
    assert np.array_equal(filled.positions[~missing], gappy.positions[~missing])  # observed entries untouched
    assert filled.metadata["refinement"]["filled"] == int(missing.sum())


def test_short_gaps_stay_with_the_temporal_guess_and_a_never_seen_joint_comes_from_the_pose(fitted):
    clean = swinging_body(200, 12)
    missing = np.zeros((200, CMU31.num_joints), bool)
    wrist, thumb = CMU31.joint_names.index("lwrist"), CMU31.joint_names.index("lthumb")
    missing[100:103, wrist] = True  # 3 frames: the cubic guess is right
    missing[:, thumb] = True  # never observed in the take
    gappy = Motion(
        np.where(missing[..., None], np.nan, clean.positions),
        clean.joint_names,
        clean.fps,
        parents=clean.parents,
        layout_name="cmu31",
    )
    filled = fitted.refine(gappy)
    cubic = fitted.temporal_guess(gappy.positions, ~gappy.missing)
    short = np.linalg.norm(filled.positions[100:103, wrist] - clean.positions[100:103, wrist], axis=-1).max()
    assert short < 0.002 and np.abs(filled.positions[100:103, wrist] - cubic[100:103, wrist]).max() < 0.002
    assert np.linalg.norm(filled.positions[:, thumb] - clean.positions[:, thumb], axis=-1).mean() < 0.01


def test_frames_with_nothing_observed_at_the_ends_stay_missing_and_corruptions_are_filled(fitted):
    clean = swinging_body(250, 13)
    corruption = corrupt(clean, "long_gaps", "5x1s", seed=0)
    positions = corruption.motion.positions.copy()
    positions[:20] = np.nan
    gappy = Motion(positions, clean.joint_names, clean.fps, parents=clean.parents, layout_name="cmu31")
    filled = fitted.refine(gappy)
    assert filled.missing[:20].all() and not filled.missing[20:].any()
    assert filled.metadata["refinement"]["unfilled"]


def test_errors_not_fitted_other_layout_no_complete_frame_and_bad_parameters(fitted):
    motion = swinging_body(50, 1)
    with pytest.raises(NotFittedError):
        PosePriorRefiner().refine(motion)
    other = Motion(motion.positions[:, :5], CMU31.joint_names[:5], 120.0, parents=CMU31.parents[:5])
    with pytest.raises(RefinementError, match="another skeleton layout"):
        fitted.refine(other)
    gappy = Motion(
        np.where(np.eye(50, 31, dtype=bool)[..., None], np.nan, motion.positions),
        CMU31.joint_names,
        120.0,
        parents=CMU31.parents,
    )
    gappy.missing[:, 0] = True
    with pytest.raises(RefinementError, match="fewer than 2 training frames with every joint observed"):
        PosePriorRefiner().fit(
            [
                Motion(
                    np.where(gappy.missing[..., None], np.nan, motion.positions),
                    CMU31.joint_names,
                    120.0,
                    parents=CMU31.parents,
                )
            ]
        )
    with pytest.raises(ValueError, match="drift"):
        PosePriorRefiner(drift=0).fit([motion])


def test_the_noise_floor_bounds_the_prior_confidence_and_keeps_short_gaps_with_the_guess():
    train = [swinging_body(300, s) for s in range(2)]  # exactly low-rank poses
    tight = PosePriorRefiner(n_components=90, noise_floor=0.0, short_gap_seconds=0).fit(train)
    floored = PosePriorRefiner(n_components=90, noise_floor=0.01, short_gap_seconds=0).fit(train)
    assert tight.noise_variance_ < 1e-8 and floored.noise_variance_ == pytest.approx(1e-4)
    clean = swinging_body(200, 21)
    tibia = CMU31.joint_names.index("ltibia")
    t = np.arange(200) / 120.0
    positions = clean.positions.copy()  # a knee motion the training poses lack
    positions[:, tibia] += 0.02 * np.stack([np.sin(2 * t), np.cos(3 * t), np.sin(5 * t)], axis=1)
    missing = np.zeros((200, CMU31.num_joints), bool)
    missing[50:150:2, tibia] = True  # every other frame: a 1-frame gap each
    gappy = Motion(
        np.where(missing[..., None], np.nan, positions),
        clean.joint_names,
        clean.fps,
        parents=clean.parents,
        layout_name="cmu31",
    )
    error = {
        name: np.linalg.norm(r.refine(gappy).positions[missing] - positions[missing], axis=-1).mean()
        for name, r in (("tight", tight), ("floored", floored))
    }
    assert error["tight"] > 0.005  # the exact prior pulls the knee back into its subspace
    assert error["floored"] < 0.1 * error["tight"]  # the floor leaves the gap to the temporal guess


def test_short_gaps_go_to_the_spline_and_longer_ones_stay_with_the_fusion(fitted):
    """``short_gap_seconds``: interior gaps up to that length come out as the not-a-knot spline through the joint's
    samples fills them; a longer gap, a gap at the take's start and every observed sample are the fusion's."""
    from mocapkit.refinement.gap_filling import SplineInterpolation

    clean = swinging_body(300, 12)
    hand, knee = CMU31.joint_names.index("lhand"), CMU31.joint_names.index("ltibia")
    missing = np.zeros((300, CMU31.num_joints), bool)
    missing[100:110, hand] = True  # 10 frames: short
    missing[150:200, hand] = True  # 50 frames: long
    missing[:8, knee] = True  # at the start: not interior
    gappy = Motion(
        np.where(missing[..., None], np.nan, clean.positions),
        clean.joint_names,
        clean.fps,
        parents=clean.parents,
        layout_name="cmu31",
    )
    handed = (
        PosePriorRefiner(**{**fitted.get_params(), "short_gap_seconds": 0.2})
        .fit([swinging_body(300, s) for s in range(4)])
        .refine(gappy)
        .positions
    )
    fused = fitted.refine(gappy).positions
    spline = SplineInterpolation().refine(gappy).positions
    np.testing.assert_allclose(handed[100:110, hand], spline[100:110, hand], atol=1e-9)
    assert np.abs(fused[100:110, hand] - spline[100:110, hand]).max() > 1e-4  # the fusion differs there
    np.testing.assert_allclose(handed[150:200, hand], fused[150:200, hand], atol=1e-9)
    np.testing.assert_allclose(handed[:8, knee], fused[:8, knee], atol=1e-9)
    np.testing.assert_array_equal(handed[~missing], clean.positions[~missing])
    with pytest.raises(ValueError, match="short_gap_seconds"):
        PosePriorRefiner(short_gap_seconds=-1).fit([clean])
    # in seconds: at 30 fps 0.2 s is 6 frames, so a 10-frame gap stays with the fusion
    train30 = [
        Motion(swinging_body(1200, s).positions[::4], CMU31.joint_names, 30.0, parents=CMU31.parents) for s in range(4)
    ]
    prior30 = PosePriorRefiner(n_components=8).fit(train30)
    assert prior30.get_params()["short_gap_seconds"] == 0.2
    slow_missing = missing[::4].copy()
    slow_missing[60:70, hand] = True  # 10 frames at 30 fps: 0.33 s
    slow = Motion(
        np.where(slow_missing[..., None], np.nan, clean.positions[::4]),
        clean.joint_names,
        30.0,
        parents=clean.parents,
        layout_name="cmu31",
    )
    spline30 = SplineInterpolation().refine(slow).positions[60:70, hand]
    handed30 = prior30.refine(slow).positions
    fused30 = PosePriorRefiner(n_components=8, short_gap_seconds=0).fit(train30).refine(slow).positions
    np.testing.assert_allclose(handed30[60:70, hand], fused30[60:70, hand], atol=1e-9)
    assert np.abs(handed30[60:70, hand] - spline30).max() > 1e-4
