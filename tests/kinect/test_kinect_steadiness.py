"""The real-data proxies (mocapkit.kinect.metrics: bone-length sd, jitter, joint-angle violations, left/right swap
events), the output options that keep a corrected skeleton steady (mocapkit.kinect.steady), and the issue's
promise on real files: the registry's default, trained small on a few HDM05 clips, does not make real MSR Action3D
and NTU skeletons less steady."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.kinect.metrics import (
    bone_length_sd_cm,
    jitter_cm,
    joint_angle_violations,
    steadiness,
    steadiness_summary,
    swap_events,
)
from mocapkit.kinect.steady import check_steady_params, rigid, steady_output, zero_lag_smooth
from mocapkit.motion.layouts import LANDMARK_NAMES
from tests.datasets.test_kinect_noise import moving_clip
from tests.shared_data import SHARED, needs

J = {name: k for k, name in enumerate(LANDMARK_NAMES)}
HDM05 = SHARED / "data" / "hdm05_cuts11"
MSR = SHARED / "data" / "msr_action3d"
NTU = SHARED / "samples" / "ntu_skeleton"


def walking(seconds: float = 4.0) -> np.ndarray:
    """float64 ``[T, 20, 3]``: :func:`moving_clip` walking forward at 1 m/s, legs swinging."""
    clip = moving_clip(seconds=seconds).astype(np.float64)
    t = np.arange(len(clip)) / 30.0
    clip[..., 2] += t[:, None]
    for side, sign in (("l_", 1.0), ("r_", -1.0)):
        for part, reach in (("knee", 0.5), ("ankle", 1.0), ("foot", 1.0)):
            clip[:, J[side + part], 2] += sign * reach * 0.2 * np.sin(2 * np.pi * t)
    return clip


def test_a_leg_swap_is_two_events_and_natural_motion_none():
    clip = walking()
    assert swap_events(clip) == 0
    swapped = clip.copy()
    for part in ("knee", "ankle", "foot"):
        swapped[40:50, [J["l_" + part], J["r_" + part]]] = clip[40:50, [J["r_" + part], J["l_" + part]]]
    assert swap_events(swapped) == 2  # the swap and its undoing
    # a 15 fps file resampled to 30 fps spreads each jump over two frames: lag 2 finds it, lag 1 does not
    halfway = swapped.copy()
    halfway[1:-1:2] = 0.5 * (swapped[:-2:2] + swapped[2::2])
    assert swap_events(halfway, lag=2) == 2 and swap_events(halfway, lag=1) == 0


def test_a_folded_elbow_violates_the_joint_limits():
    clip = walking()
    assert joint_angle_violations(clip) == 0.0
    folded = clip.copy()
    folded[:10, J["l_wrist"]] = folded[:10, J["l_shoulder"]] + 0.01  # the forearm back onto the upper arm
    share = joint_angle_violations(folded)
    assert share == pytest.approx(100.0 * 10 / (len(clip) * 5))  # 10 frames of one of the 5 limited joints


def test_smoothing_has_no_lag_keeps_quadratic_motion_and_removes_jitter():
    rng = np.random.default_rng(0)
    t = np.arange(90, dtype=np.float64)
    quadratic = np.zeros((90, 20, 3)) + (0.001 * t**2 - 0.02 * t)[:, None, None]
    np.testing.assert_allclose(zero_lag_smooth(quadratic, 9), quadratic, atol=1e-12)
    wave = np.zeros((90, 20, 3)) + np.sin(2 * np.pi * t / 30.0)[:, None, None]
    smooth = zero_lag_smooth(wave, 9)
    assert np.argmax(smooth[:30, 0, 0]) == np.argmax(wave[:30, 0, 0])  # the peak stays in its frame
    noisy = walking() + rng.normal(0, 0.01, (120, 20, 3))
    assert jitter_cm(zero_lag_smooth(noisy, 9)) < 0.5 * jitter_cm(noisy)
    assert zero_lag_smooth(noisy[:4], 9).shape == (4, 20, 3)  # too short to filter: returned as it is


def test_rigid_bones_and_tracked_correction():
    rng = np.random.default_rng(1)
    raw = walking() + rng.normal(0, 0.01, (120, 20, 3))
    assert bone_length_sd_cm(raw) > 0.5 and bone_length_sd_cm(rigid(raw)) < 1e-9
    corrected = raw + 0.05
    state = np.full((120, 20), 2, dtype=np.int8)
    state[:, J["l_hand"]] = 1
    out = steady_output(raw, corrected, state, tracked_correction=0.0)
    np.testing.assert_array_equal(out[:, J["l_hand"]], corrected[:, J["l_hand"]])
    np.testing.assert_array_equal(out[:, J["r_hand"]], raw[:, J["r_hand"]])
    assert steady_output(raw, corrected, state) is corrected  # the defaults change nothing
    for bad, match in (
        ((1.5, 0, False), "tracked_correction"),
        ((1.0, 4, False), "smooth_window"),
        ((1.0, 8, False), "smooth_window"),
        ((1.0, 0, "yes"), "rigid_bones"),
    ):
        with pytest.raises(ValueError, match=match):
            check_steady_params(*bad, "owner")


def test_summary_counts_files_not_worse_and_new_swaps():
    clip = walking()
    swapped = clip.copy()
    swapped[40:50, [J["l_knee"], J["r_knee"]]] = clip[40:50, [J["r_knee"], J["l_knee"]]]
    before = [steadiness(clip), steadiness(clip)]
    after = [steadiness(rigid(clip)), steadiness(swapped)]
    s = steadiness_summary(before, after)
    assert s["files"] == 2 and s["new_swap_events"] == 2
    assert s["swap_events_not_worse"] == 0.5 and s["bone_sd_cm_not_worse"] == 0.5
    with pytest.raises(ValueError, match="as many files"):
        steadiness_summary(before, after[:1])


def _small(method: str) -> list[str]:
    """Overrides that train the registry's ``method`` in seconds (its other parameters are the config's)."""
    from mocapkit.train.registry import method_config

    params = method_config("kinect", method)
    if "steps" in params:
        return ["steps=40", "window=32", "batch_size=8"]
    if "gp_iterations" in params:
        return ["gp_iterations=3", "n_inducing=20", "max_train_frames=400"]
    return []


@pytest.mark.slow
@needs(HDM05)
@needs(MSR)
@needs(NTU)
def test_the_default_does_not_make_real_skeletons_less_steady(tmp_path):
    from mocapkit.kinect.kinect_fix import fix_kinect_files, train_kinect_model
    from mocapkit.train.registry import default_method

    method = default_method("kinect")
    model = tmp_path / "model.pt"
    train_kinect_model(sorted((HDM05 / "bd").glob("*.amc"))[:4], model, overrides=_small(method))
    msr = sorted(MSR.glob("*_skeleton3D.txt"))
    files = [msr[i] for i in range(0, len(msr), 40)] + sorted(NTU.glob("*.skeleton"))
    report = fix_kinect_files(model, files, tmp_path / "out", skip_bad=True)
    s = report.summary
    assert s["files"] >= 15
    assert s["bone_sd_cm_not_worse"] >= 0.95 and s["jitter_cm_not_worse"] >= 0.95
    assert s["bone_sd_cm_after"] < s["bone_sd_cm_before"] and s["jitter_cm_after"] < s["jitter_cm_before"]
    assert s["new_swap_events"] == 0
    ntu = [f for f in report.fixed if f["input"].endswith(".skeleton")]
    assert ntu and all(f["untracked_entries"] > 0 for f in ntu)  # the SDK's own INFERRED states were read
