"""C3D marker files: read in pure Python and NumPy, written with the maintained ``ezc3d`` library.

:func:`read_c3d` returns a :class:`~mocapkit.motion.container.Motion` of marker
trajectories (``parents=None``, unless the labels are the joints of a known layout, see below):

- positions in **metres**, converted from ``POINT:UNITS`` (``mm``, ``cm``, ``dm``, ``m``;
  ``mm``, the C3D default, when the parameter is absent);
- ``joint_names`` are the marker labels, only the first ``POINT:USED`` of them
  (``POINT:LABELS`` is often padded with empty or stale names beyond it; ``LABELS2``...
  are appended for files with more than 255 markers). A ``Subject:`` prefix is stripped
  when ``strip_prefix`` (the prefixes go to ``metadata["label_prefixes"]``, and
  :func:`write_c3d` puts them back). Unlabelled markers keep their names (``*0``...);
  empty labels within ``POINT:USED`` become ``unnamed_<index>``;
- gaps are NaN and ``missing`` (one rule, docs/robustness.md#c3d-gaps): a negative residual
  word, a non-finite coordinate whatever the residual, and, unless ``zero_as_missing=False``,
  coordinates exactly ``(0, 0, 0)``, which some writers use for gaps (Qualisys' Sample26 file
  stores the residual word as 65535.0 rather than -1, so the sample looks valid at the origin);
- labels that are exactly the joint names of a layout of
  :data:`~mocapkit.motion.layouts.LAYOUTS` (the same set, in any order: what
  :func:`write_c3d` writes for joint positions, e.g. ``mocapkit refine`` of an AMC to C3D)
  make it that layout: ``layout_name`` is set and ``parents`` is the layout's hierarchy,
  re-indexed to the file's marker order (which is kept);
- ``fps`` is ``POINT:RATE``; ``up_axis`` comes from ``POINT:Y_SCREEN`` (the C3D
  parameter naming the axis that points up on screen) when it names one, otherwise the
  lab convention ``"z"``; the ``up_axis`` argument overrides both;
- ``metadata`` holds the first frame number (``first_frame``, 1-based as in the file
  header), the full labels, storage format, processor type, point scale, gap counts, the
  events and a summary of the analog data (rate, channel count, labels, units), which is
  never loaded into ``positions``.

**No C extension sees the bytes of a file** (docs/robustness.md#c3d-reader): ezc3d trusts the
file, and one wrong byte in the parameter section can crash it (SIGSEGV) or make it loop.
:func:`validate_c3d` checks the structure (~0.2-1 ms per file): a regular file, the header, the
parameter section's block count and processor type, every group/parameter record (name length,
group id, exact offset to the next record, data type, dimensions x element size and description
inside the section), POINT:USED / SCALE / RATE / DATA_START and ANALOG:USED / RATE against the
header, and frames x (points x 4 + analog samples) x element size within the file (a shorter
file is "truncated", naming the first incomplete frame). :func:`decode_parameters` and
:func:`read_point_words` then decode parameters and data with struct and NumPy (integer and
float storage; Intel, DEC and MIPS formats). Errors are :class:`C3DFormatError` naming the file
and the byte offset and parameter at fault.

:func:`patch_samples` writes a byte copy of a file with some samples replaced (what
``mocapkit refine`` does for C3D in, C3D out); :func:`write_c3d` writes a new file from a
Motion through ezc3d (trusted, in-memory data).
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import regular_file_size
from mocapkit.motion.container import AXES, Motion, all_coordinates
from mocapkit.motion.layouts import LAYOUTS

#: Metres per unit for the POINT:UNITS values understood.
UNIT_SCALE = {"mm": 1e-3, "cm": 1e-2, "dm": 1e-1, "m": 1.0}

_PROCESSORS = {84: "intel", 85: "dec", 86: "mips"}


class C3DFormatError(MotionFormatError):
    """A C3D file that cannot be read. The message names the file (and the frame where known)."""

    def __init__(self, path: str | os.PathLike, message: str, frame: int | None = None):
        super().__init__(path, None, message, frame)

    def __reduce__(self):
        return (type(self), (self.path, self.detail, self.frame))


# --------------------------------------------------------------------------- reading


def read_c3d(
    path: str | os.PathLike,
    labels: list[str] | None = None,
    strip_prefix: bool = True,
    up_axis: str | None = None,
    zero_as_missing: bool = True,
) -> Motion:
    """Read the marker trajectories of a C3D file (see the module docstring).

    Args:
        labels: markers to keep, in this order, by stripped or full label; a missing one
            raises ``KeyError`` naming it.
        strip_prefix: drop a ``Subject:`` prefix from the labels (kept when stripping
            would make two labels equal, i.e. several subjects share marker names).
        up_axis: ``"x"``, ``"y"`` or ``"z"`` to override the file's (or the default) up axis.
        zero_as_missing: treat markers exactly at ``(0, 0, 0)`` as gaps.

    Raises:
        C3DFormatError: unreadable, truncated or not a C3D file, or unusable parameters.
    """
    path = Path(path)
    layout = validate_c3d(path)
    params = decode_parameters(path, layout)
    point = params.get("POINT")
    if point is None:
        raise C3DFormatError(path, "no POINT parameter group")
    if layout.points == 0 or layout.frames == 0:
        raise C3DFormatError(
            path, f"no marker data: {layout.points} points x {layout.frames} frames (an analog-only file?)"
        )
    xyz, word4 = read_point_words(path, layout)  # [frames, markers, 3] file units, [frames, markers]

    # ---- units and rate
    units_raw = _first(point, "UNITS")
    units = (units_raw or "mm").strip().lower()
    if units not in UNIT_SCALE:
        raise C3DFormatError(path, f"unknown POINT:UNITS {units_raw!r}; expected one of {sorted(UNIT_SCALE)}")
    fps = float(_first(point, "RATE") or layout.header_rate or 0.0)
    if not (math.isfinite(fps) and fps > 0):
        raise C3DFormatError(path, "POINT:RATE (and the header frame rate) is not positive")

    # ---- labels
    full = _labels(point, layout.points)
    names, prefixes = _strip(full) if strip_prefix else (list(full), {})

    # ---- gaps: one rule (docs/robustness.md#c3d-gaps). A negative residual word means "not observed"; so does a
    # non-finite coordinate whatever its residual (ezc3d and many tools write gaps as NaN with residual 0), and,
    # unless zero_as_missing=False, a sample exactly at (0, 0, 0) (what some writers store for a gap).
    invalid = word4 < 0
    nan_valid = ~invalid & ~all_coordinates(np.isfinite(xyz))
    invalid_or_nan = invalid | nan_valid
    zero = all_coordinates(xyz == 0.0) & ~invalid_or_nan if zero_as_missing else np.zeros_like(invalid)
    missing = invalid_or_nan | zero
    positions = (xyz * UNIT_SCALE[units]).astype(np.float32)
    positions[missing] = np.nan
    if not np.isfinite(positions[~missing]).all():  # finite in file units, overflowing float32 in metres
        frame, marker = np.argwhere(~all_coordinates(np.isfinite(positions)) & ~missing)[0]
        raise C3DFormatError(
            path, f"marker {full[marker]!r} at frame {frame + 1}: coordinates too large for float32", frame=frame + 1
        )

    # ---- up axis
    screen = _first(point, "Y_SCREEN")
    screen_axis = screen.strip().lstrip("+-").lower() if isinstance(screen, str) else ""
    if up_axis is not None:
        if up_axis not in AXES:
            raise ValueError(f"up_axis must be x, y or z, got {up_axis!r}")
        up, up_from = up_axis, "argument"
    elif screen_axis in AXES:
        up, up_from = screen_axis, f"POINT:Y_SCREEN {screen.strip()!r}"
    else:
        up, up_from = "z", "default (lab convention)"

    scale = layout.point_scale
    metadata = {
        "format": "c3d",
        "first_frame": layout.first_frame,
        "labels": tuple(full),
        "label_prefixes": prefixes,
        "descriptions": tuple(_strings(point, "DESCRIPTIONS")[: layout.points]),
        "point_scale": scale,
        "storage": "float" if layout.element_size == 4 else "integer",
        "processor": layout.processor,
        "up_axis_from": up_from,
        "gaps": {
            "invalid_residual": int(invalid.sum()),
            "nan_coordinates": int(nan_valid.sum()),
            "zero_coordinates": int(zero.sum()),
            "total": int(missing.sum()),
        },
        "nan_gaps_per_marker": {full[j]: int(n) for j, n in enumerate(nan_valid.sum(axis=0)) if n},
        "analog": _analog_summary(params, layout, fps),
        "events": _events(params, layout),
    }
    subjects = sorted(set(prefixes.values()))
    if len(subjects) == 1:
        metadata["subject"] = subjects[0].rstrip(":")

    layout_name, parents = known_layout(names)
    motion = Motion(
        positions=positions,
        joint_names=tuple(names),
        fps=fps,
        parents=parents,
        missing=missing,
        source_units=units,
        up_axis=up,
        name=path.stem,
        source=str(path),
        layout_name=layout_name,
        metadata=metadata,
    )
    if labels is not None:
        motion = motion.select([_find_label(path, names, full, label) for label in labels])
    return motion


def known_layout(names) -> tuple[str | None, tuple[int, ...] | None]:
    """``(layout name, parents)`` when ``names`` are exactly the joint names of a layout of
    :data:`~mocapkit.motion.layouts.LAYOUTS` (same set, any order; parents re-indexed to the order
    of ``names``), else ``(None, None)``."""
    names = tuple(names)
    if len(set(names)) != len(names):
        return None, None
    for layout in LAYOUTS.values():
        if len(layout.joint_names) != len(names) or set(layout.joint_names) != set(names):
            continue
        where = {name: i for i, name in enumerate(names)}
        parents = tuple(
            -1 if p < 0 else where[layout.joint_names[p]]
            for p in (layout.parents[layout.index(name)] for name in names)
        )
        return layout.name, parents
    return None, None


def _first(group: dict, name: str):
    """First value of a decoded parameter (a string, or a number), or None."""
    value = group.get(name)
    if value is None:
        return None
    if isinstance(value, list):
        return value[0] if value else None
    return value.ravel()[0] if value.size else None


def _strings(group: dict, name: str) -> list[str]:
    """A string parameter and its continuations (``NAME2``, ``NAME3``...), stripped."""
    out: list[str] = []
    key, k = name, 2
    while key in group:
        value = group[key]
        out.extend(value if isinstance(value, list) else [str(v) for v in value.ravel()])
        key, k = f"{name}{k}", k + 1
    return out


def _labels(point: dict, n_markers: int) -> list[str]:
    labels = _strings(point, "LABELS")[:n_markers]
    labels += [""] * (n_markers - len(labels))
    return [lab if lab else f"unnamed_{i}" for i, lab in enumerate(labels)]


def _strip(full: list[str]) -> tuple[list[str], dict[str, str]]:
    """Drop ``Subject:`` prefixes unless that makes two labels equal. Returns names and {name: prefix}."""
    names, prefixes = [], {}
    for label in full:
        head, sep, tail = label.partition(":")
        if sep and head and tail:
            names.append(tail)
            prefixes[tail] = head + ":"
        else:
            names.append(label)
    if len(set(names)) < len(set(full)):  # several subjects with the same markers: keep the prefixes
        return list(full), {}
    return names, prefixes


def _find_label(path: Path, names: list[str], full: list[str], label: str) -> int:
    for candidates in (names, full):
        if label in candidates:
            return candidates.index(label)
    raise KeyError(f"{path}: no marker labelled {label!r}; the file has {', '.join(names)}")


def _analog_summary(params: dict, layout: C3DLayout, point_rate: float) -> dict:
    """Rate, channel count, labels and units of the analog data (never loaded into ``positions``)."""
    analog = params.get("ANALOG", {})
    channels = layout.analog_channels
    labels = _strings(analog, "LABELS")
    rate = _first(analog, "RATE")
    per_channel = layout.analog_per_frame // channels if channels else 0
    return {
        "rate": float(rate) if rate is not None else float(point_rate * per_channel),
        "channels": channels,
        "labels": tuple(labels[:channels]),
        "units": tuple(_strings(analog, "UNITS")[:channels]),
        "labels_declared": len(labels),
    }


def _events(params: dict, layout: C3DLayout) -> list[dict]:
    """Events from the EVENT group when it has any, else from the header's event block (18 slots)."""
    group = params.get("EVENT", {})
    used = _first(group, "USED")
    if used:
        labels = _strings(group, "LABELS")
        contexts = _strings(group, "CONTEXTS")
        times = np.asarray(group.get("TIMES", np.zeros(0)), dtype=np.float64)
        if times.ndim == 2 and times.shape[0] == 2:
            times = times[0] * 60.0 + times[1]
        times = times.ravel()
        out = []
        for i in range(int(used) & 0xFFFF):
            if i < len(labels) and i < len(times):
                out.append(
                    {"label": labels[i], "context": contexts[i] if i < len(contexts) else "", "time": float(times[i])}
                )
        return out
    head = layout.head
    times = _floats(head[304:376], layout.processor)  # header words 153-188: 18 event times (s)
    labels = [head[396 + 4 * k : 400 + 4 * k].decode("latin-1").strip(" \x00") for k in range(18)]  # words 199-234
    return [{"label": label, "context": "", "time": float(t)} for label, t in zip(labels, times.tolist()) if label]


# --------------------------------------------------------------------------- decoding, in pure Python and NumPy
#
# The parameter records and the data section are decoded here, after validate_c3d() has checked every count,
# offset and size against the section and the file, with nothing but struct and NumPy: no C extension ever sees
# the bytes of a file, so no file can crash or hang the interpreter (docs/robustness.md#c3d-reader).


def _floats(raw: bytes, processor: str) -> np.ndarray:
    """32-bit floats of ``raw`` in the processor's format (Intel/MIPS IEEE, DEC VAX F-float), as float64."""
    raw = raw[: len(raw) // 4 * 4]
    if processor == "mips":
        return np.frombuffer(raw, ">f4").astype(np.float64)
    if processor == "dec":  # VAX F-float: the two 16-bit words swapped, exponent bias 2 higher than IEEE
        words = np.frombuffer(raw, "<u2").reshape(-1, 2)[:, ::-1]
        return np.ascontiguousarray(words).view("<f4").ravel().astype(np.float64) / 4.0
    return np.frombuffer(raw, "<f4").astype(np.float64)


def _encode_floats(values: np.ndarray, processor: str) -> bytes:
    """The inverse of :func:`_floats` (float32 bytes in the processor's format)."""
    values = np.asarray(values, dtype=np.float64).ravel()
    if processor == "mips":
        return values.astype(">f4").tobytes()
    if processor == "dec":
        words = (values * 4.0).astype("<f4").view("<u2").reshape(-1, 2)[:, ::-1]
        return np.ascontiguousarray(words).tobytes()
    return values.astype("<f4").tobytes()


def decode_parameters(path: str | os.PathLike, layout: C3DLayout) -> dict[str, dict[str, list[str] | np.ndarray]]:
    """Every parameter of a validated file: ``{GROUP: {NAME: value}}``.

    Text parameters (type -1) are lists of strings (the first dimension is the string length; trailing blanks and
    NULs stripped; Latin-1, so no byte can fail to decode); numbers are arrays shaped by the parameter's dimensions
    in C3D's column-major order (``EVENT:TIMES`` is ``[2, events]``), at least 1-D: int16 for type 2, uint8 for
    type 1, float64 from the processor's float format for type 4.
    """
    big = layout.processor == "mips"
    out: dict[str, dict[str, list[str] | np.ndarray]] = {}
    for (group, name), (ptype, dims, data, _at) in layout.params.items():
        if ptype == -1:
            text = data.decode("latin-1")
            if len(dims) <= 1:
                value: list[str] | np.ndarray = [text.rstrip(" \x00")]
            else:
                width = dims[0]
                value = [text[k : k + width].rstrip(" \x00") for k in range(0, len(text), width)] if width else []
        else:
            if ptype == 1:
                flat = np.frombuffer(data, np.uint8)
            elif ptype == 2:
                flat = np.frombuffer(data, ">i2" if big else "<i2")
            else:
                flat = _floats(data, layout.processor)
            value = np.atleast_1d(flat.reshape(dims, order="F") if dims else flat)
        out.setdefault(group, {})[name] = value
    return out


def read_point_words(path: str | os.PathLike, layout: C3DLayout) -> tuple[np.ndarray, np.ndarray]:
    """The 3-D point data of a validated file: ``(xyz [frames, points, 3], word4 [frames, points])``, float64.

    ``xyz`` is in the file's ``POINT:UNITS`` (integer storage multiplied by ``POINT:SCALE``); ``word4`` is the
    fourth word of each sample (residual and camera mask), negative for a sample the system marks invalid. The
    analog samples interleaved with the points are skipped.
    """
    n_words = layout.points * 4 + layout.analog_per_frame
    count = layout.frames * n_words
    if layout.element_size == 4:
        raw = _read_exact(path, layout.data_offset, count * 4)
        words = _floats(raw, layout.processor).reshape(layout.frames, n_words)
    else:
        raw = _read_exact(path, layout.data_offset, count * 2)
        words = np.frombuffer(raw, ">i2" if layout.processor == "mips" else "<i2").reshape(layout.frames, n_words)
        words = words.astype(np.float64)
    points = words[:, : layout.points * 4].reshape(layout.frames, layout.points, 4)
    xyz = points[..., :3] * (layout.point_scale if layout.element_size == 2 else 1.0)
    return np.ascontiguousarray(xyz), np.ascontiguousarray(points[..., 3])


def _read_exact(path: Path | str, offset: int, n_bytes: int) -> bytes:
    try:
        with open(path, "rb") as fh:
            fh.seek(offset)
            raw = fh.read(n_bytes)
    except OSError as exc:
        raise C3DFormatError(path, f"cannot read file ({exc.strerror or exc})") from exc
    if len(raw) < n_bytes:  # the file changed since validate_c3d() measured it
        raise C3DFormatError(path, f"truncated: {n_bytes} bytes of data expected from byte {offset}, {len(raw)} read")
    return raw


# --------------------------------------------------------------------------- validation
#
# A single wrong byte in the parameter section (a name length, a record offset, a dimension,
# POINT:USED...) would make a trusting decoder read out of bounds or allocate without limit.
# validate_c3d() walks the header and every parameter record first and checks each count, offset
# and size against the section and the file, so the decoders below only index inside the file.

#: Bytes per element of the parameter data types (-1 char, 1 byte, 2 int16, 4 float).
_PARAM_TYPES = {-1: 1, 1: 1, 2: 2, 4: 4}
#: Most analog samples per point frame accepted (ANALOG:RATE / POINT:RATE).
MAX_ANALOG_RATIO = 1000


@dataclass
class C3DLayout:
    """What :func:`validate_c3d` learnt about a file (byte offsets are 0-based)."""

    head: bytes
    size: int
    processor: str
    section_start: int
    section_end: int
    records: int
    params: dict = field(default_factory=dict)  # (GROUP, PARAM) -> (type, dims, data bytes, record offset)
    frames: int = 0
    points: int = 0
    analog_per_frame: int = 0  # analog samples per point frame (all channels)
    analog_channels: int = 0
    element_size: int = 4  # bytes per data word: 4 float storage, 2 integer storage
    data_start: int = 0  # 1-based 512-byte block
    point_scale: float = -1.0  # POINT:SCALE (the header's when absent); negative for float storage
    header_rate: float = 0.0  # frames/s in the header
    first_frame: int = 1  # header word 4, 1-based as in the file

    @property
    def data_offset(self) -> int:
        """Byte offset of the first frame."""
        return (self.data_start - 1) * 512

    @property
    def frame_bytes(self) -> int:
        """Bytes per frame: (points x 4 + analog samples) words."""
        return (self.points * 4 + self.analog_per_frame) * self.element_size

    def sample_offset(self, frame: int, point: int) -> int:
        """Byte offset of the 4 words (x, y, z, residual) of ``point`` at ``frame`` (both 0-based)."""
        return self.data_offset + frame * self.frame_bytes + point * 4 * self.element_size


def validate_c3d(path: str | os.PathLike) -> C3DLayout:
    """Check the structure of a C3D file without the C3D library; raise :class:`C3DFormatError` if unsound.

    Checked: the file is a regular file (links followed); the 512-byte header (parameter
    block number, key byte 0x50, data start block, frame range); the parameter section
    (block count and processor type 84/85/86, the section inside the file); every group and
    parameter record (name length, group id, offset to the next record strictly forward and
    inside the section, data type, dimensions x element size and description inside the
    section, parameters belonging to a declared group); ``POINT:USED``, ``POINT:SCALE``,
    ``POINT:RATE``, ``POINT:DATA_START``, ``ANALOG:USED``, ``ANALOG:RATE`` against the
    header; and that frames x (points x 4 + analog samples) x element size bytes from the
    data start fit in the file (a shorter file is reported as truncated, with the first
    incomplete frame). Errors name the file and the byte offset (and parameter) at fault.
    """
    path = Path(path)
    size = regular_file_size(path, lambda p, m: C3DFormatError(p, m))
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
            if len(head) < 512:
                raise C3DFormatError(path, f"not a C3D file: {len(head)} bytes, shorter than the 512-byte header")
            if head[1] != 0x50:
                raise C3DFormatError(path, f"not a C3D file: header byte 2 is {head[1]}, expected 80 (0x50)")
            if head[0] < 2:
                raise C3DFormatError(path, f"header byte 1 (first parameter block) is {head[0]}; it must be 2 or more")
            start = (head[0] - 1) * 512
            fh.seek(start)
            section_head = fh.read(4)
            if len(section_head) < 4:
                raise C3DFormatError(
                    path,
                    f"the parameter section starts at byte {start}, beyond the end of the {size}-byte file",
                )
            n_blocks, proc_byte = section_head[2], section_head[3]
            end = start + n_blocks * 512
            fh.seek(start)
            section = fh.read(n_blocks * 512)
    except OSError as exc:
        raise C3DFormatError(path, f"cannot read file ({exc.strerror or exc})") from exc
    if proc_byte not in _PROCESSORS:
        raise C3DFormatError(
            path, f"byte {start + 3}: processor type {proc_byte}, expected 84 (Intel), 85 (DEC) or 86 (MIPS)"
        )
    if n_blocks < 1:
        raise C3DFormatError(path, f"byte {start + 2}: the parameter section has {n_blocks} blocks")
    if len(section) < n_blocks * 512:
        raise C3DFormatError(
            path,
            f"the parameter section (byte {start}, {n_blocks} blocks "
            f"of 512) extends past the end of the {size}-byte file",
        )
    processor = _PROCESSORS[proc_byte]
    layout = C3DLayout(head=head, size=size, processor=processor, section_start=start, section_end=end, records=0)
    _walk_parameters(path, section, start, layout)
    _check_sizes(path, layout)
    return layout


def _walk_parameters(path: Path, section: bytes, base: int, layout: C3DLayout) -> None:
    """Every group and parameter record of ``section`` (which starts at file byte ``base``)."""
    big = layout.processor == "mips"
    groups: dict[int, str] = {}
    params: list[tuple[int, str, int, int, tuple, bytes]] = []  # (group id, name, offset, type, dims, data)
    pos, limit = 4, len(section)
    while True:
        if pos + 2 > limit:
            raise C3DFormatError(
                path,
                f"byte {base + pos}: the parameter records run past the end of the parameter "
                f"section (byte {base + limit}) without a terminating record",
            )
        n_name = struct.unpack_from("b", section, pos)[0]
        if n_name == 0:
            break
        gid = struct.unpack_from("b", section, pos + 1)[0]
        where = f"byte {base + pos}"
        if gid == 0:
            raise C3DFormatError(path, f"{where}: parameter record with group id 0")
        name_end = pos + 2 + abs(n_name)
        if name_end + 2 > limit:
            raise C3DFormatError(
                path, f"{where}: record name of {abs(n_name)} characters runs past the end of the parameter section"
            )
        name = section[pos + 2 : name_end].decode("latin-1").strip().upper()
        offset_at = name_end
        offset = struct.unpack_from(">H" if big else "<H", section, offset_at)[0]
        what = f"group {name}" if gid < 0 else f"parameter {groups.get(gid, f'(group id {gid})')}:{name}"
        cursor = offset_at + 2
        if gid < 0:
            if -gid in groups:
                raise C3DFormatError(path, f"{where}: {what} reuses group id {-gid} of group {groups[-gid]!r}")
            groups[-gid] = name
        else:
            if cursor + 2 > limit:
                raise C3DFormatError(path, f"{where}: {what} runs past the end of the parameter section")
            ptype, n_dims = struct.unpack_from("bB", section, cursor)
            if ptype not in _PARAM_TYPES:
                raise C3DFormatError(
                    path,
                    f"byte {base + cursor}: {what} has data type {ptype}, expected -1 (char), "
                    "1 (byte), 2 (int16) or 4 (float)",
                )
            if n_dims > 7:
                raise C3DFormatError(path, f"byte {base + cursor + 1}: {what} has {n_dims} dimensions (at most 7)")
            cursor += 2
            if cursor + n_dims > limit:
                raise C3DFormatError(
                    path, f"{where}: the dimensions of {what} run past the end of the parameter section"
                )
            dims = tuple(section[cursor : cursor + n_dims])
            cursor += n_dims
            count = 1
            for d in dims:
                count *= d
            n_bytes = count * _PARAM_TYPES[ptype]
            if cursor + n_bytes > limit:
                raise C3DFormatError(
                    path,
                    f"byte {base + cursor}: {what} with dimensions {list(dims)} x "
                    f"{_PARAM_TYPES[ptype]} bytes ({n_bytes} bytes) runs past the end of the "
                    f"parameter section (byte {base + limit})",
                )
            params.append((gid, name, base + pos, ptype, dims, section[cursor : cursor + n_bytes]))
            cursor += n_bytes
        if cursor + 1 > limit:
            raise C3DFormatError(path, f"{where}: {what} runs past the end of the parameter section")
        n_desc = section[cursor]
        cursor += 1 + n_desc
        if cursor > limit:
            raise C3DFormatError(path, f"{where}: the description of {what} runs past the end of the parameter section")
        layout.records += 1
        if offset == 0:  # the last record
            break
        nxt = offset_at + offset
        if nxt != cursor:
            raise C3DFormatError(
                path,
                f"byte {base + offset_at}: {what}: the offset to the next record ({offset}) "
                f"points to byte {base + nxt}, but the record ends at byte {base + cursor}",
            )
        pos = nxt
    for gid, name, at, ptype, dims, data in params:
        if gid not in groups:
            raise C3DFormatError(
                path, f"byte {at}: parameter {name!r} belongs to group id {gid}, which no group record declares"
            )
        layout.params[(groups[gid], name)] = (ptype, dims, data, at)


def _param_numbers(path: Path, layout: C3DLayout, group: str, name: str) -> list[float] | None:
    """The numeric values of ``GROUP:NAME`` (ints as signed 16-bit, floats per processor), or None if absent."""
    entry = layout.params.get((group, name))
    if entry is None:
        return None
    ptype, _dims, data, at = entry
    if ptype == -1:
        raise C3DFormatError(path, f"byte {at}: {group}:{name} is text; a number was expected")
    big = layout.processor == "mips"
    if ptype == 1:
        return [float(b) for b in data]
    if ptype == 2:
        return [float(v) for v in struct.unpack((">" if big else "<") + f"{len(data) // 2}h", data)]
    return [_float(data[k : k + 4], layout.processor) for k in range(0, len(data), 4)]


def _float(raw: bytes, processor: str) -> float:
    if processor == "mips":
        return struct.unpack(">f", raw)[0]
    if processor == "dec":  # VAX F-float: swapped 16-bit words, exponent bias 2 higher
        return struct.unpack("<f", raw[2:4] + raw[0:2])[0] / 4.0
    return struct.unpack("<f", raw)[0]


def _check_sizes(path: Path, layout: C3DLayout) -> None:
    """Header and POINT/ANALOG parameters against each other and the file length."""
    head, big, proc = layout.head, layout.processor == "mips", layout.processor
    words = struct.unpack((">" if big else "<") + "256H", head)  # 1-based word k is words[k - 1]
    h_points, h_analog, h_first, h_last = words[1], words[2], words[3], words[4]
    h_scale = _float(head[12:16], proc)
    h_data_start = words[8]
    h_rate = _float(head[20:24], proc)

    def one(group: str, name: str) -> float | None:
        values = _param_numbers(path, layout, group, name)
        return values[0] if values else None

    def at(group: str, name: str) -> str:
        entry = layout.params.get((group, name))
        return f"byte {entry[3]} ({group}:{name})" if entry else f"{group}:{name}"

    if ("POINT", "USED") not in layout.params and h_points:
        raise C3DFormatError(path, f"no POINT:USED parameter although the header announces {h_points} points")
    used = one("POINT", "USED")
    points = h_points if used is None else int(used) & 0xFFFF  # > 32767 points are stored as unsigned words
    if points != h_points:
        raise C3DFormatError(path, f"{at('POINT', 'USED')}: {points} points, but header word 2 says {h_points}")
    scale = one("POINT", "SCALE")
    scale = h_scale if scale is None else scale
    if not math.isfinite(scale) or not math.isfinite(h_scale):
        raise C3DFormatError(path, f"{at('POINT', 'SCALE')}: the point scale factor is not finite")
    element = 4 if (scale < 0 or h_scale < 0) else 2
    rate = one("POINT", "RATE")
    rate = h_rate if rate is None else rate
    if not math.isfinite(rate) or rate < 0 or not math.isfinite(h_rate):
        raise C3DFormatError(path, f"{at('POINT', 'RATE')}: point rate {rate} is not a finite non-negative number")

    a_used = one("ANALOG", "USED")
    channels = 0 if a_used is None else int(a_used) & 0xFFFF
    a_rate = one("ANALOG", "RATE")
    if a_rate is not None and (not math.isfinite(a_rate) or a_rate < 0):
        raise C3DFormatError(path, f"{at('ANALOG', 'RATE')}: analog rate {a_rate} is not a finite non-negative number")
    analog = h_analog
    if channels:
        if h_analog % channels:
            raise C3DFormatError(
                path,
                f"{at('ANALOG', 'USED')}: {channels} channels, but header word 3 announces "
                f"{h_analog} analog samples per frame, not a multiple of it",
            )
        ratio = h_analog // channels
        if a_rate is not None and rate > 0:
            expected_ratio = a_rate / rate
            if expected_ratio > MAX_ANALOG_RATIO:
                raise C3DFormatError(
                    path,
                    f"{at('ANALOG', 'RATE')}: {expected_ratio:g} analog samples per point "
                    f"frame (more than {MAX_ANALOG_RATIO})",
                )
            if ratio and abs(expected_ratio - ratio) > 0.5 + 1e-6 * ratio:
                raise C3DFormatError(
                    path,
                    f"{at('ANALOG', 'RATE')}: ANALOG:RATE / POINT:RATE = {expected_ratio:g}, "
                    f"but the header stores {ratio} samples per channel and frame",
                )
    elif h_analog and a_used is not None:
        raise C3DFormatError(
            path, f"{at('ANALOG', 'USED')}: 0 channels, but header word 3 announces {h_analog} analog samples per frame"
        )

    ds = one("POINT", "DATA_START")
    data_start = h_data_start if ds is None else int(ds) & 0xFFFF
    if data_start != h_data_start:
        raise C3DFormatError(
            path, f"{at('POINT', 'DATA_START')}: block {data_start}, but header word 9 says {h_data_start}"
        )
    first_free = layout.section_end // 512 + 1
    if data_start < first_free:
        raise C3DFormatError(
            path,
            f"header word 9: the data starts in block {data_start}, inside the header or the "
            f"parameter section (which ends before block {first_free})",
        )
    frames = h_last - h_first + 1 if h_last >= h_first else 0
    if h_last < h_first and not (h_last == 0 and h_first in (0, 1)):
        raise C3DFormatError(path, f"header words 4-5: last frame {h_last} before first frame {h_first}")
    # Long trials keep the real count in POINT:FRAMES or TRIAL:ACTUAL_START/END_FIELD (the header caps at 65535).
    p_frames = one("POINT", "FRAMES")
    if p_frames is not None:
        frames = max(frames, int(p_frames) & 0xFFFF)
    trial = [_param_numbers(path, layout, "TRIAL", k) for k in ("ACTUAL_START_FIELD", "ACTUAL_END_FIELD")]
    if all(trial):
        s, e = ([int(v) & 0xFFFF for v in values] for values in trial)
        start = s[0] + (s[1] << 16 if len(s) > 1 else 0)
        end = e[0] + (e[1] << 16 if len(e) > 1 else 0)
        if end >= start > 0:
            frames = max(frames, end - start + 1)
    if frames and points + analog and not rate > 0:
        raise C3DFormatError(path, f"{at('POINT', 'RATE')}: point rate is {rate} for {frames} frames of data")

    frame_bytes = (points * 4 + analog) * element
    begin = (data_start - 1) * 512
    available = max(layout.size - begin, 0)
    if frame_bytes and frames * frame_bytes > available:
        complete = available // frame_bytes
        raise C3DFormatError(
            path,
            f"truncated: the header announces {frames} frames but the data ends after "
            f"{complete} (this frame is incomplete or absent): {frames} frames x "
            f"({points} points x 4 + {analog} analog samples) x {element} bytes from byte "
            f"{begin} need {begin + frames * frame_bytes} bytes, the file has {layout.size}",
            frame=complete + 1,
        )
    layout.frames, layout.points, layout.analog_per_frame = frames, points, analog
    layout.analog_channels = channels if channels else (analog if analog and a_used is None else 0)
    layout.element_size, layout.data_start = element, data_start
    layout.point_scale = -abs(scale) if element == 4 else scale
    layout.header_rate, layout.first_frame = h_rate, h_first


# --------------------------------------------------------------------------- patching samples in place


def patch_samples(
    src: str | os.PathLike, dst: str | os.PathLike, frames: np.ndarray, points: np.ndarray, values: np.ndarray
) -> str:
    """Write a byte copy of ``src`` to ``dst`` in which only the given samples are replaced and marked valid.

    ``frames``, ``points``: ``[n]`` 0-based indices; ``values``: ``[n, 3]`` in the file's ``POINT:UNITS``. Each
    sample's 4 data words are overwritten in the file's own storage and byte order: x, y, z (integer storage:
    ``round(value / POINT:SCALE)``, so filled values are quantised to the scale) and a fourth word of 0 (residual
    0 = a computed, not measured, point; empty camera mask). Every other byte of the file (header, parameters,
    the other samples, analog data) is kept, so observed samples stay bit-identical. ``dst`` is then decoded and
    checked: only the bytes of the changed samples differ, and each reads back valid at its value.

    Returns a one-line description of the write. Raises :class:`C3DFormatError` (an unsound ``src``) or
    ``ValueError`` naming point and frame (a value that integer storage cannot hold).
    """
    src, dst = Path(src), Path(dst)
    layout = validate_c3d(src)
    frames, points = np.asarray(frames, dtype=np.int64), np.asarray(points, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    if len(frames) and (
        frames.max() >= layout.frames or points.max() >= layout.points or min(frames.min(), points.min()) < 0
    ):
        raise ValueError(f"{src}: sample indices outside its {layout.frames} frames x {layout.points} points")
    if not np.isfinite(values).all():
        raise ValueError(f"{src}: non-finite values cannot be written as valid samples")
    raw = bytearray(_read_exact(src, 0, layout.size))
    size = 4 * layout.element_size
    if layout.element_size == 2:
        words = np.rint(values / layout.point_scale)
        bad = np.abs(words).max(axis=1, initial=0) > 32767
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(
                f"{src}: the value of point {points[k]} at frame {frames[k] + 1} is outside the int16 range of "
                f"this integer-storage file (POINT:SCALE {layout.point_scale:g})"
            )
        samples = np.concatenate([words, np.zeros((len(words), 1))], axis=1)
        encoded = samples.astype(">i2" if layout.processor == "mips" else "<i2").tobytes()
        mode = f"integer storage (POINT:SCALE {layout.point_scale:g}), filled values quantised to it"
    else:
        encoded = _encode_floats(np.concatenate([values, np.zeros((len(values), 1))], axis=1), layout.processor)
        mode = f"float storage ({layout.processor})"
    offsets = [layout.sample_offset(f, j) for f, j in zip(frames.tolist(), points.tolist())]
    for k, offset in enumerate(offsets):
        raw[offset : offset + size] = encoded[k * size : (k + 1) * size]
    from mocapkit.io_atomic import atomic_path

    with atomic_path(dst) as tmp:
        tmp.write_bytes(bytes(raw))
        _check_patch(src, tmp, layout, offsets, frames, points, values)
    return f"byte copy of the source with {len(offsets)} samples rewritten; {mode}"


def _check_patch(src: Path, written: Path, layout: C3DLayout, offsets, frames, points, values) -> None:
    """Only the changed samples' bytes differ from ``src``, and each decodes valid at its value."""
    a = np.frombuffer(_read_exact(src, 0, layout.size), np.uint8)
    b = np.frombuffer(_read_exact(written, 0, layout.size), np.uint8)
    allowed = np.zeros(layout.size, bool)
    for offset in offsets:
        allowed[offset : offset + 4 * layout.element_size] = True
    if len(a) != len(b) or (a != b)[~allowed].any():
        raise ValueError(f"{src}: the patched copy differs outside the changed samples; nothing written")
    xyz, word4 = read_point_words(written, validate_c3d(written))
    got = xyz[frames, points]
    tolerance = abs(layout.point_scale) if layout.element_size == 2 else 0.0
    close = np.allclose(got, values, rtol=1e-6, atol=max(tolerance, 1e-6))
    if not (np.isfinite(got).all() and (word4[frames, points] >= 0).all() and close):
        raise ValueError(f"{src}: the patched samples do not read back at their values; nothing written")


# --------------------------------------------------------------------------- writing


def write_c3d(path: str | os.PathLike, motion: Motion, units: str = "mm", restore_prefix: bool = True) -> None:
    """Write the markers of ``motion`` to a C3D file (Intel float storage, ``POINT:SCALE -1``).

    Labels are ``motion.joint_names`` (with their ``Subject:`` prefix put back from
    ``metadata["label_prefixes"]`` when ``restore_prefix``), ``POINT:RATE`` is ``motion.fps``,
    ``POINT:UNITS`` is ``units`` (positions are converted from metres), ``POINT:Y_SCREEN``
    names the up axis and the header's first frame is ``metadata["first_frame"]`` (default 1).
    Missing markers are written as invalid (NaN coordinates, residual -1), so
    :func:`read_c3d` gives the same values (to float32 precision) and the same mask.
    Analog data, rotations and the hierarchy are not written.
    """
    import ezc3d

    path = Path(path)
    units = units.strip().lower()
    if units not in UNIT_SCALE:
        raise ValueError(f"units must be one of {sorted(UNIT_SCALE)}, got {units!r}")
    prefixes = motion.metadata.get("label_prefixes", {}) if restore_prefix else {}
    labels = [prefixes.get(name, "") + name for name in motion.joint_names]
    frames, markers = motion.num_frames, motion.num_joints

    xyz = motion.positions.astype(np.float64) / UNIT_SCALE[units]
    xyz[motion.missing] = np.nan
    points = np.ones((4, markers, frames))
    points[:3] = np.transpose(xyz, (2, 1, 0))
    residuals = np.zeros((1, markers, frames))
    residuals[0] = np.where(motion.missing.T, -1.0, 0.0)

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = np.array([float(motion.fps)])
    point["LABELS"]["value"] = labels
    point["DESCRIPTIONS"]["value"] = [""] * markers
    point["UNITS"]["value"] = [units]
    point["SCALE"]["value"] = np.array([-1.0])
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {"residuals": residuals}
    first = motion.metadata.get("first_frame", 1)
    c3d["header"]["points"]["first_frame"] = max(int(first) - 1, 0) if isinstance(first, (int, np.integer)) else 0
    x_screen, y_screen = {"x": ("+Y", "+X"), "y": ("+X", "+Y"), "z": ("+X", "+Z")}[motion.up_axis]
    c3d.add_parameter("POINT", "X_SCREEN", [x_screen])
    c3d.add_parameter("POINT", "Y_SCREEN", [y_screen])
    c3d.add_parameter("MANUFACTURER", "SOFTWARE", ["mocapkit"])

    from mocapkit.io_atomic import atomic_path

    with atomic_path(path, suffix=".c3d") as tmp:  # ezc3d appends ".c3d" to other names
        try:
            c3d.write(str(tmp))
        except TypeError as exc:  # ezc3d's SWIG overloads, broken by another SWIG module (faiss) loaded first
            raise RuntimeError(
                f"{path}: ezc3d could not write the file ({exc.args[0].splitlines()[0]}); this happens when faiss "
                "was imported before ezc3d in this process: import ezc3d first (mocapkit.retrieval.ann does)"
            ) from exc
