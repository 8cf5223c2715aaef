"""The pure-Python C3D reader against ezc3d, the NaN-gap rule, byte-level patching and the process boundary.

``read_c3d`` decodes header, parameters and data with struct and NumPy only (no C extension sees the bytes);
ezc3d, the maintained C++ reader, is the reference here: every real C3D file under ``shared/`` must decode to
the same coordinates, gaps, labels, rate and first frame.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from mocapkit.datasets.formats.c3d import (
    UNIT_SCALE,
    C3DFormatError,
    decode_parameters,
    patch_samples,
    read_c3d,
    validate_c3d,
)
from mocapkit.motion.container import Motion
from tests.datasets.formats.test_reader_robustness import C3D_CRASHES
from tests.shared_data import SHARED, needs

C3D = SHARED / "samples" / "c3d"
REAL_C3D = sorted(C3D.glob("*.c3d")) + sorted((SHARED / "data").glob("**/*.c3d"))
REPO = Path(__file__).resolve().parents[3]


def _ezc3d_points(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """ezc3d's reading: ``xyz [frames, points, 3]`` in file units and ``invalid [frames, points]``."""
    c3d = ezc3d.c3d(str(path))
    xyz = np.transpose(c3d["data"]["points"][:3], (2, 1, 0))
    residuals = c3d["data"]["meta_points"]["residuals"][0].T
    return xyz, residuals < 0


@needs(C3D)
@pytest.mark.parametrize("path", REAL_C3D, ids=lambda p: p.name)
def test_every_real_file_decodes_as_ezc3d_reads_it(path):
    motion = read_c3d(path, zero_as_missing=False)
    xyz, invalid = _ezc3d_points(path)
    reference = (xyz * UNIT_SCALE[motion.source_units]).astype(np.float32)
    reference[invalid] = np.nan
    assert np.array_equal(motion.positions, reference, equal_nan=True)
    assert np.array_equal(motion.missing, invalid | ~np.isfinite(xyz).all(axis=-1))

    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    assert motion.fps == pytest.approx(float(point["RATE"]["value"][0]))
    assert list(motion.metadata["labels"]) == [
        s.strip() or f"unnamed_{i}" for i, s in enumerate(point["LABELS"]["value"][: motion.num_joints])
    ]
    assert motion.metadata["first_frame"] == c3d["header"]["points"]["first_frame"] + 1
    assert motion.metadata["analog"]["channels"] == c3d["data"]["analogs"].shape[1]
    params = decode_parameters(path, validate_c3d(path))
    for group, names in params.items():  # every numeric parameter as ezc3d decodes it
        for name, value in names.items():
            theirs = c3d["parameters"][group][name]["value"]
            if isinstance(value, np.ndarray) and np.size(theirs):
                assert np.allclose(value.ravel(), np.asarray(theirs, dtype=np.float64).ravel(), equal_nan=True), (
                    group,
                    name,
                )


def _nan_gapped(tmp_path: Path, src: Path) -> tuple[Path, np.ndarray]:
    """``src`` rewritten by ezc3d with gaps cut as users do: coordinates NaN, residual left as it was (0)."""
    c3d = ezc3d.c3d(str(src))
    points = c3d["data"]["points"]
    rng = np.random.default_rng(0)
    observed = np.isfinite(points[:3]).all(axis=0)  # [markers, frames]
    cut = np.zeros_like(observed)
    for marker in rng.choice(points.shape[1], 4, replace=False):
        start = int(rng.integers(10, points.shape[2] - 30))
        cut[marker, start : start + 12] = True
    cut &= observed
    points[:3, cut] = np.nan
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"][0][cut] = 0.0
    out = tmp_path / "nan_gapped.c3d"
    c3d.write(str(out))
    return out, cut.T  # [frames, markers]


@needs(C3D)
def test_nan_coordinates_with_a_valid_residual_are_gaps_counted_per_marker(tmp_path):
    path, cut = _nan_gapped(tmp_path, C3D / "HDM_dg_06-03_03_120.c3d")
    assert (ezc3d.c3d(str(path))["data"]["meta_points"]["residuals"][0].T[cut] >= 0).all()  # valid residual, NaN
    motion = read_c3d(path)
    assert motion.missing[cut].all() and np.isnan(motion.positions[cut]).all()
    gaps = motion.metadata["gaps"]
    assert gaps["nan_coordinates"] == int(cut.sum()) and gaps["total"] >= int(cut.sum())
    per_marker = motion.metadata["nan_gaps_per_marker"]
    assert sum(per_marker.values()) == int(cut.sum()) and len(per_marker) == int(cut.any(axis=0).sum())


@needs(C3D)
def test_refine_fills_nan_gaps_and_keeps_observed_samples_bit_identical(tmp_path, capsys):
    from mocapkit.cli import main

    src, cut = _nan_gapped(tmp_path, C3D / "HDM_dg_06-03_03_120.c3d")
    out = tmp_path / "refined.c3d"
    assert main(["refine", str(src), str(out), "--method", "linear"]) == 0
    printed = capsys.readouterr().out
    assert f"{int(cut.sum())} samples were NaN with a valid residual" in printed
    before, after = read_c3d(src), read_c3d(out)
    assert not after.missing[cut].any()
    observed = ~before.missing
    assert np.array_equal(after.positions[observed], before.positions[observed])
    a, b = ezc3d.c3d(str(src)), ezc3d.c3d(str(out))
    keep = ~cut.T  # [markers, frames]
    assert np.array_equal(a["data"]["points"][:3][:, keep], b["data"]["points"][:3][:, keep], equal_nan=True)


@needs(C3D)
@pytest.mark.parametrize("name", ["Eb015pi.c3d", "Eb015pr.c3d", "Eb015vr.c3d", "Walking_Hybrid_1_1.c3d"])
def test_patching_rewrites_only_the_given_samples_in_the_files_own_storage(tmp_path, name):
    src = C3D / name
    layout = validate_c3d(src)
    motion = read_c3d(src)
    frames, points = np.array([0, 5, layout.frames - 1]), np.array([1, 0, layout.points - 1])
    values = np.array([[100.25, -200.5, 300.75], [1.0, 2.0, 3.0], [-5.5, 6.25, 700.0]])
    out = tmp_path / "patched.c3d"
    mode = patch_samples(src, out, frames, points, values)
    assert ("integer" in mode) == (motion.metadata["storage"] == "integer")
    a, b = np.frombuffer(src.read_bytes(), np.uint8), np.frombuffer(out.read_bytes(), np.uint8)
    changed = np.flatnonzero(a != b)
    for offset in changed:  # every changed byte lies inside one of the three samples
        assert any(0 <= offset - layout.sample_offset(f, j) < 4 * layout.element_size for f, j in zip(frames, points))
    patched = read_c3d(out)
    tolerance = abs(layout.point_scale) if layout.element_size == 2 else 1e-4
    got = patched.positions[frames, points] / UNIT_SCALE[motion.source_units]
    assert np.allclose(got, values, atol=tolerance) and not patched.missing[frames, points].any()
    others = np.ones(motion.missing.shape, bool)
    others[frames, points] = False
    assert np.array_equal(patched.positions[others], motion.positions[others], equal_nan=True)


@needs(C3D)
def test_patching_refuses_values_beyond_integer_storage(tmp_path):
    with pytest.raises(ValueError, match=r"Eb015pi.c3d: the value of point 2 at frame 4 is outside the int16"):
        patch_samples(C3D / "Eb015pi.c3d", tmp_path / "x.c3d", [3], [2], [[1e7, 0.0, 0.0]])
    assert not (tmp_path / "x.c3d").exists()


def test_a_motion_written_and_patched_round_trips(tmp_path):
    from mocapkit.datasets.formats.c3d import write_c3d

    rng = np.random.default_rng(1)
    positions = rng.normal(size=(30, 4, 3)).astype(np.float32)
    missing = np.zeros((30, 4), bool)
    missing[10:14, 2] = True
    write_c3d(tmp_path / "m.c3d", Motion(positions, ("a", "b", "c", "d"), 60.0, missing=missing, up_axis="z"))
    fill = positions[10:14, 2] * 1000.0  # mm
    patch_samples(tmp_path / "m.c3d", tmp_path / "p.c3d", np.arange(10, 14), np.full(4, 2), fill)
    back = read_c3d(tmp_path / "p.c3d")
    assert not back.missing.any() and np.allclose(back.positions, positions, atol=1e-6)


# --------------------------------------------------------------------------- the process boundary

_CHILD = textwrap.dedent("""
    import sys, tempfile
    from pathlib import Path
    from mocapkit.cli import main
    from mocapkit.datasets.formats.errors import MotionFormatError
    from mocapkit.datasets.formats.motion_io import read_motion

    bad = Path(sys.argv[1])
    try:
        read_motion(bad)
    except MotionFormatError as exc:
        print("read_motion:", exc)
    out = Path(tempfile.mkdtemp())
    print("refine rc", main(["refine", str(bad), str(out / "r.c3d"), "--method", "linear"]))
    print("index rc", main(["index", str(bad.parent), "--out", str(out / "index"), "--method", "dtw_positions", "--skip-bad"]))
    print("SURVIVED")
""")


@needs(C3D)
@pytest.mark.parametrize("sample,offset,value", C3D_CRASHES[:3] + C3D_CRASHES[-2:])
def test_known_crashers_end_in_located_errors_and_the_process_survives(tmp_path, sample, offset, value):
    """The byte changes that once killed the interpreter inside ezc3d, through read_motion, refine and index."""
    folder = tmp_path / "library"
    folder.mkdir()
    data = bytearray((C3D / sample).read_bytes())
    data[offset] = value
    bad = folder / f"crasher_{offset}_{value}.c3d"
    bad.write_bytes(bytes(data))
    walk = (SHARED / "samples" / "bvh" / "AV_8Walk_Meredith_HVHA_Rep1.bvh").read_bytes()
    for k in range(2):  # clips the index can use beside the crasher
        (folder / f"walk{k}.bvh").write_bytes(walk)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    child = subprocess.run(
        [sys.executable, "-c", _CHILD, str(bad)], capture_output=True, text=True, timeout=300, env=env, cwd=REPO
    )
    assert child.returncode == 0, f"child died (exit {child.returncode}): {child.stderr[-2000:]}"
    out, err = child.stdout, child.stderr
    assert "SURVIVED" in out and f"read_motion: {bad}" in out and "byte " in out, out
    assert "refine rc 1" in out or "refine rc 2" in out, out
    assert bad.name in err  # refine's error and index's skip report name the file
    assert "index rc 0" in out, out + err
    assert err.count(bad.name) >= 2, err


def test_c3d_format_error_pickles_with_its_frame(tmp_path):
    import pickle

    exc = pickle.loads(pickle.dumps(C3DFormatError(tmp_path / "a.c3d", "truncated", frame=3)))
    assert exc.frame == 3 and "a.c3d" in str(exc)
