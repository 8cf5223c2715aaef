"""DTW's world-frame features: the unturned posture, the pelvis velocity and the root-centred joints, and the gate
that keeps them only for libraries whose clips share one frame (``world_frame="auto"``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.motion.geometry import TEMPLATE_BONES, landmark_track, normalised_landmarks
from mocapkit.retrieval.dtw import WORLD_MIN_CONCENTRATION, DTWRetrieval, frame_features, heading_concentration
from tests.retrieval.test_retrieval import _walker


def _turned(motion, yaw: float, velocity=(0.0, 0.0, 0.0)):
    """``motion`` turned by ``yaw`` radians about +y and moving at ``velocity`` (m/s, applied after the turn)."""
    c, s = np.cos(yaw), np.sin(yaw)
    p = motion.positions.copy()
    x, z = p[..., 0].copy(), p[..., 2].copy()
    p[..., 0], p[..., 2] = c * x + s * z, -s * x + c * z
    t = np.arange(motion.num_frames)[:, None, None] / motion.fps
    return replace(motion, positions=p + t * np.asarray(velocity, dtype=float))


@pytest.mark.parametrize("heading", ["frame", "clip", "none"])
def test_world_positions_are_the_unturned_landmarks_whatever_the_heading(heading):
    motion = _turned(_walker(seed=1), 1.1)
    track = landmark_track(motion, heading=heading)
    np.testing.assert_array_equal(track.landmarks, normalised_landmarks(motion, heading=heading))
    expected = normalised_landmarks(motion, heading="none").reshape(motion.num_frames, -1)
    np.testing.assert_allclose(frame_features(track, "world_positions", 30.0), expected, atol=1e-5)


def test_world_velocity_is_the_pelvis_velocity_scaled_to_the_template_leg():
    """The walker's legs are about the template's 0.83 m (0.42 + 0.41): 1.5 m/s along x reads as about 1.5 m/s; the
    same walk by a body twice as big reads as half as fast (strides compare across bodies)."""
    assert TEMPLATE_BONES["l_knee"] + TEMPLATE_BONES["l_ankle"] == pytest.approx(0.83)
    walker = _walker(seed=2)
    velocity = frame_features(landmark_track(_turned(walker, 0.0, (1.5, 0, 0))), "world_velocity", 30.0)
    np.testing.assert_allclose(velocity[5:-5], [[1.5, 0.0, 0.0]] * (len(velocity) - 10), atol=0.05)
    giant = replace(walker, positions=walker.positions * 2)
    slow = frame_features(landmark_track(_turned(giant, 0.0, (1.5, 0, 0))), "world_velocity", 30.0)
    np.testing.assert_allclose(slow[5:-5, 0], velocity[5:-5, 0] / 2, atol=0.02)


def test_the_gate_keeps_world_features_only_for_clips_that_face_alike():
    aligned = [_turned(_walker(seed=i), 0.1 * i) for i in range(6)]
    spread = [_turned(_walker(seed=i), 2 * np.pi * i / 6) for i in range(6)]
    features = ["positions", "world_positions", "world_velocity"]
    tracks = DTWRetrieval().sequences(spread)
    assert heading_concentration(tracks, 30.0) < 0.05 < WORLD_MIN_CONCENTRATION
    assert DTWRetrieval(features=features).fit(aligned).features_ == features
    assert DTWRetrieval(features=features).fit(spread).features_ == ["positions"]
    assert DTWRetrieval(features=features, world_frame="on").fit(spread).features_ == features
    assert DTWRetrieval(features=features, world_frame="off").fit(aligned).features_ == ["positions"]
    with pytest.raises(ValueError, match="all world features.*concentration is 0.0"):
        DTWRetrieval(features=["world_velocity"]).fit(spread)
    with pytest.raises(ValueError, match="world_frame must be one of"):
        DTWRetrieval(features=features, world_frame="maybe").fit(aligned)


def test_in_a_shared_frame_a_walk_to_the_left_finds_walks_to_the_left():
    """One studio: walkers facing +z walk sideways to the left (+x) or to the right. Per-frame-turned positions
    cannot tell them apart (the same posture); the default's world terms can."""
    left = [_turned(_walker(seed=i), 0.05 * i, (1.0, 0, 0)) for i in range(4)]
    right = [_turned(_walker(seed=10 + i), -0.05 * i, (-1.0, 0, 0)) for i in range(4)]
    query = _turned(_walker(seed=99), 0.02, (1.0, 0, 0))
    default = DTWRetrieval(
        features=["positions", "relational", "world_positions", "world_velocity"], hubness="mutual_proximity"
    ).fit(left + right)
    assert "world_velocity" in default.features_
    order = np.argsort(default.distances([query])[0])
    assert set(order[:4]) == {0, 1, 2, 3}


def test_an_index_says_which_features_its_library_chose(tmp_path_factory, capsys):
    """``mocapkit index`` prints the features used and the heading concentration, and the manifest keeps them."""
    import json

    from mocapkit.retrieval import build_index
    from tests.shared_data import synthetic_hdm05_folder

    src = synthetic_hdm05_folder(tmp_path_factory, ("walk2StepsLstart", "squat1Reps"), clips_per_actor=1)
    out = tmp_path_factory.mktemp("index")
    index = build_index(src, out, overrides=["n_reference=4"])
    method = index.method
    err = capsys.readouterr().err
    assert f"features {', '.join(method.features_)} (the clips' starting headings: concentration" in err
    assert f"concentration {method.heading_concentration_:.2f}; world_frame=auto" in err
    learned = json.loads((out / "manifest.json").read_text())["learned"]
    assert learned == {"features_": method.features_, "heading_concentration_": method.heading_concentration_}


# ------------------------------------------------------------------------------------------ joints
def _fewer_joints(motion):
    """``motion`` without its last joint (a right toe): another skeleton with the same landmarks."""
    from mocapkit.motion.container import Motion

    return Motion(
        motion.positions[:, :-1], list(motion.joint_names[:-1]), motion.fps, parents=motion.parents[:-1], name="toeless"
    )


def test_the_joints_feature_is_plain_dtw():
    """``features="joints"`` compares what plain DTW compares: the same distances, and not turned."""
    from mocapkit.retrieval.dtw import PlainDTWRetrieval

    library = [_turned(_walker(seed=i), 0.3 * i, (0.5 * i, 0, 0)) for i in range(5)]
    queries = [_turned(_walker(seed=20), 0.2), _turned(_walker(seed=21), 1.0, (1.0, 0, 0))]
    joints = DTWRetrieval(features="joints", world_frame="on", parallel=False).fit(library)
    plain = PlainDTWRetrieval(parallel=False).fit(library)
    np.testing.assert_allclose(joints.distances(queries), plain.distances(queries), rtol=1e-6)
    assert joints.distances([_turned(library[0], np.pi / 2)])[0, 0] > 0.1  # a turned clip is another clip here


def test_weights_divide_the_scales():
    library = [_turned(_walker(seed=i), 0.05 * i, (0.3 * i, 0, 0)) for i in range(6)]
    features = ["positions", "world_velocity", "joints"]
    plain = DTWRetrieval(features=features, parallel=False).fit(library)
    half = DTWRetrieval(features=features, weights={"joints": 0.5}, parallel=False).fit(library)
    assert half.features_ == features
    np.testing.assert_allclose(half.scales_, plain.scales_ * [1.0, 1.0, 2.0])
    with pytest.raises(ValueError, match=r"weights: \['hands'\] are not among the features"):
        DTWRetrieval(features=features, weights={"hands": 2.0}).fit(library)
    with pytest.raises(ValueError, match="weights must be positive numbers"):
        DTWRetrieval(features=features, weights={"joints": 0.0}).fit(library)
    with pytest.raises(ValueError, match="weights must be positive numbers"):  # checked with one feature too
        DTWRetrieval(features="positions", weights={"positions": float("nan")}).fit(library)


def test_the_joints_feature_needs_one_skeleton():
    """Mixed skeletons in the library: ``auto`` leaves the joints out, ``on`` refuses; a fitted library refuses a
    query or an added clip of another skeleton, naming the file and both joint counts."""
    from mocapkit.motion.geometry import SkeletonInputError

    library = [_turned(_walker(seed=i), 0.05 * i) for i in range(4)]
    other = _fewer_joints(_walker(seed=9))
    features = ["positions", "joints"]
    assert DTWRetrieval(features=features).fit([*library, other]).features_ == ["positions"]
    with pytest.raises(ValueError, match=r"the database's clips have \[21, 22\] joints"):
        DTWRetrieval(features=features, world_frame="on").fit([*library, other])
    method = DTWRetrieval(features=features).fit(library)
    assert method.features_ == features
    with pytest.raises(SkeletonInputError, match="toeless: 21 joints, the database clips have 22"):
        method.distances([other])
    with pytest.raises(SkeletonInputError, match="toeless: 21 joints, the database clips have 22"):
        method.add([other])
    assert method.n_database_ == 4
    sequences = DTWRetrieval(features=features).sequences([other])  # made apart, as the index's workers make them
    with pytest.raises(SkeletonInputError, match="clip 0: 21 joints"):
        method.add_sequences(sequences)
