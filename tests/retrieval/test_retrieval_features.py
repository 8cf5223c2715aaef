"""Motion features of mocapkit.retrieval.features: relational features, HOD, pose descriptors, GPF bag of words."""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from mocapkit.motion.layouts import LANDMARK_NAMES
from mocapkit.retrieval.features import (
    RELATIONAL_FEATURE_NAMES,
    GPFBagOfWords,
    hod,
    llc_codes,
    pose_descriptors,
    relational_features,
)

J = {name: k for k, name in enumerate(LANDMARK_NAMES)}


def standing_pose() -> np.ndarray:
    """[20, 3] a template-sized upright body, pelvis at the origin, y up, facing +z, left side at +x."""
    p = {"pelvis": (0, 0, 0), "spine": (0, 0.2, 0), "neck": (0, 0.5, 0), "head": (0, 0.7, 0)}
    for s, x in (("l", 1.0), ("r", -1.0)):
        p.update(
            {
                f"{s}_shoulder": (0.18 * x, 0.5, 0),
                f"{s}_elbow": (0.2 * x, 0.22, 0),
                f"{s}_wrist": (0.2 * x, -0.03, 0.02),
                f"{s}_hand": (0.2 * x, -0.11, 0.03),
                f"{s}_hip": (0.1 * x, -0.02, 0),
                f"{s}_knee": (0.1 * x, -0.44, 0.01),
                f"{s}_ankle": (0.1 * x, -0.85, 0),
                f"{s}_foot": (0.1 * x, -0.88, 0.13),
            }
        )
    return np.array([p[name] for name in LANDMARK_NAMES], dtype=np.float64)


def moving_sequence(T=40, seed=0) -> np.ndarray:
    """[T, 20, 3] the standing pose with both arms and the left leg swinging (random phases)."""
    rng = np.random.default_rng(seed)
    seq = np.repeat(standing_pose()[None], T, axis=0)
    t = np.linspace(0, 2 * np.pi, T)
    for j, amp in (("l_hand", 0.3), ("r_hand", 0.25), ("l_wrist", 0.2), ("l_foot", 0.2), ("l_ankle", 0.1)):
        phase = rng.uniform(0, 2 * np.pi)
        seq[:, J[j], 2] += amp * np.sin(t + phase)
        seq[:, J[j], 1] += 0.5 * amp * np.cos(2 * t + phase)
    return seq.astype(np.float32)


def raise_right_hand(pose: np.ndarray) -> np.ndarray:
    up = pose.copy()
    sx = pose[J["r_shoulder"], 0]
    up[J["r_elbow"]] = (sx, 0.78, 0)
    up[J["r_wrist"]] = (sx, 1.03, 0)
    up[J["r_hand"]] = (sx, 1.11, 0)
    return up


# --------------------------------------------------------------------------- relational features


def test_relational_features_shape_and_values():
    seq = moving_sequence()
    f = relational_features(seq)
    assert f.dtype == np.float32 and f.shape == (len(seq), len(RELATIONAL_FEATURE_NAMES))
    assert 30 <= f.shape[1] <= 45
    assert set(np.unique(f)) <= {0.0, 1.0}
    soft = relational_features(seq, soft=True)
    assert soft.shape == f.shape and np.all((soft > 0) & (soft < 1))
    assert np.array_equal(soft > 0.5, f > 0.5)  # the soft version agrees on the side


def test_relational_features_flip_when_the_right_hand_is_raised():
    rest = np.repeat(standing_pose()[None], 5, axis=0)
    raised = np.repeat(raise_right_hand(standing_pose())[None], 5, axis=0)
    before = dict(zip(RELATIONAL_FEATURE_NAMES, relational_features(rest)[2], strict=True))
    after = dict(zip(RELATIONAL_FEATURE_NAMES, relational_features(raised)[2], strict=True))
    for name in ("r_hand_above_head", "r_hand_above_neck", "r_elbow_raised"):
        assert before[name] == 0.0 and after[name] == 1.0, name
    for name in ("l_hand_above_head", "l_hand_above_neck", "lying", "pelvis_low", "r_hand_fast"):
        assert before[name] == after[name] == 0.0, name
    soft_before = relational_features(rest, soft=True)[2, RELATIONAL_FEATURE_NAMES.index("r_hand_above_head")]
    soft_after = relational_features(raised, soft=True)[2, RELATIONAL_FEATURE_NAMES.index("r_hand_above_head")]
    assert soft_before < 0.01 and soft_after > 0.99


def test_relational_features_do_not_depend_on_heading():
    seq = moving_sequence().astype(np.float64)
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # a turn about the vertical
    assert np.array_equal(relational_features(seq), relational_features(seq @ R.T))


# --------------------------------------------------------------------------- HOD


def test_hod_shape_normalisation_and_translation_invariance():
    seq = moving_sequence(T=37)
    h = hod(seq)
    assert h.dtype == np.float32 and h.shape == (19 * 3 * 8 * 7,)
    hist = h.reshape(19, 3, 7, 8)
    sums = hist.sum(-1)
    assert np.all(np.isclose(sums, 1.0, atol=1e-5) | (sums == 0))
    assert np.isclose(sums[J["l_hand"] - 1], 1.0, atol=1e-5).all()  # a moving landmark: every segment filled
    assert (sums[J["head"] - 1] == 0).all()  # a still one: zeros
    assert np.allclose(hod(seq + np.array([1.5, -0.2, 3.0], np.float32)), h, atol=1e-5)
    assert hod(seq, bins=4, levels=2).shape == (19 * 3 * 4 * 3,)
    assert not hod(seq[:1]).any()  # one frame: no displacement


def test_hod_bins_the_direction_of_motion():
    seq = np.repeat(standing_pose()[None], 9, axis=0)
    seq[:, J["r_hand"], 0] += np.linspace(0, 0.4, 9)  # r_hand moves along +x only
    hist = hod(seq).reshape(19, 3, 7, 8)[J["r_hand"] - 1]
    # xy and xz planes: angle 0 → the bin starting at 0 (index 4 of 8 over [−π, π)); yz: no displacement
    assert hist[0, 0, 4] == pytest.approx(1.0) and hist[1, 0, 4] == pytest.approx(1.0)
    assert not hist[2].any()


# --------------------------------------------------------------------------- pose descriptors and GPF


def test_pose_descriptors():
    seq = moving_sequence()
    d = pose_descriptors(seq, fps=30.0)
    assert d.dtype == np.float32 and d.shape == (len(seq), 104) and np.isfinite(d).all()
    assert np.allclose(pose_descriptors(seq + np.float32(2.0)), d, atol=1e-4)
    still = pose_descriptors(np.repeat(standing_pose()[None], 4, axis=0))
    assert np.allclose(still[:, -27:], 0.0)  # velocities of a still body
    fast = pose_descriptors(seq, fps=60.0)
    assert np.allclose(fast[:, -27:], 2 * d[:, -27:], atol=1e-4)  # velocities scale with fps
    assert pose_descriptors(seq[:1]).shape == (1, 104)


def test_llc_codes_sum_to_one_on_k_words():
    rng = np.random.default_rng(0)
    codes = llc_codes(rng.normal(size=(30, 6)), rng.normal(size=(12, 6)), k=4)
    assert codes.shape == (30, 12)
    assert np.allclose(codes.sum(1), 1.0)
    assert ((codes != 0).sum(1) <= 4).all()


def test_gpf_bag_of_words():
    seqs = [moving_sequence(T=30 + 3 * i, seed=i) for i in range(6)]
    bow = GPFBagOfWords(n_words=16, random_state=0)
    with pytest.raises(NotFittedError):
        bow.transform(seqs)
    codes = bow.fit(seqs).transform(seqs)
    assert codes.dtype == np.float32 and codes.shape == (6, 16)
    assert np.allclose(np.linalg.norm(codes, axis=1), 1.0, atol=1e-5)
    assert bow.codebook_.shape == (16, 104)
    again = GPFBagOfWords(n_words=16, random_state=0).fit(seqs).transform(seqs)
    assert np.array_equal(codes, again)  # seeded
    mean = GPFBagOfWords(n_words=16, pooling="mean").fit(seqs).transform(seqs[:2])
    assert np.allclose(np.linalg.norm(mean, axis=1), 1.0, atol=1e-5)
    with pytest.raises(ValueError, match="pooling"):
        GPFBagOfWords(pooling="median").fit(seqs)
    with pytest.raises(ValueError, match="frames"):
        GPFBagOfWords(n_words=1000).fit(seqs)
