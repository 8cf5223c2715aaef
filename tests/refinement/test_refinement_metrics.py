"""Refinement metrics: Wang eq. 3.18/4.16 per-frame RMSE (cm), §4.2.3 matrix RMSE, mean 3-D error (mm)."""

import numpy as np
import pytest

from mocapkit.motion.container import Motion
from mocapkit.refinement import corrupt
from mocapkit.refinement.gap_filling import LinearInterpolation
from mocapkit.refinement.metrics import (
    matrix_rmse,
    mean_joint_error,
    per_frame_rmse,
    score_refinement,
    sequence_rmse,
)


def motion(positions):
    positions = np.asarray(positions, dtype=np.float32)
    return Motion(positions=positions, joint_names=[f"j{i}" for i in range(positions.shape[1])], fps=100.0)


@pytest.fixture
def pair():
    clean = np.zeros((4, 3, 3))
    refined = clean.copy()
    refined[0, 0, 0] = 0.03  # frame 0: 3 cm and 4 cm errors on the two corrupted markers
    refined[0, 1, 1] = 0.04
    refined[1, 2] = [0.0, 0.0, 0.02]  # frame 1: one corrupted marker, 2 cm
    refined[2, 0, 0] = 0.05  # frame 2: an error on an UNcorrupted marker only
    mask = np.zeros((4, 3), bool)
    mask[0, :2] = mask[1, 2] = mask[2, 1] = True
    return clean, refined, mask


def test_per_frame_rmse_is_wang_eq_3_18_in_cm(pair):
    clean, refined, mask = pair
    curve = per_frame_rmse(clean, refined, mask, numerator="corrupted")
    assert curve[0] == pytest.approx(np.sqrt((3**2 + 4**2) / 2))  # divided by n_e = 2 markers
    assert curve[1] == pytest.approx(2.0)
    assert curve[2] == pytest.approx(0.0)
    assert np.isnan(curve[3])  # no corrupted entry in frame 3
    assert sequence_rmse(clean, refined, mask, "corrupted") == pytest.approx((np.sqrt(12.5) + 2.0 + 0.0) / 3)


def test_literal_frame_numerator_counts_changes_to_uncorrupted_entries(pair):
    clean, refined, mask = pair
    curve = per_frame_rmse(clean, refined, mask)  # numerator="frame" (literal eq.)
    assert curve[0] == pytest.approx(np.sqrt(12.5)) and curve[2] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="numerator"):
        per_frame_rmse(clean, refined, mask, numerator="all")


def test_matrix_rmse_and_mean_error(pair):
    clean, refined, mask = pair
    # §4.2.3: RMS over the 3 coordinates of each of the 4 corrupted entries
    assert matrix_rmse(clean, refined, mask) == pytest.approx(np.sqrt((9 + 16 + 4 + 0) / 12))
    assert mean_joint_error(clean, refined, mask) == pytest.approx((30 + 40 + 20 + 0) / 4)  # mm
    assert np.isnan(mean_joint_error(clean, refined, np.zeros_like(mask)))


def test_unfilled_and_ground_truth_missing_entries_are_not_scored(pair):
    clean, refined, mask = pair
    refined[1, 2] = np.nan  # refiner left it missing
    clean[0, 1] = np.nan  # no ground truth here
    curve = per_frame_rmse(clean, refined, mask, numerator="corrupted")
    assert curve[0] == pytest.approx(3.0) and np.isnan(curve[1])
    with pytest.raises(ValueError, match="mask"):
        per_frame_rmse(clean, refined, mask[:2])
    with pytest.raises(ValueError, match="frames, joints, 3"):
        per_frame_rmse(clean, refined[:2], mask)


def test_score_refinement_of_a_gap_filler():
    t = np.linspace(0, 1, 200)
    positions = np.stack([np.stack([t * (j + 1), np.sin(t + j), np.full_like(t, j)], 1) for j in range(12)], 1)
    clean = motion(positions)
    c = corrupt(clean, "continuous_missing", 20, seed=0)
    perfect = score_refinement(clean, clean, c)
    assert perfect.rmse_cm == 0 and perfect.mean_error_mm == 0 and perfect.coverage == 1.0
    assert perfect.corrupted == 200 and perfect.changed_clean == 0
    refined = LinearInterpolation().refine(c.motion)
    score = score_refinement(refined, clean, c)
    assert score.changed_clean == 0 and score.unfilled == 0 and score.protocol == "continuous_missing"
    assert score.rmse_curve_cm.shape == (200,) and np.isnan(score.rmse_curve_cm[~c.removed.any(1)]).all()
    assert 0 < score.rmse_cm and score.mean_error_removed_mm == pytest.approx(score.mean_error_mm)
    assert np.isnan(score.mean_error_perturbed_mm)
    assert "rmse_curve_cm" not in score.as_dict() and len(score.as_dict(curve=True)["rmse_curve_cm"]) == 200
    # a "refiner" that moves clean entries is caught; one that leaves gaps is caught
    moved = refined.positions.copy()
    moved[0, 0, 0] += 0.01
    holey = c.motion
    assert score_refinement(motion(moved), clean, c).changed_clean == 1
    left = score_refinement(holey, clean, c)
    assert left.unfilled == 200 and left.coverage == 0.0 and np.isnan(left.rmse_cm)
