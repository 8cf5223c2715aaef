"""The NTU ``.skeleton`` reader/writer against real files, an independent parse, and broken files."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.formats.ntu_skeleton import (
    SkeletonFormatError,
    parse_ntu_name,
    read_missing_list,
    read_skeleton,
    select_main_bodies,
    sequence_from_positions,
    write_skeleton,
)
from tests.shared_data import NTU_SAMPLES as SAMPLES
from tests.shared_data import needs

needs_samples = needs(SAMPLES)

# From shared/samples/SOURCES.md: frames and distinct body IDs per file.
EXPECTED = {
    "S001C001P001R001A011": (82, 1),
    "S001C003P008R002A058": (70, 2),
    "S002C001P003R001A003": (100, 1),
    "S003C001P015R001A034": (71, 1),
    "S004C002P003R001A017": (124, 1),
}
LINES_PER_BODY = 27  # body line + joint count + 25 joint lines


def sample(name: str) -> Path:
    return SAMPLES / f"{name}.skeleton"


# --------------------------------------------------------------------------- real files


@needs_samples
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_real_file_counts(name):
    frames, bodies = EXPECTED[name]
    seq = read_skeleton(sample(name))
    assert seq.name == name
    assert seq.num_frames == frames
    assert seq.num_bodies == bodies
    assert seq.joints.shape == (bodies, frames, 25, 12)
    assert seq.positions.shape == (bodies, frames, 25, 3) and seq.positions.dtype == np.float32
    assert seq.present.all()  # SOURCES.md: every body is in every frame of these files
    assert len(set(seq.body_ids)) == bodies


def _independent_fields(path: Path, frame: int, body: int, joint: int, bodies_per_frame: int):
    """Minimal parse of a file whose frames all hold ``bodies_per_frame`` bodies."""
    lines = path.read_bytes().decode("ascii").split("\r\n")
    frame_start = 1 + frame * (1 + bodies_per_frame * LINES_PER_BODY)  # 0-based line of the body count
    assert int(lines[frame_start]) == bodies_per_frame
    body_line = frame_start + 1 + body * LINES_PER_BODY
    body_tokens = lines[body_line].split()
    assert int(lines[body_line + 1]) == 25
    joint_tokens = lines[body_line + 2 + joint].split()
    return body_tokens, joint_tokens


@needs_samples
@pytest.mark.parametrize(
    "name, frame, body, joint",
    [
        ("S001C001P001R001A011", 0, 0, 0),
        ("S001C001P001R001A011", 81, 0, 24),
        ("S001C003P008R002A058", 0, 1, 11),
        ("S001C003P008R002A058", 37, 0, 7),
        ("S004C002P003R001A017", 60, 0, 3),
    ],
)
def test_fields_agree_with_an_independent_parse(name, frame, body, joint):
    bodies = EXPECTED[name][1]
    body_tokens, joint_tokens = _independent_fields(sample(name), frame, body, joint, bodies)
    assert len(body_tokens) == 10 and len(joint_tokens) == 12
    seq = read_skeleton(sample(name))
    track = seq.body_ids.index(int(body_tokens[0]))  # exact 64-bit ID, no float rounding
    assert seq.slot[track, frame] == body
    np.testing.assert_array_equal(seq.body_info[track, frame], [float(v) for v in body_tokens[1:]])
    np.testing.assert_array_equal(seq.joints[track, frame, joint], [float(v) for v in joint_tokens])
    assert seq.joint_tracking_state[track, frame, joint] == int(joint_tokens[11])
    assert seq.body_field("tracking_state")[track, frame] == float(body_tokens[9])
    np.testing.assert_allclose(seq.positions[track, frame, joint], [float(v) for v in joint_tokens[:3]], rtol=1e-6)


@needs_samples
def test_two_person_file_keeps_both_exact_body_ids():
    seq = read_skeleton(sample("S001C003P008R002A058"))
    lines = sample("S001C003P008R002A058").read_text().splitlines()
    assert seq.body_ids == [int(lines[2].split()[0]), int(lines[2 + LINES_PER_BODY].split()[0])]
    assert seq.body_ids == [72057594037944738, 72057594037944734]


@needs_samples
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_round_trip_is_byte_identical(name, tmp_path):
    out = tmp_path / f"{name}.skeleton"
    write_skeleton(out, read_skeleton(sample(name)))
    assert out.read_bytes() == sample(name).read_bytes()


@needs_samples
def test_lf_and_crlf_both_accepted(tmp_path):
    original = sample("S001C003P008R002A058")
    crlf = original.read_bytes()
    assert b"\r\n" in crlf
    lf_path = tmp_path / original.name
    lf_path.write_bytes(crlf.replace(b"\r\n", b"\n"))
    a, b = read_skeleton(original), read_skeleton(lf_path)
    np.testing.assert_array_equal(a.joints, b.joints)
    np.testing.assert_array_equal(a.body_info, b.body_info)
    assert a.body_ids == b.body_ids
    again = tmp_path / "again" / original.name
    again.parent.mkdir()
    write_skeleton(again, b, newline="\n")
    assert again.read_bytes() == lf_path.read_bytes()


@needs_samples
def test_missing_lists():
    ntu60 = read_missing_list(SAMPLES / "NTU_RGBD_samples_with_missing_skeletons.txt")
    ntu120 = read_missing_list(SAMPLES / "NTU_RGBD120_samples_with_missing_skeletons.txt")
    assert len(ntu60) == 302
    assert len(ntu120) == 535
    assert all(parse_ntu_name(n).setup <= 17 for n in ntu60)
    assert not (set(EXPECTED) & (ntu60 | ntu120))


# --------------------------------------------------------------------------- names


def test_parse_ntu_name():
    s = parse_ntu_name("S001C003P008R002A058")
    assert (s.setup, s.camera, s.subject, s.replication, s.action) == (1, 3, 8, 2, 58)
    assert s.label == 57
    assert str(s) == "S001C003P008R002A058"
    assert parse_ntu_name(Path("/data/nturgb+d_skeletons/S017C002P040R001A120.skeleton")).action == 120
    with pytest.raises(ValueError, match="not an NTU sample name"):
        parse_ntu_name("walk_01.skeleton")


# --------------------------------------------------------------------------- broken files


def _valid_lines(frames: int = 2) -> list[str]:
    """Lines of a valid 2-frame, 1-body file (line k of the file is index k-1)."""
    rng = np.random.default_rng(0)
    positions = rng.normal(0.0, 0.3, size=(1, frames, 25, 3)) + [0.0, 0.0, 3.0]
    return _lines_of(sequence_from_positions("S001C001P001R001A001", positions))


def _lines_of(seq) -> list[str]:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.skeleton"
        write_skeleton(path, seq, newline="\n")
        return path.read_text().split("\n")[:-1]


# Layout of _valid_lines(): 1 frame count, 2 body count, 3 body, 4 joint count, 5-29 joints,
# 30 body count, 31 body, 32 joint count, 33-57 joints.
def _break(lines: list[str], line: int, new: str | None) -> list[str]:
    lines = list(lines)
    if new is None:
        del lines[line - 1]
    else:
        lines[line - 1] = new
    return lines


def _drop_value(text: str) -> str:
    return " ".join(text.split()[:-1])


BROKEN = {
    # case: (edit, expected line, words in the message)
    "truncated inside joints": (lambda ls: ls[:40], 41, "ends inside the joints"),
    "truncated before frame": (lambda ls: ls[:29], 30, "ends before frame 2"),
    "non-numeric joint value": (
        lambda ls: _break(ls, 10, " ".join(["0.1x"] + ls[9].split()[1:])),
        10,
        "non-numeric joint value '0.1x'",
    ),
    "wrong joint count": (lambda ls: _break(ls, 32, "24"), 32, "joint count is 24"),
    "joint line with 11 values": (lambda ls: _break(ls, 45, _drop_value(ls[44])), 45, "11 values, expected 12"),
    "body line with 9 values": (lambda ls: _break(ls, 31, _drop_value(ls[30])), 31, "9 values, expected 10"),
    "non-numeric frame count": (lambda ls: _break(ls, 1, "two"), 1, "frame count"),
    "non-numeric body count": (lambda ls: _break(ls, 30, "x"), 30, "body count of frame 2"),
    "trailing content": (lambda ls: ls + ["1"], 58, "after the last"),
}


def test_valid_fixture_reads(tmp_path):
    lines = _valid_lines()
    assert len(lines) == 57 and lines[3] == "25" and lines[29] == "1"
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_text("\n".join(lines) + "\n")
    assert read_skeleton(path).num_frames == 2


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
@pytest.mark.parametrize("case", sorted(BROKEN))
def test_malformed_file_names_file_and_line(case, newline, tmp_path):
    edit, line, words = BROKEN[case]
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_bytes((newline.join(edit(_valid_lines())) + newline).encode())
    with pytest.raises(SkeletonFormatError) as info:
        read_skeleton(path)
    err = info.value
    assert err.path == str(path)
    assert err.line == line
    assert f"{path}, line {line}:" in str(err)
    assert words in str(err)


def test_empty_file(tmp_path):
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_bytes(b"")
    with pytest.raises(SkeletonFormatError, match=r"line 1: empty file") as info:
        read_skeleton(path)
    assert info.value.line == 1 and str(path) in str(info.value)


def test_unreadable_file_is_a_format_error(tmp_path):
    with pytest.raises(SkeletonFormatError, match="cannot read"):
        read_skeleton(tmp_path / "absent.skeleton")


# --------------------------------------------------------------------------- body selection


def test_select_main_bodies_keeps_the_two_with_most_motion():
    rng = np.random.default_rng(1)
    T = 30
    base = np.zeros((3, T, 25, 3)) + [0.0, 0.0, 3.0]
    amplitude = [0.01, 0.2, 0.05]  # body 1 moves most, then body 2, body 0 barely moves
    tall = np.array([0.3, 1.0, 0.3])  # taller than wide, as people are: spread denoising keeps them
    positions = base + rng.normal(size=(3, T, 25, 3)) * np.array(amplitude)[:, None, None, None] * tall
    ids = [72057594037900001, 72057594037900002, 72057594037900003]
    seq = sequence_from_positions("S001C001P001R001A050", positions, body_ids=ids)
    sel = select_main_bodies(seq)
    assert sel.kept == [1, 2]
    assert list(sel.dropped) == [0] and "less motion" in sel.dropped[0]
    assert sel.positions.shape == (2, T, 25, 3) and sel.positions.dtype == np.float32
    np.testing.assert_array_equal(sel.positions, seq.positions[[1, 2]])


def test_select_main_bodies_pads_a_missing_second_body_and_filters_short_tracks():
    positions = np.zeros((2, 20, 25, 3)) + [0.0, 0.0, 3.0]
    positions[0] += np.linspace(0, 1, 20)[:, None, None]
    positions[1, 5:] = 0.0  # second body present in frames 0-4 only
    seq = sequence_from_positions("S001C001P001R001A001", positions)
    sel = select_main_bodies(seq, min_frames=12)
    assert sel.kept == [0]
    assert "present in 5 frames" in sel.dropped[1]
    assert not sel.positions[1].any()


# --------------------------------------------------------------------------- default rules: length, spread, flicker


def person(T: int, x: float = 0.0, sway: float = 0.05, seed: int = 0) -> np.ndarray:
    """A tall, slowly swaying "person" ``[T, 25, 3]``: 25 points in a 0.4 m × 1.7 m × 0.3 m box, 3 m away."""
    rng = np.random.default_rng(seed)
    shape = rng.uniform(-0.5, 0.5, (25, 3)) * [0.4, 1.7, 0.3] + [x, 0.9, 3.0]
    return shape + sway * np.sin(np.linspace(0, 6, T))[:, None, None] * [1.0, 0.2, 0.0]


def wide_blob(T: int) -> np.ndarray:
    """A static chair-like "body", wider than tall."""
    return (
        np.random.default_rng(9).uniform(-0.5, 0.5, (25, 3)) * [0.7, 0.3, 0.6] + [1.2, 0.4, 3.0] + np.zeros((T, 1, 1))
    )


def rules(seq, **options) -> dict:
    sel = select_main_bodies(seq, **options)
    return {seq.body_ids[b]: sel.rules[b] for b in range(seq.num_bodies)}


def test_a_short_clip_still_gives_its_bodies():
    """Tracks shorter than 12 frames are dropped, never the longest of the file."""
    two = sequence_from_positions(
        "S001C001P001R001A050", np.stack([person(8), person(8, x=1.0, seed=1)]), body_ids=[1, 2]
    )
    assert rules(two) == {1: "rescued_short", 2: "rescued_short"}
    sel = select_main_bodies(two)
    assert len(sel.kept) == 2 and "no track of the file is longer" in sel.kept_reasons[sel.kept[0]]
    positions = np.stack([person(30), person(30, x=1.0, seed=1)])
    positions[1, 11:] = 0.0  # the second track is present in 11 frames: "more than 11" fails
    assert rules(sequence_from_positions("S001C001P001R001A001", positions, body_ids=[1, 2])) == {
        1: "only_candidate",
        2: "short",
    }


def test_spread_denoising_is_on_by_default_and_never_empties_a_file():
    seq = sequence_from_positions("S001C001P001R001A001", np.stack([wide_blob(40), person(40)]), body_ids=[1, 2])
    sel = select_main_bodies(seq)
    assert sel.kept == [1] and sel.rules == {0: "spread", 1: "only_candidate"}
    assert "wider than tall in 100% of its frames" in sel.dropped[0]
    assert select_main_bodies(seq, denoise_spread=False).rules[0] in ("most_motion", "less_motion")
    taller = wide_blob(40)
    taller[:8] *= [1.0, 4.0, 1.0]  # taller than wide in 8 of its 40 frames: wide in 80 % (>= 69.754 %)
    blobs = sequence_from_positions("S001C001P001R001A001", np.stack([wide_blob(40), taller]), body_ids=[1, 2])
    sel = select_main_bodies(blobs)  # every track is wide: the least wide is kept, and says so
    assert sel.kept == [1] and sel.rules[1] == "rescued_spread" and "least wide" in sel.kept_reasons[1]


def test_a_flickering_track_is_dropped_not_ranked_first():
    rng = np.random.default_rng(3)
    T = 60
    ghost = person(T, x=0.3, seed=2) + rng.normal(0, 0.6, (T, 1, 3)) * [1, 0.05, 1]  # jumps every frame
    positions = np.stack([ghost, person(T)])
    positions[0, rng.random(T) < 0.5] = 0.0  # and is there half of the time
    seq = sequence_from_positions("S001C001P001R001A001", positions, body_ids=[7, 8])
    assert select_main_bodies(seq, denoise_flicker=False).kept == [0, 1]  # most "motion": the ghost
    sel = select_main_bodies(seq)
    assert sel.kept == [1] and sel.rules[0] == "flicker" and "flickering: present in" in sel.dropped[0]


def test_a_track_that_jumps_without_gaps_is_dropped():
    rng = np.random.default_rng(4)
    T = 40
    jumper = person(T, seed=3) + rng.normal(0, 0.8, (T, 1, 3)) * [1, 0, 1]
    seq = sequence_from_positions("S001C001P001R001A001", np.stack([jumper, person(T)]), body_ids=[1, 2])
    sel = select_main_bodies(seq)
    assert sel.kept == [1] and sel.rules[0] == "jump" and "m a frame" in sel.dropped[0]


def test_frames_the_sensor_lost_are_not_flicker():
    T = 60
    positions = np.stack([person(T), person(T, x=1.0, seed=1)])
    positions[:, ::3] = 0.0  # every third frame has no body at all
    seq = sequence_from_positions("S001C001P001R001A050", positions, body_ids=[1, 2])
    sel = select_main_bodies(seq)
    assert sorted(sel.kept) == [0, 1] and not sel.dropped


def test_when_every_track_flickers_the_steadiest_is_kept():
    rng = np.random.default_rng(5)
    T = 60
    positions = np.stack([person(T), person(T, x=1.0, seed=1)])
    positions[0, rng.random(T) < 0.5] = 0.0  # present in about 50 % and 40 % of the frames, independently
    positions[1, rng.random(T) < 0.6] = 0.0
    positions[:, 0] = person(T)[0]  # both seen in the first frame, so no frame is empty
    seq = sequence_from_positions("S001C001P001R001A001", positions, body_ids=[1, 2])
    sel = select_main_bodies(seq)
    assert sel.kept == [0] and sel.rules == {0: "rescued_flicker", 1: "flicker"}
    assert "the steadiest is kept" in sel.kept_reasons[0]
