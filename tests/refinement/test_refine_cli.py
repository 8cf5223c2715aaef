"""``mocapkit refine IN OUT --method NAME [--set k=v] [--train PATH] [--skip-bad]`` on real files.

C3D in, C3D out is checked with ezc3d reading both files: labels, rate, units, analog data kept; every sample
the refiner did not fill bit-identical (coordinates and residuals); filled samples valid and finite; samples it
could not fill still missing and named in the printed report. Joint positions (HDM05 AMC) go to ``.npz`` and
``.c3d``. Bad input exits with code 2 and a one-line error naming the file.
"""

from __future__ import annotations

import inspect
import re
import shutil
from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml

from mocapkit.cli import main
from mocapkit.datasets.formats.c3d import read_c3d, write_c3d
from mocapkit.motion.container import Motion
from mocapkit.refinement.apply import refine_motion
from mocapkit.refinement.base import RefinementError
from mocapkit.refinement.gap_filling import LinearInterpolation, PchipInterpolation
from mocapkit.train.config import CONFIG_DIR
from mocapkit.train.registry import build_method, method_names
from tests.shared_data import SHARED, needs

C3D = SHARED / "samples" / "c3d"
WALK = C3D / "Walking_Hybrid_1_1.c3d"  # Qualisys, float storage, gaps stored as (0, 0, 0)
EB_INT = C3D / "Eb015pi.c3d"  # integer storage, invalid residuals
EB_REAL = C3D / "Eb015pr.c3d"  # the same take, float storage
EB_DEC = C3D / "Eb015vr.c3d"  # the same take, DEC floats
PC = C3D / "pc_real.c3d"  # float storage, invalid residuals, 36 markers
AMC = SHARED / "data" / "hdm05_cuts11" / "mm" / "HDM_mm_squat1Reps_040_120.amc"
BVH = SHARED / "samples" / "bvh" / "test_freebvh.bvh"

NAMES = [
    "dynammo",
    "filter-bases",
    "learned",
    "linear",
    "lrmf",
    "onnx",
    "pca",
    "pchip",
    "pose-prior",
    "psc",
    "spline",
    "svt",
    "trnn",
]
TRAINED = {"learned", "onnx"}  # need a model file (checkpoint / path: ???)


def refine(capsys, *argv) -> tuple[int, str, str]:
    rc = main(["refine", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert lines and lines[0].startswith("mocapkit: error: "), err
    assert len(lines) == 2 and lines[1].startswith("(set MOCAPKIT_DEBUG=1"), err  # the error is one line
    return lines[0]


# --------------------------------------------------------------------------- the registry


def test_configs_are_the_registry():
    assert method_names("refinement") == NAMES
    primary = yaml.safe_load((CONFIG_DIR / "refinement" / "method.yaml").read_text())
    assert primary["defaults"][0] == {"method": "linear"}
    for name in NAMES:
        node = yaml.safe_load((CONFIG_DIR / "refinement" / "method" / f"{name}.yaml").read_text())
        assert node["_target_"].startswith("mocapkit.refinement."), name
        extra = [f"{key}=model.file" for key, value in node.items() if value == "???"]
        assert bool(extra) == (name in TRAINED), name
        refiner = build_method("refinement", name, extra)
        signature = inspect.signature(type(refiner).__init__).parameters
        for key, value in node.items():
            if key != "_target_" and value != "???":
                assert key in signature, (name, key)
                default = signature[key].default
                default = list(default) if isinstance(default, tuple) else default
                assert default == value, (name, key, value)  # the YAML holds the class defaults
        assert set(signature) - set(node) <= {"self", "dtype"}, name  # every parameter is declared


def test_set_overrides_and_their_errors(capsys):
    assert build_method("refinement", "pca", ["min_cum_sv=0.95"]).min_cum_sv == 0.95
    assert build_method("refinement", "linear", ["extrapolate=hold"]).extrapolate == "hold"
    assert (
        build_method("refinement", "lrmf", ["outlier_threshold=null", "rank=4"]).get_params()["outlier_threshold"]
        is None
    )
    rc, _, err = refine(capsys, "in.c3d", "out.c3d", "--method", "pca", "--set", "no_such_key=1")
    line = error_line(err)
    assert rc == 2 and "no_such_key" in line and "min_cum_sv" in line
    rc, _, err = refine(capsys, "in.c3d", "out.c3d", "--method", "nope")
    line = error_line(err)
    assert rc == 2 and "'nope'" in line and all(name in line for name in NAMES)
    rc, _, err = refine(capsys, "in.c3d", "out.c3d", "--out", "other.c3d", "--method", "linear")
    assert rc == 2 and "give OUT once" in error_line(err)


@needs(AMC)
def test_out_may_be_given_as_an_option(tmp_path, capsys):
    rc, printed, err = refine(capsys, AMC, "--out", tmp_path / "squat.npz", "--method", "pchip")
    assert rc == 0 and (tmp_path / "squat.npz").is_file(), err


# --------------------------------------------------------------------------- C3D in, C3D out


def _check_c3d(src: Path, out: Path, capture: str) -> None:
    """The acceptance checks of a C3D refined with ``linear`` (see the module docstring)."""
    a, b = ezc3d.c3d(str(src)), ezc3d.c3d(str(out))
    pa, pb = a["parameters"]["POINT"], b["parameters"]["POINT"]
    for key in ("LABELS", "UNITS", "DESCRIPTIONS"):
        assert pa[key]["value"] == pb[key]["value"], key
    assert np.array_equal(pa["RATE"]["value"], pb["RATE"]["value"])
    assert a["header"]["points"]["first_frame"] == b["header"]["points"]["first_frame"]
    assert np.array_equal(a["data"]["analogs"], b["data"]["analogs"], equal_nan=True)

    before, after = read_c3d(src), read_c3d(out)
    assert after.joint_names == before.joint_names and after.fps == before.fps
    assert after.metadata["events"] == before.metadata["events"]
    expected = LinearInterpolation().refine(before)
    filled = before.missing & ~expected.missing  # [frames, markers]
    assert filled.any() and expected.missing.any()

    xyz_a, xyz_b = a["data"]["points"][:3], b["data"]["points"][:3]  # [3, markers, frames]
    res_a, res_b = (c["data"]["meta_points"]["residuals"][0] for c in (a, b))
    kept = ~filled.T  # [markers, frames]
    observed = ~before.missing.T
    # every originally observed sample, and every sample not filled, is bit-identical
    assert np.array_equal(xyz_a[:, observed], xyz_b[:, observed])
    assert np.array_equal(xyz_a[:, kept], xyz_b[:, kept], equal_nan=True)
    assert np.array_equal(res_a[kept], res_b[kept])
    # filled samples: finite, valid (residual >= 0), at the linear interpolation
    assert np.isfinite(xyz_b[:, filled.T]).all() and (res_b[filled.T] >= 0).all()
    assert not after.missing[filled].any()
    tol = 1e-6 if before.metadata["storage"] == "float" else before.metadata["point_scale"] * 1e-3 / 2 + 1e-7
    np.testing.assert_allclose(after.positions[filled], expected.positions[filled], atol=tol, rtol=0)
    # samples the method could not fill: still missing (invalid, or the file's zero gaps), named with their frames
    left = expected.missing
    assert np.array_equal(after.missing, left)
    gaps = xyz_b[:, left.T]
    assert (np.isnan(gaps) | (gaps == 0)).all(axis=0).all()
    for j in np.flatnonzero(left.any(axis=0)):
        name = before.joint_names[j]
        first = int(np.flatnonzero(left[:, j])[0])
        assert re.search(
            rf"^  {re.escape(name)}\s+{int(left[:, j].sum())} samples: frames {first}[-\s]", capture, re.MULTILINE
        ), name
    for j in np.flatnonzero(filled.any(axis=0)):
        n = int(filled[:, j].sum())
        assert re.search(
            rf"^{re.escape(before.joint_names[j])}\s+filled {n} samples, longest gap \d+ frames "
            rf"\(\d+\.\d{{3}} s\)",
            capture,
            re.MULTILINE,
        )


@needs(C3D)
@pytest.mark.parametrize("name", ["Walking_Hybrid_1_1.c3d", "Eb015pi.c3d", "Eb015vr.c3d"])
def test_real_c3d_gaps_filled_in_place(tmp_path, capsys, name):
    src, out = C3D / name, tmp_path / f"refined_{name}"
    assert read_c3d(src).metadata["gaps"]["total"] > 0  # real gaps, as exported
    rc, printed, err = refine(capsys, src, out, "--method", "linear")
    assert rc == 0, err
    assert f"wrote {out}" in printed
    _check_c3d(src, out, printed)
    if name == "Eb015pi.c3d":  # integer storage stays integer
        assert "integer storage" in printed
        assert read_c3d(out).metadata["storage"] == "integer"
        assert out.stat().st_size == src.stat().st_size


@needs(C3D)
def test_marker_missing_in_every_frame_is_reported_and_left(tmp_path, capsys):
    c3d = ezc3d.c3d(str(PC))
    data = c3d.c3d_swig.data()
    gone = read_c3d(PC).joint_names.index("RFT2")
    for f in range(c3d["data"]["points"].shape[2]):
        data.frame(f).points().point(gone).residual(-1.0)
    src = tmp_path / "pc_no_rft2.c3d"
    c3d.c3d_swig.write(str(src))
    out = tmp_path / "out.c3d"
    rc, printed, err = refine(capsys, src, out, "--method", "pca", "--set", "min_cum_sv=0.95", "--set", "max_iter=5")
    assert rc == 0, err
    assert re.search(r"^  RFT2\s+89 samples: frames 0-88 \(missing in every frame\)", printed, re.MULTILINE), printed
    refined = read_c3d(out)
    assert refined.missing[:, gone].all() and not np.delete(refined.missing, gone, axis=1).any()
    assert np.isnan(ezc3d.c3d(str(out))["data"]["points"][:3, gone]).all()


# --------------------------------------------------------------------------- joint positions


@needs(AMC)
def test_amc_with_a_gap_to_npz_and_c3d(tmp_path, capsys, monkeypatch):
    from mocapkit.datasets.formats import motion_io

    real_read = motion_io.read_motion
    truth = real_read(AMC)
    gaps = {"lwrist": slice(60, 90), "rtibia": slice(100, 112)}

    def read_with_gap(path, **options):  # AMC holds angles, never gaps: cut them out after reading
        motion = real_read(path, **options)
        if Path(path) != AMC:
            return motion
        positions = motion.positions.copy()
        for joint, frames in gaps.items():
            positions[frames, motion.joint_names.index(joint)] = np.nan
        return Motion(
            positions=positions,
            joint_names=motion.joint_names,
            fps=motion.fps,
            parents=motion.parents,
            up_axis=motion.up_axis,
            name=motion.name,
            source=motion.source,
            metadata=motion.metadata,
        )

    monkeypatch.setattr(motion_io, "read_motion", read_with_gap)
    gap = np.zeros(truth.missing.shape, bool)
    for joint, frames in gaps.items():
        gap[frames, truth.joint_names.index(joint)] = True

    rc, printed, err = refine(capsys, AMC, tmp_path / "squat.npz", "--method", "pchip")
    assert rc == 0, err
    assert re.search(r"^lwrist\s+filled 30 samples, longest gap 30 frames \(0\.250 s\)$", printed, re.MULTILINE), (
        printed
    )
    assert re.search(r"^rtibia\s+filled 12 samples, longest gap 12 frames \(0\.100 s\)$", printed, re.MULTILINE), (
        printed
    )
    with np.load(tmp_path / "squat.npz") as z:
        assert z["positions"].dtype == np.float32 and z["positions"].shape == truth.positions.shape
        assert tuple(z["joint_names"]) == truth.joint_names and float(z["fps"]) == 120.0
        assert not z["missing"].any() and np.array_equal(z["filled"], gap)
        assert np.array_equal(z["positions"][~gap], truth.positions[~gap])  # observed joints untouched
        error = np.linalg.norm(z["positions"][gap] - truth.positions[gap], axis=1)
        assert error.max() < 0.10 and np.sqrt((error**2).mean()) < 0.05  # a smooth squat: within cm
        positions = z["positions"]

    rc, printed, err = refine(capsys, AMC, tmp_path / "squat.c3d", "--method", "pchip")
    assert rc == 0, err
    back = real_read(tmp_path / "squat.c3d")
    assert back.joint_names == truth.joint_names and back.fps == 120.0 and not back.missing.any()
    np.testing.assert_allclose(back.positions, positions, atol=1e-6)


# --------------------------------------------------------------------------- training data


@needs(C3D)
def test_data_driven_method_needs_train_and_checks_layout(tmp_path, capsys, monkeypatch):
    # No in-tree stable refiner requires training (lrmf does not): make linear one for the duration of the test.
    assert not build_method("refinement", "lrmf").requires_fit
    monkeypatch.setattr(LinearInterpolation, "requires_fit", True)
    out = tmp_path / "out.c3d"
    rc, _, err = refine(capsys, EB_REAL, out, "--method", "linear")
    assert rc == 2 and "--train" in error_line(err) and not out.exists()

    folder = tmp_path / "train"
    (folder / "sub").mkdir(parents=True)
    shutil.copy(EB_DEC, folder / "sub" / "Eb015vr.c3d")
    (folder / "notes.txt").write_text("not a motion file: ignored")
    (folder / "broken.c3d").write_bytes(b"\x02\x50" + bytes(100))
    rc, _, err = refine(capsys, EB_REAL, out, "--method", "linear", "--train", folder)
    assert rc == 2 and "broken.c3d" in error_line(err) and "--skip-bad" in err
    rc, printed, err = refine(capsys, EB_REAL, out, "--method", "linear", "--train", folder, "--skip-bad")
    assert rc == 0, err
    assert "trained on 1 motion file(s)" in printed and f"skipped training file {folder / 'broken.c3d'}" in printed

    rc, _, err = refine(capsys, EB_REAL, tmp_path / "x.c3d", "--method", "linear", "--train", PC)  # 36 markers
    line = error_line(err)
    assert rc == 2 and "Eb015pr.c3d" in line and "another skeleton layout" in line

    monkeypatch.undo()
    _check_c3d(EB_REAL, out, printed)


# --------------------------------------------------------------------------- bad input


@needs(C3D)
def test_bad_input_exits_2_naming_the_file(tmp_path, capsys):
    out = tmp_path / "out.c3d"
    all_nan = tmp_path / "all_nan.c3d"
    write_c3d(
        all_nan, Motion(positions=np.full((40, 3, 3), np.nan, np.float32), joint_names=("A", "B", "C"), fps=100.0)
    )
    rc, _, err = refine(capsys, all_nan, out, "--method", "linear")
    assert rc == 2 and "all_nan.c3d" in error_line(err) and "every entry is missing" in err

    c3d = ezc3d.c3d(str(PC))  # a real file with every residual invalidated
    data = c3d.c3d_swig.data()
    markers, frames = c3d["data"]["points"].shape[1:]
    for f in range(frames):
        for j in range(markers):
            data.frame(f).points().point(j).residual(-1.0)
    invalid = tmp_path / "all_invalid.c3d"
    c3d.c3d_swig.write(str(invalid))
    rc, _, err = refine(capsys, invalid, out, "--method", "pchip")
    assert rc == 2 and "all_invalid.c3d" in error_line(err)

    short = tmp_path / "short.c3d"
    write_c3d(short, _first_frames(read_c3d(PC), 10))
    rc, _, err = refine(capsys, short, out, "--method", "trnn")
    line = error_line(err)
    assert rc == 2 and "short.c3d" in line and "10 frames" in line and "16" in line

    rc, _, err = refine(capsys, PC, tmp_path / "out.csv", "--method", "linear")
    line = error_line(err)
    assert rc == 2 and "out.csv" in line and ".c3d" in line and ".npz" in line
    assert not out.exists()


def _first_frames(motion: Motion, n: int) -> Motion:
    return Motion(
        positions=motion.positions[:n],
        joint_names=motion.joint_names,
        fps=motion.fps,
        missing=motion.missing[:n],
        up_axis=motion.up_axis,
        name=motion.name,
    )


@needs(BVH)
def test_inf_in_an_observed_entry(tmp_path, capsys):
    lines = BVH.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip().startswith("Frame Time")) + 3
    values = lines[k].split()
    values[0] = "inf"
    lines[k] = " ".join(values)
    bad = tmp_path / "inf.bvh"
    bad.write_text("\n".join(lines) + "\n")
    rc, _, err = refine(capsys, bad, tmp_path / "out.npz", "--method", "linear")
    assert rc == 2 and "inf.bvh" in error_line(err)  # the reader rejects it, naming file and line

    motion = Motion(positions=np.zeros((20, 2, 3), np.float32), joint_names=("a", "b"), fps=30.0, source="take.c3d")
    motion.positions[5, 1, 2] = np.inf  # what a reader could let through
    with pytest.raises(RefinementError, match=r"take\.c3d: non-finite value at frame 5 of marker 'b'"):
        refine_motion(PchipInterpolation(), motion)


def spiky_walk(tmp_path: Path) -> tuple[Path, int, int, np.ndarray]:
    """``(path, marker, frame, points [3, markers, frames] mm)`` of the Qualisys walk with a 30 cm spike planted in
    the first marker observed between frames 20 and 70."""
    spiky = tmp_path / "spiky.c3d"
    c3d = ezc3d.c3d(str(WALK))
    points = c3d["data"]["points"]
    valid = np.isfinite(points[:3]).all(axis=0) & (points[:3] != 0).any(axis=0)  # [markers, frames]
    marker, frame = np.argwhere(valid[:, 20:70])[0]
    points[0, marker, 20 + frame] += 300.0  # a 30 cm spike (mm file)
    c3d["data"]["points"] = points
    c3d.write(str(spiky))
    return spiky, int(marker), int(20 + frame), ezc3d.c3d(str(spiky))["data"]["points"][:3]


@needs(C3D)  # on the test: a skip mark on the helper it calls does nothing
def test_robust_method_keeps_observed_samples_unless_asked_to_repair(tmp_path, capsys):
    """TrNN flags observed outliers; the command writes only the gap fills unless --repair-outliers."""
    spiky, marker, frame, before = spiky_walk(tmp_path)
    observed = np.isfinite(before).all(axis=0) & (before != 0).any(axis=0)
    kept, repaired = tmp_path / "kept.c3d", tmp_path / "repaired.c3d"
    rc, _, err = refine(capsys, spiky, kept, "--method", "trnn")
    assert rc == 0, err
    assert np.array_equal(ezc3d.c3d(str(kept))["data"]["points"][:3][:, observed], before[:, observed])
    rc, printed, err = refine(capsys, spiky, repaired, "--method", "trnn", "--repair-outliers")
    assert rc == 0, err
    after = ezc3d.c3d(str(repaired))["data"]["points"][:3]
    assert "repaired" in printed
    assert abs(after[0, marker, frame] - before[0, marker, frame]) > 100.0  # the spike was pulled back
