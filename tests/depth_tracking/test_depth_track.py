"""``mocapkit depth-track`` end to end on a tiny synthetic depth video (4 frames of a synthetic HDM05-style clip),
with a prior from other synthetic clips and two Gauss–Newton iterations per frame; the errors it names."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from mocapkit.cli import main
from mocapkit.datasets.formats.depth_images import (
    DepthFormatError,
    read_depth_sequence,
    write_depth_sequence,
    write_intrinsics,
)
from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.datasets.synthetic.depth import render_depth_sequence
from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion
from mocapkit.depth_tracking.base import TRACKED_JOINTS, DepthInputError, tracked_joints
from mocapkit.depth_tracking.depth_track import (
    DepthTrackError,
    find_depth_sequences,
    to_y_up,
    track_depth_files,
    tracked_motion,
    tracked_parents,
)
from mocapkit.testing.estimator_checks import synthetic_clips
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
FRAMES = 4
FAST = ("iterations=2",)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """``seq``: the depth video (npz) of the first 4 frames of one clip, ``world``: its ground-truth 16 joints (y up,
    the clip's frame), ``prior``: a folder of other clips (another actor)."""
    root = tmp_path_factory.mktemp("depth_track")
    (clip,) = synthetic_clips(root / "performer", classes=("squat1Reps",), actors=("bd",), clips_per_actor=1)
    synthetic_clips(root / "prior", actors=("bk",), clips_per_actor=1, seed=1)
    positions = kinect20_from_motion(clip)[:FRAMES]
    sequence = render_depth_sequence(positions, 30.0, source="squat")
    path = write_depth_sequence(sequence, root / "squat.npz")
    return {"root": root, "seq": path, "world": tracked_joints(positions), "prior": root / "prior"}


def _variant(data, name: str, **changes):
    """The test sequence with some fields changed, written as ``name``."""
    sequence = dataclasses.replace(read_depth_sequence(data["seq"]), **changes)
    return write_depth_sequence(sequence, data["root"] / name)


def _error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("mocapkit: error: ") and "Traceback" not in err
    return err


def test_tracked_motion_reads_back_to_the_same_positions(tmp_path):
    rng = np.random.default_rng(0)
    joints = rng.normal(size=(5, 16, 3)) + [0.0, 0.0, 3.0]
    assert np.allclose(to_y_up(joints, None), joints * [1, -1, -1])
    matrix = np.eye(4)
    matrix[:3, :3] = [[0, 0, 1], [0, -1, 0], [1, 0, 0]]
    matrix[:3, 3] = [1, 2, 3]
    assert np.allclose(to_y_up(joints, matrix), joints @ matrix[:3, :3].T + [1, 2, 3])
    motion = tracked_motion(to_y_up(joints, None), 30.0, "x")
    for suffix in ("c3d", "bvh"):
        from mocapkit.datasets.formats.motion_io import write_motion

        write_motion(tmp_path / f"x.{suffix}", motion)
        back = read_motion(tmp_path / f"x.{suffix}")
        assert back.joint_names == TRACKED_JOINTS and back.fps == 30.0 and back.up_axis == "y"
        np.testing.assert_allclose(back.positions, motion.positions, atol=1e-4)
    assert back.parents == tracked_parents()  # the BVH keeps the bones


def test_track_writes_c3d_picture_and_report(data, tmp_path):
    from mocapkit.visualization.render import render_file

    out = tmp_path / "out"
    report = track_depth_files([data["seq"]], [data["prior"]], out=out, overrides=FAST, pictures=3, progress=False)
    motion = read_motion(out / "squat.c3d")
    assert motion.joint_names == TRACKED_JOINTS and motion.num_frames == FRAMES and motion.fps == 30.0
    # camera_to_world is known: the joints are in the clip's own world frame, near the ground truth
    assert np.linalg.norm(motion.positions - data["world"], axis=-1).mean() < 0.3
    picture = out / "squat_frames.png"
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert render_file(out / "squat.c3d", tmp_path / "strip.png", strip=True, n=2).is_file()
    saved = json.loads((out / "report.json").read_text())
    (entry,) = saved["files"]
    assert entry["frames"] == FRAMES and entry["seconds"] > 0 and entry["frames_per_s"] > 0
    assert entry["method"] == "tracker" and entry["parameters"]["iterations"] == 2
    assert entry["parameters"]["prior"] == "lpca"  # --prior turns the registry default's prior=none into LPCA
    assert entry["picture"] == str(picture) and entry["coordinates"].startswith("world")
    errors = entry["joint_error_mm"]
    assert 0 < errors["tracker"] < 400 and 0 < errors["sensor"] < 400
    assert saved["prior"]["takes"] == 2 and saved["prior"]["frames"] > 0 and saved["skipped"] == []
    assert report.tracked[0]["output"] == str(out / "squat.c3d")


def test_cli_writes_bvh_and_prints_a_summary(data, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["depth-track", str(data["seq"]), "--out", str(out), "--prior", str(data["prior"]), "--set", *FAST]
    assert main([*argv, "--format", "bvh", "--pictures", "0", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "tracked 1 file(s) with tracker" in text and "frames/s" in text and "error vs truth" in text
    motion = read_motion(out / "squat.bvh")
    assert motion.joint_names == TRACKED_JOINTS and motion.parents == tracked_parents()
    assert motion.num_frames == FRAMES and motion.fps == pytest.approx(30.0)
    assert not (out / "squat_frames.png").exists()


def test_without_sensor_skeleton_needs_the_flags(data, tmp_path, capsys):
    path = _variant(data, "nosensor.npz", sensor_joints=None, sensor_state=None, camera_to_world=None)
    err = _error(capsys, ["depth-track", str(path), "--out", str(tmp_path / "a")])
    assert str(path) in err and "--start standing" in err and "--skeleton template" in err
    out = tmp_path / "b"
    argv = ["depth-track", str(path), "--out", str(out), "--set", *FAST, "--quiet"]
    assert main([*argv, "--start", "standing", "--skeleton", "template", "--pictures", "1"]) == 0
    assert "prior=none" in capsys.readouterr().out
    saved = json.loads((out / "report.json").read_text())
    assert saved["parameters"]["start"] == "standing" and saved["parameters"]["prior"] == "none"
    assert "no --prior" in saved["prior"]["note"] and saved["files"][0]["coordinates"].startswith("camera")
    assert read_motion(out / "nosensor.c3d").num_frames == FRAMES
    assert "give start once" in _error(capsys, [*argv, "--start", "standing", "--set", "start=sensor"])


def test_bare_png_folder_needs_a_camera(data, tmp_path, capsys):
    from PIL import Image

    folder = tmp_path / "recording"
    folder.mkdir()
    for t, image in enumerate(read_depth_sequence(data["seq"]).depth_mm):
        Image.fromarray(image).save(folder / f"{t}.png")
    err = _error(capsys, ["depth-track", str(folder), "--out", str(tmp_path / "out")])
    assert str(folder) in err and "--camera" in err
    # with the camera it reads; without a sensor skeleton the flags are named next
    err = _error(capsys, ["depth-track", str(folder), "--camera", "kinect_v1", "--out", str(tmp_path / "out")])
    assert str(folder) in err and "--start standing" in err


def test_all_background_frame_and_mismatched_resolution(data, tmp_path, capsys):
    depth = read_depth_sequence(data["seq"]).depth_mm.copy()
    depth[2] = 0
    empty = _variant(data, "empty.npz", depth_mm=depth)
    err = _error(capsys, ["depth-track", str(empty), "--out", str(tmp_path / "out")])
    assert str(empty) in err and "frame 2" in err
    with pytest.raises(DepthInputError, match="frame 2"):
        track_depth_files([empty], out=tmp_path / "out", progress=False)
    sensor = read_depth_sequence(data["seq"]).sensor_joints.copy()
    sensor[1, 3] = np.nan
    with pytest.raises(DepthInputError, match="sensor_joints are not finite in frame 1"):
        track_depth_files([_variant(data, "nan.npz", sensor_joints=sensor)], out=tmp_path / "out", progress=False)
    # another camera's resolution than the images
    err = _error(capsys, ["depth-track", str(data["seq"]), "--camera", "azure_kinect", "--out", str(tmp_path / "o")])
    assert str(data["seq"]) in err and "320×240" in err and "640×576" in err
    # a folder whose frames differ in size: the file and the frame
    folder = _variant(data, "folder", depth_mm=read_depth_sequence(data["seq"]).depth_mm)
    from PIL import Image

    Image.fromarray(np.ones((10, 12), np.uint16)).save(folder / "depth" / "000001.png")
    with pytest.raises(DepthFormatError, match=r"000001\.png.*frame 1"):
        track_depth_files([folder], out=tmp_path / "out", progress=False)


def test_skip_bad_reports_the_bad_file_and_writes_the_good_one(data, tmp_path, capsys):
    depth = read_depth_sequence(data["seq"]).depth_mm.copy()
    depth[0] = 0
    bad = _variant(data, "bad.npz", depth_mm=depth)
    broken = tmp_path / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT")
    out = tmp_path / "out"
    prior = [str(data["prior"]), str(broken)]
    with pytest.raises(DepthTrackError, match="broken.bvh"):
        track_depth_files([data["seq"]], prior, out=out, progress=False)
    argv = ["depth-track", str(bad), str(data["seq"]), "--out", str(out), "--prior", *prior, "--set", *FAST]
    assert main([*argv, "--skip-bad", "--quiet", "--pictures", "0"]) == 0
    text = capsys.readouterr().out
    assert f"skipped {bad}" in text and "frame 0" in text and f"skipped prior {broken}" in text
    saved = json.loads((out / "report.json").read_text())
    assert [entry["input"] for entry in saved["files"]] == [str(data["seq"])]
    assert saved["skipped"][0][0] == str(bad) and "frame 0" in saved["skipped"][0][1]
    assert saved["prior"]["skipped"][0][0] == str(broken) and saved["prior"]["takes"] == 2
    assert (out / "squat.c3d").is_file() and not (out / "bad.c3d").exists()


def test_input_folders_are_expanded(data, tmp_path):
    shutil.copy(data["seq"], tmp_path / "a.npz")
    (tmp_path / "nested").mkdir()
    write_depth_sequence(read_depth_sequence(data["seq"]), tmp_path / "nested" / "b")
    (tmp_path / "nested" / "notes.txt").write_text("not a sequence")
    assert find_depth_sequences([tmp_path]) == [tmp_path / "a.npz", tmp_path / "nested" / "b"]
    assert find_depth_sequences([tmp_path / "nested" / "b"]) == [tmp_path / "nested" / "b"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(DepthTrackError, match="no depth sequences"):
        find_depth_sequences([tmp_path / "empty"])
    shutil.copy(data["seq"], tmp_path / "nested" / "a.npz")
    with pytest.raises(DepthTrackError, match="same name"):
        find_depth_sequences([tmp_path])
    with pytest.raises(FileNotFoundError, match="missing"):
        find_depth_sequences([tmp_path / "missing"])


def test_bare_png_camera_yaml(data, tmp_path):
    """A recorder's folder of bare PNGs with a camera.yaml beside them reads without --camera."""
    from PIL import Image

    sequence = read_depth_sequence(data["seq"])
    for t, image in enumerate(sequence.depth_mm):
        Image.fromarray(image).save(tmp_path / f"frame{t}.png")
    write_intrinsics(sequence.intrinsics, tmp_path / "camera.yaml", fps=15)
    assert find_depth_sequences([tmp_path]) == [tmp_path]
    assert read_depth_sequence(tmp_path).fps == 15


@needs(HDM05)
def test_real_hdm05_prior_and_performer(tmp_path):
    """Real HDM05 takes: the depth video of one (3 frames), the prior from another actor's take, the performer's
    bone lengths from a third take of the same actor."""
    clip = read_motion(HDM05 / "bd" / "HDM_bd_rotateArmsBothBackward1Reps_001_120.amc")
    positions = kinect20_from_motion(clip)[:3]
    sequence = render_depth_sequence(positions, 30.0, source="bd")
    path = write_depth_sequence(sequence, tmp_path / "bd.npz")
    prior = HDM05 / "bk" / "HDM_bk_hopBothLegs1hops_013_120.amc"
    performer = HDM05 / "bd" / "HDM_bd_depositFloorR_001_120.amc"
    report = track_depth_files(
        [path], [prior], out=tmp_path / "out", overrides=FAST, performer=performer, pictures=0, progress=False
    )
    (entry,) = report.tracked
    assert report.performer == str(performer) and entry["joint_error_mm"]["tracker"] < 400
    motion = read_motion(tmp_path / "out" / "bd.c3d")
    assert np.linalg.norm(motion.positions - tracked_joints(positions), axis=-1).mean() < 0.4


def test_methods_without_a_mocap_prior_and_unknown_parameters(data, tmp_path, capsys):
    argv = ["depth-track", str(data["seq"]), "--out", str(tmp_path / "out")]
    err = _error(capsys, [*argv, "--method", "cnn_regressor"])
    assert "--method cnn_regressor" in err and "fit_mocap" in err
    assert "bogus" in _error(capsys, [*argv, "--set", "bogus=1"])
    assert "prior=lpca needs" in _error(capsys, [*argv, "--set", "prior=lpca"])
    assert not (tmp_path / "out").exists()
