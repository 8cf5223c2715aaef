"""C3D reading and writing (mocapkit.datasets.formats.c3d), on synthetic files and on every real sample."""

import pickle

import numpy as np
import pytest

from mocapkit.datasets.formats.c3d import C3DFormatError, read_c3d, write_c3d
from mocapkit.motion.container import Motion
from tests.shared_data import SHARED, needs

C3D = SHARED / "samples" / "c3d"

# file -> (markers, frames, rate, first frame (1-based), analog channels, analog rate)   (SOURCES.md, section c3d/)
SAMPLES = {
    "HDM_dg_06-03_03_120.c3d": (44, 202, 120.0, 2925, 0, 0.0),
    "Eb015pi.c3d": (26, 450, 50.0, 1, 16, 200.0),
    "Eb015pr.c3d": (26, 450, 50.0, 1, 16, 200.0),
    "Eb015vr.c3d": (26, 450, 50.0, 1, 16, 200.0),
    "pc_real.c3d": (36, 89, 50.0, 1, 16, 200.0),
    "Walking_Hybrid_1_1.c3d": (25, 672, 240.0, 290, 16, 240.0),
}

# A marker near the head / pelvis and one on the foot, per sample, to check the up axis physically.
HIGH_LOW = {
    "HDM_dg_06-03_03_120.c3d": ("LFHD", "LTOE"),
    "Eb015pi.c3d": ("PV1", "RFT1"),
    "Eb015pr.c3d": ("PV1", "RFT1"),
    "Eb015vr.c3d": ("PV1", "RFT1"),
    "pc_real.c3d": ("RPV1", "RFT1"),
    "Walking_Hybrid_1_1.c3d": ("R_ASIS", "R_HEEL"),
}


def _motion(frames=6, markers=3, seed=0, **kw) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-2, 2, (frames, markers, 3)).astype(np.float32)
    missing = np.zeros((frames, markers), dtype=bool)
    missing[2, 1] = missing[4, 0] = True
    defaults = {
        "positions": pos,
        "joint_names": [f"M{j}" for j in range(markers)],
        "fps": 100.0,
        "missing": missing,
        "up_axis": "z",
        "name": "synthetic",
    }
    defaults.update(kw)
    return Motion(**defaults)


# --------------------------------------------------------------------------- synthetic round trips


@pytest.mark.parametrize("units", ["mm", "cm", "m"])
def test_write_read_round_trip(tmp_path, units):
    m = _motion()
    path = tmp_path / "rt.c3d"
    write_c3d(path, m, units=units)
    r = read_c3d(path)
    assert r.joint_names == m.joint_names and r.parents is None
    assert r.fps == 100.0 and r.source_units == units and r.up_axis == "z"
    np.testing.assert_array_equal(r.missing, m.missing)
    assert np.isnan(r.positions[2, 1]).all() and np.isnan(r.positions[4, 0]).all()
    np.testing.assert_allclose(r.positions[~m.missing], m.positions[~m.missing], atol=1e-6, rtol=0)
    assert r.metadata["gaps"]["invalid_residual"] == 2 and r.metadata["storage"] == "float"
    assert r.metadata["first_frame"] == 1


def test_write_keeps_prefix_first_frame_and_up_axis(tmp_path):
    m = _motion(up_axis="y", metadata={"label_prefixes": {"M1": "Bob:"}, "first_frame": 37})
    write_c3d(tmp_path / "p.c3d", m)
    r = read_c3d(tmp_path / "p.c3d")
    assert r.metadata["labels"] == ("M0", "Bob:M1", "M2")
    assert r.joint_names == ("M0", "M1", "M2") and r.metadata["subject"] == "Bob"
    assert r.metadata["first_frame"] == 37
    assert r.up_axis == "y" and "Y_SCREEN" in r.metadata["up_axis_from"]
    assert read_c3d(tmp_path / "p.c3d", up_axis="x").up_axis == "x"
    full = read_c3d(tmp_path / "p.c3d", strip_prefix=False)
    assert full.joint_names == ("M0", "Bob:M1", "M2") and full.metadata["label_prefixes"] == {}


def test_write_needs_no_c3d_suffix_case(tmp_path):
    write_c3d(tmp_path / "UPPER.C3D", _motion())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["UPPER.C3D"]
    assert read_c3d(tmp_path / "UPPER.C3D").num_frames == 6


def test_label_selection(tmp_path):
    write_c3d(tmp_path / "s.c3d", _motion(metadata={"label_prefixes": {"M2": "Ann:"}}))
    r = read_c3d(tmp_path / "s.c3d", labels=["M2", "M0"])
    assert r.joint_names == ("M2", "M0")
    assert read_c3d(tmp_path / "s.c3d", labels=["Ann:M2"]).joint_names == ("M2",)
    with pytest.raises(KeyError, match="NOPE"):
        read_c3d(tmp_path / "s.c3d", labels=["M0", "NOPE"])


def test_zero_coordinates_are_gaps_unless_disabled(tmp_path):
    m = _motion()
    pos = m.positions.copy()
    pos[1, 2] = 0.0
    write_c3d(tmp_path / "z.c3d", Motion(pos, m.joint_names, 100.0, missing=m.missing, up_axis="z"))
    r = read_c3d(tmp_path / "z.c3d")
    assert r.missing[1, 2] and r.metadata["gaps"] == {
        "invalid_residual": 2,
        "nan_coordinates": 0,
        "zero_coordinates": 1,
        "total": 3,
    }
    kept = read_c3d(tmp_path / "z.c3d", zero_as_missing=False)
    assert not kept.missing[1, 2] and (kept.positions[1, 2] == 0).all()


def test_same_names_from_two_subjects_keep_their_prefixes(tmp_path):
    m = _motion(joint_names=["A:LFHD", "B:LFHD", "A:RFHD"])
    write_c3d(tmp_path / "two.c3d", m)
    r = read_c3d(tmp_path / "two.c3d")
    assert r.joint_names == ("A:LFHD", "B:LFHD", "A:RFHD")


# --------------------------------------------------------------------------- errors


def test_missing_file(tmp_path):
    with pytest.raises(C3DFormatError, match="nothere.c3d.*cannot read"):
        read_c3d(tmp_path / "nothere.c3d")


@pytest.mark.parametrize("content", [b"", b"hello, this is not a C3D file\n" * 40, bytes(2048)])
def test_not_a_c3d(tmp_path, content):
    path = tmp_path / "bad.c3d"
    path.write_bytes(content)
    with pytest.raises(C3DFormatError, match="bad.c3d"):
        read_c3d(path)


def test_truncated_data_and_parameters(tmp_path):
    write_c3d(tmp_path / "full.c3d", _motion(frames=400, markers=10))
    raw = (tmp_path / "full.c3d").read_bytes()
    (tmp_path / "cut.c3d").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(C3DFormatError, match=r"cut.c3d, frame \d+: truncated: the header announces 400 frames"):
        read_c3d(tmp_path / "cut.c3d")
    (tmp_path / "head.c3d").write_bytes(raw[:700])  # inside the parameter section
    with pytest.raises(C3DFormatError, match=r"head.c3d: the parameter section \(byte 512, \d+ blocks"):
        read_c3d(tmp_path / "head.c3d")


def test_error_is_picklable():
    err = pickle.loads(pickle.dumps(C3DFormatError("x.c3d", "truncated", frame=3)))
    assert str(err) == "x.c3d, frame 3: truncated" and err.frame == 3


# --------------------------------------------------------------------------- real samples


@needs(C3D)
@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_real_sample(name):
    markers, frames, rate, first, channels, analog_rate = SAMPLES[name]
    m = read_c3d(C3D / name)
    assert m.positions.shape == (frames, markers, 3) and m.positions.dtype == np.float32
    assert m.fps == rate and m.parents is None and m.up_axis == "z" and m.source_units == "mm"
    assert m.metadata["first_frame"] == first
    assert len(set(m.joint_names)) == markers and "" not in m.joint_names
    assert m.metadata["analog"]["channels"] == channels and m.metadata["analog"]["rate"] == analog_rate
    assert len(m.metadata["analog"]["labels"]) == channels
    # metres: a person's markers span 0.3-2.5 m in every frame where most of them are seen
    full = m.missing.mean(axis=1) < 0.2
    assert full.sum() > frames // 2
    spread = np.nanmax(m.positions[full], axis=1) - np.nanmin(m.positions[full], axis=1)  # [frames, 3]
    assert 0.3 < spread.max(axis=1).min() and spread.max() < 2.5
    # z is up: a head/pelvis marker is above a foot marker in every frame both are seen
    high, low = (m.positions[:, m.index(n), 2] for n in HIGH_LOW[name])
    both = ~np.isnan(high) & ~np.isnan(low)
    assert both.sum() > frames // 4 and (high[both] > low[both] + 0.3).all()
    # the mask and the NaNs agree, and the gap count is reported
    np.testing.assert_array_equal(m.missing, np.isnan(m.positions).any(axis=2))
    assert m.metadata["gaps"]["total"] == int(m.missing.sum())


@needs(C3D)
def test_hdm05_labels_prefix_and_unlabelled():
    m = read_c3d(C3D / "HDM_dg_06-03_03_120.c3d")
    assert m.joint_names[:4] == ("*0", "*1", "*2", "LFHD")
    assert m.metadata["labels"][3] == "Daniel:LFHD" and m.metadata["subject"] == "Daniel"
    assert m.metadata["label_prefixes"]["LFHD"] == "Daniel:" and "*0" not in m.metadata["label_prefixes"]
    assert not m.missing.any() and m.metadata["analog"]["channels"] == 0


@needs(C3D)
def test_eb015_padding_labels_analog_and_events():
    m = read_c3d(C3D / "Eb015pi.c3d")
    assert m.joint_names[-2:] == ("PV3", "pv4")  # LABELS holds 48 names, POINT:USED is 26
    analog = m.metadata["analog"]
    assert analog["labels_declared"] == 32 and analog["labels"][:3] == ("FX1", "FY1", "FZ1")
    assert [e["label"] for e in m.metadata["events"]] == ["RIC", "RHS", "RTO"]
    assert m.metadata["gaps"] == {"invalid_residual": 226, "nan_coordinates": 0, "zero_coordinates": 0, "total": 226}


@needs(C3D)
def test_eb015_integer_float_and_dec_storage_agree():
    pi, pr, vr = (read_c3d(C3D / f"Eb015{k}.c3d") for k in ("pi", "pr", "vr"))
    assert (pi.metadata["storage"], pr.metadata["storage"], vr.metadata["storage"]) == ("integer", "float", "float")
    assert (pi.metadata["processor"], vr.metadata["processor"]) == ("intel", "dec")
    assert pi.joint_names == pr.joint_names == vr.joint_names
    np.testing.assert_array_equal(pi.missing, pr.missing)
    np.testing.assert_array_equal(pi.missing, vr.missing)
    # Integer storage quantises to POINT:SCALE = 1/12 mm; the float files hold the same values, so
    # they must agree within half a quantum (4.2e-5 m). Measured: 2.4e-7 m (float32 rounding).
    half_quantum = abs(pi.metadata["point_scale"]) * 1e-3 / 2
    ok = ~pi.missing
    assert np.abs(pi.positions[ok] - pr.positions[ok]).max() < half_quantum
    assert np.abs(pr.positions[ok] - vr.positions[ok]).max() < 1e-6  # DEC and Intel floats: identical values


@needs(C3D)
def test_walking_hybrid_zero_gaps_and_trailing_bytes():
    m = read_c3d(C3D / "Walking_Hybrid_1_1.c3d")  # 512 bytes after the last data block are ignored
    assert m.metadata["gaps"]["zero_coordinates"] == 3902 and m.metadata["gaps"]["invalid_residual"] == 0
    assert not (m.filled(np.nan) == 0).all(axis=2).any()


@needs(C3D)
def test_real_sample_round_trip(tmp_path):
    m = read_c3d(C3D / "pc_real.c3d", labels=["RFT1", "RPV1", "LFA3"])
    assert m.joint_names == ("RFT1", "RPV1", "LFA3")
    write_c3d(tmp_path / "pc.c3d", m)
    r = read_c3d(tmp_path / "pc.c3d")
    np.testing.assert_array_equal(r.missing, m.missing)
    np.testing.assert_allclose(r.filled(), m.filled(), atol=1e-6, rtol=0)
    assert r.fps == 50.0
