"""The median outlier screen (mocapkit.refinement.screening) in front of classical and learned refiners.

Exact checks on planted corruption of smooth synthetic trajectories (which samples are flagged, which come back
bit-identical, what the report counts), the comparison runner's fold logic through the wrapper, and
``mocapkit refine --screen-outliers`` on a real C3D take with a planted spike.
"""

from __future__ import annotations

import re

import ezc3d
import numpy as np
import pytest
from sklearn.base import clone

from mocapkit.cli import main
from mocapkit.motion.container import Motion
from mocapkit.refinement.base import MotionRefiner
from mocapkit.refinement.gap_filling import PchipInterpolation
from mocapkit.refinement.screening import (
    SCREEN_HALF_WINDOW,
    SCREEN_THRESHOLD,
    MedianScreen,
    median_outliers,
)
from tests.refinement.test_refine_cli import spiky_walk
from tests.shared_data import SHARED, needs

WALK = SHARED / "samples" / "c3d" / "Walking_Hybrid_1_1.c3d"


def smooth_motion(frames: int = 240, joints: int = 4, fps: float = 120.0) -> Motion:
    """Joints on slow circles and a steady walk forward (0.8 m/s), in metres: nothing a median should flag."""
    t = np.arange(frames)[:, None] / fps
    phase = np.arange(joints)[None, :]
    positions = np.stack(
        [0.8 * t + 0.2 * np.cos(2.0 * t + phase), 1.0 + 0.1 * np.sin(3.0 * t + phase), 0.2 * np.sin(2.0 * t + phase)],
        axis=-1,
    ).astype(np.float32)
    return Motion(positions=positions, joint_names=tuple(f"j{i}" for i in range(joints)), fps=fps, name="smooth")


def with_noise(motion: Motion, rng, fraction: float = 0.2, sigma: float = 0.02):
    """``(noisy motion, bool [T, J] of the perturbed samples)``: σ per coordinate on ``fraction`` of the samples,
    every perturbed sample at least 1.5 cm off (so that each one is a clear outlier)."""
    positions = motion.positions.copy()
    hit = rng.random(motion.missing.shape) < fraction
    hit[[0, -1]] = False
    noise = rng.normal(0.0, sigma, positions.shape)
    norm = np.linalg.norm(noise, axis=-1, keepdims=True)
    noise *= np.maximum(norm, 0.015) / norm
    positions[hit] += noise[hit].astype(np.float32)
    return Motion(positions=positions, joint_names=motion.joint_names, fps=motion.fps, name="noisy"), hit


def test_the_defaults_are_the_selected_screen():
    assert SCREEN_HALF_WINDOW >= 1 and 0 < SCREEN_THRESHOLD < 0.05
    screen = MedianScreen(PchipInterpolation())
    assert (screen.half_window, screen.threshold) == (SCREEN_HALF_WINDOW, SCREEN_THRESHOLD)


def test_smooth_motion_is_never_flagged_and_planted_noise_is():
    clean = smooth_motion()
    assert not median_outliers(clean.positions, clean.missing, threshold=0.002).any()
    noisy, hit = with_noise(clean, np.random.default_rng(0))
    flags = median_outliers(noisy.positions, noisy.missing, half_window=3, threshold=0.01)
    assert flags.sum() >= 0.97 * hit.sum()  # nearly every perturbed sample (all ≥ 1.5 cm off)
    # a clean sample may be flagged when noisy neighbours pull its median (2 of 7 noisy: the median moves by a
    # frame's motion, 7 mm here): rarely, and it is refilled from its neighbours
    assert (flags & ~hit).sum() < 0.05 * (~hit).sum()
    assert not flags[[0, -1]].any()  # a joint's first and last samples are never judged


def test_windows_skip_missing_samples_and_do_not_reach_across_long_gaps():
    clean = smooth_motion()
    positions, missing = clean.positions.copy(), clean.missing.copy()
    missing[::2, 0] = True  # every other frame of joint 0 missing
    positions[missing] = np.nan
    positions[101, 0] += [0.03, 0.0, 0.0]  # an observed spike among them
    assert np.array_equal(np.argwhere(median_outliers(positions, missing, 3, 0.01)), [[101, 0]])
    # a sample right after a 60-frame gap: every window spans more than 4·half_window frames, so it is not judged
    positions, missing = clean.positions.copy(), clean.missing.copy()
    missing[40:100, 1] = True
    positions[100, 1] += [0.03, 0.0, 0.0]
    assert not median_outliers(positions, missing, 3, 0.01)[100, 1]
    assert median_outliers(positions, missing, 3, 0.01, max_span=200)[100, 1]
    # beside a 10-frame gap the window narrows to one neighbour on each side (12 frames): still judged
    missing[40:100, 1] = False
    missing[90:100, 1] = True
    assert np.array_equal(np.argwhere(median_outliers(positions, missing, 3, 0.01)), [[100, 1]])


def test_bad_shapes_and_windows_are_errors():
    clean = smooth_motion()
    with pytest.raises(ValueError, match="half_window"):
        median_outliers(clean.positions, clean.missing, half_window=0)
    with pytest.raises(ValueError, match=r"\[T, J, 3\]"):
        median_outliers(clean.positions[..., :2], clean.missing)


def test_screened_pchip_repairs_noise_and_keeps_every_other_sample():
    clean = smooth_motion()
    noisy, hit = with_noise(clean, np.random.default_rng(1))
    missing = noisy.missing.copy()
    missing[50:60, 2] = True  # and a gap to fill
    positions = noisy.positions.copy()
    positions[missing] = np.nan
    noisy = Motion(positions=positions, joint_names=noisy.joint_names, fps=noisy.fps, name="noisy")
    hit &= ~missing

    plain = PchipInterpolation().refine(noisy)
    screened = MedianScreen(PchipInterpolation(), half_window=3, threshold=0.01).refine(noisy)
    flags = median_outliers(noisy.positions, noisy.missing, 3, 0.01)
    report = screened.metadata["refinement"]
    assert report["screened"] == int(flags.sum()) and report["repaired"] == int(flags.sum())
    assert report["filled"] == int(missing.sum()) and report["method"] == "MedianScreen(PchipInterpolation)"
    assert not screened.missing.any()
    kept = ~missing & ~flags
    assert np.array_equal(screened.positions[kept], noisy.positions[kept])  # bit-identical

    def rms(m, where):
        return float(np.sqrt(np.mean(np.sum((m.positions[where] - clean.positions[where]) ** 2, axis=-1))))

    assert rms(screened, hit) < 0.25 * rms(plain, hit)  # most of the noise is gone (plain PCHIP keeps it all)
    assert rms(screened, missing) < rms(plain, missing)


class FillsNothing(MotionRefiner):
    """A refiner that cannot fill anything (every missing entry stays missing)."""

    def _refine_matrix(self, X, observed):
        return np.where(observed, X, np.nan), None


def test_flagged_samples_the_refiner_cannot_fill_keep_their_value():
    clean = smooth_motion()
    positions = clean.positions.copy()
    positions[120, 3] += [0.0, 0.05, 0.0]
    spiky = Motion(positions=positions, joint_names=clean.joint_names, fps=clean.fps, name="spiky")
    out = MedianScreen(FillsNothing()).refine(spiky)
    assert not out.missing.any() and np.array_equal(out.positions, spiky.positions)
    assert out.metadata["refinement"]["screened"] == 1 and out.metadata["refinement"]["repaired"] == 0


def test_fit_clones_and_requires_fit_follows_the_refiner():
    class NeedsFit(PchipInterpolation):
        requires_fit = True

    screen = MedianScreen(NeedsFit())
    assert screen.requires_fit and not MedianScreen(PchipInterpolation()).requires_fit
    clean = smooth_motion()
    fitted = clone(screen).fit([clean])
    assert fitted.refiner_ is not screen.refiner and fitted.refiner_.joint_names_ == clean.joint_names
    assert "refiner__extrapolate" in screen.get_params(deep=True)  # the runner's fit cache key sees inside


@needs(WALK)
def test_cli_screen_outliers_pulls_a_spike_back(tmp_path, capsys):
    spiky, marker, frame, before = spiky_walk(tmp_path)

    plain, screened = tmp_path / "plain.c3d", tmp_path / "screened.c3d"
    assert main(["refine", str(spiky), str(plain), "--method", "pchip", "--repair-outliers"]) == 0
    assert ezc3d.c3d(str(plain))["data"]["points"][0, marker, frame] == before[0, marker, frame]
    capsys.readouterr()
    assert main(["refine", str(spiky), str(screened), "--method", "pchip", "--screen-outliers"]) == 0
    printed = capsys.readouterr().out
    assert "MedianScreen(PchipInterpolation)" in printed and "repaired" in printed
    after = ezc3d.c3d(str(screened))["data"]["points"][:3]
    assert abs(after[0, marker, frame] - before[0, marker, frame]) > 250.0  # back near the trajectory
    neighbours = before[:, marker, [frame - 1, frame + 1]].mean(axis=1)
    assert np.linalg.norm(after[:, marker, frame] - neighbours) < 20.0  # mm
    assert main(["refine", str(spiky), str(tmp_path / "x.c3d"), "--method", "pchip", "--screen-outliers", "0"]) == 2
    assert "--screen-outliers" in capsys.readouterr().err


def test_the_hampel_rule_spares_fast_motion_and_still_flags_noise():
    # a 30 fps take: one joint swings fast (1.2 m at 3 Hz), one is nearly still; σ = 2 cm noise on the still one
    fps = 30.0
    t = np.arange(120)[:, None] / fps
    fast = np.stack([0.6 * np.sin(2 * np.pi * 3.0 * t[:, 0]), 1.0 + 0.0 * t[:, 0], 0.0 * t[:, 0]], axis=-1)
    still = np.stack([0.01 * t[:, 0], 1.0 + 0.0 * t[:, 0], 0.2 + 0.0 * t[:, 0]], axis=-1)
    positions = np.stack([fast, still], axis=1).astype(np.float32)
    noisy = positions.copy()
    hit = np.zeros((120, 2), bool)
    hit[10:110:7, 1] = True
    noisy[hit] += np.float32([0.02, -0.015, 0.01])
    missing = np.zeros((120, 2), bool)
    fixed = median_outliers(noisy, missing, 2, 0.005)
    hampel = median_outliers(noisy, missing, 2, 0.005, n_sigmas=3.0)
    assert fixed[:, 0].mean() > 0.2  # the fixed distance flags a fifth of the fast joint's samples
    assert not hampel[:, 0].any()  # its own spread raises the bar there
    assert np.array_equal(hampel[:, 1], hit[:, 1])  # and the noise on the still joint is still found, exactly


DASH = SHARED / "data" / "bandai_motion_1" / "data" / "dataset-1_dash_proud_001.bvh"
SQUAT = SHARED / "data" / "hdm05_cuts11" / "bd" / "HDM_bd_squat1Reps_004_120.amc"


@needs(DASH)
@needs(SQUAT)
def test_cli_reports_what_the_screen_hid_and_warns_at_low_frame_rates(tmp_path, capsys):
    # a clean 120 fps HDM05 squat: nothing hidden, no warning
    assert main(["refine", str(SQUAT), str(tmp_path / "squat.npz"), "--method", "pchip", "--screen-outliers"]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"^median screen: hid 0 of \d+ observed samples \(0\.00 %\)", printed, re.MULTILINE), printed
    assert "warning:" not in printed
    # a clean 30 fps Bandai dash: fast limbs at a quarter of the rate the defaults were chosen at
    assert main(["refine", str(DASH), str(tmp_path / "dash.npz"), "--method", "pchip", "--screen-outliers"]) == 0
    printed = capsys.readouterr().out
    share = float(re.search(r"^median screen: hid \d+ of \d+ observed samples \((\S+) %\)", printed, re.MULTILINE)[1])
    assert share > 2.0
    assert re.search(r"^warning: the screen hid .* chosen at 120 fps, and at 30 fps", printed, re.MULTILINE), printed
    # a threshold raised for the rate quiets it
    assert (
        main(["refine", str(DASH), str(tmp_path / "dash2.npz"), "--method", "pchip", "--screen-outliers", "0.08"]) == 0
    )
    assert "warning:" not in capsys.readouterr().out
