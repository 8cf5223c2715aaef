"""Biovision Hierarchy (``.bvh``) files: reading to a :class:`~mocapkit.motion.container.Motion`, and writing.

The format::

    HIERARCHY
    ROOT Hips
    {
        OFFSET x y z
        CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
        JOINT Spine
        {
            OFFSET x y z
            CHANNELS 3 Zrotation Xrotation Yrotation
            End Site
            {
                OFFSET x y z
            }
        }
    }
    MOTION
    Frames: N
    Frame Time: dt
    <N lines of sum(channels) numbers: the channels of every joint, in hierarchy order>

Accepted quirks: CRLF, LF and both mixed in one file; tabs or spaces anywhere
(also after ``Frames:``); joint names with colons or spaces (the name is the rest
of the ``JOINT`` line); any subset and order of the six channels per joint,
varying from joint to joint; position channels on any joint; several ROOTs.

Conventions (the decisions are also recorded in ``Motion.metadata``):

* **Rotation.** A joint's local rotation is the product of its per-channel axis
  rotations *in the order the channels are listed*, as intrinsic rotations:
  ``Zrotation Yrotation Xrotation`` gives ``R = Rz(z) @ Ry(y) @ Rx(x)`` acting on
  column vectors. Angles are degrees. Forward kinematics::

      G[j]   = G[parent] @ R[j]
      pos[j] = pos[parent] + G[parent] @ t[j]

  where ``t[j]`` is the joint's translation in its parent's frame (below).
* **Position channels replace the OFFSET** on the axes they cover (the OFFSET is
  then only the rest/bind position). This is what exporters mean by it: e.g. the
  PyMO sample has ROOT OFFSET ``(11.27, 35.42, -54.33)`` and first-frame root
  channels ``(-6.5, 35.6, -163.0)``: adding them would lift the character by its
  own hip height. ``position_mode="add"`` adds the channels to the OFFSET instead.
* **End Sites** carry no channels, so by default they are *not* joints of the
  Motion: joint counts and indices then match the channel layout (31 joints for
  CMU, not 38). They are kept in :class:`BvhSkeleton` (so :func:`write_bvh`
  round-trips them) and ``end_sites=True`` appends them as extra joints *after*
  all real joints (named ``"<parent>/End Site"``, parent = the joint they end,
  identity rotation), so real-joint indices never change.
* **Units.** Positions are returned in metres. The caller may pass ``scale``
  (metres per file unit) or ``units`` (one of :data:`UNITS`). Otherwise the unit
  is *inferred*: the rest-pose size of the skeleton (the largest extent along any
  axis of all joints and End Sites placed by their OFFSETs, i.e. the height in a
  standing T-pose) is compared with a 1.7 m adult, and the candidate unit among
  m, cm, mm, inch and CMU (``inch/0.45`` = 0.05644 m) whose scaled size is nearest
  in ratio (log scale) wins. The candidates lie a factor >= 2.2 apart, so a
  skeleton between roughly 1.1 and 2.6 m tall gets the right unit; a child-sized
  skeleton in inches (< ~1.15 m) would be taken for CMU units and a partial
  skeleton (upper body only) may be mis-read: pass ``units`` for those.
  ``source_units`` says what was decided, ``metadata["units_inferred"]`` whether
  it was guessed, ``metadata["rest_size"]`` the size in file units.

Raw channel values stay available (``metadata["channels"]``, float64 ``[frames,
channels]`` in file units and degrees, and the :class:`BvhSkeleton` in
``metadata["bvh"]``) so that :func:`write_bvh` writes them back exactly.
"""

from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes
from mocapkit.motion.container import Motion

#: Metres per file unit for the named units accepted by ``read_bvh(units=...)``.
UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": 0.0254 / 0.45,
}
#: What ``source_units`` says for each named unit.
UNIT_LABELS = {"m": "m", "cm": "cm", "mm": "mm", "inch": "inch", "cmu": "inch/0.45 (CMU)"}
#: The adult height (metres) the unit inference aims at.
REFERENCE_HEIGHT_M = 1.7

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CHANNEL_BY_LOWER = {c.lower(): c for c in CHANNEL_NAMES}
_FRAMES_RE = re.compile(rb"^\s*Frames\s*:\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(rb"^\s*Frame\s+Time\s*:\s*(\S+)\s*$", re.IGNORECASE)


class BvhFormatError(MotionFormatError):
    """A malformed ``.bvh`` file. The message names the file and the 1-based line."""


@dataclass
class BvhSkeleton:
    """The HIERARCHY section, in file units.

    Joints are in file (depth-first) order, which is also the channel order of
    the data lines; every parent comes before its children.

    Attributes:
        joint_names: ``J`` names (End Sites excluded).
        parents: ``J`` parent indices, ``-1`` for a ROOT.
        offsets: float64 ``[J, 3]`` OFFSET of each joint in its parent's frame (file units).
        channels: per joint, the tuple of its channel names in file order (canonical
            spelling, e.g. ``("Zrotation", "Xrotation", "Yrotation")``).
        end_sites: ``(parent joint index, float64 [3] offset)`` per End Site, in file order.
    """

    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: tuple[tuple[int, np.ndarray], ...] = ()

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    @property
    def channel_starts(self) -> np.ndarray:
        """int ``[J]``: column of each joint's first channel in a data line."""
        counts = np.array([len(c) for c in self.channels], dtype=np.int64)
        return np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else counts

    def rest_positions(self) -> np.ndarray:
        """float64 ``[J + E, 3]``: joints then End Sites placed by their OFFSETs alone (file units)."""
        pos = np.zeros((self.num_joints + len(self.end_sites), 3))
        for j, p in enumerate(self.parents):
            pos[j] = self.offsets[j] + (pos[p] if p >= 0 else 0.0)
        for e, (p, off) in enumerate(self.end_sites):
            pos[self.num_joints + e] = pos[p] + off
        return pos

    def rest_size(self) -> float:
        """Largest extent along any axis of :meth:`rest_positions` (file units): the T-pose height."""
        pos = self.rest_positions()
        return float((pos.max(0) - pos.min(0)).max()) if len(pos) else 0.0


# --------------------------------------------------------------------------- reading


def read_bvh(
    path: str | os.PathLike,
    scale: float | None = None,
    units: str | None = None,
    end_sites: bool = False,
    position_mode: str = "replace",
) -> Motion:
    """Read a ``.bvh`` file as a :class:`Motion` in metres (see the module docstring for the conventions).

    Args:
        path: the file.
        scale: metres per file unit; overrides ``units`` and the inference.
        units: one of :data:`UNITS` (``"m"``, ``"cm"``, ``"mm"``, ``"inch"``, ``"cmu"``).
        end_sites: append the End Sites as extra joints after the real ones.
        position_mode: ``"replace"`` (position channels replace the OFFSET) or ``"add"``.

    Returns:
        A Motion with ``positions`` float32 ``[frames, joints, 3]`` (metres, y up),
        ``rotations`` float32 ``[frames, joints, 3, 3]`` (local, per the channels),
        ``parents``, ``fps = 1 / frame_time`` and ``metadata`` holding ``"bvh"``
        (:class:`BvhSkeleton`), ``"channels"`` (float64 ``[frames, channels]``, raw),
        ``"frame_time"``, ``"scale"`` (metres per unit), ``"units_inferred"``,
        ``"rest_size"``, ``"end_sites"``, ``"position_mode"``.

    Raises:
        BvhFormatError: malformed hierarchy, bad header, a data line whose value
            count differs from the declared channels, non-numeric or non-finite
            values, fewer (or more) data lines than ``Frames:``; the message names
            the file and the 1-based line.
    """
    path = Path(path)
    data = read_file_bytes(path, lambda p, message: BvhFormatError(p, None, message))
    return parse_bvh_text(data, source=path, scale=scale, units=units, end_sites=end_sites, position_mode=position_mode)


def parse_bvh_text(
    text: bytes | str,
    source: str | os.PathLike = "<memory>",
    scale: float | None = None,
    units: str | None = None,
    end_sites: bool = False,
    position_mode: str = "replace",
) -> Motion:
    """Parse the content of a ``.bvh`` file (see :func:`read_bvh`)."""
    if isinstance(text, str):
        text = text.encode()
    if position_mode not in ("replace", "add"):
        raise ValueError(f"position_mode must be 'replace' or 'add', got {position_mode!r}")
    lines = text.splitlines()  # \r\n, \n and \r, mixed
    skeleton, motion_line = _parse_hierarchy(lines, source)
    values, frame_time, _ = _parse_motion(lines, motion_line, skeleton.num_channels, source)

    rest_size = skeleton.rest_size()
    scale, label, inferred = _decide_scale(scale, units, rest_size)
    return bvh_motion(
        skeleton,
        values,
        frame_time,
        scale,
        name=Path(str(source)).stem,
        source=str(source),
        end_sites=end_sites,
        position_mode=position_mode,
        source_units=label,
        units_inferred=inferred,
    )


def bvh_motion(
    skeleton: BvhSkeleton,
    values: np.ndarray,
    frame_time: float,
    scale: float,
    name: str = "",
    source: str | None = None,
    end_sites: bool = False,
    position_mode: str = "replace",
    source_units: str | None = None,
    units_inferred: bool = False,
) -> Motion:
    """The :class:`Motion` of a hierarchy and its raw channel values (float64 ``[frames, channels]``, degrees and
    file units), what :func:`read_bvh` returns for the file they would make; ``scale`` is metres per file unit."""
    positions, rotations, glob = _fk(skeleton, values, position_mode)
    names, parents = list(skeleton.joint_names), list(skeleton.parents)
    if end_sites and skeleton.end_sites:
        eye = np.broadcast_to(np.eye(3), (len(values), len(skeleton.end_sites), 3, 3))
        positions = np.concatenate([positions, _end_site_positions(skeleton, positions, glob)], axis=1)
        rotations = np.concatenate([rotations, eye], axis=1)
        names += [f"{skeleton.joint_names[p]}/End Site" for p, _ in skeleton.end_sites]
        parents += [p for p, _ in skeleton.end_sites]
    return Motion(
        positions=(positions * scale).astype(np.float32),
        joint_names=tuple(names),
        parents=tuple(parents),
        rotations=rotations.astype(np.float32),
        fps=1.0 / frame_time,
        source_units=source_units or f"{scale:g} m per unit",
        up_axis="y",
        name=name,
        source=source,
        metadata={
            "format": "bvh",
            "bvh": skeleton,
            "channels": values,
            "frame_time": frame_time,
            "scale": scale,
            "units_inferred": units_inferred,
            "rest_size": skeleton.rest_size(),
            "end_sites": bool(end_sites and skeleton.end_sites),
            "position_mode": position_mode,
        },
    )


def infer_scale(rest_size: float) -> tuple[str, float]:
    """The named unit (and its metres per unit) that makes a skeleton of ``rest_size`` file units
    closest in ratio to :data:`REFERENCE_HEIGHT_M`."""
    if not rest_size > 0:
        return "m", 1.0
    best = min(UNITS, key=lambda u: abs(math.log(rest_size * UNITS[u] / REFERENCE_HEIGHT_M)))
    return best, UNITS[best]


def _decide_scale(scale, units, rest_size) -> tuple[float, str, bool]:
    if scale is not None:
        scale = float(scale)
        if not scale > 0:
            raise ValueError(f"scale must be positive (metres per file unit), got {scale}")
        named = [u for u, s in UNITS.items() if abs(s - scale) <= 1e-9 * s]
        return scale, (UNIT_LABELS[named[0]] if named else f"{scale:g} m/unit"), False
    if units is not None:
        key = units.lower()
        if key not in UNITS:
            raise ValueError(f"unknown units {units!r}; expected one of {sorted(UNITS)}")
        return UNITS[key], UNIT_LABELS[key], False
    unit, s = infer_scale(rest_size)
    return s, UNIT_LABELS[unit], True


def _tokenize_hierarchy(lines: list[bytes], source) -> tuple[list[tuple[str, str, int]], int]:
    """Tokens ``(kind, value, 1-based line)`` up to the MOTION line; returns them and MOTION's 0-based index.

    ROOT/JOINT lines give one ``("joint", name)`` token (the name is the rest of
    the line, so it may hold colons or spaces); ``End Site`` gives ``("end", "")``.
    """
    tokens: list[tuple[str, str, int]] = []
    seen_header = False
    for k, raw in enumerate(lines):
        line = raw.decode("utf-8", errors="replace")
        parts = line.split()
        if not parts:
            continue
        head = parts[0].upper()
        if not seen_header:
            if head != "HIERARCHY":
                raise BvhFormatError(source, k + 1, f"expected HIERARCHY, found {line.strip()[:40]!r}")
            seen_header = True
            parts = parts[1:]
            if not parts:
                continue
            head = parts[0].upper()
        if head == "MOTION":
            return tokens, k
        brace_open = False
        if head in ("ROOT", "JOINT"):
            rest = parts[1:]
            if rest and rest[-1] == "{":
                rest, brace_open = rest[:-1], True
            if not rest:
                raise BvhFormatError(source, k + 1, f"{parts[0]} without a name")
            tokens.append(("root" if head == "ROOT" else "joint", " ".join(rest), k + 1))
        elif head == "END":
            rest = parts[1:]
            if rest and rest[-1] == "{":
                rest, brace_open = rest[:-1], True
            if len(rest) != 1 or rest[0].upper() != "SITE":
                raise BvhFormatError(source, k + 1, f"expected 'End Site', found {line.strip()[:40]!r}")
            tokens.append(("end", "", k + 1))
        else:
            tokens.extend(("word", p, k + 1) for p in parts)
            continue
        if brace_open:
            tokens.append(("word", "{", k + 1))
    if not seen_header:
        raise BvhFormatError(source, 1, "empty file: expected HIERARCHY")
    raise BvhFormatError(source, len(lines) + 1, "file ends before the MOTION section")


def _parse_hierarchy(lines: list[bytes], source) -> tuple[BvhSkeleton, int]:
    tokens, motion_line = _tokenize_hierarchy(lines, source)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray | None] = []
    channels: list[tuple[str, ...] | None] = []
    ends: list[tuple[int, np.ndarray | None]] = []
    # stack entries: ("joint", index) or ("end", index into ends); opened says whether "{" was seen
    stack: list[list] = []
    pending = None  # a ROOT/JOINT/End Site that still needs its "{"
    n = len(tokens)
    i = 0

    def take_numbers(count: int, what: str, line: int) -> np.ndarray:
        nonlocal i
        vals = []
        for _ in range(count):
            if i >= n or tokens[i][0] != "word":
                raise BvhFormatError(source, line, f"{what} needs {count} numbers")
            try:
                vals.append(float(tokens[i][1]))
            except ValueError:
                raise BvhFormatError(source, tokens[i][2], f"non-numeric {what} value {tokens[i][1]!r}") from None
            i += 1
        arr = np.array(vals, dtype=np.float64)
        if not np.isfinite(arr).all():
            raise BvhFormatError(source, line, f"non-finite {what} value")
        return arr

    roots = 0
    while i < n:
        kind, value, line = tokens[i]
        i += 1
        if pending is not None and not (kind == "word" and value == "{"):
            raise BvhFormatError(source, line, f"expected '{{' after {pending[0]}, found {value or kind!r}")
        if kind in ("root", "joint"):
            if kind == "root" and stack:
                raise BvhFormatError(source, line, "ROOT inside another joint (missing '}'?)")
            if kind == "joint" and (not stack or stack[-1][0] != "joint"):
                raise BvhFormatError(source, line, "JOINT outside a ROOT or inside an End Site")
            roots += kind == "root"
            names.append(value)
            parents.append(stack[-1][1] if stack else -1)
            offsets.append(None)
            channels.append(None)
            pending = (f"{kind.upper()} {value}", ("joint", len(names) - 1))
        elif kind == "end":
            if not stack or stack[-1][0] != "joint":
                raise BvhFormatError(source, line, "End Site outside a joint")
            ends.append((stack[-1][1], None))
            pending = ("End Site", ("end", len(ends) - 1))
        elif value == "{":
            if pending is None:
                raise BvhFormatError(source, line, "unexpected '{'")
            stack.append(list(pending[1]) + [line])
            pending = None
        elif value == "}":
            if not stack:
                raise BvhFormatError(source, line, "unexpected '}'")
            what, idx, _ = stack.pop()
            if what == "joint":
                if offsets[idx] is None:
                    raise BvhFormatError(source, line, f"joint {names[idx]!r} has no OFFSET")
                if channels[idx] is None:
                    channels[idx] = ()
            elif ends[idx][1] is None:
                raise BvhFormatError(source, line, "End Site has no OFFSET")
        elif value.upper() == "OFFSET":
            if not stack:
                raise BvhFormatError(source, line, "OFFSET outside a joint")
            what, idx, _ = stack[-1]
            off = take_numbers(3, "OFFSET", line)
            if what == "joint":
                if offsets[idx] is not None:
                    raise BvhFormatError(source, line, f"second OFFSET for joint {names[idx]!r}")
                offsets[idx] = off
            else:
                if ends[idx][1] is not None:
                    raise BvhFormatError(source, line, "second OFFSET for an End Site")
                ends[idx] = (ends[idx][0], off)
        elif value.upper() == "CHANNELS":
            if not stack or stack[-1][0] != "joint":
                raise BvhFormatError(source, line, "CHANNELS outside a joint")
            idx = stack[-1][1]
            if channels[idx] is not None:
                raise BvhFormatError(source, line, f"second CHANNELS for joint {names[idx]!r}")
            if i >= n or tokens[i][0] != "word":
                raise BvhFormatError(source, line, "CHANNELS needs a count")
            try:
                count = int(tokens[i][1])
            except ValueError:
                raise BvhFormatError(source, tokens[i][2], f"non-integer channel count {tokens[i][1]!r}") from None
            i += 1
            if not 0 <= count <= 6:
                raise BvhFormatError(source, line, f"channel count {count} is not between 0 and 6")
            chans = []
            for _ in range(count):
                if i >= n or tokens[i][0] != "word" or tokens[i][1].lower() not in _CHANNEL_BY_LOWER:
                    got = tokens[i][1] if i < n else "end of hierarchy"
                    raise BvhFormatError(
                        source, tokens[i][2] if i < n else line, f"expected one of {count} channel names, found {got!r}"
                    )
                chans.append(_CHANNEL_BY_LOWER[tokens[i][1].lower()])
                i += 1
            if len(set(chans)) != len(chans):
                raise BvhFormatError(source, line, f"repeated channel in {' '.join(chans)}")
            channels[idx] = tuple(chans)
        else:
            raise BvhFormatError(source, line, f"unexpected {value!r} in the hierarchy")
    if pending is not None:
        raise BvhFormatError(source, motion_line + 1, f"{pending[0]} has no body before MOTION")
    if stack:
        raise BvhFormatError(
            source, motion_line + 1, f"{len(stack)} unclosed '{{' before MOTION (opened at line {stack[-1][2]})"
        )
    if roots == 0:
        raise BvhFormatError(source, motion_line + 1, "no ROOT in the hierarchy")
    skeleton = BvhSkeleton(
        joint_names=tuple(names),
        parents=tuple(parents),
        offsets=np.array(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(channels),
        end_sites=tuple((p, off) for p, off in ends),
    )
    return skeleton, motion_line


def _parse_motion(lines: list[bytes], motion_line: int, num_channels: int, source):
    """Frames, frame time and the ``[frames, channels]`` float64 values after the MOTION line."""
    n_lines = len(lines)
    k = motion_line + 1
    rest_of_motion = lines[motion_line].split()[1:]
    if rest_of_motion:
        raise BvhFormatError(source, motion_line + 1, "unexpected text after MOTION")

    def header_value(k, pattern, expected, convert, what):
        """``(line, value)`` of the first non-blank line from ``k`` (0-based), matched by ``pattern``."""
        while k < n_lines and not lines[k].strip():
            k += 1
        m = pattern.match(lines[k]) if k < n_lines else None
        if m is None:
            raise BvhFormatError(source, k + 1, f"expected '{expected}'")
        try:
            return k, convert(m.group(1))
        except ValueError:
            raise BvhFormatError(source, k + 1, f"{what} {m.group(1).decode(errors='replace')!r}") from None

    k, num_frames = header_value(k, _FRAMES_RE, "Frames: <count>", int, "non-integer frame count")
    if num_frames < 0:
        raise BvhFormatError(source, k + 1, f"negative frame count {num_frames}")
    k, frame_time = header_value(k + 1, _FRAME_TIME_RE, "Frame Time: <seconds>", float, "non-numeric frame time")
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise BvhFormatError(source, k + 1, f"frame time must be positive, got {frame_time}")
    first = k + 1

    data_idx = [j for j in range(first, n_lines) if lines[j].strip()]
    if len(data_idx) < num_frames:
        after = data_idx[-1] + 2 if data_idx else first + 1
        raise BvhFormatError(source, after, f"file ends after {len(data_idx)} of {num_frames} frames (truncated)")
    if len(data_idx) > num_frames:
        raise BvhFormatError(
            source,
            data_idx[num_frames] + 1,
            f"more data lines than 'Frames: {num_frames}' (line is frame {num_frames + 1})",
        )
    if num_frames == 0:
        return np.zeros((0, num_channels)), frame_time, data_idx
    if num_channels == 0:
        raise BvhFormatError(source, data_idx[0] + 1, "data line but no channels declared")
    data_lines = [lines[j] for j in data_idx]
    values = None
    try:  # numpy's C parser for the whole block; any irregularity goes to the line-by-line check
        values = np.loadtxt(io.BytesIO(b"\n".join(data_lines)), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        values = None
    if values is None or values.shape != (num_frames, num_channels) or not np.isfinite(values).all():
        _raise_bad_data_line(lines, data_idx, num_channels, source)
    return values, frame_time, data_idx


def _raise_bad_data_line(lines, indices, width, source):
    for k in indices:
        tok = lines[k].split()
        if len(tok) != width:
            raise BvhFormatError(
                source, k + 1, f"data line has {len(tok)} values, expected {width} (the declared channels)"
            )
        for v in tok:
            try:
                x = float(v)
            except ValueError:
                raise BvhFormatError(source, k + 1, f"non-numeric value {v.decode(errors='replace')!r}") from None
            if not math.isfinite(x):
                raise BvhFormatError(source, k + 1, f"non-finite value {v.decode(errors='replace')!r}")
    raise BvhFormatError(source, None, "unparseable motion data")  # pragma: no cover - defensive


# --------------------------------------------------------------------------- kinematics


def axis_rotations(axis: str, degrees: np.ndarray) -> np.ndarray:
    """float64 ``[..., 3, 3]`` rotations about ``axis`` (``"X"``, ``"Y"`` or ``"Z"``) by ``degrees`` ``[...]``."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    i = "XYZ".index(axis.upper())
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def local_transforms(skeleton: BvhSkeleton, values: np.ndarray, position_mode: str = "replace"):
    """Local rotations float64 ``[F, J, 3, 3]`` and translations ``[F, J, 3]`` (file units) from the channels.

    ``values`` is float64 ``[F, channels]`` as in the data lines (degrees, file units).
    """
    rot, trans = _local_joint_major(skeleton, values, position_mode)
    return rot.transpose(1, 0, 2, 3), trans.transpose(1, 0, 2)


def _local_joint_major(skeleton: BvhSkeleton, values: np.ndarray, position_mode: str):
    """As :func:`local_transforms` but joint-major, ``[J, F, 3, 3]`` and ``[J, F, 3]`` (contiguous per joint)."""
    F = values.shape[0]
    J = skeleton.num_joints
    rot = np.empty((J, F, 3, 3))
    rot[:] = np.eye(3)
    trans = np.empty((J, F, 3))
    trans[:] = skeleton.offsets[:, None, :]
    columns = np.ascontiguousarray(values.T)  # [C, F]
    # Group joints by channel signature so that each distinct order is one batched product.
    groups: dict[tuple[str, ...], list[int]] = {}
    for j, chans in enumerate(skeleton.channels):
        groups.setdefault(chans, []).append(j)
    starts = skeleton.channel_starts
    for chans, joints in groups.items():
        if not chans:
            continue
        joints_arr = np.asarray(joints)
        cols = starts[joints_arr][:, None] + np.arange(len(chans))[None, :]  # [G, C]
        block = columns[cols]  # [G, C, F]
        r = None
        for c, ch in enumerate(chans):
            if ch.endswith("rotation"):
                m = axis_rotations(ch[0], block[:, c])  # [G, F, 3, 3]
                r = m if r is None else r @ m
            else:
                axis = "XYZ".index(ch[0])
                if position_mode == "add":
                    trans[joints_arr, :, axis] += block[:, c]
                else:
                    trans[joints_arr, :, axis] = block[:, c]
        if r is not None:
            rot[joints_arr] = r
    return rot, trans


def forward_kinematics(skeleton: BvhSkeleton, values: np.ndarray, position_mode: str = "replace"):
    """Global joint positions float64 ``[F, J, 3]`` (file units) and local rotations ``[F, J, 3, 3]``.

    Vectorised over frames; one batched step per joint in hierarchy order.
    """
    pos, rot, _ = _fk(skeleton, values, position_mode)
    return pos, rot


def _fk(skeleton: BvhSkeleton, values: np.ndarray, position_mode: str):
    """Positions ``[F, J, 3]``, local and global rotations ``[F, J, 3, 3]`` (views of joint-major arrays)."""
    rot, trans = _local_joint_major(skeleton, values, position_mode)
    glob = np.empty_like(rot)
    pos = np.empty_like(trans)
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            glob[j] = rot[j]
            pos[j] = trans[j]
        else:
            np.matmul(glob[p], rot[j], out=glob[j])
            pos[j] = pos[p] + (glob[p] @ trans[j][:, :, None])[:, :, 0]
    return pos.transpose(1, 0, 2), rot.transpose(1, 0, 2, 3), glob.transpose(1, 0, 2, 3)


def _end_site_positions(skeleton: BvhSkeleton, positions: np.ndarray, glob: np.ndarray) -> np.ndarray:
    """float64 ``[F, E, 3]``: End Sites placed from their joint's global frame (file units)."""
    return np.stack([positions[:, p] + glob[:, p] @ off for p, off in skeleton.end_sites], axis=1)


# --------------------------------------------------------------------------- writing

#: Channels :func:`write_bvh` gives joints when it builds a hierarchy from ``rotations`` (no BVH metadata).
ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")


def write_bvh(
    path: str | os.PathLike, motion: Motion, scale: float | None = None, newline: str = "\n", tolerance: float = 1e-5
) -> None:
    """Write ``motion`` as a ``.bvh`` file that :func:`read_bvh` reads back to the same positions.

    Two sources for the hierarchy and channels, tried in order:

    1. The BVH the motion was read from (``metadata["bvh"]`` and ``metadata["channels"]``):
       the same hierarchy, End Sites, channel orders and raw values are written
       (values printed with Python's shortest round-trip repr, so they read back bit-exact).
       Used only while the positions still agree with those channels (a view such as
       ``root_centered`` or ``select`` changes them).
    2. Otherwise ``parents`` + ``rotations`` + ``positions``: OFFSETs are the bone vectors
       in the parent's frame (averaged over frames); ROOTs, and joints whose bone vector
       changes over time, get :data:`ROOT_CHANNELS` (positions + rotations), the other
       joints :data:`JOINT_CHANNELS` (Euler angles decomposed from ``rotations``).

    Args:
        scale: metres per file unit; default: the unit of the source BVH (case 1) or metres (case 2).
        newline: line end, ``"\\n"`` or ``"\\r\\n"``.
        tolerance: the largest position error (metres) accepted when checking that the
            written channels reproduce ``motion.positions``.

    Raises:
        ValueError: the motion has missing values, no hierarchy, or (case 2) no
            rotations, or rotations that do not reproduce its positions.
    """
    skeleton, values, file_scale = _writer_source(motion, tolerance)
    skeleton, values = _depth_first(skeleton, values)
    if scale is not None and scale != file_scale:
        skeleton, values = _rescale(skeleton, values, file_scale / float(scale))
    frame_time = motion.metadata.get("frame_time") if skeleton is motion.metadata.get("bvh") else None
    if frame_time is None or abs(1.0 / frame_time - motion.fps) > 1e-9 * motion.fps:
        frame_time = 1.0 / motion.fps
    out = ["HIERARCHY"]
    children: dict[int, list[int]] = {}
    for j, p in enumerate(skeleton.parents):
        children.setdefault(p, []).append(j)
    ends: dict[int, list[np.ndarray]] = {}
    for p, off in skeleton.end_sites:
        ends.setdefault(p, []).append(off)

    def num(x: float) -> str:
        return repr(float(x))

    def emit(j: int, depth: int) -> None:
        tab = "\t" * depth
        out.append(f"{tab}{'ROOT' if skeleton.parents[j] < 0 else 'JOINT'} {skeleton.joint_names[j]}")
        out.append(f"{tab}{{")
        out.append(f"{tab}\tOFFSET {' '.join(num(v) for v in skeleton.offsets[j])}")
        chans = skeleton.channels[j]
        out.append(f"{tab}\tCHANNELS {len(chans)}" + "".join(f" {c}" for c in chans))
        for c in children.get(j, []):
            emit(c, depth + 1)
        for off in ends.get(j, []):
            out.extend(
                [f"{tab}\tEnd Site", f"{tab}\t{{", f"{tab}\t\tOFFSET {' '.join(num(v) for v in off)}", f"{tab}\t}}"]
            )
        out.append(f"{tab}}}")

    for root in children.get(-1, []):
        emit(root, 0)
    out += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {num(frame_time)}"]
    out += [" ".join(map(repr, row)) for row in values.tolist()]
    Path(path).write_text(newline.join(out) + newline, encoding="utf-8", newline="")


def _writer_source(motion: Motion, tolerance: float) -> tuple[BvhSkeleton, np.ndarray, float]:
    """(skeleton, raw values [F, C], metres per unit) to write for ``motion``."""
    if motion.parents is None:
        raise ValueError(
            f"{motion.source or motion.name}: a BVH needs a joint hierarchy (parents); marker sets cannot be written"
        )
    if motion.missing is not None and motion.missing.any():
        raise ValueError(f"{motion.source or motion.name}: a BVH cannot hold missing (NaN) positions")
    skeleton = motion.metadata.get("bvh")
    values = motion.metadata.get("channels")
    if isinstance(skeleton, BvhSkeleton) and values is not None and len(values) == motion.num_frames:
        n_end = len(skeleton.end_sites) if motion.metadata.get("end_sites") else 0
        expected_names = skeleton.joint_names + tuple(
            f"{skeleton.joint_names[p]}/End Site" for p, _ in skeleton.end_sites[:n_end]
        )
        if motion.joint_names == expected_names:
            s = float(motion.metadata.get("scale", 1.0))
            mode = motion.metadata.get("position_mode", "replace")
            pos, _, glob = _fk(skeleton, values, mode)
            if n_end:
                pos = np.concatenate([pos, _end_site_positions(skeleton, pos, glob)], axis=1)
            if np.abs(pos * s - motion.positions).max(initial=0.0) <= tolerance:
                if mode == "add":  # the file convention of the reader's default is "replace"
                    skeleton, values = _add_to_replace(skeleton, values)
                return skeleton, values, s
    return _from_rotations(motion, tolerance)


def _depth_first(skeleton: BvhSkeleton, values: np.ndarray) -> tuple[BvhSkeleton, np.ndarray]:
    """The skeleton and its channel columns reordered into file (depth-first) order, if they are not."""
    children: dict[int, list[int]] = {}
    for j, p in enumerate(skeleton.parents):
        children.setdefault(p, []).append(j)
    order: list[int] = []
    todo = list(reversed(children.get(-1, [])))
    while todo:
        j = todo.pop()
        order.append(j)
        todo.extend(reversed(children.get(j, [])))
    if order == list(range(skeleton.num_joints)):
        return skeleton, values
    new_of = {old: new for new, old in enumerate(order)}
    starts = skeleton.channel_starts
    cols = [starts[j] + c for j in order for c in range(len(skeleton.channels[j]))]
    reordered = BvhSkeleton(
        joint_names=tuple(skeleton.joint_names[j] for j in order),
        parents=tuple(new_of[skeleton.parents[j]] if skeleton.parents[j] >= 0 else -1 for j in order),
        offsets=skeleton.offsets[order],
        channels=tuple(skeleton.channels[j] for j in order),
        end_sites=tuple((new_of[p], off) for p, off in skeleton.end_sites),
    )
    return reordered, values[:, cols]


def _add_to_replace(skeleton: BvhSkeleton, values: np.ndarray) -> tuple[BvhSkeleton, np.ndarray]:
    values = values.copy()
    starts = skeleton.channel_starts
    for j, chans in enumerate(skeleton.channels):
        for c, ch in enumerate(chans):
            if ch.endswith("position"):
                values[:, starts[j] + c] += skeleton.offsets[j, "XYZ".index(ch[0])]
    return skeleton, values


def _rescale(skeleton: BvhSkeleton, values: np.ndarray, factor: float) -> tuple[BvhSkeleton, np.ndarray]:
    """Lengths multiplied by ``factor`` (angles unchanged)."""
    values = values.copy()
    starts = skeleton.channel_starts
    for j, chans in enumerate(skeleton.channels):
        for c, ch in enumerate(chans):
            if ch.endswith("position"):
                values[:, starts[j] + c] *= factor
    return BvhSkeleton(
        skeleton.joint_names,
        skeleton.parents,
        skeleton.offsets * factor,
        skeleton.channels,
        tuple((p, off * factor) for p, off in skeleton.end_sites),
    ), values


def _from_rotations(motion: Motion, tolerance: float) -> tuple[BvhSkeleton, np.ndarray, float]:
    from scipy.spatial.transform import Rotation

    label = motion.source or motion.name or "motion"
    if motion.rotations is None:
        raise ValueError(
            f"{label}: writing a BVH needs local joint rotations (Motion.rotations) or the BVH it was read from"
        )
    parents = motion.parents
    if any(p >= j for j, p in enumerate(parents)):
        raise ValueError(f"{label}: joints must be ordered parents first to be written as a BVH")
    F, J = motion.num_frames, motion.num_joints
    rot = motion.rotations.astype(np.float64)
    pos = motion.positions.astype(np.float64)
    glob = np.empty_like(rot)
    local = pos.copy()  # [F, J, 3] translation of each joint in its parent's frame
    for j, p in enumerate(parents):
        glob[:, j] = rot[:, j] if p < 0 else glob[:, p] @ rot[:, j]
        if p >= 0:
            local[:, j] = np.einsum("fba,fb->fa", glob[:, p], pos[:, j] - pos[:, p])
    offsets = local.mean(0)
    # bones whose length or direction changes over time keep per-frame position channels
    moving = [parents[j] < 0 or np.abs(local[:, j] - offsets[j]).max(initial=0.0) > tolerance / 4 for j in range(J)]
    # Leaf joints named "<joint>/End Site" (read_bvh(end_sites=True)) go back to End Sites.
    has_child = {p for p in parents if p >= 0}
    is_end = [
        j not in has_child and p >= 0 and not moving[j] and motion.joint_names[j].endswith("/End Site")
        for j, p in enumerate(parents)
    ]
    keep = [j for j in range(J) if not is_end[j]]
    new_of = {old: new for new, old in enumerate(keep)}
    end_sites = tuple((new_of[parents[j]], offsets[j]) for j in range(J) if is_end[j])
    channels = tuple(ROOT_CHANNELS if moving[j] else JOINT_CHANNELS for j in keep)
    columns = []
    for j in keep:
        euler = Rotation.from_matrix(rot[:, j]).as_euler("ZYX", degrees=True)  # intrinsic: Rz @ Ry @ Rx
        columns.append(np.concatenate([local[:, j], euler], axis=1) if moving[j] else euler)
    values = np.concatenate(columns, axis=1) if columns else np.zeros((F, 0))
    skeleton = BvhSkeleton(
        tuple(motion.joint_names[j] for j in keep),
        tuple(new_of[parents[j]] if parents[j] >= 0 else -1 for j in keep),
        offsets[keep],
        channels,
        end_sites,
    )
    check, _, glob_check = _fk(skeleton, values, "replace")
    if end_sites:
        ends = _end_site_positions(skeleton, check, glob_check)
        full = np.empty((F, J, 3))
        full[:, keep] = check
        full[:, [j for j in range(J) if is_end[j]]] = ends
        check = full
    err = np.abs(check - pos).max(initial=0.0)
    if err > tolerance:
        raise ValueError(
            f"{label}: its rotations do not reproduce its positions by BVH forward kinematics "
            f"(error {err:.3g} m > {tolerance:g} m); is it a BVH-convention rotation set?"
        )
    return skeleton, values, 1.0
