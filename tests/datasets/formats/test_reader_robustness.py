"""Readers against damaged and hostile inputs: crashes, special files, huge allocations, NaN/Inf.

The C3D cases are real samples with one byte changed in the parameter section; each one
killed the interpreter (SIGSEGV) inside ezc3d before ``read_c3d`` validated files itself.
They run in a child process, so a regression fails the test instead of killing pytest.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.formats import safe_io
from mocapkit.datasets.formats.asf_amc import AsfFormatError, parse_asf_text, read_asf
from mocapkit.datasets.formats.c3d import C3DFormatError, read_c3d, validate_c3d
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.datasets.formats.msr_action3d import MSRFormatError, read_msr_skeleton
from mocapkit.datasets.formats.ntu_skeleton import (
    SkeletonFormatError,
    parse_skeleton_text,
    read_skeleton,
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.datasets.ntu.prepare import prepare_ntu
from tests.shared_data import SHARED, needs

C3D = SHARED / "samples" / "c3d"
REPO = Path(__file__).resolve().parents[3]

# (sample, byte offset, new value): each made ezc3d 1.7.2 die with SIGSEGV (found by flipping
# bytes of the parameter section and keeping the candidates whose child exited on a signal).
C3D_CRASHES = [
    ("pc_real.c3d", 525, 255),  # POINT group: offset to the next record
    ("pc_real.c3d", 547, 255),  # ANALOG group id equal to POINT's
    ("pc_real.c3d", 640, 0),  # POINT:DESCRIPTIONS offset to the next record
    ("HDM_dg_06-03_03_120.c3d", 549, 128),  # TRIAL:ACTUAL_START_FIELD dimension count
    ("HDM_dg_06-03_03_120.c3d", 583, 255),  # TRIAL:ACTUAL_END_FIELD offset
    ("HDM_dg_06-03_03_120.c3d", 866, 255),  # POINT:SCALE data type
    ("HDM_dg_06-03_03_120.c3d", 751, 0),  # LABEL_PREFIXES offset
]

_CHILD = textwrap.dedent("""
    import sys
    from mocapkit.datasets.formats.c3d import C3DFormatError, read_c3d
    try:
        read_c3d(sys.argv[1])
    except C3DFormatError as exc:
        print("C3DFormatError:", exc)
    else:
        print("READ")
""")


def _mutated(tmp_path: Path, sample: str, offset: int, value: int) -> Path:
    data = bytearray((C3D / sample).read_bytes())
    assert data[offset] != value
    data[offset] = value
    path = tmp_path / f"{Path(sample).stem}_{offset}_{value}.c3d"
    path.write_bytes(bytes(data))
    return path


@needs(C3D)
@pytest.mark.parametrize("sample,offset,value", C3D_CRASHES)
def test_one_byte_c3d_damage_is_an_error_not_a_crash(tmp_path, sample, offset, value):
    path = _mutated(tmp_path, sample, offset, value)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    child = subprocess.run(
        [sys.executable, "-c", _CHILD, str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        env=env,
        cwd=REPO,
    )
    assert child.returncode == 0, f"child died (exit {child.returncode}): {child.stderr[-2000:]}"
    out = child.stdout.strip()
    assert out.startswith("C3DFormatError:"), out
    assert path.name in out and "byte " in out, out


@needs(C3D)
def test_validation_accepts_every_real_sample_and_is_cheap():
    samples = sorted(C3D.glob("*.c3d"))
    for path in samples:
        layout = validate_c3d(path)
        assert layout.frames > 0 and layout.points > 0 and layout.records > 10
    started = time.perf_counter()
    for _ in range(5):
        for path in samples:
            validate_c3d(path)
    per_file = (time.perf_counter() - started) / (5 * len(samples))
    assert per_file < 0.05, f"validation takes {per_file * 1e3:.1f} ms per file"


@needs(C3D)
def test_c3d_truncated_data_named_before_ezc3d(tmp_path):
    raw = (C3D / "pc_real.c3d").read_bytes()
    path = tmp_path / "cut.c3d"
    path.write_bytes(raw[: len(raw) - 20000])
    with pytest.raises(C3DFormatError, match=r"cut.c3d, frame \d+: truncated: the header announces 89 frames"):
        read_c3d(path)


@needs(C3D)
def test_c3d_point_count_beyond_the_file(tmp_path):
    raw = bytearray((C3D / "pc_real.c3d").read_bytes())
    raw[2:4] = (5000).to_bytes(2, "little")  # header word 2: 5000 points
    path = tmp_path / "many.c3d"
    path.write_bytes(bytes(raw))
    with pytest.raises(C3DFormatError, match=r"many.c3d: .*POINT:USED.*5000"):
        read_c3d(path)


# --------------------------------------------------------------------------- special files and size caps


def _dev_zero_link(tmp_path: Path, name: str) -> Path:
    link = tmp_path / name
    link.symlink_to("/dev/zero")
    return link


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
@pytest.mark.parametrize(
    "name", ["S001C001P001R001A001.skeleton", "walk.bvh", "walk.c3d", "a01_s01_e01_skeleton3D.txt"]
)
def test_link_to_dev_zero_is_refused_by_name(tmp_path, name):
    link = _dev_zero_link(tmp_path, name)
    with pytest.raises(
        MotionFormatError, match=rf"{name}: refusing to read a character device \(a link to /dev/zero\)"
    ):
        read_motion(link)


def test_asf_and_amc_special_files_refused(tmp_path):
    if not os.path.exists("/dev/zero"):
        pytest.skip("needs /dev/zero")
    with pytest.raises(AsfFormatError, match="character device"):
        read_asf(_dev_zero_link(tmp_path, "x.asf"))


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_and_directory_refused_without_blocking(tmp_path):
    fifo = tmp_path / "S001C001P001R001A001.skeleton"
    os.mkfifo(fifo)
    with pytest.raises(SkeletonFormatError, match="FIFO"):
        read_skeleton(fifo)  # opening a FIFO would block forever
    folder = tmp_path / "take.bvh"
    folder.mkdir()
    with pytest.raises(MotionFormatError, match="take.bvh: refusing to read a directory"):
        read_motion(folder)


def test_whole_file_reads_are_capped(tmp_path, monkeypatch):
    path = tmp_path / "a01_s01_e01_skeleton3D.txt"
    path.write_text("1 2 3 1\n" * 20)
    monkeypatch.setattr(safe_io, "MAX_FILE_BYTES", 100)
    with pytest.raises(MSRFormatError, match=r"160 bytes, more than the 100-byte limit"):
        read_msr_skeleton(path)


# --------------------------------------------------------------------------- NTU .skeleton


def _skeleton_text(bodies: int = 1, frames: int = 3, seed: int = 0, tmp: Path | None = None) -> str:
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(bodies, frames, 25, 3)) * 0.1 + [0.0, 0.5, 3.0]
    path = (tmp or Path("/tmp")) / f"gen_{os.getpid()}_{seed}.skeleton"
    write_skeleton(path, sequence_from_positions("S001C001P001R001A001", positions), newline="\n")
    text = path.read_text()
    path.unlink()
    return text


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e309", "NaN"])
def test_ntu_non_finite_joint_value_names_the_line(tmp_path, value):
    lines = _skeleton_text(tmp=tmp_path).splitlines()
    fields = lines[10].split()  # line 11: a joint line of frame 1
    fields[4] = value
    lines[10] = " ".join(fields)
    with pytest.raises(SkeletonFormatError, match=r"x.skeleton, line 11: non-finite joint value"):
        parse_skeleton_text("\n".join(lines) + "\n", name="x.skeleton")


@pytest.mark.parametrize("value", ["nan", "inf", "1e309"])
def test_ntu_non_finite_body_line_value_names_the_line(tmp_path, value):
    lines = _skeleton_text(tmp=tmp_path).splitlines()
    fields = lines[2].split()  # line 3: the body line of frame 1
    fields[7] = value  # lean_x
    lines[2] = " ".join(fields)
    with pytest.raises(SkeletonFormatError, match=r"x.skeleton, line 3: non-finite value .* body line"):
        parse_skeleton_text("\n".join(lines) + "\n", name="x.skeleton")


def test_ntu_cr_only_line_ends_read_like_lf(tmp_path):
    text = _skeleton_text(bodies=2, frames=4, tmp=tmp_path)
    lf = parse_skeleton_text(text, name="x.skeleton")
    cr = parse_skeleton_text(text.replace("\n", "\r"), name="x.skeleton")
    np.testing.assert_array_equal(lf.joints, cr.joints)


def test_ntu_new_body_id_every_frame_is_bounded(tmp_path):
    """A body ID per frame used to allocate tracks x frames x 2.4 KB (GiBs for a MB file)."""
    frames = 800
    one = _skeleton_text(frames=1, tmp=tmp_path).splitlines()  # "1", "1", body line, "25", 25 joints
    body = one[2].split()
    out = [str(frames)]
    for t in range(frames):
        body[0] = str(72057594037927936 + t)
        out += ["1", " ".join(body)] + one[3:]
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_text("\n".join(out) + "\n")
    size = path.stat().st_size
    started = time.perf_counter()
    with pytest.raises(SkeletonFormatError, match=r"800 distinct body IDs over 800 frames would need \d+ MiB"):
        read_skeleton(path)
    assert time.perf_counter() - started < 20
    assert size < 2_000_000


# --------------------------------------------------------------------------- ASF / MSR numbers

_ASF = """:version 1.10
:name t
:units
  mass 1.0
  length 1.0
  angle deg
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name a
    direction 0 1 0
    length {length}
    axis 0 0 0 XYZ
    dof rx ry rz
    limits (-inf inf)
           (-inf inf)
           (-inf inf)
  end
:hierarchy
  begin
    root a
  end
"""


def test_asf_infinite_limits_still_read():
    skel = parse_asf_text(_ASF.format(length="2.5"), source="t.asf")
    assert skel.bones[0].limits[0] == (-np.inf, np.inf)


@pytest.mark.parametrize("value", ["nan", "inf", "1e309", "-inf"])
def test_asf_non_finite_values_name_the_line(value):
    with pytest.raises(AsfFormatError, match=rf"t.asf, line 17: non-finite length '{value}'"):
        parse_asf_text(_ASF.format(length=value), source="t.asf")


@pytest.mark.parametrize(
    "value,match", [("1e39", "beyond the float32 range"), ("nan", "non-finite"), ("inf", "non-finite")]
)
def test_msr_values_beyond_float32_name_the_line(tmp_path, value, match):
    lines = ["0.1 0.2 2.5 1"] * 40
    lines[23] = f"0.1 {value} 2.5 1"
    path = tmp_path / "a01_s01_e01_skeleton3D.txt"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MSRFormatError, match=rf"a01_s01_e01_skeleton3D.txt, line 24: .*{match}"):
        read_msr_skeleton(path)


# --------------------------------------------------------------------------- prepare ntu --skip-bad


def test_prepare_ntu_skip_bad_survives_every_bad_file(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    good = {"S001C001P001R001A001": 0, "S001C001P001R001A002": 1, "S001C001P001R001A003": 2, "S001C001P001R001A004": 3}
    texts = {name: _skeleton_text(frames=5, seed=seed, tmp=tmp_path) for name, seed in good.items()}
    (src / "S001C001P001R001A001.skeleton").write_text(texts["S001C001P001R001A001"])
    (src / "S001C001P001R001A002.skeleton").write_text(texts["S001C001P001R001A002"].replace("\n", "\r"))  # CR only
    (src / "S001C001P001R001A003.skeleton").write_text(" " * 100 + texts["S001C001P001R001A003"])  # long 1st line
    (src / "S001C001P001R001A004.skeleton").write_text(texts["S001C001P001R001A004"])
    bad_lines = texts["S001C001P001R001A001"].splitlines()
    nan_joint = list(bad_lines)
    nan_joint[5] = nan_joint[5].replace(nan_joint[5].split()[0], "nan", 1)
    (src / "S002C001P001R001A001.skeleton").write_text("\n".join(nan_joint) + "\n")
    inf_body = list(bad_lines)
    fields = inf_body[2].split()
    fields[7] = "inf"
    inf_body[2] = " ".join(fields)
    (src / "S002C001P001R001A002.skeleton").write_text("\n".join(inf_body) + "\n")
    (src / "S002C001P001R001A003.skeleton").mkdir()  # a directory
    if os.path.exists("/dev/zero"):
        (src / "S002C001P001R001A004.skeleton").symlink_to("/dev/zero")  # a device
    if hasattr(os, "mkfifo"):
        os.mkfifo(src / "S002C001P001R001A005.skeleton")  # a FIFO

    report = prepare_ntu(src, tmp_path / "out", skip_bad=True, progress=False)
    assert report.samples_written == 4
    messages = {Path(s["file"]).stem: s["message"] for s in report.skipped}
    assert all(s["reason"] == "malformed" for s in report.skipped)
    assert "line 6: non-finite joint value" in messages["S002C001P001R001A001"]
    assert "line 3: non-finite value" in messages["S002C001P001R001A002"]
    assert "directory" in messages["S002C001P001R001A003"]
    if os.path.exists("/dev/zero"):
        assert "character device" in messages["S002C001P001R001A004"]
    if hasattr(os, "mkfifo"):
        assert "FIFO" in messages["S002C001P001R001A005"]
    from mocapkit.datasets.ntu.cache import NTUCache

    cache = NTUCache(tmp_path / "out")
    assert list(cache.lengths) == [5, 5, 5, 5]
    cache.verify()
    for i, name in enumerate(good):
        expected = read_skeleton(src / f"{name}.skeleton").positions[0]
        np.testing.assert_allclose(cache.positions(i)[0], expected)
