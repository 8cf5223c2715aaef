"""ASF/AMC reading, forward kinematics and writing: real CMU/HDM05 samples, an AMC ↔ C3D
cross-check on HDM05 take dg 06-03_03, round trips and malformed input."""

from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.formats.asf_amc import (
    AmcFormatError,
    AsfFormatError,
    AsfSkeleton,
    amc_motion,
    find_asf,
    forward_kinematics,
    read_amc,
    read_asf,
    write_amc,
    write_asf,
)
from mocapkit.motion.layouts import CMU31
from tests.shared_data import SHARED, needs

ASF_AMC = SHARED / "samples" / "asf_amc"
HDM_AMC = ASF_AMC / "hdm05" / "HDM_dg_06-03_03_120.amc"
HDM_C3D = SHARED / "samples" / "c3d" / "HDM_dg_06-03_03_120.c3d"

#: every real AMC sample, its ASF and its frame count (shared/samples/SOURCES.md)
SAMPLES = [
    ("hdm05/HDM_dg_06-03_03_120.amc", "hdm05/HDM_dg.asf", 202),
    ("cmu/backflip.amc", "cmu/backflip.asf", 247),
    ("cmu/charleston1.amc", "cmu/charleston.asf", 506),
    ("cmu/charleston2.amc", "cmu/charleston.asf", 546),
    ("cmu/pirouette.amc", "cmu/pirouette.asf", 591),
    ("cmu_01/test.amc", "cmu_01/test.asf", 2751),
]
# standing clips: frame 0 is an upright pose (the back flip and the dances start upright too)
UNIT = 0.0254 / 0.45

needs_samples = needs(ASF_AMC)


def _bone_lengths(m):
    par = np.array(m.parents[1:])
    return np.linalg.norm(m.positions[:, 1:] - m.positions[:, par], axis=-1)  # [T, J-1]


# --------------------------------------------------------------------------- real samples


@needs_samples
@pytest.mark.parametrize("amc,asf,frames", SAMPLES, ids=[s[0] for s in SAMPLES])
def test_real_samples_read(amc, asf, frames):
    m = read_amc(ASF_AMC / amc)  # the ASF is found beside the AMC
    assert Path(m.metadata["asf_path"]).name == Path(asf).name
    assert m.num_frames == frames
    assert m.joint_names == CMU31.joint_names and m.parents == CMU31.parents and m.layout_name == "cmu31"
    assert m.positions.dtype == np.float32 and m.rotations.shape == (frames, 31, 3, 3)
    assert not m.missing.any() and m.fps == 120.0 and m.up_axis == "y" and m.source_units == "inch/0.45 (CMU)"
    # FK is rigid: every bone keeps the ASF length (metres) in every frame
    skel = m.metadata["asf"]
    expected = np.array([b.length * UNIT for b in skel.bones])
    np.testing.assert_allclose(_bone_lengths(m), np.broadcast_to(expected, (frames, 30)), atol=2e-5)
    # local rotations are rotations
    R = m.rotations.astype(np.float64)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-5)
    # a plausible human, upright in the first frame: head above the feet, 1.5-1.9 m tall
    p = m.positions[0]
    feet = min(p[m.index(j), 1] for j in ("lfoot", "rfoot", "ltoes", "rtoes"))
    assert p[m.index("head"), 1] > p[m.index("root"), 1] > p[m.index("lfoot"), 1]
    assert 1.4 < p[m.index("head"), 1] - feet < 1.95
    # the body stays near the floor (y up, metres)
    assert -0.1 < m.positions[..., 1].min() < 0.2 and m.positions[..., 1].max() < 2.5


@needs_samples
def test_asf_fields_hdm05():
    s = read_asf(ASF_AMC / "hdm05" / "HDM_dg.asf")  # CRLF, VICON header
    assert s.units == {"mass": 1.0, "length": 0.45, "angle": "deg"}
    assert abs(s.metres_per_unit - 0.0254 / 0.45) < 1e-12
    assert s.root_order == ("TX", "TY", "TZ", "RX", "RY", "RZ") and s.root_axis == "XYZ"
    assert "BodyBuilder" in s.documentation and s.name == "VICON"
    assert len(s.bones) == 30 and s.bones[0].name == "lhipjoint" and s.bones[0].dof == ()
    femur = s.bone("lfemur")
    assert femur.dof == ("rx", "ry", "rz") and femur.limits == [(-160.0, 20.0), (-70.0, 70.0), (-60.0, 70.0)]
    np.testing.assert_allclose(femur.axis, [0, 0, 20])
    assert abs(femur.length - 6.69088) < 1e-9
    assert s.hierarchy["thorax"] == ["lowerneck", "lclavicle", "rclavicle"]
    assert s.amc_bones[0] == "root" and len(s.amc_bones) == 29  # no lhipjoint / rhipjoint lines


@needs_samples
def test_latin1_header_kept():
    m = read_amc(HDM_AMC)
    assert "für Bonn" in m.metadata["amc_header"][0]
    # HDM05 lists bones in its own order, not the ASF's: kept for writing
    assert m.metadata["amc_bone_order"][:8] == (
        "root",
        "lowerback",
        "upperback",
        "thorax",
        "lowerneck",
        "upperneck",
        "head",
        "rclavicle",
    )
    np.testing.assert_array_equal(m.metadata["amc_frame_numbers"], np.arange(1, 203))


@needs_samples
def test_fk_matches_explicit_matrices_on_one_frame():
    """An independent per-joint FK with hand-written Rx/Ry/Rz on HDM05 frame 100."""
    m = read_amc(HDM_AMC)
    s = m.metadata["asf"]
    vals = {b: v[100] for b, v in m.metadata["amc_values"].items()}

    def rot(axis, deg):
        a = np.deg2rad(deg)
        c, n = np.cos(a), np.sin(a)
        return {
            "x": np.array([[1, 0, 0], [0, c, -n], [0, n, c]]),
            "y": np.array([[c, 0, n], [0, 1, 0], [-n, 0, c]]),
            "z": np.array([[c, -n, 0], [n, c, 0], [0, 0, 1]]),
        }[axis]

    def euler(angles, axes):  # fixed axes, first applied first
        R = np.eye(3)
        for a, ax in zip(angles, axes):
            R = rot(ax, a) @ R
        return R

    glob = {"root": euler(vals["root"][3:], "xyz")}
    pos = {"root": vals["root"][:3] * UNIT}
    parent = s.parent_names
    for b in s.bones:  # ASF order is topological for CMU/HDM05
        C = euler(b.axis, b.axis_order.lower())
        M = euler(vals[b.name], [d[1] for d in b.dof]) if b.dof else np.eye(3)
        glob[b.name] = glob[parent[b.name]] @ C @ M @ C.T
        pos[b.name] = pos[parent[b.name]] + glob[b.name] @ (b.direction * b.length * UNIT)
    expected = np.stack([pos[n] for n in m.joint_names])
    np.testing.assert_allclose(m.positions[100], expected, atol=1e-5)


# --------------------------------------------------------------------------- AMC ↔ C3D


@needs(HDM_C3D)
@needs_samples
def test_amc_matches_c3d_markers_hdm05():
    """HDM05 take dg 06-03_03 exists as AMC (FK joints) and as C3D (44 Vicon markers), 202 frames each.

    Compared: each AMC joint against the mean of the markers around it, on every frame —
    head (end of the ``head`` bone) ↔ LFHD/RFHD/LBHD/RBHD; pelvis (``root``) ↔ LFWT/RFWT/LBWT/RBWT;
    wrists (``l/rradius`` ends) ↔ L/RWRA+L/RWRB; elbows (``l/rhumerus``) ↔ L/RELB; knees
    (``l/rfemur``) ↔ L/RKNE; ankles (``l/rtibia``) ↔ L/RANK (markers carry the ``Daniel:`` prefix).
    One rigid transform (Kabsch, no scale) over all frames maps the AMC's y-up metres to the
    C3D's z-up millimetres / 1000.

    Tolerances (markers sit on the skin, 3-9 cm from the joint centres): the fitted rotation is the
    y-up → z-up axis permutation within 0.02; a free scale would be 1 within 2 %; per joint, the
    mean distance over frames is below 10 cm and the distance on every frame below 13 cm; the mean
    over joints is below 7 cm on every frame. Measured: per-joint means from 2.2 cm (pelvis) and
    3.6 cm (head) to 7.0 cm (wrists) and 8.2 cm (right knee), worst single frame 11.1 cm (right knee),
    worst per-frame mean 6.3 cm, 5.6 cm overall. Swapping left and right markers gives 37 cm
    (asserted > 15 cm), so the test can tell the sides apart.
    """
    import ezc3d

    m = read_amc(HDM_AMC)
    c3d = ezc3d.c3d(str(HDM_C3D))
    pts = c3d["data"]["points"][:3].transpose(2, 1, 0) / 1000.0  # [frames, markers, 3] metres
    labels = [lab.split(":")[-1] for lab in c3d["parameters"]["POINT"]["LABELS"]["value"]]
    assert pts.shape == (202, 44, 3) == (m.num_frames, 44, 3)
    assert c3d["header"]["points"]["first_frame"] == 2924  # 2925 1-based
    assert not np.isnan(pts).any()
    pairs = {
        "head": ("LFHD", "RFHD", "LBHD", "RBHD"),
        "root": ("LFWT", "RFWT", "LBWT", "RBWT"),
        "lradius": ("LWRA", "LWRB"),
        "rradius": ("RWRA", "RWRB"),
        "lhumerus": ("LELB",),
        "rhumerus": ("RELB",),
        "lfemur": ("LKNE",),
        "rfemur": ("RKNE",),
        "ltibia": ("LANK",),
        "rtibia": ("RANK",),
    }
    joints = m.positions[:, [m.index(j) for j in pairs]].astype(np.float64)  # [T, K, 3]
    markers = np.stack([pts[:, [labels.index(x) for x in v]].mean(1) for v in pairs.values()], 1)

    def kabsch(a, b):
        ca, cb = a.mean(0), b.mean(0)
        U, S, Vt = np.linalg.svd((a - ca).T @ (b - cb))
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        R = Vt.T @ np.diag([1, 1, d]) @ U.T
        scale = (S * [1, 1, d]).sum() / ((a - ca) ** 2).sum()
        return R, ca, cb, scale

    R, ca, cb, scale = kabsch(joints.reshape(-1, 3), markers.reshape(-1, 3))
    np.testing.assert_allclose(R, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=0.02)  # AMC z→C3D x, x→y, y→z (up)
    assert abs(scale - 1) < 0.02
    dist = np.linalg.norm((joints - ca) @ R.T + cb - markers, axis=-1)  # [T, K] metres
    assert (dist.mean(0) < 0.10).all(), dict(zip(pairs, dist.mean(0).round(3)))
    assert (dist < 0.13).all()
    assert (dist.mean(1) < 0.07).all()
    # negative control: left/right swapped markers do not fit
    swapped = markers[:, [0, 1, 3, 2, 5, 4, 7, 6, 9, 8]]
    R2, ca2, cb2, _ = kabsch(joints.reshape(-1, 3), swapped.reshape(-1, 3))
    assert np.linalg.norm((joints - ca2) @ R2.T + cb2 - swapped, axis=-1).mean() > 0.15


# --------------------------------------------------------------------------- round trips


@needs_samples
@pytest.mark.parametrize("amc", ["hdm05/HDM_dg_06-03_03_120.amc", "cmu/charleston2.amc"])
def test_read_write_read(tmp_path, amc):
    m = read_amc(ASF_AMC / amc)
    write_asf(tmp_path / "x.asf", m.metadata["asf"])
    write_amc(tmp_path / "x.amc", m)
    m2 = read_amc(tmp_path / "x.amc")  # finds x.asf
    assert np.abs(m2.positions - m.positions).max() < 1e-6
    assert m2.metadata["amc_bone_order"] == m.metadata["amc_bone_order"]
    s1, s2 = m.metadata["asf"], m2.metadata["asf"]
    assert s2.units == s1.units and s2.hierarchy == s1.hierarchy and s2.documentation == s1.documentation
    for b1, b2 in zip(s1.bones, s2.bones):
        assert (b1.name, b1.dof, b1.limits, b1.axis_order) == (b2.name, b2.dof, b2.limits, b2.axis_order)
        np.testing.assert_allclose(b1.direction, b2.direction, atol=1e-9)


def _toy_skeleton(angle="deg", length=0.45) -> AsfSkeleton:
    text = f"""# toy
:version 1.10
:name toy
:units mass 1.0 length {length} angle {angle}
:documentation
  two bones
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name hip
    direction 0 -1 0
    length 10
    axis 0 0 0 XYZ
  end
  begin
    id 2
    name leg
    direction 0 -1 0
    length 5
    axis 0 0 90 XYZ
    dof rx rz
    limits (-180 180)
           (-inf inf)
  end
:hierarchy
  begin
    root hip
    hip leg
  end
"""
    from mocapkit.datasets.formats.asf_amc import parse_asf_text

    return parse_asf_text(text.replace("\n", "\r\n"), source="toy.asf")


def test_toy_fk_conventions_and_radians(tmp_path):
    s = _toy_skeleton()
    assert s.joint_names == ("root", "hip", "leg") and s.parents == (-1, 0, 1) and s.layout_name is None
    assert s.bone("leg").limits == [(-180.0, 180.0), (-np.inf, np.inf)]
    # rx of "leg" is about C's x axis = global y (axis 0 0 90): a leg along -y does not move;
    # rz is about C's z = global z: 90 deg swings -y to +x
    for vals, end in [([90, 0], [0, -15, 0]), ([0, 90], [5, -10, 0])]:
        pos, _ = forward_kinematics(s, {"root": np.zeros((1, 6)), "leg": np.array([vals], float)})
        np.testing.assert_allclose(pos[0, 2] / (0.0254 / 0.45), end, atol=1e-9)
    # root translation is in ASF units; a root yaw of 90 deg turns the body about y
    pos, _ = forward_kinematics(s, {"root": np.array([[1, 2, 3, 0, 90, 0.0]]), "leg": np.zeros((1, 2))})
    np.testing.assert_allclose(pos[0, 0] / (0.0254 / 0.45), [1, 2, 3], atol=1e-9)
    # the same motion written in radians reads back to the same positions
    values = {"root": np.array([[1, 2, 3, 10, 20, 30.0]] * 3), "leg": np.array([[15, -40.0]] * 3)}
    m = amc_motion(s, values)
    rad = {k: v.copy() for k, v in values.items()}
    rad["root"][:, 3:] = np.deg2rad(rad["root"][:, 3:])
    rad["leg"] = np.deg2rad(rad["leg"])
    write_amc(tmp_path / "r.amc", rad, s, angle_unit="rad")
    assert ":RADIANS" in (tmp_path / "r.amc").read_text()
    m2 = read_amc(tmp_path / "r.amc", asf=s, fps=60)
    assert m2.fps == 60 and m2.metadata["amc_angle_unit"] == "rad"
    np.testing.assert_allclose(m2.positions, m.positions, atol=1e-6)
    # unit override
    m3 = read_amc(tmp_path / "r.amc", asf=s, unit_scale=0.01)
    np.testing.assert_allclose(m3.positions[0, 0], [0.01, 0.02, 0.03], atol=1e-7)


# --------------------------------------------------------------------------- bad input


def _write_toy(tmp_path, frames_text: str, name="bad"):
    s = _toy_skeleton()
    write_asf(tmp_path / f"{name}.asf", s)
    path = tmp_path / f"{name}.amc"
    path.write_text(":FULLY-SPECIFIED\n:DEGREES\n" + frames_text)
    return path


GOOD = "1\nroot 0 0 0 0 0 0\nleg 1 2\n2\nroot 0 0 0 0 0 0\nleg 3 4\n"


def test_good_toy_amc(tmp_path):
    m = read_amc(_write_toy(tmp_path, GOOD))
    assert m.num_frames == 2 and m.metadata["amc_values"]["leg"].tolist() == [[1, 2], [3, 4]]


@pytest.mark.parametrize(
    "text,line,frame,words",
    [
        ("1\nroot 0 0 0 0 0 0\n2\nroot 0 0 0 0 0 0\nleg 3 4\n", 5, 1, "truncated"),  # frame 1 lacks 'leg'
        ("1\nroot 0 0 0 0 0 0\nleg 1 2\n2\nroot 0 0 0 0 0 0\n", 8, 2, "truncated"),  # file ends in frame 2
        ("1\nroot 0 0 0 0 0 0\nleg 1 x\n", 5, 1, "non-numeric"),
        ("1\nroot 0 0 0 0 0 0\nleg 1 2 3\n", 5, 1, "needs 2 values"),
        ("1\nroot 0 0 0 0 0 0\nleg 1 2\narm 1\n", 6, 1, "unknown bone 'arm'"),
        ("1\nroot 0 0 0 0 0 0\nleg 1 2\nleg 1 2\n", 6, 1, "twice"),
        ("1\nroot 0 0 0 0 0 0\nhip 1 2\nleg 1 2\n", 5, 1, "no dof"),
        ("root 0 0 0 0 0 0\n", 3, None, "frame number"),
    ],
)
def test_bad_amc_names_file_line_frame(tmp_path, text, line, frame, words):
    path = _write_toy(tmp_path, text)
    with pytest.raises(AmcFormatError) as err:
        read_amc(path)
    e = err.value
    assert e.line == line and e.frame == frame and e.path == str(path)
    msg = str(e)
    assert str(path) in msg and f"line {line}" in msg and words in msg
    if frame is not None:
        assert f"frame {frame}" in msg


@needs_samples
def test_truncated_real_amc(tmp_path):
    lines = HDM_AMC.read_bytes().splitlines(keepends=True)
    # frame 3 starts at line 4 + 2*30; drop its last bone line (ltoes), keep frames 4..202
    cut = 4 + 2 * 30 + 29 - 1  # 0-based index of frame 3's last line
    assert lines[cut].startswith(b"ltoes")
    bad = tmp_path / "HDM_dg_cut.amc"
    bad.write_bytes(b"".join(lines[:cut] + lines[cut + 1 :]))
    with pytest.raises(AmcFormatError) as err:
        read_amc(bad, asf=ASF_AMC / "hdm05" / "HDM_dg.asf")
    assert err.value.frame == 3 and err.value.line == cut + 1 and "HDM_dg_cut.amc" in str(err.value)


def test_missing_or_ambiguous_asf(tmp_path):
    amc = tmp_path / "clip.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n" + GOOD)
    with pytest.raises(FileNotFoundError, match="no .asf"):
        read_amc(amc)
    write_asf(tmp_path / "a.asf", _toy_skeleton())
    assert find_asf(amc).name == "a.asf"  # the only one
    write_asf(tmp_path / "b.asf", _toy_skeleton())
    with pytest.raises(ValueError, match="cannot tell"):
        read_amc(amc)
    write_asf(tmp_path / "cl.asf", _toy_skeleton())  # prefix of the AMC stem
    assert find_asf(amc).name == "cl.asf"
    (tmp_path / "walk2StepsLstart_bd_001.amc").write_text(GOOD)
    write_asf(tmp_path / "HDM_bd.asf", _toy_skeleton())
    assert find_asf(tmp_path / "walk2StepsLstart_bd_001.amc").name == "HDM_bd.asf"
    with pytest.raises(AsfFormatError):
        read_amc(amc, asf=tmp_path / "missing.asf")


@pytest.mark.parametrize(
    "edit,words",
    [
        (lambda t: t.replace("length 5", "length five"), "non-numeric length"),
        (lambda t: t.replace("hip leg\n", "hip foot\n"), "unknown bone 'foot'"),
        (lambda t: t.replace("dof rx rz", "dof rx rz tx"), "unsupported dof"),
        (lambda t: t.replace(":bonedata", ":bonestuff"), "unknown section"),
        (lambda t: t.replace("           (-inf inf)\n", ""), "1 limit pairs for 2 dofs"),
    ],
)
def test_bad_asf(tmp_path, edit, words):
    write_asf(tmp_path / "ok.asf", _toy_skeleton())
    text = edit((tmp_path / "ok.asf").read_text())
    (tmp_path / "bad.asf").write_text(text)
    with pytest.raises(AsfFormatError, match=words) as err:
        read_asf(tmp_path / "bad.asf")
    assert "bad.asf" in str(err.value)
