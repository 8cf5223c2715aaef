"""The Motion container (mocapkit.motion.container): constructor checks and views."""

import numpy as np
import pytest

from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import LANDMARKS, MSR20, NTU25, SkeletonLayout


def _ntu(frames=11, fps=100.0, seed=0, up_axis="y", **kw) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.normal(0, 0.5, (frames, 25, 3)).astype(np.float32)
    return Motion(pos, NTU25.joint_names, fps, parents=NTU25.parents, up_axis=up_axis, layout_name="ntu25", **kw)


# --------------------------------------------------------------------------- constructor


def test_basics_and_missing_consistency():
    pos = np.zeros((4, 2, 3))
    pos[1, 0, 2] = np.nan  # one NaN coordinate: the joint is missing
    missing = np.zeros((4, 2), dtype=bool)
    missing[3, 1] = True  # flagged missing: its coordinates become NaN
    m = Motion(pos, ["a", "b"], 30.0, missing=missing)
    assert m.positions.dtype == np.float32 and m.num_frames == 4 and m.num_joints == 2
    assert m.duration == pytest.approx(0.1)
    assert m.missing[1, 0] and m.missing[3, 1] and m.missing.sum() == 2
    assert np.isnan(m.positions[1, 0]).all() and np.isnan(m.positions[3, 1]).all()
    assert (m.filled(7.0)[3, 1] == 7.0).all() and m.index("b") == 1
    with pytest.raises(KeyError, match="'c'"):
        m.index("c")
    with pytest.raises(ValueError, match="no joint hierarchy"):
        _ = m.layout


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"positions": np.zeros((4, 2))}, r"positions must be \[frames, joints, 3\]"),
        ({"positions": np.zeros((4, 2, 2))}, r"positions must be \[frames, joints, 3\]"),
        ({"joint_names": ["a"]}, "1 joint names for 2 joints"),
        ({"parents": (-1,)}, "parents must give one index"),
        ({"parents": (-1, 2)}, "parents must give one index"),
        ({"parents": (-2, 0)}, "parents must give one index"),
        ({"fps": 0}, "frame rate must be positive"),
        ({"fps": -30.0}, "frame rate must be positive"),
        ({"up_axis": "w"}, "up_axis must be x, y or z"),
        ({"missing": np.zeros((5, 3), dtype=bool)}, None),  # shape mismatch (ValueError from numpy or the check)
        ({"rotations": np.zeros((4, 2, 3))}, r"rotations must be \[4, 2, 3, 3\]"),
    ],
)
def test_constructor_errors(kwargs, match):
    args = {"positions": np.zeros((4, 2, 3)), "joint_names": ["a", "b"], "fps": 30.0, "source": "clip.bvh"}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Motion(**args)


def test_error_names_the_source():
    with pytest.raises(ValueError, match="^clip.c3d: frame rate"):
        Motion(np.zeros((2, 1, 3)), ["a"], 0, source="clip.c3d")


# --------------------------------------------------------------------------- resample


def test_resample_halves_and_keeps_shared_time_points():
    m = _ntu(frames=11, fps=100.0)
    half = m.resample(50.0)
    assert half.num_frames == 6 and half.fps == 50.0
    np.testing.assert_array_equal(half.positions, m.positions[::2])
    assert half.duration == pytest.approx(m.duration)


def test_resample_doubles_and_interpolates_midpoints():
    m = _ntu(frames=11, fps=100.0)
    double = m.resample(200.0)
    assert double.num_frames == 21 and double.fps == 200.0
    np.testing.assert_allclose(double.positions[::2], m.positions, atol=1e-6)
    np.testing.assert_allclose(double.positions[1::2], (m.positions[:-1] + m.positions[1:]) / 2, atol=1e-6)
    # up and down again gives the original
    np.testing.assert_allclose(double.resample(100.0).positions, m.positions, atol=1e-6)


def test_resample_propagates_missing():
    missing = np.zeros((11, 25), dtype=bool)
    missing[4, 3] = True
    m = _ntu(frames=11, fps=100.0, missing=missing)
    double = m.resample(200.0)
    # frame 8 is source frame 4; frames 7 and 9 interpolate between it and a neighbour
    assert np.flatnonzero(double.missing[:, 3]).tolist() == [7, 8, 9]
    assert double.missing.sum() == 3 and np.isnan(double.positions[7:10, 3]).all()
    half = m.resample(50.0)
    assert np.flatnonzero(half.missing[:, 3]).tolist() == [2] and half.missing.sum() == 1
    third = m.resample(100.0 / 3)  # source frames 0, 3, 6, 9: frame 4 is not one
    assert third.num_frames == 4 and not third.missing.any()


def test_resample_drops_rotations_and_checks_fps():
    rot = np.tile(np.eye(3, dtype=np.float32), (11, 25, 1, 1))
    m = _ntu(frames=11, rotations=rot)
    assert m.resample(50.0).rotations is None
    assert m.resample(100.0).rotations is not None  # same rate: nothing to interpolate
    with pytest.raises(ValueError, match="fps must be positive"):
        m.resample(0)


# --------------------------------------------------------------------------- root_centered / torso_aligned


def test_root_centered():
    m = _ntu()
    c = m.root_centered()
    assert (c.positions[:, NTU25.index("SpineBase")] == 0).all()
    np.testing.assert_allclose(c.positions + m.positions[:, :1], m.positions, atol=1e-6)
    h = m.root_centered("Head")
    assert (h.positions[:, NTU25.index("Head")] == 0).all()
    markers = Motion(np.random.default_rng(1).normal(size=(3, 4, 3)), list("abcd"), 10.0)
    assert (markers.root_centered().positions[:, 0] == 0).all()  # no hierarchy: joint 0
    assert m.positions[:, 0].any()  # the original is unchanged


@pytest.mark.parametrize("up_axis", ["y", "z"])
def test_torso_aligned_hip_line_along_x(up_axis):
    m = _ntu(frames=20, seed=3, up_axis=up_axis)
    up = "xyz".index(up_axis)
    a = m.torso_aligned("HipLeft", "HipRight")
    hips = a.positions[:, NTU25.index("HipRight")] - a.positions[:, NTU25.index("HipLeft")]
    other = next(ax for ax in (1, 2) if ax != up)  # the horizontal axis that is not x
    assert np.abs(hips[:, other]).max() < 1e-5
    assert (hips[:, 0] > 0).all()  # left -> right points to +x
    np.testing.assert_allclose(hips[:, up], (m.positions[:, 16] - m.positions[:, 12])[:, up], atol=1e-5)
    assert (a.positions[:, 0] == 0).all()  # root centred
    # a rotation about the up axis: every joint keeps its distance to the root and its height
    c = m.root_centered()
    np.testing.assert_allclose(np.linalg.norm(a.positions, axis=2), np.linalg.norm(c.positions, axis=2), atol=1e-5)
    np.testing.assert_allclose(a.positions[..., up], c.positions[..., up], atol=1e-6)


# --------------------------------------------------------------------------- map_layout


def test_map_layout_ntu_msr_ntu():
    m = _ntu(frames=5)
    msr = m.map_layout(MSR20)
    assert msr.joint_names == MSR20.joint_names and msr.parents == MSR20.parents and msr.layout_name == "msr20"
    assert not msr.missing.any()  # every MSR joint is a shared landmark
    back = msr.map_layout(NTU25)
    shared = {LANDMARKS["ntu25"][lm] for lm in LANDMARKS["ntu25"] if lm in LANDMARKS["msr20"]}
    for j, name in enumerate(NTU25.joint_names):
        if name in shared:
            assert not back.missing[:, j].any()
            np.testing.assert_array_equal(back.positions[:, j], m.positions[:, j])
        else:
            assert back.missing[:, j].all() and np.isnan(back.positions[:, j]).all()
    assert sorted(n for n in NTU25.joint_names if n not in shared) == [
        "HandTipLeft",
        "HandTipRight",
        "Neck",
        "ThumbLeft",
        "ThumbRight",
    ]
    assert back.metadata["mapped_from"] == "msr20"
    np.testing.assert_array_equal(
        msr.positions[:, MSR20.index("ShoulderCenter")], m.positions[:, NTU25.index("SpineShoulder")]
    )


def test_map_layout_keeps_missing_and_needs_known_layouts():
    missing = np.zeros((5, 25), dtype=bool)
    missing[2, NTU25.index("KneeLeft")] = True
    msr = _ntu(frames=5, missing=missing).map_layout(MSR20)
    assert msr.missing[2, MSR20.index("KneeLeft")] and msr.missing.sum() == 1
    with pytest.raises(ValueError, match="no landmark table"):
        Motion(np.zeros((2, 25, 3)), NTU25.joint_names, 30.0).map_layout(MSR20)  # no layout_name
    with pytest.raises(ValueError, match="no landmark table"):
        _ntu().map_layout(SkeletonLayout("other", ("a",), (-1,)))


# --------------------------------------------------------------------------- select


def test_select_keeps_parents():
    m = _ntu()
    s = m.select(["SpineBase", "SpineMid", "SpineShoulder", "Neck", "Head"])
    assert s.parents == (-1, 0, 1, 2, 3) and s.layout.bones == ((1, 0), (2, 1), (3, 2), (4, 3))
    np.testing.assert_array_equal(s.positions, m.positions[:, [0, 1, 20, 2, 3]])
    assert s.layout_name is None
    reordered = m.select(["Head", "Neck", "SpineBase"])  # Head -> Neck; Neck's parent not selected
    assert reordered.parents is None  # two roots: not a tree any more
    by_index = m.select([0, 12, 13])
    assert by_index.parents == (-1, 0, 1) and by_index.joint_names == ("SpineBase", "HipLeft", "KneeLeft")


def test_select_markers_and_missing():
    missing = np.zeros((3, 4), dtype=bool)
    missing[1, 2] = True
    m = Motion(np.ones((3, 4, 3)), list("abcd"), 10.0, missing=missing)
    s = m.select(["c", "a"])
    assert s.parents is None and s.joint_names == ("c", "a")
    assert s.missing[:, 0].tolist() == [False, True, False] and not s.missing[:, 1].any()
    with pytest.raises(KeyError, match="'z'"):
        m.select(["z"])


def test_coordinate_helpers_match_numpy_reductions():
    """any_coordinate / all_coordinates / point_distance are the numpy reductions over the last axis of 3,
    NaN and Inf included (they only read the three coordinates one at a time, for speed)."""
    from mocapkit.motion.container import (
        all_coordinates,
        any_coordinate,
        point_distance,
    )

    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 7, 3)), rng.normal(size=(40, 7, 3))
    a[3, 2, 1], a[5, 0, 0], b[7, 6, 2] = np.nan, np.inf, -np.inf
    mask = rng.random((40, 7, 3)) < 0.5
    np.testing.assert_array_equal(any_coordinate(mask), mask.any(-1))
    np.testing.assert_array_equal(all_coordinates(mask), mask.all(-1))
    np.testing.assert_array_equal(all_coordinates(np.isfinite(a)), np.isfinite(a).all(-1))
    np.testing.assert_array_equal(any_coordinate(np.isnan(a)), np.isnan(a).any(-1))
    np.testing.assert_allclose(point_distance(a, b), np.linalg.norm(a - b, axis=-1), rtol=1e-12)
    assert any_coordinate(np.isnan(a)).sum() == 1 and not all_coordinates(np.isfinite(a))[5, 0]


# --------------------------------------------------------------------------- mirror image


def test_mirror_joints_pairs_asf_bvh_and_kinect_names():
    from mocapkit.motion.layouts import CMU31, mirror_joints

    names = list(CMU31.joint_names)
    swap = mirror_joints(names)
    assert names[swap[names.index("lhumerus")]] == "rhumerus" and names[swap[names.index("rtoes")]] == "ltoes"
    for mid in ("root", "lowerback", "lowerneck", "head"):  # an l / r first letter alone is not a side
        assert swap[names.index(mid)] == names.index(mid)
    assert all(swap[swap[j]] == j for j in range(len(names)))
    rig = ["Hips", "LeftUpLeg", "RightUpLeg", "Spine", "UpperArm_L", "UpperArm_R", "L_Hand", "R_Hand"]
    assert mirror_joints(rig) == [0, 2, 1, 3, 5, 4, 7, 6]
    ntu = list(NTU25.joint_names)
    assert ntu[mirror_joints(ntu)[ntu.index("ElbowLeft")]] == "ElbowRight"
    with pytest.raises(ValueError, match="'LeftFoot'.*no joint is its counterpart"):
        mirror_joints(["Hips", "LeftFoot"])


@pytest.mark.parametrize("up_axis", ["y", "z"])
def test_mirrored_swaps_sides_negates_one_horizontal_axis_and_is_an_involution(up_axis):
    motion = _ntu(up_axis=up_axis, missing=np.eye(11, 25, dtype=bool))
    mirrored = motion.mirrored()
    names = list(NTU25.joint_names)
    left, right = names.index("HandLeft"), names.index("HandRight")
    first = 0  # x is the first horizontal axis for y and z up
    assert np.allclose(
        mirrored.positions[~mirrored.missing[:, right], right, first],
        -motion.positions[~motion.missing[:, left], left, first],
    )
    keep = [a for a in range(3) if a != first]
    assert np.allclose(
        mirrored.positions[~mirrored.missing[:, right]][:, right][:, keep],
        motion.positions[~motion.missing[:, left]][:, left][:, keep],
    )
    assert np.array_equal(mirrored.missing[:, right], motion.missing[:, left])
    twice = mirrored.mirrored()
    assert np.array_equal(twice.missing, motion.missing)
    assert np.allclose(twice.filled(), motion.filled())
    # a mirror image keeps distances: bone lengths and per-frame speeds
    bones = lambda m: np.linalg.norm(m.filled()[:, 1:] - m.filled()[:, [p for p in NTU25.parents[1:]]], axis=-1)
    assert np.allclose(np.sort(bones(mirrored), axis=1), np.sort(bones(motion), axis=1), atol=1e-6)


def test_mirrored_rejects_an_asymmetric_hierarchy():
    names = ("Hips", "LeftUpLeg", "RightUpLeg", "Spine")
    motion = Motion(np.zeros((3, 4, 3)), names, 30.0, parents=(-1, 0, 3, 0))  # the right leg hangs off the spine
    with pytest.raises(ValueError, match="not left-right symmetric"):
        motion.mirrored()
