"""Depth sequences on disk: npz and PNG-folder round trips, camera.yaml, bare PNG folders from real cameras, and an
error naming the file (and the key or frame) for every malformed input."""

import json
import zipfile

import numpy as np
import pytest
from PIL import Image

from mocapkit.datasets.formats.depth_images import (
    ARRAY_FIELDS,
    CameraIntrinsics,
    DepthFormatError,
    DepthSequence,
    camera_from_argument,
    read_camera_file,
    read_depth_sequence,
    read_intrinsics,
    write_depth_sequence,
    write_intrinsics,
)

SMALL = CameraIntrinsics(32, 24, 30.5, 29.0, 15.5, 11.5, "tiny")


def _sequence(intrinsics=SMALL, frames=3, seed=0):
    rng = np.random.default_rng(seed)
    H, W = intrinsics.shape
    depth = rng.integers(0, 5000, (frames, H, W)).astype(np.uint16)
    depth[1] = 0  # an all-background frame is data, not an error
    return DepthSequence(
        depth_mm=depth,
        intrinsics=intrinsics,
        fps=29.97,
        colour=rng.integers(0, 256, (frames, H, W, 3)).astype(np.uint8),
        parts=rng.integers(0, 3, (frames, H, W)).astype(np.uint8),
        part_names=("torso", "head"),
        joints=rng.normal(size=(frames, 4, 3)).astype(np.float32),
        joint_names=("a", "b", "c", "d"),
        sensor_joints=rng.normal(size=(frames, 4, 3)).astype(np.float32),
        sensor_state=rng.integers(0, 3, (frames, 4)).astype(np.int8),
        camera_to_world=rng.normal(size=(4, 4)),
        source="take.amc",
        metadata={"seed": 3, "noise": "kinect_v1"},
    )


def _assert_same(read, written):
    for name in ARRAY_FIELDS:
        a, b = getattr(read, name), getattr(written, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert read.intrinsics == written.intrinsics
    assert read.fps == written.fps
    assert read.part_names == written.part_names and read.joint_names == written.joint_names
    assert read.metadata == {**written.metadata, "source": written.source}


@pytest.mark.parametrize("name", ["seq.npz", "seq"])
def test_round_trip_is_exact(tmp_path, name):
    sequence = _sequence()
    path = write_depth_sequence(sequence, tmp_path / name)
    read = read_depth_sequence(path)
    _assert_same(read, sequence)
    assert read.source == str(path)
    # writing again replaces it, and leaves no temporary files behind
    write_depth_sequence(_sequence(seed=1), path)
    _assert_same(read_depth_sequence(path), _sequence(seed=1))
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_folder_layout_and_preset_camera(tmp_path):
    sequence = _sequence(CameraIntrinsics.preset("kinect_v1"), frames=2)
    sequence.colour = sequence.parts = sequence.joints = sequence.sensor_joints = sequence.sensor_state = None
    write_depth_sequence(sequence, tmp_path / "seq")
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == ["camera.yaml", "depth"]
    assert sorted(p.name for p in (tmp_path / "seq" / "depth").iterdir()) == ["000000.png", "000001.png"]
    with Image.open(tmp_path / "seq" / "depth" / "000000.png") as image:
        assert image.mode == "I;16"
    assert (tmp_path / "seq" / "camera.yaml").read_text().startswith("preset: kinect_v1\n")
    _assert_same(read_depth_sequence(tmp_path / "seq"), sequence)


def test_writer_refuses_bad_arrays_and_foreign_folders(tmp_path):
    sequence = _sequence()
    sequence.depth_mm = sequence.depth_mm.astype(np.float32)
    with pytest.raises(ValueError, match="depth_mm must be uint16"):
        write_depth_sequence(sequence, tmp_path / "a.npz")
    sequence = _sequence()
    sequence.joints = sequence.joints[:, :3]
    with pytest.raises(ValueError, match="joints has 3 joints but sensor_joints 4"):
        write_depth_sequence(sequence, tmp_path / "a.npz")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    with pytest.raises(FileExistsError, match="not a depth-sequence folder"):
        write_depth_sequence(_sequence(), tmp_path / "mine")
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep me"
    assert not (tmp_path / "a.npz").exists()


# ------------------------------------------------------------------------------------------ camera.yaml


def test_intrinsics_yaml_presets_and_custom(tmp_path):
    for name in ("kinect_v1", "azure_kinect"):
        path = write_intrinsics(CameraIntrinsics.preset(name), tmp_path / f"{name}.yaml")
        assert path.read_text() == f"preset: {name}\n"
        assert read_intrinsics(path) == CameraIntrinsics.preset(name) == camera_from_argument(name)
        assert camera_from_argument(str(path)) == CameraIntrinsics.preset(name)
    assert CameraIntrinsics.preset("kinect_v1").shape == (240, 320)
    assert CameraIntrinsics.preset("azure_kinect").shape == (576, 640)
    matrix = np.arange(16.0).reshape(4, 4)
    path = write_intrinsics(SMALL, tmp_path / "custom.yaml", fps=15, camera_to_world=matrix, joint_names=("a", "b"))
    camera, extras = read_camera_file(path)
    assert camera == SMALL
    assert extras["fps"] == 15.0 and extras["joint_names"] == ("a", "b")
    assert np.array_equal(extras["camera_to_world"], matrix)
    (tmp_path / "plain.yaml").write_text("width: 4\nheight: 3\nfx: 2\nfy: 2\ncx: 1.5\ncy: 1\n")
    assert read_intrinsics(tmp_path / "plain.yaml") == CameraIntrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)
    with pytest.raises(ValueError, match=r"custom\.yaml: unknown camera-file key 'focal'"):
        write_intrinsics(SMALL, tmp_path / "custom.yaml", focal=3)
    with pytest.raises(ValueError, match="neither a camera preset"):
        camera_from_argument("kinect_v3")


@pytest.mark.parametrize(
    "text, message",
    [
        ("preset: kinect_v1\nfocal: 3\n", "unknown key 'focal'"),
        ("preset: kinect_v3\n", "unknown camera preset 'kinect_v3' in key 'preset'"),
        ("width: 4\nheight: 3\nfx: 2\nfy: 2\ncx: 1\n", "missing key.* cy"),
        ("width: 4.5\nheight: 3\nfx: 2\nfy: 2\ncx: 1\ncy: 1\n", "key 'width' must be a positive whole number"),
        ("width: 4\nheight: 3\nfx: -2\nfy: 2\ncx: 1\ncy: 1\n", "key 'fx' must be a positive number"),
        ("width: 4\nheight: 3\nfx: 2\nfy: 2\ncx: one\ncy: 1\n", "key 'cx' must be a number"),
        ("preset: kinect_v1\nwidth: 4\n", "either 'preset' or the numbers"),
        ("preset: kinect_v1\nfps: fast\n", "key 'fps' must be a positive number"),
        ("preset: kinect_v1\ncamera_to_world: [[1, 0], [0, 1]]\n", "key 'camera_to_world' must be a 4×4 list"),
        ("preset: kinect_v1\njoint_names: head\n", "key 'joint_names' must be a list of names"),
        ("- kinect_v1\n", "must be a mapping"),
        ("preset: [kinect_v1\n", r"line \d+: not valid YAML"),
    ],
)
def test_camera_yaml_errors_name_the_file_and_key(tmp_path, text, message):
    path = tmp_path / "camera.yaml"
    path.write_text(text)
    with pytest.raises(DepthFormatError, match=message) as info:
        read_intrinsics(path)
    assert str(info.value).startswith(str(path))


# ----------------------------------------------------------------------------------- bare PNG folders


def _png(path, array):
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)
    return path


@pytest.mark.parametrize("subfolder", ["", "depth"])
def test_a_folder_of_bare_16_bit_pngs_reads_with_a_camera(tmp_path, subfolder):
    folder = tmp_path / "recording"
    frames = {name: np.full((240, 320), 1000 + 10 * k, np.uint16) for k, name in enumerate(["2", "10", "1"])}
    for name, image in frames.items():
        _png(folder / subfolder / f"frame_{name}.png", image)
    (folder / subfolder / "notes.txt").write_text("not a frame")
    with pytest.raises(DepthFormatError, match="no camera intrinsics for .*recording.* --camera kinect_v1"):
        read_depth_sequence(folder)
    sequence = read_depth_sequence(folder, intrinsics="kinect_v1")
    assert sequence.intrinsics == CameraIntrinsics.preset("kinect_v1") and sequence.fps == 30.0
    # natural order of the names: 1, 2, 10
    assert sequence.depth_mm[:, 0, 0].tolist() == [1020, 1000, 1010]
    assert sequence.colour is None and sequence.joints is None
    write_intrinsics(CameraIntrinsics.preset("kinect_v1"), folder / "camera.yaml", fps=15)
    assert read_depth_sequence(folder).fps == 15.0
    assert read_depth_sequence(folder, fps=10).fps == 10.0
    # the argument overrides camera.yaml: an Azure Kinect camera does not fit 320×240 images
    with pytest.raises(DepthFormatError, match=r"frame_1\.png, frame 0: depth images are 320×240 but the camera"):
        read_depth_sequence(folder, intrinsics="azure_kinect")


def test_png_folder_errors_name_the_file_and_frame(tmp_path):
    folder = tmp_path / "rec"
    (folder / "depth").mkdir(parents=True)
    with pytest.raises(DepthFormatError, match=r"rec: no depth images"):
        read_depth_sequence(folder, intrinsics=SMALL)
    good = np.full((24, 32), 1500, np.uint16)
    _png(folder / "depth" / "000000.png", good)
    _png(folder / "depth" / "000001.png", good[:20])
    with pytest.raises(DepthFormatError, match=r"000001\.png, frame 1: image is 32×20 but frame 0 \(000000\.png\)"):
        read_depth_sequence(folder, intrinsics=SMALL)
    _png(folder / "depth" / "000001.png", good.astype(np.uint8))
    with pytest.raises(DepthFormatError, match=r"000001\.png, frame 1: not a 16-bit single-channel PNG.*'L'"):
        read_depth_sequence(folder, intrinsics=SMALL)
    _png(folder / "depth" / "000001.png", np.zeros((24, 32, 3), np.uint8))
    with pytest.raises(DepthFormatError, match=r"frame 1: not a 16-bit single-channel PNG.*'RGB'"):
        read_depth_sequence(folder, intrinsics=SMALL)
    data = (folder / "depth" / "000000.png").read_bytes()
    (folder / "depth" / "000001.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(DepthFormatError, match=r"000001\.png, frame 1: unreadable image"):
        read_depth_sequence(folder, intrinsics=SMALL)
    Image.fromarray(np.zeros((24, 32), np.uint8)).save(folder / "depth" / "000001.png", format="JPEG")
    with pytest.raises(DepthFormatError, match=r"000001\.png, frame 1: a JPEG image, not a PNG"):
        read_depth_sequence(folder, intrinsics=SMALL)
    (folder / "depth" / "000001.png").unlink()
    assert read_depth_sequence(folder, intrinsics=SMALL).num_frames == 1
    _png(folder / "colour" / "000007.png", np.zeros((24, 32, 3), np.uint8))
    with pytest.raises(DepthFormatError, match=r"colour: colour images must match depth/.*000000\.png is missing"):
        read_depth_sequence(folder, intrinsics=SMALL)


def test_damaged_sequence_folder_files(tmp_path):
    path = write_depth_sequence(_sequence(), tmp_path / "seq")
    np.savez(path / "joints.npz", joints=np.zeros((2, 4, 3), np.float32))
    with pytest.raises(DepthFormatError, match=r"joints\.npz: joints has \[2, 4, 3\]: not one row per depth frame"):
        read_depth_sequence(path)
    np.savez(path / "joints.npz", bones=np.zeros((3, 4, 3), np.float32))
    with pytest.raises(DepthFormatError, match=r"joints\.npz: unknown entry 'bones'"):
        read_depth_sequence(path)
    (path / "joints.npz").unlink()
    text = (path / "camera.yaml").read_text()
    (path / "camera.yaml").write_text(text.replace("fps:", "rate:"))
    with pytest.raises(DepthFormatError, match=r"camera\.yaml: unknown key 'rate'"):
        read_depth_sequence(path)


# ------------------------------------------------------------------------------------------------- npz


def _npz(path, **arrays):
    header = {"format": "mocapkit-depth-sequence 1", "preset": "kinect_v1", "fps": 30.0}
    arrays.setdefault("header", np.array(json.dumps(header)))
    arrays.setdefault("depth_mm", np.zeros((2, 240, 320), np.uint16))
    arrays = {k: v for k, v in arrays.items() if v is not None}
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize(
    "arrays, message",
    [
        ({"depth_mm": None}, "missing entry 'depth_mm'"),
        ({"header": None}, "missing entry 'header'"),
        ({"depth_mm": np.zeros((2, 240, 320), np.float32)}, "depth_mm must be uint16"),
        (
            {"depth_mm": np.zeros((2, 24, 32), np.uint16)},
            "depth images are 32×24 but the camera intrinsics are 320×240",
        ),
        ({"depth_mm": np.zeros((0, 240, 320), np.uint16)}, "no frames"),
        ({"colour": np.zeros((2, 240, 320), np.uint8)}, r"colour must be uint8 \[frames, height, width, 3\]"),
        ({"joints": np.zeros((3, 20, 3), np.float32)}, r"joints must be float \[2, joints, 3\]"),
        ({"sensor_joints": np.zeros((2, 20, 3)), "sensor_state": np.full((2, 20), 7)}, "sensor_state must hold 0"),
        ({"parts": np.ones((2, 240, 320), np.uint8)}, "parts has label 1 but only 0 part_names"),
        ({"extra": np.zeros(3)}, "unknown entry 'extra'"),
        ({"header": np.array(json.dumps({"preset": "kinect_v1"}))}, "no format 'mocapkit-depth-sequence 1'"),
        ({"header": np.array("{not json")}, "entry 'header' is not JSON"),
        ({"header": np.array(json.dumps({"format": "mocapkit-depth-sequence 1", "preset": "x"}))}, "preset 'x'"),
    ],
)
def test_npz_errors_name_the_file_and_entry(tmp_path, arrays, message):
    path = _npz(tmp_path / "bad.npz", **arrays)
    with pytest.raises(DepthFormatError, match=message) as info:
        read_depth_sequence(path)
    assert str(info.value).startswith(str(path))


def test_npz_that_is_not_an_archive_or_holds_pickles(tmp_path):
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(DepthFormatError, match=r"text\.npz: not a readable npz archive"):
        read_depth_sequence(tmp_path / "text.npz")
    np.save(tmp_path / "single.npy", np.zeros(3))
    (tmp_path / "single.npy").rename(tmp_path / "single.npz")
    with pytest.raises(DepthFormatError, match=r"single\.npz: a single \.npy array"):
        read_depth_sequence(tmp_path / "single.npz")
    path = _npz(tmp_path / "pickle.npz", colour=np.array([{"a": 1}], dtype=object))
    with pytest.raises(DepthFormatError, match=r"pickle\.npz: damaged npz archive.*allow_pickle=False"):
        read_depth_sequence(path)
    data = (tmp_path / "pickle.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(DepthFormatError, match=r"cut\.npz: "):
        read_depth_sequence(tmp_path / "cut.npz")
    assert zipfile.is_zipfile(tmp_path / "pickle.npz")
    with pytest.raises(DepthFormatError, match=r"notes\.txt: not a depth sequence"):
        (tmp_path / "notes.txt").write_text("x")
        read_depth_sequence(tmp_path / "notes.txt")
    with pytest.raises(FileNotFoundError, match="missing.npz: no such file"):
        read_depth_sequence(tmp_path / "missing.npz")
