"""Gait Energy Images: silhouette normalisation, gait period and per-cycle GEIs."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from PIL import Image, ImageDraw

from mocapkit.datasets.casia_b.gei import (
    GaitSequenceError,
    gait_energy_images,
    gait_period,
    lag_correlation,
    normalize_silhouettes,
    period_from_signal,
)


def walking_silhouettes(
    num_frames: int,
    cycle: float,
    size: tuple[int, int] = (120, 160),
    x0: float = 30.0,
    speed: float = 1.0,
    scale: float = 1.0,
    phase: float = 0.0,
) -> np.ndarray:
    """A stick walker, uint8 ``[T, H, W]`` in {0, 255}: head, torso and two legs swinging ±0.45 rad.

    The legs' angle is ``±0.45 sin(2π t / cycle + phase)``, so they are together twice per
    ``cycle`` frames (one step each), as in a real walk. It moves ``speed`` px per frame to the right.
    """
    height, width = size
    frames = np.zeros((num_frames, height, width), dtype=np.uint8)
    for t in range(num_frames):
        image = Image.new("L", (width, height), 0)
        draw = ImageDraw.Draw(image)
        theta = 0.45 * math.sin(2 * math.pi * t / cycle + phase)
        cx, hip, leg = x0 + speed * t, 10 + 30 * scale, 40 * scale
        draw.ellipse([cx - 5 * scale, 10, cx + 5 * scale, 10 + 9 * scale], fill=255)
        draw.rectangle([cx - 6 * scale, 10 + 9 * scale, cx + 6 * scale, hip], fill=255)
        for side in (1, -1):
            draw.line(
                [cx, hip, cx + side * leg * math.sin(theta), hip + leg * math.cos(theta)],
                fill=255,
                width=max(1, int(6 * scale)),
            )
        frames[t] = np.asarray(image)
    return frames


def rectangle_frame(top: int, left: int, height: int, width: int, size=(120, 160)) -> np.ndarray:
    frame = np.zeros(size, dtype=np.uint8)
    frame[top : top + height, left : left + width] = 255
    return frame


# --------------------------------------------------------------------------- normalisation


def test_a_rectangle_aligns_the_same_wherever_and_however_large_it_is():
    frames = np.stack(
        [
            rectangle_frame(10, 30, 40, 20),
            rectangle_frame(70, 120, 40, 20),
            rectangle_frame(5, 60, 80, 40),
            rectangle_frame(0, 0, 20, 10),
        ]
    )
    aligned, kept = normalize_silhouettes(frames, height=64, width=44)
    assert aligned.shape == (4, 64, 44) and aligned.dtype == np.float32
    np.testing.assert_array_equal(kept, [0, 1, 2, 3])
    # 40x20 scaled to 64 rows is 32 columns wide, centred on column 22: columns 6..37.
    expected = np.zeros((64, 44), dtype=np.float32)
    expected[:, 6:38] = 1.0
    for image in aligned:
        np.testing.assert_allclose(image, expected, atol=1e-5)


def test_the_median_column_lands_on_the_centre_column_not_the_bounding_box_centre():
    frame = np.zeros((64, 160), dtype=np.uint8)
    frame[:, 50:60] = 255  # a 10-column block, 640 px
    frame[0, 60:100] = 255  # a thin 40-px arm to the right: bounding-box centre 74.5, mass median column 55
    aligned, _ = normalize_silhouettes(frame[None], height=64, width=44)  # 64 rows: scale 1
    image = aligned[0]
    # Column 55 (first past half the mass) lands on output column 22: the block is columns 17..26.
    np.testing.assert_allclose(image[1:, 17:27], 1.0, atol=1e-6)
    np.testing.assert_allclose(image[1:, :17], 0.0, atol=1e-6)
    np.testing.assert_allclose(image[1:, 27:], 0.0, atol=1e-6)
    # The arm runs from output column 27 to the right edge (input column 76), the rest is cut.
    np.testing.assert_allclose(image[0, 17:], 1.0, atol=1e-6)


def test_a_silhouette_at_the_frame_edge_is_zero_padded():
    frame = rectangle_frame(0, 0, 64, 10, size=(64, 100))
    aligned, _ = normalize_silhouettes(frame[None], height=64, width=44)
    # Median column 5 -> output column 22: the block is 17..26, the 17 columns left of it lie outside the frame.
    np.testing.assert_allclose(aligned[0][:, 17:27], 1.0, atol=1e-6)
    assert aligned[0][:, :17].max() == 0 and aligned[0][:, 27:].max() == 0


def test_empty_and_nearly_empty_frames_are_dropped_and_reported_by_kept():
    frames = walking_silhouettes(6, cycle=24)
    frames[1] = 0
    frames[4] = 0
    frames[4, 50, 50:53] = 255  # 3 px: below 0.1 % of 120x160 = 19.2 px
    aligned, kept = normalize_silhouettes(frames)
    np.testing.assert_array_equal(kept, [0, 2, 3, 5])
    assert len(aligned) == 4
    _, kept_all = normalize_silhouettes(frames, min_foreground=0.0)  # only truly empty frames go
    np.testing.assert_array_equal(kept_all, [0, 2, 3, 4, 5])
    none, kept_none = normalize_silhouettes(np.zeros((3, 20, 20), np.uint8))
    assert none.shape == (0, 64, 44) and kept_none.shape == (0,)


def test_square_thesis_size_and_bool_input():
    frames = walking_silhouettes(4, cycle=24)
    aligned, _ = normalize_silhouettes(frames > 0, height=124, width=None)
    assert aligned.shape == (4, 124, 124)
    assert aligned.min() >= 0.0 and aligned.max() <= 1.0
    assert aligned[:, 0].max() > 0.5 and aligned[:, -1].max() > 0.5  # the silhouette spans all rows
    np.testing.assert_allclose(aligned, normalize_silhouettes(frames, 124, 124)[0], atol=1e-6)


def dense_box_alignment(frames: np.ndarray, height: int, width: int) -> np.ndarray:
    """The definition, one frame at a time: ``R · F · Cᵀ`` with dense box-filter (area) matrices."""
    out = []
    for frame in frames.astype(np.float64) / 255:
        if frame.sum() < 0.001 * frame.size or not frame.any():
            continue
        rows = np.flatnonzero(frame.sum(axis=1))
        scale = height / (rows[-1] - rows[0] + 1.0)
        median = np.argmax(np.cumsum(frame.sum(axis=0)) > frame.sum() / 2)

        def box(start, n_out, n_in, scale=scale):
            edges, k = start + np.arange(n_out + 1) / scale, np.arange(n_in)
            return np.clip(np.minimum(edges[1:, None], k + 1) - np.maximum(edges[:-1, None], k), 0, None) * scale

        out.append(
            box(rows[0], height, frame.shape[0]) @ frame @ box(median - width / 2 / scale, width, frame.shape[1]).T
        )
    return np.clip(np.array(out), 0, 1)


@pytest.mark.parametrize("size", [(64, 44), (124, 124), (32, 60), (16, 8)])
def test_the_batched_resampler_equals_the_dense_box_filter_definition(size):
    rng = np.random.default_rng(size[0])
    for _ in range(8):
        rows, cols = rng.integers(20, 200, 2)
        frames = np.zeros((4, rows, cols), np.uint8)
        for t in range(4):  # random speckled blobs anywhere, also touching the sides
            a, b = sorted(rng.integers(0, rows, 2))
            c, d = sorted(rng.integers(0, cols, 2))
            frames[t, a : b + 1, c : d + 1] = 255 * (rng.random((b - a + 1, d - c + 1)) > 0.3)
        aligned, _ = normalize_silhouettes(frames, *size)
        expected = dense_box_alignment(frames, *size)
        assert aligned.shape == expected.shape
        np.testing.assert_allclose(aligned, expected, atol=1e-5)


@pytest.mark.parametrize(
    "frames, match", [(np.zeros((10, 10), np.uint8), r"\[T, H, W\]"), (np.zeros((2, 10, 10), np.float32), "dtype")]
)
def test_bad_frames_are_rejected_with_a_clear_message(frames, match):
    with pytest.raises(ValueError, match=match):
        normalize_silhouettes(frames)


# --------------------------------------------------------------------------- gait period


def test_lag_correlation_matches_numpy_corrcoef():
    x = np.random.default_rng(0).normal(size=40)
    r = lag_correlation(x, 20)
    assert r[0] == pytest.approx(1.0)
    for k in (1, 7, 20):
        assert r[k] == pytest.approx(np.corrcoef(x[:-k], x[k:])[0, 1], abs=1e-12)


@pytest.mark.parametrize("cycle", [18, 20, 24, 25, 27, 31, 34])
def test_the_period_of_a_synthetic_leg_signal_is_exact(cycle):
    t = np.arange(100)
    rng = np.random.default_rng(cycle)
    # One oscillation per step (two per cycle), slightly uneven legs, a drift and noise.
    signal = (
        np.cos(4 * np.pi * t / cycle)
        + 0.2 * np.cos(2 * np.pi * t / cycle + 0.5)
        + 0.01 * t
        + 0.1 * rng.normal(size=len(t))
    )
    assert period_from_signal(100 + 20 * signal) == cycle


def test_two_steps_not_three_are_a_cycle_when_both_legs_are_alike():
    t = np.arange(100)
    signal = np.cos(4 * np.pi * t / 20)  # steps of 10: lags 20 and 30 both repeat the signal exactly
    assert period_from_signal(signal, min_cycle=18, max_cycle=34) == 20


def test_single_frame_glitches_do_not_hide_the_period():
    t = np.arange(90)
    signal = np.cos(4 * np.pi * t / 26)
    signal[[5, 31, 47, 70]] = 25.0  # e.g. a frame whose lower half the segmentation lost
    assert period_from_signal(signal) == 26


def test_no_period_in_a_flat_or_too_short_signal():
    assert period_from_signal(np.full(60, 7.0)) is None
    assert period_from_signal(np.cos(np.arange(20) * 4 * np.pi / 25)) is None
    with pytest.raises(ValueError, match="NaN"):
        period_from_signal(np.array([1.0, np.nan] * 20))


@pytest.mark.parametrize("cycle, scale, speed", [(22, 1.0, 1.5), (25, 1.0, 0.0), (29, 1.4, -1.0), (33, 0.8, 1.0)])
def test_the_period_of_a_stick_walk_is_within_one_frame(cycle, scale, speed):
    frames = walking_silhouettes(80, cycle, x0=80.0 - 40 * speed, speed=speed, scale=scale, phase=0.7)  # in frame
    aligned, kept = normalize_silhouettes(frames)
    period = gait_period(aligned, kept)
    assert period is not None and abs(period - cycle) <= 1


def test_dropped_frames_keep_the_sequence_clock():
    frames = walking_silhouettes(90, cycle=26)
    frames[[20, 21, 50]] = 0
    aligned, kept = normalize_silhouettes(frames)
    assert len(kept) == 87
    assert gait_period(aligned, kept) == 26


@pytest.mark.parametrize("subject, view", [(1, 90), (2, 90), (3, 36), (4, 144), (5, 72)])
def test_the_period_of_a_synthetic_casia_b_walk_is_within_one_frame(subject, view):
    from mocapkit.datasets.synthetic import casia_b as synthetic

    params = synthetic.draw_subject(0, subject)
    rng = np.random.default_rng(100 * subject + view)
    walk = synthetic.draw_walk(rng)
    frames = synthetic.render_walk(params, view, "nm", 80, 96, rng, walk=walk)  # with segmentation noise
    geis, info = gait_energy_images(frames)
    assert info.period_detected and abs(info.period - params.period / walk.speed) <= 1
    assert len(geis) == (info.kept[-1] + 1 - info.kept[0]) // info.period


# --------------------------------------------------------------------------- GEIs


def test_one_gei_per_whole_cycle_is_the_mean_of_its_aligned_frames():
    frames = walking_silhouettes(91, cycle=25)
    frames[[0, 30]] = 0  # empty frames: the cycles start at frame 1 and the second one averages 24 frames
    geis, info = gait_energy_images(frames, size=(64, 44), per="cycle")
    aligned, kept = normalize_silhouettes(frames, 64, 44)
    assert info.per == "cycle" and info.period == 25 and info.period_detected
    np.testing.assert_array_equal(info.kept, kept)
    assert 0 not in kept and 30 not in kept
    np.testing.assert_array_equal(info.spans, [[1, 26], [26, 51], [51, 76]])
    np.testing.assert_array_equal(info.frames_per_gei, [25, 24, 25])
    assert geis.shape == (3, 64, 44)
    for gei, (start, stop) in zip(geis, info.spans):
        inside = (kept >= start) & (kept < stop)
        np.testing.assert_allclose(gei, aligned[inside].mean(axis=0), atol=1e-6)
    assert geis.min() >= 0.0 and geis.max() <= 1.0
    assert geis.max() == pytest.approx(1.0)  # the torso is always there
    grey = (geis > 0.05) & (geis < 0.95)
    assert grey[:, 48:].sum() > grey[:, :16].sum()  # the swinging legs, not the torso, are grey


def test_one_gei_per_sequence_and_a_given_period():
    frames = walking_silhouettes(40, cycle=25)
    geis, info = gait_energy_images(frames, size=(124, 124), per="sequence")
    assert geis.shape == (1, 124, 124) and info.period is None
    np.testing.assert_array_equal(info.frames_per_gei, [40])
    np.testing.assert_allclose(geis[0], normalize_silhouettes(frames, 124, 124)[0].mean(axis=0), atol=1e-6)
    geis, info = gait_energy_images(frames, per="cycle", period=10)
    assert len(geis) == 4 and info.period == 10 and not info.period_detected


def test_sequences_that_give_no_gei_raise_gait_sequence_errors():
    with pytest.raises(GaitSequenceError, match="shorter than one gait cycle") as caught:
        gait_energy_images(walking_silhouettes(20, cycle=25), period=25)
    assert caught.value.reason == "too_short"
    with pytest.raises(GaitSequenceError, match="no gait period") as caught:  # too short to find a cycle
        gait_energy_images(walking_silhouettes(20, cycle=25))
    assert caught.value.reason == "no_period"
    still = np.repeat(walking_silhouettes(1, cycle=25), 60, axis=0)  # standing still: no leg oscillation
    with pytest.raises(GaitSequenceError, match="no gait period") as caught:
        gait_energy_images(still)
    assert caught.value.reason == "no_period"
    geis, info = gait_energy_images(still, fallback_period=25)  # unless a fallback is asked for
    assert len(geis) == 2 and info.period == 25 and not info.period_detected
    for per in ("cycle", "sequence"):
        with pytest.raises(GaitSequenceError, match="no non-empty silhouette|0 non-empty") as caught:
            gait_energy_images(np.zeros((30, 40, 40), np.uint8), per=per)
        assert caught.value.reason == "no_frames"
    few = walking_silhouettes(3, cycle=25)
    with pytest.raises(GaitSequenceError, match="need at least 5"):
        gait_energy_images(few, per="sequence", min_frames=5)
    with pytest.raises(ValueError, match="per must be"):
        gait_energy_images(few, per="frame")
    assert issubclass(GaitSequenceError, ValueError)
    copy = pickle.loads(pickle.dumps(caught.value))
    assert copy.reason == "no_frames" and str(copy) == str(caught.value)
