"""C3D marker files (reading and writing) through the maintained ``ezc3d`` library.

:func:`read_c3d` returns a :class:`~mocapkit.datasets.formats.motion.Motion` of marker
trajectories (``parents=None``):

- positions in **metres**, converted from ``POINT:UNITS`` (``mm``, ``cm``, ``dm``, ``m``;
  ``mm``, the C3D default, when the parameter is absent);
- ``joint_names`` are the marker labels, only the first ``POINT:USED`` of them
  (``POINT:LABELS`` is often padded with empty or stale names beyond it; ``LABELS2``...
  are appended for files with more than 255 markers). A ``Subject:`` prefix is stripped
  when ``strip_prefix`` (the prefixes go to ``metadata["label_prefixes"]``, and
  :func:`write_c3d` puts them back). Unlabelled markers keep their names (``*0``...);
  empty labels within ``POINT:USED`` become ``unnamed_<index>``;
- gaps are NaN and ``missing``: a negative residual (ezc3d already returns NaN for
  those) and, unless ``zero_as_missing=False``, coordinates exactly ``(0, 0, 0)``,
  which some writers use for gaps (Qualisys' Sample26 file stores the residual word as
  65535.0 rather than -1, so ezc3d sees a valid point at the origin);
- ``fps`` is ``POINT:RATE``; ``up_axis`` comes from ``POINT:Y_SCREEN`` (the C3D
  parameter naming the axis that points up on screen) when it names one, otherwise the
  lab convention ``"z"``; the ``up_axis`` argument overrides both;
- ``metadata`` holds the first frame number (``first_frame``, 1-based as in the file
  header), the full labels, storage format, processor type, point scale, gap counts, the
  events and a summary of the analog data (rate, channel count, labels, units), which is
  never loaded into ``positions``.

Damaged files raise :class:`C3DFormatError` naming the file: whatever ezc3d rejects
(its message is included), and files whose data section is shorter than the frame range
in their header (ezc3d itself silently returns the frames it could read).
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.motion import AXES, Motion

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


def read_c3d(path: str | os.PathLike, labels: list[str] | None = None, strip_prefix: bool = True,
             up_axis: str | None = None, zero_as_missing: bool = True) -> Motion:
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
    import ezc3d

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
    except OSError as exc:
        raise C3DFormatError(path, f"cannot read file ({exc.strerror or exc})") from exc
    if len(head) < 512:
        raise C3DFormatError(path, f"not a C3D file: {len(head)} bytes, shorter than the 512-byte header")
    if head[1] != 0x50:
        raise C3DFormatError(path, f"not a C3D file: header byte 2 is {head[1]}, expected 80 (0x50)")
    try:
        c3d = ezc3d.c3d(str(path))
    except Exception as exc:  # ezc3d raises OSError / RuntimeError / ValueError with its own words
        raise C3DFormatError(path, f"ezc3d cannot read it: {exc}") from exc

    params = c3d["parameters"]
    point = params.get("POINT")
    if point is None:
        raise C3DFormatError(path, "no POINT parameter group")
    data = c3d["data"]["points"]                       # [4, markers, frames], file units
    n_markers, n_frames = int(data.shape[1]), int(data.shape[2])

    processor = _processor(path, head)
    expected = _expected_frames(head, params, processor)
    if expected is not None and n_frames < expected:
        raise C3DFormatError(path, f"truncated: the header announces {expected} frames but the data "
                                   f"ends after {n_frames} (this frame is incomplete or absent)",
                              frame=n_frames + 1)

    # ---- units and rate
    units_raw = _first(point, "UNITS")
    units = (units_raw or "mm").strip().lower()
    if units not in UNIT_SCALE:
        raise C3DFormatError(path, f"unknown POINT:UNITS {units_raw!r}; expected one of {sorted(UNIT_SCALE)}")
    fps = float(_first(point, "RATE") or c3d["header"]["points"]["frame_rate"] or 0.0)
    if not fps > 0:
        raise C3DFormatError(path, "POINT:RATE (and the header frame rate) is not positive")

    # ---- labels
    full = _labels(point, n_markers)
    names, prefixes = _strip(full) if strip_prefix else (list(full), {})

    # ---- positions and gaps
    xyz = np.ascontiguousarray(np.transpose(data[:3], (2, 1, 0)), dtype=np.float64)   # [frames, markers, 3]
    invalid = ~np.isfinite(xyz).all(axis=2)
    zero = (xyz == 0.0).all(axis=2) & ~invalid if zero_as_missing else np.zeros_like(invalid)
    missing = invalid | zero
    positions = (xyz * UNIT_SCALE[units]).astype(np.float32)
    positions[missing] = np.nan

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

    scale = float(_first(point, "SCALE") or -1.0)
    first0 = int(c3d["header"]["points"]["first_frame"])
    metadata = {
        "format": "c3d",
        "first_frame": first0 + 1,
        "labels": tuple(full),
        "label_prefixes": prefixes,
        "descriptions": tuple(_strings(point, "DESCRIPTIONS")[:n_markers]),
        "point_scale": scale,
        "storage": "float" if scale < 0 else "integer",
        "processor": processor,
        "up_axis_from": up_from,
        "gaps": {"invalid_residual": int(invalid.sum()), "zero_coordinates": int(zero.sum()),
                 "total": int(missing.sum())},
        "analog": _analog_summary(params, c3d),
        "events": _events(params, c3d["header"]),
    }
    subjects = sorted(set(prefixes.values()))
    if len(subjects) == 1:
        metadata["subject"] = subjects[0].rstrip(":")

    motion = Motion(positions=positions, joint_names=tuple(names), fps=fps, parents=None, missing=missing,
                    source_units=units, up_axis=up, name=path.stem, source=str(path), metadata=metadata)
    if labels is not None:
        motion = motion.select([_find_label(path, names, full, label) for label in labels])
    return motion


def _processor(path: Path, head: bytes) -> str:
    """The processor type byte of the parameter section (84 Intel, 85 DEC, 86 MIPS)."""
    try:
        with open(path, "rb") as fh:
            fh.seek((head[0] - 1) * 512 + 3)
            byte = fh.read(1)
        return _PROCESSORS.get(byte[0], f"unknown ({byte[0]})") if byte else "unknown"
    except OSError:
        return "unknown"


def _expected_frames(head: bytes, params, processor: str) -> int | None:
    """Frame count announced by the raw file (ezc3d rewrites its copy to what it could read).

    TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (two 16-bit words each, for long trials)
    win over the 16-bit header fields; None when neither is usable.
    """
    trial = params.get("TRIAL", {})
    if "ACTUAL_START_FIELD" in trial and "ACTUAL_END_FIELD" in trial:
        try:
            s, e = (np.asarray(trial[k]["value"], dtype=np.int64).ravel() & 0xFFFF
                    for k in ("ACTUAL_START_FIELD", "ACTUAL_END_FIELD"))
            start = int(s[0]) + (int(s[1]) << 16 if len(s) > 1 else 0)
            end = int(e[0]) + (int(e[1]) << 16 if len(e) > 1 else 0)
            if end >= start > 0:
                return end - start + 1
        except (KeyError, IndexError, TypeError, ValueError):
            pass
    first, last = struct.unpack((">" if processor == "mips" else "<") + "2H", head[6:10])
    return last - first + 1 if last >= first else None


def _first(group, name):
    """First value of a parameter, or None."""
    if name not in group:
        return None
    value = group[name]["value"]
    if isinstance(value, str):
        return value
    if len(value) == 0:
        return None
    return value[0] if isinstance(value, list) else np.asarray(value).ravel()[0]


def _strings(group, name) -> list[str]:
    """A string parameter and its continuations (``NAME2``, ``NAME3``...), stripped."""
    out: list[str] = []
    key, k = name, 2
    while key in group:
        value = group[key]["value"]
        out.extend([str(v).strip() for v in (value if isinstance(value, (list, tuple)) else [value])])
        key, k = f"{name}{k}", k + 1
    return out


def _labels(point, n_markers: int) -> list[str]:
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
    if len(set(names)) < len(set(full)):   # several subjects with the same markers: keep the prefixes
        return list(full), {}
    return names, prefixes


def _find_label(path: Path, names: list[str], full: list[str], label: str) -> int:
    for candidates in (names, full):
        if label in candidates:
            return candidates.index(label)
    raise KeyError(f"{path}: no marker labelled {label!r}; the file has {', '.join(names)}")


def _analog_summary(params, c3d) -> dict:
    analog = params.get("ANALOG", {})
    channels = int(c3d["data"]["analogs"].shape[1])
    labels = _strings(analog, "LABELS")
    rate = _first(analog, "RATE")
    return {
        "rate": float(rate) if rate is not None else float(c3d["header"]["analogs"]["frame_rate"]),
        "channels": channels,
        "labels": tuple(labels[:channels]),
        "units": tuple(_strings(analog, "UNITS")[:channels]),
        "labels_declared": len(labels),
    }


def _events(params, header) -> list[dict]:
    """Events from the EVENT group when it has any, else from the header's event block."""
    group = params.get("EVENT", {})
    used = _first(group, "USED")
    if used:
        labels = _strings(group, "LABELS")
        contexts = _strings(group, "CONTEXTS")
        times = np.asarray(group.get("TIMES", {}).get("value", []), dtype=np.float64)
        if times.ndim == 2 and times.shape[0] == 2:
            times = times[0] * 60.0 + times[1]
        out = []
        for i in range(int(used)):
            if i < len(labels) and i < len(times):
                out.append({"label": labels[i], "context": contexts[i] if i < len(contexts) else "",
                            "time": float(times[i])})
        return out
    events = header.get("events", {})
    return [{"label": str(lab).strip(), "context": "", "time": float(t)}
            for lab, t in zip(events.get("events_label", ()), events.get("events_time", ())) if str(lab).strip()]


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

    # ezc3d appends ".c3d" to other names; write beside the target and move into place.
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.c3d")
    try:
        c3d.write(str(tmp))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
