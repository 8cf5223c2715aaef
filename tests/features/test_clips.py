"""Sliding-window clips and their non-negative features (numpy reference and batched torch version)."""

import numpy as np
import pytest
import torch

from mocapkit.features.clips import (
    ClipFeatures,
    clip_count,
    clip_features,
    clip_frame_offsets,
    clip_windows,
    feature_dim,
    sequence_clip_features,
)
from mocapkit.motion.layouts import MSR20


def _sequence(frames: int, seed: int = 0) -> np.ndarray:
    """A plausible MSR20 sequence ``[frames, 20, 3]``: a pose 2.5 m away drifting slowly."""
    rng = np.random.default_rng(seed)
    pose = rng.normal(scale=0.3, size=(1, 20, 3)) + [0.0, 0.0, 2.5]
    drift = np.cumsum(rng.normal(scale=0.01, size=(frames, 20, 3)), axis=0)
    return (pose + drift).astype(np.float32)


@pytest.mark.parametrize(
    "length, expected", [(10, 1), (29, 1), (30, 1), (44, 1), (45, 2), (46, 2), (60, 3), (100, 5), (936, 61)]
)
def test_window_count_follows_the_corrected_formula(length, expected):
    windows = clip_windows(length, window=30)
    assert clip_count(length, 30) == len(windows) == expected
    if length >= 30:
        assert expected == (length - 30) // 15 + 1
        assert windows[-1, 1] <= length
    np.testing.assert_array_equal(windows[:, 1] - windows[:, 0], 30)
    np.testing.assert_array_equal(windows[:, 0], np.arange(expected) * 15)


def test_window_arguments_are_checked():
    assert clip_count(40, window=10, stride=3) == (40 - 10) // 3 + 1
    with pytest.raises(ValueError, match="stride"):
        clip_windows(40, window=1)
    with pytest.raises(ValueError, match="length"):
        clip_windows(0)
    with pytest.raises(ValueError, match="frames_per_clip"):
        clip_frame_offsets(10, 11)


def test_features_are_non_negative_with_expected_shape_and_sign_split():
    seq = _sequence(70)
    features = clip_features(seq, window=30, frames_per_clip=10)
    assert features.shape == (clip_count(70, 30), feature_dim(20, 10)) == (3, 1200)
    assert features.dtype == np.float32 and (features >= 0).all()
    positive, negative = features[:, :600], features[:, 600:]
    assert not ((positive > 0) & (negative > 0)).any()  # one of the two parts is zero per coordinate
    # clip 0, frame 0, root joint (HipCenter, index 6) is the origin: all zero
    root = MSR20.parents.index(-1)
    first = (positive - negative)[0].reshape(10, 20, 3)
    np.testing.assert_allclose(first[0, root], 0.0, atol=1e-6)


def test_features_are_invariant_to_translation_and_body_size():
    seq = _sequence(50)
    base = clip_features(seq)
    np.testing.assert_allclose(clip_features(seq + np.float32([1.0, -0.5, 2.0])), base, atol=1e-5)
    np.testing.assert_allclose(clip_features(seq * np.float32(1.7)), base, atol=1e-5)


def test_short_sequence_is_edge_padded_to_one_window():
    seq = _sequence(12)
    features = clip_features(seq, window=30, frames_per_clip=10)
    assert features.shape == (1, 1200)
    frames = (features[0, :600] - features[0, 600:]).reshape(10, 20, 3)
    offsets = clip_frame_offsets(30, 10)
    past_end = offsets >= 11
    assert past_end.sum() >= 5
    for f in np.flatnonzero(past_end):  # the last frame, repeated
        np.testing.assert_allclose(frames[f], frames[np.flatnonzero(past_end)[0]], atol=1e-6)


def test_trailing_zero_frames_are_padding_and_untracked_joints_are_zero():
    seq = _sequence(40)
    padded = np.concatenate([seq, np.zeros((25, 20, 3), np.float32)])
    np.testing.assert_allclose(clip_features(padded), clip_features(seq), atol=1e-6)
    holes = seq.copy()
    holes[5, 3] = 0.0  # joint 3 untracked in frame 5
    features = clip_features(holes, window=30, frames_per_clip=30)
    frames = (features[0, :1800] - features[0, 1800:]).reshape(30, 20, 3)
    assert (frames[5, 3] == 0).all() and (frames[5, 2] != 0).any()


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match=r"\[frames, 20, 3\]"):
        clip_features(np.zeros((10, 25, 3)))
    bad = _sequence(40)
    bad[7, 2, 1] = np.nan
    with pytest.raises(ValueError, match="frame 7"):
        clip_features(bad)
    with pytest.raises(ValueError, match=r"s02: positions are all zero"):
        sequence_clip_features([_sequence(40), np.zeros((30, 20, 3))], names=["s01", "s02"])


def test_sequence_clip_features_stacks_and_tags_owners():
    features, owner = sequence_clip_features([_sequence(20), _sequence(60, 1), _sequence(45, 2)])
    np.testing.assert_array_equal(owner, [0, 1, 1, 1, 2, 2])
    assert features.shape == (6, 1200)


def test_torch_features_equal_numpy_features_in_a_zero_padded_batch():
    lengths = [12, 30, 45, 61, 100]
    seqs = [_sequence(n, seed=i) for i, n in enumerate(lengths)]
    seqs[3][10:13] = 0.0  # an untracked stretch inside a sequence
    seqs[4][20, 5] = 0.0
    batch = torch.zeros(len(seqs), max(lengths), 20, 3)
    for i, s in enumerate(seqs):
        batch[i, : len(s)] = torch.from_numpy(s)
    module = ClipFeatures("msr20", window=30, stride=15, frames_per_clip=10)
    features, valid = module(batch)
    assert features.shape == (5, -(-100 // 15), 1200) and valid.dtype == torch.bool
    for i, s in enumerate(seqs):
        expected = clip_features(s, 30, 15, 10)
        assert int(valid[i].sum()) == len(expected) == clip_count(lengths[i], 30, 15)
        np.testing.assert_allclose(features[i][valid[i]].numpy(), expected, atol=1e-5)
        assert (features[i][~valid[i]] == 0).all()


def test_torch_features_of_an_all_zero_sample_are_all_invalid():
    features, valid = ClipFeatures("msr20")(torch.zeros(2, 40, 20, 3))
    assert not valid.any() and torch.isfinite(features).all() and (features == 0).all()
