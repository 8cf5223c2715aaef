"""read_motion / write_motion: format dispatch by file name (mocapkit.datasets.formats.motion_io)."""

import numpy as np
import pytest

from mocapkit.datasets.formats import motion_io
from mocapkit.datasets.formats.c3d import C3DFormatError
from mocapkit.datasets.formats.motion_io import (
    FormatUnavailableError,
    UnsupportedFormatError,
    motion_format,
    read_motion,
    write_motion,
)
from mocapkit.datasets.formats.ntu_skeleton import (
    read_skeleton,
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import NTU25
from tests.shared_data import NTU_SAMPLES, SHARED, needs

SAMPLES = SHARED / "samples"


@pytest.mark.parametrize(
    "name, fmt",
    [
        ("a.c3d", "c3d"),
        ("A.C3D", "c3d"),
        ("x/y.bvh", "bvh"),
        ("01_01.amc", "amc"),
        ("S001C001P001R001A001.skeleton", "ntu"),
        ("a01_s01_e01_skeleton3D.txt", "msr"),
        ("a01_s01_e01_skeleton.txt", "msr"),
    ],
)
def test_motion_format(name, fmt):
    assert motion_format(name) == fmt


@pytest.mark.parametrize("name", ["notes.txt", "clip.fbx", "noext"])
def test_unknown_extension_lists_supported(name):
    with pytest.raises(UnsupportedFormatError, match=r"unknown motion file type; supported: .*\.amc.*\.bvh.*\.c3d"):
        read_motion(name)


def test_asf_alone_gets_a_hint():
    with pytest.raises(UnsupportedFormatError, match="read the .amc"):
        read_motion("skeleton.asf")


def test_missing_reader_module_names_the_format(monkeypatch, tmp_path):
    monkeypatch.setitem(
        motion_io.FORMATS, "bvh", ("BVH (.bvh)", "mocapkit.datasets.no_such_bvh", "read_bvh", "write_bvh")
    )
    with pytest.raises(FormatUnavailableError, match=r"reading BVH \(\.bvh\) needs mocapkit\.datasets\.no_such_bvh"):
        read_motion("clip.bvh")
    with pytest.raises(FormatUnavailableError, match="writing BVH"):
        write_motion("clip.bvh", Motion(np.zeros((2, 1, 3)), ["a"], 30.0))
    # the other formats still work while one is missing
    write_motion(tmp_path / "ok.c3d", Motion(np.ones((2, 1, 3)), ["a"], 30.0))
    assert read_motion(tmp_path / "ok.c3d").joint_names == ("a",)


def test_missing_reader_function(monkeypatch):
    monkeypatch.setitem(motion_io.FORMATS, "c3d", ("C3D (.c3d)", "mocapkit.datasets.formats.c3d", "read_nothing", None))
    with pytest.raises(FormatUnavailableError, match="does not define"):
        read_motion("x.c3d")


def test_reader_errors_pass_through(tmp_path):
    (tmp_path / "bad.c3d").write_bytes(b"not a c3d" * 100)
    with pytest.raises(C3DFormatError, match="bad.c3d"):
        read_motion(tmp_path / "bad.c3d")


def test_msr_has_no_writer():
    with pytest.raises(UnsupportedFormatError, match="does not write MSR"):
        write_motion("a01_s01_e01_skeleton3D.txt", Motion(np.zeros((2, 20, 3)), [str(i) for i in range(20)], 15.0))


# --------------------------------------------------------------------------- C3D


def test_c3d_round_trip_and_options(tmp_path):
    pos = np.random.default_rng(1).uniform(-1, 1, (5, 2, 3)).astype(np.float32)
    m = Motion(pos, ["A", "B"], 60.0, up_axis="z")
    write_motion(tmp_path / "m.c3d", m, units="cm")
    r = read_motion(tmp_path / "m.c3d")
    assert r.source_units == "cm" and r.fps == 60.0
    np.testing.assert_allclose(r.positions, pos, atol=1e-6, rtol=0)
    assert read_motion(tmp_path / "m.c3d", labels=["B"]).joint_names == ("B",)


@needs(SAMPLES / "c3d")
def test_c3d_real_sample():
    m = read_motion(SAMPLES / "c3d" / "HDM_dg_06-03_03_120.c3d")
    assert m.positions.shape == (202, 44, 3) and m.fps == 120.0 and m.parents is None


# --------------------------------------------------------------------------- NTU


def _two_body_file(tmp_path):
    rng = np.random.default_rng(0)
    T = 12
    pos = np.zeros((3, T, 25, 3))
    tall = np.array([0.3, 1.0, 0.3])  # taller than wide: spread denoising keeps them
    pos[0] = rng.normal(0, 0.01, (T, 25, 3)) * tall + [0, 0, 3]  # barely moves
    pos[1] = rng.normal(0, 0.30, (T, 25, 3)) * tall + [1, 0, 3]  # moves most
    pos[2, 3:9] = rng.normal(0, 0.10, (6, 25, 3)) * tall + [-1, 0, 3]  # medium, only frames 3..8
    present = np.ones((3, T), dtype=bool)
    present[2] = False
    present[2, 3:9] = True
    path = tmp_path / "S001C001P001R001A050.skeleton"
    write_skeleton(path, sequence_from_positions(path.stem, pos, body_ids=[11, 22, 33], present=present))
    return path, pos


def test_ntu_main_body_and_other_bodies(tmp_path):
    path, pos = _two_body_file(tmp_path)
    assert read_motion(path).metadata["body_ids"] == [22, 11]  # by default body 33 (6 frames) is too short
    m = read_motion(path, min_frames=1)
    assert m.joint_names == NTU25.joint_names and m.parents == NTU25.parents and m.layout_name == "ntu25"
    assert m.fps == 30.0 and m.up_axis == "y" and m.name == "S001C001P001R001A050"
    np.testing.assert_allclose(m.positions, pos[1], atol=1e-6)  # most motion first
    assert not m.missing.any()
    assert m.metadata["body_ids"] == [22, 33] and m.metadata["label"] == 49
    assert list(m.metadata["dropped_tracks"]) == [0]
    (other,) = m.metadata["other_bodies"]
    assert other.shape == (12, 25, 3)
    assert np.isnan(other[:3]).all() and np.isnan(other[9:]).all()
    np.testing.assert_allclose(other[3:9], pos[2, 3:9], atol=1e-6)
    assert len(read_motion(path, max_bodies=1, min_frames=1).metadata["other_bodies"]) == 0


def test_ntu_write_round_trip(tmp_path):
    path, _ = _two_body_file(tmp_path)
    m = read_motion(path, min_frames=1)
    write_motion(tmp_path / "out.skeleton", m)
    seq = read_skeleton(tmp_path / "out.skeleton")
    assert seq.body_ids == [22, 33] and seq.present[1].sum() == 6
    r = read_motion(tmp_path / "out.skeleton", min_frames=1)
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-6)
    np.testing.assert_allclose(r.metadata["other_bodies"][0], m.metadata["other_bodies"][0], atol=1e-6)
    with pytest.raises(ValueError, match="ntu25"):
        write_motion(tmp_path / "bad.skeleton", Motion(np.zeros((2, 1, 3)), ["a"], 30.0))


@needs(NTU_SAMPLES)
def test_ntu_real_samples():
    files = sorted(NTU_SAMPLES.glob("*.skeleton"))
    assert files
    for f in files:
        m = read_motion(f)
        seq = read_skeleton(f)
        assert m.positions.shape == (seq.num_frames, 25, 3)
        track = m.metadata["kept_tracks"][0]
        np.testing.assert_array_equal(m.missing.all(axis=1), ~seq.present[track])
        assert len(m.metadata["other_bodies"]) == min(seq.num_bodies, 2) - 1


# --------------------------------------------------------------------------- the other readers (when present)


@needs(SAMPLES / "bvh")
def test_bvh_dispatch():
    from mocapkit.datasets.formats import bvh

    path = SAMPLES / "bvh" / "cmu_131_01.bvh"
    m = read_motion(path)
    assert isinstance(m, Motion) and m.parents is not None
    np.testing.assert_array_equal(m.positions, bvh.read_bvh(path).positions)


@needs(SAMPLES / "asf_amc")
def test_amc_dispatch_finds_asf_and_accepts_asf_option():
    from mocapkit.datasets.formats import asf_amc

    amc = SAMPLES / "asf_amc" / "cmu_01" / "test.amc"
    m = read_motion(amc)
    assert isinstance(m, Motion) and m.parents is not None
    explicit = read_motion(amc, asf=amc.with_name("test.asf"))
    np.testing.assert_array_equal(m.positions, explicit.positions)
    np.testing.assert_array_equal(m.positions, asf_amc.read_amc(amc).positions)


@needs(SAMPLES / "msr3d")
@pytest.mark.parametrize("name", ["a01_s01_e01_skeleton3D.txt", "a01_s01_e01_skeleton.txt"])
def test_msr_dispatch(name):
    from mocapkit.datasets.formats import msr_action3d as msr

    path = SAMPLES / "msr3d" / name
    m = read_motion(path)
    assert isinstance(m, Motion) and m.num_joints == 20
    np.testing.assert_array_equal(m.filled(), msr.read_msr_skeleton(path).filled())


@needs(SAMPLES / "bvh")
def test_bvh_write_dispatch(tmp_path):
    m = read_motion(SAMPLES / "bvh" / "cmu_131_01.bvh")
    write_motion(tmp_path / "w.bvh", m)
    r = read_motion(tmp_path / "w.bvh")
    assert r.joint_names == m.joint_names
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-4)


@needs(SAMPLES / "asf_amc")
def test_amc_write_dispatch(tmp_path):
    amc = SAMPLES / "asf_amc" / "cmu_01" / "test.amc"
    m = read_motion(amc)
    write_motion(tmp_path / "w.amc", m)
    r = read_motion(tmp_path / "w.amc", asf=amc.with_name("test.asf"))
    np.testing.assert_allclose(r.positions, m.positions, atol=1e-4)
