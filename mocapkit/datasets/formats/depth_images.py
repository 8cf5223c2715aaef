"""Depth-camera image sequences: camera intrinsics (with the Kinect v1 and Azure Kinect presets),
:class:`DepthSequence`, the container ``mocapkit synth depth`` writes and ``mocapkit depth-track`` reads, and its two
files on disk.

Conventions (the depth-sensor SDKs' own): depth is **uint16 millimetres** along the optical axis, 0 where the sensor
has no measurement (background, holes); image pixel ``(u, v)`` has u to the right and v down; camera coordinates
are metres with x right, y down, z forward (the optical axis), so a pixel un-projects to
``((u − cx) z / fx, (v − cy) z / fy, z)``.

On disk (:func:`write_depth_sequence`, :func:`read_depth_sequence`):

- ``NAME.npz``: one compressed NumPy archive with every array of the sequence under its field name
  (``depth_mm``, ``colour``, ``parts``, ``joints``, ``sensor_joints``, ``sensor_state``, ``camera_to_world``; absent
  ones left out) and ``header``, a JSON string with the format tag, the intrinsics, ``fps``, the names, ``source``
  and ``metadata``. Read with ``allow_pickle=False``: loading it runs no code.
- ``NAME/``, a folder: ``depth/000000.png ...`` 16-bit single-channel PNGs (millimetres, 0 = none),
  ``colour/000000.png`` RGB and ``parts/000000.png`` 8-bit labels when present, ``camera.yaml``
  (:func:`write_intrinsics`: intrinsics, fps, camera_to_world, names, source, metadata) and ``joints.npz``
  (``joints``, ``sensor_joints``, ``sensor_state`` when present). A folder of nothing but 16-bit depth PNGs (what a
  real camera's recorder leaves; ``depth/*.png`` or ``*.png`` directly in the folder, in natural name order) reads
  too, given the camera (``camera.yaml`` beside them or the ``intrinsics`` argument).

``camera.yaml`` is either ``{preset: kinect_v1}`` / ``{preset: azure_kinect}`` or
``{width, height, fx, fy, cx, cy}`` (pixels; optional ``name``), with the optional keys of :data:`CAMERA_KEYS`.

Readers are strict and bounded, like every reader of :mod:`mocapkit.datasets.formats`: regular files only, at most
:data:`MAX_IMAGE_BYTES` per PNG and :data:`MAX_IMAGE_PIXELS` pixels per frame (PIL's decompression-bomb check
applies as well), at most :data:`MAX_ARRAY_BYTES` per uncompressed npz entry, and every error is a
:class:`DepthFormatError` (a ``ValueError``) naming the file and, for a frame, its 0-based index. Frames with no
depth at all are *not* reader errors (:func:`mocapkit.depth_tracking.base.check_sequence` refuses them where it
matters). Writes are atomic (:mod:`mocapkit.io_atomic`): a folder is written beside its destination and renamed
into place.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import shutil
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes, regular_file_size
from mocapkit.io_atomic import atomic_open, atomic_write_text, fsync_dir, temp_path_for


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole depth camera: image size (pixels), focal lengths and principal point (pixels).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in pixels (pixel centres are at integer coordinates).
        name: a preset's name, or ``"custom"``.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    name: str = "custom"

    @classmethod
    def from_field_of_view(
        cls, width: int, height: int, horizontal_deg: float, vertical_deg: float, name: str = "custom"
    ) -> CameraIntrinsics:
        """The camera whose image of ``width × height`` pixels spans the given full fields of view (degrees)."""
        fx = (width / 2) / math.tan(math.radians(horizontal_deg) / 2)
        fy = (height / 2) / math.tan(math.radians(vertical_deg) / 2)
        return cls(int(width), int(height), fx, fy, (width - 1) / 2, (height - 1) / 2, name)

    @classmethod
    def preset(cls, name: str) -> CameraIntrinsics:
        """A named camera of :data:`CAMERA_PRESETS`: ``"kinect_v1"`` (320×240, 57°×43°, the Kinect SDK's depth
        stream as Lou 2012 used it) or ``"azure_kinect"`` (640×576, 75°×65°, the Azure Kinect's narrow
        field-of-view unbinned depth mode)."""
        try:
            width, height, horizontal, vertical = CAMERA_PRESETS[name]
        except KeyError:
            raise ValueError(f"unknown camera preset {name!r}; known: {sorted(CAMERA_PRESETS)}") from None
        return cls.from_field_of_view(width, height, horizontal, vertical, name)

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``, the shape of one depth image."""
        return self.height, self.width

    @property
    def field_of_view_deg(self) -> tuple[float, float]:
        """Full horizontal and vertical field of view, degrees."""
        return (
            math.degrees(2 * math.atan((self.width / 2) / self.fx)),
            math.degrees(2 * math.atan((self.height / 2) / self.fy)),
        )

    def unproject(self, depth_m: np.ndarray) -> np.ndarray:
        """Depth image ``[H, W]`` in metres → camera points ``[H, W, 3]`` (metres; 0 depth gives the origin)."""
        depth_m = np.asarray(depth_m, dtype=np.float64)
        v, u = np.indices(depth_m.shape, dtype=np.float64)
        return np.stack([(u - self.cx) * depth_m / self.fx, (v - self.cy) * depth_m / self.fy, depth_m], axis=-1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera points ``[..., 3]`` (metres, z > 0) → pixel coordinates ``[..., 2]`` as ``(u, v)``."""
        points = np.asarray(points, dtype=np.float64)
        z = points[..., 2]
        return np.stack([self.fx * points[..., 0] / z + self.cx, self.fy * points[..., 1] / z + self.cy], axis=-1)


#: Named cameras: name → (width, height, horizontal FOV°, vertical FOV°).
CAMERA_PRESETS: dict[str, tuple[int, int, float, float]] = {
    "kinect_v1": (320, 240, 57.0, 43.0),
    "azure_kinect": (640, 576, 75.0, 65.0),
}


@dataclass
class DepthSequence:
    """A depth video with what is known beside it.

    Attributes:
        depth_mm: uint16 ``[T, H, W]`` depth in millimetres, 0 = no measurement.
        intrinsics: the camera.
        fps: frames per second.
        colour: uint8 ``[T, H, W, 3]`` RGB registered to the depth image, or None.
        parts: uint8 ``[T, H, W]`` body-part label per pixel (0 = background, k = part k of ``part_names``), or None.
        part_names: names of the body parts 1.. of ``parts``.
        joints: float32 ``[T, J, 3]`` ground-truth joints in camera coordinates (metres), or None.
        joint_names: names of the J joints of ``joints`` and ``sensor_joints``.
        sensor_joints: float32 ``[T, J, 3]`` the skeleton a vendor SDK reports (camera coordinates), or None.
        sensor_state: int8 ``[T, J]`` its tracking states (2 tracked, 1 inferred, 0 not tracked), or None.
        camera_to_world: float64 ``[4, 4]``: world point (metres, y up) = ``camera_to_world @ [x, y, z, 1]``, or None.
        source: where the sequence came from (a file name), for messages.
        metadata: plain JSON / YAML data about it (the synthesiser's noise preset, seed, girth factor, ...).
    """

    depth_mm: np.ndarray
    intrinsics: CameraIntrinsics
    fps: float
    colour: np.ndarray | None = None
    parts: np.ndarray | None = None
    part_names: tuple[str, ...] = ()
    joints: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()
    sensor_joints: np.ndarray | None = None
    sensor_state: np.ndarray | None = None
    camera_to_world: np.ndarray | None = None
    source: str = ""
    metadata: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.depth_mm.shape[0])

    def depth_m(self, frame: int) -> np.ndarray:
        """float32 ``[H, W]`` depth of one frame in metres (0 = no measurement)."""
        return self.depth_mm[frame].astype(np.float32) / 1000.0


# --------------------------------------------------------------------------------------------------- files


class DepthFormatError(MotionFormatError):
    """A malformed depth sequence or camera file; the message names the file and, for an image, its frame index."""


#: The ``format`` entry of an npz header; a reader refuses any other.
FORMAT_TAG = "mocapkit-depth-sequence 1"
#: Largest PNG file read (bytes) and image (pixels); a Kinect v1 frame is 320×240, an Azure Kinect one 640×576.
MAX_IMAGE_BYTES = 64 << 20
MAX_IMAGE_PIXELS = 4096 * 4096
#: Largest uncompressed array of an npz, or a whole depth/colour array (bytes; ``$MOCAPKIT_MAX_DEPTH_BYTES``).
#: Ten minutes of Azure Kinect depth at 30 fps are 13 GB, so longer recordings need the variable raised.
MAX_ARRAY_BYTES = int(os.environ.get("MOCAPKIT_MAX_DEPTH_BYTES", str(16 << 30)))
#: Largest ``camera.yaml`` read (bytes).
MAX_CAMERA_FILE_BYTES = 1 << 20
#: The six numbers of a custom camera.
INTRINSIC_KEYS: tuple[str, ...] = ("width", "height", "fx", "fy", "cx", "cy")
#: What ``camera.yaml`` (and :func:`write_intrinsics`'s ``extra``) may hold besides the camera itself.
OPTIONAL_CAMERA_KEYS: tuple[str, ...] = ("fps", "camera_to_world", "part_names", "joint_names", "source", "metadata")
#: Every key of ``camera.yaml``.
CAMERA_KEYS: tuple[str, ...] = ("preset", *INTRINSIC_KEYS, "name", *OPTIONAL_CAMERA_KEYS)
#: The array fields of :class:`DepthSequence`, as stored in the npz (and in ``joints.npz``, the last three).
ARRAY_FIELDS: tuple[str, ...] = (
    "depth_mm",
    "colour",
    "parts",
    "camera_to_world",
    "joints",
    "sensor_joints",
    "sensor_state",
)
_JOINT_FIELDS = ("joints", "sensor_joints", "sensor_state")
_FOLDER_ENTRIES = frozenset({"camera.yaml", "depth", "colour", "parts", "joints.npz"})


def _error(path, message: str, frame: int | None = None) -> DepthFormatError:
    return DepthFormatError(path, None, message, frame=frame)


def _plain(value):
    """``value`` with NumPy scalars and arrays, tuples and paths turned into plain JSON / YAML data."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _parse_camera(doc, path, allowed: tuple[str, ...] = CAMERA_KEYS) -> tuple[CameraIntrinsics, dict]:
    """The camera and the optional entries of a ``camera.yaml`` mapping (or an npz header), checked."""
    if not isinstance(doc, dict):
        raise _error(
            path, f"must be a mapping (preset: NAME, or {', '.join(INTRINSIC_KEYS)}), got {type(doc).__name__}"
        )
    unknown = [k for k in doc if k not in allowed]
    if unknown:
        raise _error(path, f"unknown key {unknown[0]!r}; the keys are {', '.join(allowed)}")
    given = [k for k in INTRINSIC_KEYS if k in doc]
    if "preset" in doc:
        if given:
            raise _error(path, f"give either 'preset' or the numbers {', '.join(INTRINSIC_KEYS)}, not both")
        preset = doc["preset"]
        if not isinstance(preset, str) or preset not in CAMERA_PRESETS:
            raise _error(path, f"unknown camera preset {preset!r} in key 'preset'; known: {', '.join(CAMERA_PRESETS)}")
        intrinsics = CameraIntrinsics.preset(preset)
    else:
        missing = [k for k in INTRINSIC_KEYS if k not in doc]
        if missing:
            raise _error(
                path, f"missing key(s) {', '.join(missing)}: give preset: NAME or all of {', '.join(INTRINSIC_KEYS)}"
            )
        for key in ("width", "height"):
            if not isinstance(doc[key], int) or isinstance(doc[key], bool) or doc[key] < 1:
                raise _error(path, f"key {key!r} must be a positive whole number of pixels, got {doc[key]!r}")
        if doc["width"] * doc["height"] > MAX_IMAGE_PIXELS:
            raise _error(path, f"{doc['width']}×{doc['height']} pixels is more than the {MAX_IMAGE_PIXELS} allowed")
        for key in ("fx", "fy", "cx", "cy"):
            if not _is_number(doc[key]) or (key in ("fx", "fy") and doc[key] <= 0):
                kind = "a positive number" if key in ("fx", "fy") else "a number"
                raise _error(path, f"key {key!r} must be {kind} (pixels), got {doc[key]!r}")
        name = doc.get("name", "custom")
        if not isinstance(name, str):
            raise _error(path, f"key 'name' must be text, got {name!r}")
        intrinsics = CameraIntrinsics(
            doc["width"], doc["height"], float(doc["fx"]), float(doc["fy"]), float(doc["cx"]), float(doc["cy"]), name
        )
    extras: dict = {}
    if "fps" in doc:
        if not _is_number(doc["fps"]) or doc["fps"] <= 0:
            raise _error(path, f"key 'fps' must be a positive number, got {doc['fps']!r}")
        extras["fps"] = float(doc["fps"])
    if "camera_to_world" in doc:
        matrix = doc["camera_to_world"]
        ok = isinstance(matrix, list) and len(matrix) == 4
        ok = ok and all(isinstance(row, list) and len(row) == 4 and all(map(_is_number, row)) for row in matrix)
        if not ok:
            raise _error(path, "key 'camera_to_world' must be a 4×4 list of numbers (rows)")
        extras["camera_to_world"] = np.array(matrix, dtype=np.float64)
    for key in ("part_names", "joint_names"):
        if key in doc:
            names = doc[key]
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise _error(path, f"key {key!r} must be a list of names, got {names!r}")
            extras[key] = tuple(names)
    if "source" in doc:
        if not isinstance(doc["source"], str):
            raise _error(path, f"key 'source' must be text, got {doc['source']!r}")
        extras["source"] = doc["source"]
    if "metadata" in doc:
        if not isinstance(doc["metadata"], dict):
            raise _error(path, f"key 'metadata' must be a mapping, got {type(doc['metadata']).__name__}")
        extras["metadata"] = doc["metadata"]
    return intrinsics, extras


def read_camera_file(path: str | os.PathLike) -> tuple[CameraIntrinsics, dict]:
    """A ``camera.yaml``: the camera and its optional entries (``fps`` float, ``camera_to_world`` float64 ``[4, 4]``,
    ``part_names`` / ``joint_names`` tuples, ``source``, ``metadata``), checked.

    Raises:
        DepthFormatError: unreadable or not YAML (with the line), an unknown key, a missing key, a value of the wrong
            type; the message names the file and the key.
    """
    import yaml

    path = Path(path)
    data = read_file_bytes(path, lambda p, m: _error(p, m), max_bytes=MAX_CAMERA_FILE_BYTES)
    try:
        doc = yaml.safe_load(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise _error(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        raise DepthFormatError(path, line, f"not valid YAML: {getattr(exc, 'problem', None) or exc}") from None
    return _parse_camera(doc, path)


def read_intrinsics(path: str | os.PathLike) -> CameraIntrinsics:
    """The camera of a ``camera.yaml`` (``{preset: NAME}`` or ``{width, height, fx, fy, cx, cy}``); see
    :func:`read_camera_file` for the optional keys and the errors."""
    return read_camera_file(path)[0]


def _camera_doc(intrinsics: CameraIntrinsics) -> dict:
    """``{preset: NAME}`` for an unchanged preset, else the six numbers (and the name)."""
    if intrinsics.name in CAMERA_PRESETS and intrinsics == CameraIntrinsics.preset(intrinsics.name):
        return {"preset": intrinsics.name}
    doc = {
        "width": int(intrinsics.width),
        "height": int(intrinsics.height),
        "fx": float(intrinsics.fx),
        "fy": float(intrinsics.fy),
        "cx": float(intrinsics.cx),
        "cy": float(intrinsics.cy),
    }
    if intrinsics.name != "custom":
        doc["name"] = intrinsics.name
    return doc


def _optional_doc(path, extra: dict) -> dict:
    unknown = [k for k in extra if k not in OPTIONAL_CAMERA_KEYS]
    if unknown:
        raise ValueError(
            f"{path}: unknown camera-file key {unknown[0]!r}; the optional keys are {OPTIONAL_CAMERA_KEYS}"
        )
    doc = {}
    for key in OPTIONAL_CAMERA_KEYS:
        value = extra.get(key)
        if value is None or (key in ("part_names", "joint_names", "source") and len(value) == 0):
            continue
        doc[key] = float(value) if key == "fps" else _plain(value)
    return doc


def write_intrinsics(intrinsics: CameraIntrinsics, path: str | os.PathLike, **extra) -> Path:
    """Write ``camera.yaml`` atomically: ``{preset: NAME}`` for an unchanged preset, else the six numbers; ``extra``:
    any of :data:`OPTIONAL_CAMERA_KEYS` (None or empty values are left out). Returns ``path``.

    Raises:
        ValueError: an unknown key in ``extra``, naming it and the file.
    """
    import yaml

    doc = {**_camera_doc(intrinsics), **_optional_doc(path, extra)}
    _parse_camera(json.loads(json.dumps(doc)), path)  # refuse to write what the reader would refuse
    return atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))


def camera_from_argument(text: str | os.PathLike | CameraIntrinsics) -> CameraIntrinsics:
    """The camera a command-line ``--camera`` names: a preset (``kinect_v1``, ``azure_kinect``) or a YAML file."""
    if isinstance(text, CameraIntrinsics):
        return text
    text = os.fspath(text)
    if text in CAMERA_PRESETS:
        return CameraIntrinsics.preset(text)
    if text.lower().endswith((".yaml", ".yml")) or os.path.exists(text):
        return read_intrinsics(text)
    raise ValueError(f"--camera {text!r}: neither a camera preset ({', '.join(CAMERA_PRESETS)}) nor a .yaml file")


# ------------------------------------------------------------------------------------------- validation


def _check_sequence_arrays(sequence: DepthSequence, label) -> None:
    """Every array of ``sequence`` of the documented dtype and shape, consistent with the others; ValueError
    (DepthFormatError) naming ``label`` otherwise."""
    depth = sequence.depth_mm
    if not isinstance(depth, np.ndarray) or depth.dtype != np.uint16 or depth.ndim != 3:
        got = f"{getattr(depth, 'dtype', type(depth).__name__)} {list(np.shape(depth))}"
        raise _error(label, f"depth_mm must be uint16 [frames, height, width] millimetres, got {got}")
    T = depth.shape[0]
    if T == 0:
        raise _error(label, "no frames")
    if depth.shape[1:] != sequence.intrinsics.shape:
        raise _error(
            label,
            f"depth images are {depth.shape[2]}×{depth.shape[1]} but the camera intrinsics are "
            f"{sequence.intrinsics.width}×{sequence.intrinsics.height}",
        )
    if not (_is_number(sequence.fps) and sequence.fps > 0):
        raise _error(label, f"fps must be a positive number, got {sequence.fps!r}")
    H, W = depth.shape[1:]
    expected = {
        "colour": (np.uint8, (T, H, W, 3), "uint8 [frames, height, width, 3] RGB"),
        "parts": (np.uint8, (T, H, W), "uint8 [frames, height, width] labels"),
    }
    for name, (dtype, shape, what) in expected.items():
        value = getattr(sequence, name)
        if value is not None and (not isinstance(value, np.ndarray) or value.dtype != dtype or value.shape != shape):
            got = f"{getattr(value, 'dtype', type(value).__name__)} {list(np.shape(value))}"
            raise _error(label, f"{name} must be {what} like the depth ({list(shape)}), got {got}")
    if sequence.parts is not None:
        top = int(sequence.parts.max(initial=0))
        if top > len(sequence.part_names):
            raise _error(label, f"parts has label {top} but only {len(sequence.part_names)} part_names")
    joint_count = None
    for name in ("joints", "sensor_joints"):
        value = getattr(sequence, name)
        if value is None:
            continue
        if (
            not isinstance(value, np.ndarray)
            or value.dtype.kind != "f"
            or value.ndim != 3
            or value.shape[::2] != (T, 3)
        ):
            got = f"{getattr(value, 'dtype', type(value).__name__)} {list(np.shape(value))}"
            raise _error(label, f"{name} must be float [{T}, joints, 3] metres, got {got}")
        if joint_count is not None and value.shape[1] != joint_count:
            raise _error(label, f"joints has {joint_count} joints but sensor_joints {value.shape[1]}")
        joint_count = value.shape[1]
    if joint_count is not None and sequence.joint_names and len(sequence.joint_names) != joint_count:
        raise _error(label, f"{len(sequence.joint_names)} joint_names for {joint_count} joints")
    state = sequence.sensor_state
    if state is not None:
        if sequence.sensor_joints is None:
            raise _error(label, "sensor_state without sensor_joints")
        if (
            not isinstance(state, np.ndarray)
            or state.dtype.kind not in "iu"
            or state.shape != sequence.sensor_joints.shape[:2]
        ):
            got = f"{getattr(state, 'dtype', type(state).__name__)} {list(np.shape(state))}"
            raise _error(label, f"sensor_state must be integer {list(sequence.sensor_joints.shape[:2])}, got {got}")
        if state.size and (state.min() < 0 or state.max() > 2):
            raise _error(label, "sensor_state must hold 0 (not tracked), 1 (inferred) or 2 (tracked)")
    matrix = sequence.camera_to_world
    if matrix is not None and (
        not isinstance(matrix, np.ndarray)
        or matrix.shape != (4, 4)
        or matrix.dtype.kind != "f"
        or not np.isfinite(matrix).all()
    ):
        raise _error(label, f"camera_to_world must be a finite float [4, 4] matrix, got {list(np.shape(matrix))}")


def _normalised(sequence: DepthSequence) -> DepthSequence:
    """The documented dtypes (float32 joints, int8 states, float64 matrix) after :func:`_check_sequence_arrays`."""
    for name, dtype in (("joints", np.float32), ("sensor_joints", np.float32), ("sensor_state", np.int8)):
        value = getattr(sequence, name)
        if value is not None and value.dtype != dtype:
            setattr(sequence, name, value.astype(dtype))
    if sequence.camera_to_world is not None:
        sequence.camera_to_world = sequence.camera_to_world.astype(np.float64)
    return sequence


# ---------------------------------------------------------------------------------------------- writing


def _header(sequence: DepthSequence) -> dict:
    return {
        **_camera_doc(sequence.intrinsics),
        **_optional_doc(
            "header",
            {
                "fps": sequence.fps,
                "part_names": sequence.part_names,
                "joint_names": sequence.joint_names,
                "source": sequence.source,
                "metadata": sequence.metadata or None,
            },
        ),
    }


def write_depth_sequence(sequence: DepthSequence, path: str | os.PathLike) -> Path:
    """Write ``sequence`` atomically: ``path`` ending in ``.npz`` → one compressed archive, anything else → a folder
    (module docstring). An existing folder is replaced only when it is a depth-sequence folder itself.

    Raises:
        ValueError: arrays of the wrong dtype or shape (naming the field); FileExistsError: ``path`` is a file
            where a folder is to go, or a folder that is not a depth-sequence folder.
    """
    path = Path(path)
    _check_sequence_arrays(sequence, path)
    if path.suffix.lower() == ".npz":
        arrays = {"header": np.array(json.dumps({"format": FORMAT_TAG, **_header(sequence)}))}
        for name in ARRAY_FIELDS:
            value = getattr(sequence, name)
            if value is not None:
                arrays[name] = np.ascontiguousarray(value)
        with atomic_open(path, "wb") as f:
            np.savez_compressed(f, **arrays)
        return path
    _write_folder(sequence, path)
    return path


def _write_file(path: Path, data: bytes) -> None:
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _png_bytes(image: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def _write_folder(sequence: DepthSequence, dest: Path) -> None:
    if dest.exists() and not dest.is_dir():
        raise FileExistsError(f"{dest}: is a file; a depth-sequence folder (or a .npz name) was expected")
    if dest.is_dir() and any(dest.iterdir()) and not _is_sequence_folder(dest):
        raise FileExistsError(
            f"{dest}: exists and is not a depth-sequence folder (camera.yaml and depth/ only); not replacing it"
        )
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"{dest.parent}: no such folder (to write {dest.name})")
    # the whole folder is built beside the destination and renamed into place: a reader never sees half of it
    tmp = temp_path_for(dest)
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        for name, images in (("depth", sequence.depth_mm), ("colour", sequence.colour), ("parts", sequence.parts)):
            if images is None:
                continue
            (tmp / name).mkdir()
            for t, image in enumerate(images):
                _write_file(tmp / name / f"{t:06d}.png", _png_bytes(image))
            fsync_dir(tmp / name)
        joints = {k: getattr(sequence, k) for k in _JOINT_FIELDS if getattr(sequence, k) is not None}
        if joints:
            buffer = io.BytesIO()
            np.savez_compressed(buffer, **joints)
            _write_file(tmp / "joints.npz", buffer.getvalue())
        header = _header(sequence)
        if sequence.camera_to_world is not None:
            header["camera_to_world"] = _plain(sequence.camera_to_world)
        import yaml

        _write_file(tmp / "camera.yaml", yaml.safe_dump(header, sort_keys=False, allow_unicode=True).encode())
        fsync_dir(tmp)
        old = dest.with_name(f"{dest.name}.old-{os.getpid()}")
        shutil.rmtree(old, ignore_errors=True)
        if dest.exists():
            os.replace(dest, old)
        os.replace(tmp, dest)
        fsync_dir(dest.parent)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _is_sequence_folder(folder: Path) -> bool:
    names = {p.name for p in folder.iterdir()}
    return "camera.yaml" in names and "depth" in names and names <= _FOLDER_ENTRIES


# ---------------------------------------------------------------------------------------------- reading


def read_depth_sequence(
    path: str | os.PathLike, intrinsics: CameraIntrinsics | str | None = None, fps: float | None = None
) -> DepthSequence:
    """Read a depth sequence: a ``.npz`` or a folder (module docstring).

    Args:
        path: the ``.npz`` file or the folder.
        intrinsics: the camera (or a preset name / YAML path, as ``--camera``); it overrides the file's own and is
            needed for a folder of bare PNGs without ``camera.yaml``.
        fps: frame rate; it overrides the file's own (a folder without one: 30 fps, the Kinect rate).

    Returns:
        the :class:`DepthSequence`; its ``source`` is ``path`` (the source stored in the file, e.g. the mocap file
        it was rendered from, is ``metadata["source"]``).

    Raises:
        DepthFormatError: a damaged, inconsistent or unreadable file, naming it (and the frame for an image).
        FileNotFoundError: no such file or folder.
    """
    path = Path(path)
    if intrinsics is not None:
        intrinsics = camera_from_argument(intrinsics)
    if fps is not None and not (_is_number(fps) and fps > 0):
        raise ValueError(f"{path}: fps must be a positive number, got {fps!r}")
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    if path.is_dir():
        sequence = _read_folder(path, intrinsics)
    elif path.suffix.lower() == ".npz":
        sequence = _read_npz(path, intrinsics)
    else:
        raise _error(path, "not a depth sequence: expected a .npz file or a folder of depth PNGs")
    if fps is not None:
        sequence.fps = float(fps)
    _check_sequence_arrays(sequence, path)
    return _normalised(sequence)


def _load_npz(path: Path, allowed: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Every entry of an npz (only ``allowed`` names, none pickled, none above :data:`MAX_ARRAY_BYTES`)."""
    regular_file_size(path, lambda p, m: _error(p, m), max_bytes=MAX_ARRAY_BYTES)
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # BadZipFile: a cut or damaged archive
        raise _error(path, f"not a readable npz archive ({type(exc).__name__}: {exc})") from None
    if not hasattr(archive, "files"):
        raise _error(path, "a single .npy array, not an npz archive")
    try:
        with archive:
            unknown = [name for name in archive.files if name not in allowed]
            if unknown:
                raise _error(path, f"unknown entry {unknown[0]!r}; the entries are {', '.join(allowed)}")
            for name in archive.files:
                size = archive.zip.getinfo(f"{name}.npy").file_size
                if size > MAX_ARRAY_BYTES:
                    raise _error(
                        path,
                        f"entry {name!r} is {size} bytes uncompressed, more than {MAX_ARRAY_BYTES} "
                        "(MOCAPKIT_MAX_DEPTH_BYTES)",
                    )
            return {name: archive[name] for name in archive.files}
    except DepthFormatError:
        raise
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, MemoryError) as exc:
        raise _error(path, f"damaged npz archive ({type(exc).__name__}: {exc})") from None


def _read_npz(path: Path, intrinsics: CameraIntrinsics | None) -> DepthSequence:
    data = _load_npz(path, ("header", *ARRAY_FIELDS))
    for name in ("header", "depth_mm"):
        if name not in data:
            raise _error(path, f"missing entry {name!r}: not a depth sequence written by mocapkit")
    header = data.pop("header")
    if header.dtype.kind != "U" or header.ndim != 0:
        raise _error(path, f"entry 'header' must be a JSON string, got {header.dtype} {list(header.shape)}")
    try:
        doc = json.loads(str(header[()]))
    except json.JSONDecodeError as exc:
        raise _error(path, f"entry 'header' is not JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.pop("format", None) != FORMAT_TAG:
        raise _error(path, f"entry 'header' has no format {FORMAT_TAG!r}: not a depth sequence written by mocapkit")
    file_intrinsics, extras = _parse_camera(doc, f"{path} (header)")
    return _sequence(path, intrinsics or file_intrinsics, extras, data)


def _sequence(path: Path, intrinsics: CameraIntrinsics, extras: dict, arrays: dict) -> DepthSequence:
    metadata = dict(extras.get("metadata", {}))
    if extras.get("source"):
        metadata.setdefault("source", extras["source"])
    return DepthSequence(
        depth_mm=arrays["depth_mm"],
        intrinsics=intrinsics,
        fps=extras.get("fps", 30.0),
        colour=arrays.get("colour"),
        parts=arrays.get("parts"),
        part_names=extras.get("part_names", ()),
        joints=arrays.get("joints"),
        joint_names=extras.get("joint_names", ()),
        sensor_joints=arrays.get("sensor_joints"),
        sensor_state=arrays.get("sensor_state"),
        camera_to_world=arrays.get("camera_to_world", extras.get("camera_to_world")),
        source=str(path),
        metadata=metadata,
    )


def _natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name)]


def _png_files(folder: Path) -> list[Path]:
    return sorted(
        (p for p in folder.iterdir() if p.suffix.lower() == ".png" and not p.name.startswith(".") and p.is_file()),
        key=_natural_key,
    )


#: PIL modes of each kind of image: 16-bit grey depth, RGB colour, 8-bit grey part labels.
_MODES = {"depth": ("I;16", "I;16L", "I;16B", "I"), "colour": ("RGB",), "parts": ("L",)}
_KIND_TEXT = {
    "depth": "a 16-bit single-channel PNG (millimetres)",
    "colour": "an 8-bit RGB PNG",
    "parts": "an 8-bit single-channel PNG (labels)",
}


def _read_png(path: Path, frame: int, kind: str) -> np.ndarray:
    """One PNG of ``kind`` (``depth``, ``colour``, ``parts``) as uint16 / uint8 pixels, checked."""
    from PIL import Image, UnidentifiedImageError

    data = read_file_bytes(path, lambda p, m: _error(p, m, frame), max_bytes=MAX_IMAGE_BYTES)
    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format != "PNG":
                raise _error(path, f"a {image.format} image, not a PNG", frame)
            if image.width * image.height > MAX_IMAGE_PIXELS:
                raise _error(
                    path, f"{image.width}×{image.height} pixels, more than the {MAX_IMAGE_PIXELS} allowed", frame
                )
            if image.mode not in _MODES[kind]:
                raise _error(path, f"not {_KIND_TEXT[kind]}: PIL mode {image.mode!r}", frame)
            image.load()
            pixels = np.asarray(image)
    except DepthFormatError:
        raise
    except (
        OSError,
        SyntaxError,
        ValueError,
        EOFError,
        UnidentifiedImageError,
        Image.DecompressionBombError,
        MemoryError,
    ) as exc:  # MemoryError: a damaged chunk length asking PIL for gigabytes
        raise _error(path, f"unreadable image ({type(exc).__name__}: {exc})", frame) from None
    if kind == "depth":
        if pixels.dtype.kind not in "iu" or (pixels.size and (pixels.min() < 0 or pixels.max() > 65535)):
            raise _error(path, f"not {_KIND_TEXT[kind]}: values outside 0..65535", frame)
        return pixels.astype(np.uint16)
    return pixels.astype(np.uint8)


def _read_images(files: list[Path], kind: str, shape: tuple[int, int] | None) -> np.ndarray:
    """Frames ``files`` as one array; every frame the size of ``shape`` (default: the first frame's)."""
    first = _read_png(files[0], 0, kind)
    reference = (files[0], first.shape[:2])
    if shape is not None and first.shape[:2] != shape:
        raise _error(
            files[0], f"image is {first.shape[1]}×{first.shape[0]} but the depth images are {shape[1]}×{shape[0]}", 0
        )
    total = len(files) * first.nbytes
    if total > MAX_ARRAY_BYTES:
        raise _error(
            files[0].parent,
            f"{len(files)} frames need {total} bytes, more than {MAX_ARRAY_BYTES} (MOCAPKIT_MAX_DEPTH_BYTES)",
        )
    out = np.empty((len(files), *first.shape), dtype=first.dtype)
    out[0] = first
    for t, path in enumerate(files[1:], start=1):
        image = _read_png(path, t, kind)
        if image.shape != first.shape:
            raise _error(
                path,
                f"image is {image.shape[1]}×{image.shape[0]} but frame 0 ({reference[0].name}) is "
                f"{first.shape[1]}×{first.shape[0]}",
                t,
            )
        out[t] = image
    return out


def _read_folder(folder: Path, intrinsics: CameraIntrinsics | None) -> DepthSequence:
    camera_file = folder / "camera.yaml"
    file_intrinsics, extras = read_camera_file(camera_file) if camera_file.exists() else (None, {})
    depth_dir = folder / "depth" if (folder / "depth").is_dir() else folder
    files = _png_files(depth_dir)
    if not files:
        raise _error(folder, "no depth images: expected depth/000000.png, ... or *.png in the folder")
    intrinsics = intrinsics or file_intrinsics
    if intrinsics is None:
        raise _error(
            folder,
            f"no camera intrinsics for {folder}: add camera.yaml or pass --camera kinect_v1|azure_kinect|FILE.yaml "
            "(intrinsics= in Python)",
        )
    depth = _read_images(files, "depth", None)
    if depth.shape[1:] != intrinsics.shape:
        raise _error(
            files[0],
            f"depth images are {depth.shape[2]}×{depth.shape[1]} but the camera intrinsics "
            f"({'camera.yaml' if intrinsics is file_intrinsics else 'given'}) are {intrinsics.width}×{intrinsics.height}",
            0,
        )
    arrays = {"depth_mm": depth}
    if depth_dir != folder:
        for kind in ("colour", "parts"):
            sub = folder / kind
            if not sub.is_dir():
                continue
            names = {p.name for p in _png_files(sub)}
            wanted = [sub / p.name for p in files]
            missing = [p for p in wanted if p.name not in names]
            if missing or len(names) != len(files):
                what = (
                    f"{missing[0].name} is missing" if missing else f"{len(names)} images for {len(files)} depth frames"
                )
                raise _error(sub, f"{kind} images must match depth/ one for one: {what}")
            arrays[kind] = _read_images(wanted, kind, depth.shape[1:])
        joints_file = folder / "joints.npz"
        if joints_file.exists():
            joints = _load_npz(joints_file, _JOINT_FIELDS)
            for name, value in joints.items():
                if value.ndim < 2 or value.shape[0] != len(files):
                    raise _error(
                        joints_file, f"{name} has {list(value.shape)}: not one row per depth frame ({len(files)})"
                    )
            arrays.update(joints)
    return _sequence(folder, intrinsics, extras, arrays)


__all__ = [
    "ARRAY_FIELDS",
    "CAMERA_KEYS",
    "CAMERA_PRESETS",
    "FORMAT_TAG",
    "MAX_ARRAY_BYTES",
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_PIXELS",
    "OPTIONAL_CAMERA_KEYS",
    "CameraIntrinsics",
    "DepthFormatError",
    "DepthSequence",
    "camera_from_argument",
    "read_camera_file",
    "read_depth_sequence",
    "read_intrinsics",
    "write_depth_sequence",
    "write_intrinsics",
]
