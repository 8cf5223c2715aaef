"""BVH reading and writing: hand-checked kinematics, units, errors, round trips and the real samples."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.bvh import (
    UNITS,
    BvhFormatError,
    infer_scale,
    parse_bvh_text,
    read_bvh,
    write_bvh,
)
from mocapkit.motion.container import Motion
from tests.shared_data import SHARED, needs

BVH_DIR = SHARED / "samples" / "bvh"

# Mixed CRLF / LF, tabs (also after "Frames:"), a colon in a name, a non-zero ROOT OFFSET,
# per-joint channel orders, a position channel on a non-root joint, End Sites, a joint
# with no CHANNELS line.
TINY = (
    "HIERARCHY\r\n"
    "ROOT rig:Hips\r\n"
    "{\n"
    "\tOFFSET\t5 90 0\r\n"
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
    "\tJOINT rig:Spine\r\n"
    "\t{\n"
    "\t\tOFFSET 0 10 0\n"
    "\t\tCHANNELS 4 Yposition Xrotation Yrotation Zrotation\n"
    "\t\tEnd Site\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0 20 0\n"
    "\t\t}\n"
    "\t}\n"
    "\tJOINT Leg\n"
    "\t{\n"
    "\t\tOFFSET 10 -40 0\n"
    "\t\tCHANNELS 1 Xrotation\n"
    "\t\tJOINT Foot\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0 -40 0\n"
    "\t\t\tEnd Site\n"
    "\t\t\t{\n"
    "\t\t\t\tOFFSET 0 0 10\n"
    "\t\t\t}\n"
    "\t\t}\n"
    "\t}\n"
    "}\r\n"
    "MOTION\r\n"
    "Frames:\t3\r\n"
    "Frame Time:\t0.04\n"
    "0 90 0 0 0 0 10 0 0 0 0\n"
    "1 90 0 90 0 0 12 0 0 0 90\r\n"
    "2 91 0 0 0 0 10 30 40 50 -30\n"
)
N_CHANNELS = 11


def tiny(**kw) -> Motion:
    return parse_bvh_text(TINY, source="tiny.bvh", **kw)


def lines_with(data_lines, frames=None) -> str:
    head = TINY.split("MOTION")[0]
    frames = len(data_lines) if frames is None else frames
    return head + f"MOTION\nFrames: {frames}\nFrame Time: 0.04\n" + "\n".join(data_lines) + "\n"


# --------------------------------------------------------------------------- parsing and kinematics


def test_tiny_structure_and_hand_checked_positions():
    m = tiny(units="cm")
    assert m.joint_names == ("rig:Hips", "rig:Spine", "Leg", "Foot")
    assert m.parents == (-1, 0, 0, 2)
    assert m.num_frames == 3 and m.fps == pytest.approx(25.0)
    assert m.up_axis == "y" and m.source_units == "cm" and m.metadata["units_inferred"] is False
    skel = m.metadata["bvh"]
    assert skel.channels[1] == ("Yposition", "Xrotation", "Yrotation", "Zrotation")
    assert skel.channels[3] == ()
    assert [p for p, _ in skel.end_sites] == [1, 3]
    assert m.metadata["channels"].shape == (3, N_CHANNELS)
    p = m.positions.astype(np.float64) / 0.01  # back to file units
    # frame 0: rest pose, root channels (0, 90, 0) replace the OFFSET (5, 90, 0)
    np.testing.assert_allclose(p[0], [[0, 90, 0], [0, 100, 0], [10, 50, 0], [10, 10, 0]], atol=1e-4)
    # frame 1: root Zrotation 90 turns (x, y) -> (-y, x); Spine's Yposition 12 replaces its OFFSET y
    np.testing.assert_allclose(p[1, 0], [1, 90, 0], atol=1e-4)
    np.testing.assert_allclose(p[1, 1], [1 - 12, 90, 0], atol=1e-4)
    np.testing.assert_allclose(p[1, 2], [1 + 40, 90 + 10, 0], atol=1e-4)
    # Leg's Xrotation 90 turns its child's (0, -40, 0) to (0, 0, -40), then the root's Z turn leaves z alone
    np.testing.assert_allclose(p[1, 3], [41, 100, -40], atol=1e-4)


def test_rotation_is_intrinsic_product_in_channel_order():
    m = tiny(units="cm")
    # Spine in frame 2: "Xrotation Yrotation Zrotation" 30 40 50 -> Rx @ Ry @ Rz (intrinsic XYZ)
    expected = Rotation.from_euler("XYZ", [30, 40, 50], degrees=True).as_matrix()
    np.testing.assert_allclose(m.rotations[2, 1], expected, atol=1e-6)
    # root in frame 1: "Zrotation Yrotation Xrotation" 90 0 0 -> Rz(90)
    np.testing.assert_allclose(m.rotations[1, 0], Rotation.from_euler("Z", 90, degrees=True).as_matrix(), atol=1e-6)
    # the order matters: ZYX != XYZ for the same angles
    assert not np.allclose(Rotation.from_euler("ZYX", [30, 40, 50], degrees=True).as_matrix(), expected, atol=1e-3)


def test_end_sites_as_extra_joints_after_the_real_ones():
    a, b = tiny(units="cm"), tiny(units="cm", end_sites=True)
    assert b.joint_names == a.joint_names + ("rig:Spine/End Site", "Foot/End Site")
    assert b.parents == a.parents + (1, 3)
    np.testing.assert_array_equal(b.positions[:, :4], a.positions)
    np.testing.assert_allclose(b.positions[0, 4] / 0.01, [0, 120, 0], atol=1e-4)
    np.testing.assert_allclose(b.positions[0, 5] / 0.01, [10, 10, 10], atol=1e-4)
    np.testing.assert_allclose(b.rotations[:, 4:], np.broadcast_to(np.eye(3), (3, 2, 3, 3)))


def test_position_mode_add_adds_channels_to_offset():
    m = tiny(units="cm", position_mode="add")
    np.testing.assert_allclose(m.positions[0, 0] / 0.01, [5, 180, 0], atol=1e-4)


def test_units_scale_and_inference():
    assert tiny(units="m").positions[0, 0, 1] == pytest.approx(90.0)
    assert tiny(scale=0.5).positions[0, 0, 1] == pytest.approx(45.0)
    assert tiny(units="cmu").source_units == "inch/0.45 (CMU)"
    assert UNITS["cmu"] == pytest.approx(0.05644, abs=1e-5)
    # the tiny rig is 1.1 units tall in rest pose (90 + 10 + 20 ... -40 -40): inferred from its size
    assert infer_scale(170.0) == ("cm", 0.01)
    assert infer_scale(1.75) == ("m", 1.0)
    assert infer_scale(1750.0) == ("mm", 0.001)
    assert infer_scale(66.0) == ("inch", 0.0254)
    assert infer_scale(30.0)[0] == "cmu"
    m = tiny()
    assert m.metadata["units_inferred"] is True
    assert m.metadata["rest_size"] == pytest.approx(110.0)  # y from 10 (foot) to 120 (head end)
    assert m.source_units == "cm"
    with pytest.raises(ValueError, match="unknown units"):
        tiny(units="furlong")


# --------------------------------------------------------------------------- bad input


def test_channel_count_mismatch_names_the_line():
    good = TINY.split("Frame Time:\t0.04\n")[1].splitlines()
    text = lines_with([good[0], good[1] + " 7", good[2]])
    with pytest.raises(BvhFormatError) as err:
        parse_bvh_text(text, source="bad.bvh")
    header_lines = text.split("MOTION")[0].count("\n") + 1  # MOTION, Frames, Frame Time follow
    assert err.value.line == header_lines + 4
    assert "bad.bvh, line" in str(err.value) and f"has {N_CHANNELS + 1} values, expected {N_CHANNELS}" in str(err.value)


def test_consistent_but_wrong_column_count_is_caught():
    text = lines_with([" ".join(["0"] * (N_CHANNELS - 1))] * 2)
    with pytest.raises(BvhFormatError, match=f"has {N_CHANNELS - 1} values"):
        parse_bvh_text(text, source="bad.bvh")


def test_frames_10_with_9_lines_is_truncated():
    row = " ".join(["0"] * N_CHANNELS)
    text = lines_with([row] * 9, frames=10)
    with pytest.raises(BvhFormatError, match="after 9 of 10 frames") as err:
        parse_bvh_text(text, source="short.bvh")
    last_data_line = text.rstrip("\n").count("\n") + 1
    assert err.value.line == last_data_line + 1
    assert "short.bvh" in str(err.value)


def test_truncated_file_cut_mid_hierarchy(tmp_path):
    path = tmp_path / "cut.bvh"
    path.write_text(TINY[: TINY.index("JOINT Leg")])
    with pytest.raises(BvhFormatError, match="before the MOTION section") as err:
        read_bvh(path)
    assert str(path) in str(err.value)


def test_extra_data_lines_are_an_error():
    row = " ".join(["0"] * N_CHANNELS)
    with pytest.raises(BvhFormatError, match="more data lines"):
        parse_bvh_text(lines_with([row] * 3, frames=2))


def test_non_numeric_and_non_finite_values():
    row = ["0"] * N_CHANNELS
    bad = row.copy()
    bad[4] = "abc"
    with pytest.raises(BvhFormatError, match="non-numeric value 'abc'") as err:
        parse_bvh_text(lines_with([" ".join(row), " ".join(bad)]))
    assert err.value.line is not None
    bad[4] = "nan"
    with pytest.raises(BvhFormatError, match="non-finite"):
        parse_bvh_text(lines_with([" ".join(bad)]))


@pytest.mark.parametrize(
    "edit, message",
    [
        (("\t\t\tOFFSET 0 0 10\n", "\t\t\tOFFSET 0 zero 10\n"), "non-numeric OFFSET value"),
        (("CHANNELS 1 Xrotation", "CHANNELS 1 Wrotation"), "channel names"),
        (("CHANNELS 1 Xrotation", "CHANNELS 2 Xrotation"), "channel names"),
        (("JOINT Leg\n\t{\n", "JOINT Leg\n"), "expected '{'"),
        (("}\r\nMOTION", "MOTION"), "unclosed"),
        (("\t\tOFFSET 10 -40 0\n", ""), "has no OFFSET"),
        (("HIERARCHY", "HIERARCHI"), "expected HIERARCHY"),
        (("Frames:\t3", "Frames: three"), "non-integer frame count"),
        (("Frame Time:\t0.04", "Frame Time: 0"), "frame time must be positive"),
        (("\tJOINT Leg", "\tBONE Leg"), "unexpected 'BONE'"),
    ],
)
def test_malformed_hierarchy_names_file_and_line(edit, message):
    old, new = edit
    assert old in TINY
    with pytest.raises(BvhFormatError, match=message) as err:
        parse_bvh_text(TINY.replace(old, new, 1), source="broken.bvh")
    assert err.value.line is not None and str(err.value).startswith("broken.bvh, line ")


def test_error_is_picklable():
    import pickle

    err = BvhFormatError("f.bvh", 3, "boom")
    again = pickle.loads(pickle.dumps(err))
    assert (again.path, again.line, str(again)) == ("f.bvh", 3, "f.bvh, line 3: boom")


# --------------------------------------------------------------------------- writing


def test_write_read_round_trip_keeps_everything(tmp_path):
    for end_sites in (False, True):
        m = tiny(units="cm", end_sites=end_sites)
        write_bvh(tmp_path / "o.bvh", m)
        r = read_bvh(tmp_path / "o.bvh", units="cm", end_sites=end_sites)
        assert r.joint_names == m.joint_names and r.parents == m.parents
        assert r.metadata["bvh"].channels == m.metadata["bvh"].channels
        np.testing.assert_array_equal(r.metadata["channels"], m.metadata["channels"])
        np.testing.assert_allclose(r.positions, m.positions, atol=1e-5)
        assert r.fps == m.fps


def test_write_from_rotations_after_a_view(tmp_path):
    m = tiny(units="cm").root_centered()  # positions no longer match the raw channels
    write_bvh(tmp_path / "c.bvh", m)
    r = read_bvh(tmp_path / "c.bvh", units="m")
    assert r.joint_names == m.joint_names and r.parents == m.parents
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-5)
    # a Motion with neither BVH metadata nor rotations cannot be written
    bare = Motion(positions=m.positions, joint_names=m.joint_names, parents=m.parents, fps=m.fps)
    with pytest.raises(ValueError, match="rotations"):
        write_bvh(tmp_path / "x.bvh", bare)
    markers = Motion(positions=m.positions, joint_names=m.joint_names, fps=m.fps)
    with pytest.raises(ValueError, match="hierarchy"):
        write_bvh(tmp_path / "x.bvh", markers)


def test_write_with_other_scale_and_crlf(tmp_path):
    m = tiny(units="cm")
    write_bvh(tmp_path / "mm.bvh", m, scale=0.001, newline="\r\n")
    assert b"\r\n" in (tmp_path / "mm.bvh").read_bytes()
    r = read_bvh(tmp_path / "mm.bvh", units="mm")
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-5)


# --------------------------------------------------------------------------- real samples

#: file: (frames, joints, End Sites, fps, source_units) from shared/samples/SOURCES.md
REAL = {
    "cmu_131_01.bvh": (994, 31, 7, 120.0, "inch/0.45 (CMU)"),
    "cmu_131_03.bvh": (1102, 31, 7, 120.0, "inch/0.45 (CMU)"),
    "cmu_scaled_131_01.bvh": (995, 31, 7, 120.0, "m"),
    "test_freebvh.bvh": (69, 55, 15, 30.0, "cm"),
    "test_mocapbank.bvh": (455, 19, 5, 30.0, "cm"),
    "AV_8Walk_Meredith_HVHA_Rep1.bvh": (1064, 23, 7, 120.0, "inch"),
}


@needs(BVH_DIR)
@pytest.mark.parametrize("name", sorted(REAL))
def test_real_sample(name):
    frames, joints, ends, fps, units = REAL[name]
    m = read_bvh(BVH_DIR / name, end_sites=True)
    assert m.num_frames == frames
    assert m.num_joints == joints + ends and len(m.metadata["bvh"].end_sites) == ends
    assert m.metadata["bvh"].num_joints == joints
    assert m.fps == pytest.approx(fps, rel=1e-3)
    assert m.source_units == units and m.metadata["units_inferred"]
    assert not m.missing.any() and np.isfinite(m.positions).all()
    # rigid bones: every bone (End Sites included) keeps its length within 0.1 mm
    child = [j for j, p in enumerate(m.parents) if p >= 0]
    lengths = np.linalg.norm(m.positions[:, child] - m.positions[:, [m.parents[j] for j in child]], axis=-1)
    assert (lengths.max(0) - lengths.min(0)).max() < 1e-4
    # a plausible human in metres, y up, feet near the floor
    height = m.positions[..., 1].max(1) - m.positions[..., 1].min(1)
    assert 1.2 < np.median(height) < 2.1, np.median(height)
    assert -0.1 < m.positions[..., 1].min() < 0.1
    assert m.positions[..., 1].max() < 2.2


@needs(BVH_DIR)
def test_cmu_units_and_scaled_file_agree():
    """CMU units x 0.05644 vs the author's metre file: same skeleton, same motion within 0.1 mm.

    The scaled file has 995 frames: the first 994 match the original frame by frame (the
    scaled file's values are rounded to 6 decimals, max difference about 2e-5 m) and
    its extra frame is at the end.
    """
    a = read_bvh(BVH_DIR / "cmu_131_01.bvh", end_sites=True)
    b = read_bvh(BVH_DIR / "cmu_scaled_131_01.bvh", end_sites=True)
    assert a.joint_names == b.joint_names and a.parents == b.parents
    rest_a = a.metadata["bvh"].rest_positions() * a.metadata["scale"]
    rest_b = b.metadata["bvh"].rest_positions() * b.metadata["scale"]
    np.testing.assert_allclose(rest_a, rest_b, atol=5e-5)
    assert a.metadata["rest_size"] * a.metadata["scale"] == pytest.approx(b.metadata["rest_size"], abs=1e-4)
    assert b.num_frames == a.num_frames + 1
    np.testing.assert_allclose(a.positions, b.positions[: a.num_frames], atol=1e-4)


@needs(BVH_DIR)
def test_real_round_trip_keeps_channel_orders(tmp_path):
    m = read_bvh(BVH_DIR / "test_mocapbank.bvh")
    write_bvh(tmp_path / "o.bvh", m)
    r = read_bvh(tmp_path / "o.bvh")
    assert r.metadata["bvh"].channels == m.metadata["bvh"].channels
    assert r.source_units == m.source_units
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-5)
