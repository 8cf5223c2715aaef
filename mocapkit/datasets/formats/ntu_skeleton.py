"""NTU RGB+D ``.skeleton`` files: reading, writing, file names and body selection.

The text format (Shahroudy et al. 2016; the release's reader script)::

    framecount
    per frame:  bodycount                       (0 allowed)
      per body: bodyID clipedEdges handLeftConfidence handLeftState
                handRightConfidence handRightState isResticted leanX leanY trackingState
                jointCount                      (25)
        per joint: x y z depthX depthY colorX colorY orientW orientX orientY orientZ trackingState

CRLF, LF and CR-only line ends are accepted. Every field is kept; body IDs are
64-bit tracking IDs and are kept exact as Python ints.

Robustness (every damaged file raises :class:`SkeletonFormatError` naming the file and,
where there is one, the line): only regular files are read (directories, FIFOs and devices
such as a link to ``/dev/zero`` are refused by name) and at most
:data:`~mocapkit.datasets.formats.safe_io.MAX_FILE_BYTES`; NaN and infinite values (``nan``,
``inf``, ``1e309``) in joint lines *and* body lines are errors naming the line; the dense
per-track arrays are bounded by the file size: a file whose distinct body IDs x frames
would need more than :func:`track_memory_limit` bytes (``max(64 MiB, 32 x file size)``;
every body entry takes at least 300 bytes of text, so real files stay far below it) is
refused rather than allocated (a 1 MB file with a new body ID in every frame used to ask
for gigabytes).

Bodies are grouped into *tracks* by body ID across frames: ``positions`` is
``[tracks, frames, 25, 3]`` with zeros where a track is absent in a frame.
:func:`select_main_bodies` reduces the tracks to the (at most) two actors used
for training, following the dataset authors' preprocessing (drop tracks seen in too
few frames, then non-human "bodies" by their spread, then rank by motion) plus a
flicker rule of ours (drop tracks that come and go or jump), and says why for every
track.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes
from mocapkit.motion.layouts import NTU25

NUM_JOINTS = 25
JOINT_FIELDS = 12
BODY_FIELDS = 10

#: Names of the 10 per-body values, in file order (``isResticted`` spelt as in the SDK dump).
BODY_INFO_FIELDS = (
    "body_id",
    "clipped_edges",
    "hand_left_confidence",
    "hand_left_state",
    "hand_right_confidence",
    "hand_right_state",
    "is_restricted",
    "lean_x",
    "lean_y",
    "tracking_state",
)

#: Floor and factor of :func:`track_memory_limit`.
TRACK_MEMORY_FLOOR = 64 << 20
TRACK_MEMORY_FACTOR = 32
#: Bytes the dense arrays take per (track, frame): joints, body info, slot.
_BYTES_PER_TRACK_FRAME = NUM_JOINTS * JOINT_FIELDS * 8 + (BODY_FIELDS - 1) * 8 + 2


def track_memory_limit(text_bytes: int) -> int:
    """Most bytes :func:`parse_skeleton_text` allocates for the ``[tracks, frames, ...]`` arrays of a text this long."""
    return max(TRACK_MEMORY_FLOOR, TRACK_MEMORY_FACTOR * int(text_bytes))


_NAME_RE = re.compile(r"S(\d{3})C(\d{3})P(\d{3})R(\d{3})A(\d{3})")


class SkeletonFormatError(MotionFormatError):
    """A malformed ``.skeleton`` file. The message names the file and the 1-based line."""


@dataclass(frozen=True)
class NTUSampleName:
    """The fields of an NTU sample name ``SsssCcccPpppRrrrAaaa`` (all 1-based as written)."""

    setup: int
    camera: int
    subject: int
    replication: int
    action: int

    @property
    def label(self) -> int:
        """0-based class index (``action - 1``)."""
        return self.action - 1

    def __str__(self) -> str:
        return f"S{self.setup:03d}C{self.camera:03d}P{self.subject:03d}R{self.replication:03d}A{self.action:03d}"


def parse_ntu_name(name: str | os.PathLike) -> NTUSampleName:
    """Parse ``S001C002P003R001A004`` (optionally a path or with ``.skeleton``)."""
    stem = Path(name).name
    match = _NAME_RE.search(stem)
    if match is None:
        raise ValueError(f"{stem!r} is not an NTU sample name of the form SsssCcccPpppRrrrAaaa")
    return NTUSampleName(*(int(g) for g in match.groups()))


def _joint_values(start: int, stop: int | None, doc: str, dtype=np.float32) -> property:
    """A read-only :class:`SkeletonSequence` property documented by ``doc``: a ``dtype`` copy of some joint values.

    The values are ``joints[..., start:stop]``, or the single column ``joints[..., start]`` when ``stop`` is None.
    """
    columns = start if stop is None else slice(start, stop)

    def get(self) -> np.ndarray:
        return self.joints[..., columns].astype(dtype)

    get.__doc__ = doc
    return property(get, doc=doc)


@dataclass
class SkeletonSequence:
    """Everything in one ``.skeleton`` file, grouped into per-body tracks.

    Shapes use ``B`` = number of distinct body IDs (tracks), ``T`` = frames,
    ``J`` = 25 joints. Entries where a track is absent in a frame are zero.

    Attributes:
        name: file stem (e.g. ``S001C001P001R001A011``); parsed fields via :attr:`sample`.
        body_ids: ``B`` 64-bit tracking IDs (exact Python ints), in order of first appearance.
        joints: float64 ``[B, T, J, 12]``, the 12 per-joint values exactly as read
            (x y z in metres; depth x/y and colour x/y in pixels; orientation w x y z; tracking state).
        body_info: float64 ``[B, T, 9]``, the body line without the ID
            (``BODY_INFO_FIELDS[1:]``).
        slot: int16 ``[B, T]``, position of the body within its frame's list, ``-1`` if absent.
            Keeps the writer's output in the original order.
    """

    name: str
    body_ids: list[int]
    joints: np.ndarray
    body_info: np.ndarray
    slot: np.ndarray

    @property
    def num_frames(self) -> int:
        return int(self.slot.shape[1])

    @property
    def num_bodies(self) -> int:
        return len(self.body_ids)

    @property
    def present(self) -> np.ndarray:
        """bool ``[B, T]``: track ``b`` is in frame ``t``."""
        return self.slot >= 0

    # The 12 per-joint values by meaning (columns ``start:stop`` of ``joints``), each a converted copy.
    positions = _joint_values(0, 3, "float32 ``[B, T, 25, 3]`` camera-space joint positions in metres.")
    depth_xy = _joint_values(3, 5, "float32 ``[B, T, 25, 2]`` pixel positions in the 512×424 depth frame.")
    color_xy = _joint_values(5, 7, "float32 ``[B, T, 25, 2]`` pixel positions in the 1920×1080 colour frame.")
    orientation = _joint_values(7, 11, "float32 ``[B, T, 25, 4]`` joint orientation quaternions ``(w, x, y, z)``.")
    joint_tracking_state = _joint_values(
        11, None, "int8 ``[B, T, 25]``: 0 not tracked, 1 inferred, 2 tracked.", dtype=np.int8
    )

    @property
    def sample(self) -> NTUSampleName:
        """Setup, camera, subject, replication and action parsed from :attr:`name`."""
        return parse_ntu_name(self.name)

    @property
    def layout(self):
        return NTU25

    def body_field(self, field_name: str) -> np.ndarray:
        """``[B, T]`` values of one body-line field, e.g. ``"lean_x"`` or ``"tracking_state"``."""
        if field_name == "body_id":
            raise KeyError("body IDs are per track: use .body_ids")
        return self.body_info[..., BODY_INFO_FIELDS.index(field_name) - 1]


# --------------------------------------------------------------------------- reading


def read_skeleton(path: str | os.PathLike) -> SkeletonSequence:
    """Read one NTU ``.skeleton`` file.

    Raises:
        SkeletonFormatError: truncated, non-numeric, wrong counts or empty; the
            message names the file and the line.
    """
    path = Path(path)
    text = read_file_bytes(path, lambda p, message: SkeletonFormatError(p, None, message))
    return parse_skeleton_text(text, name=path.name, source=path)


def parse_skeleton_text(
    text: bytes | str, name: str = "<memory>", source: str | os.PathLike | None = None
) -> SkeletonSequence:
    """Parse the content of a ``.skeleton`` file (see :func:`read_skeleton`).

    The fast path splits the text into lines once, walks only the count lines in
    Python, and converts all joint lines with a single numpy call. Any
    inconsistency falls back to a line-by-line check that reports the line.
    """
    source = source if source is not None else name
    if isinstance(text, str):
        text = text.encode()
    lines = text.splitlines()  # handles \r\n, \n and \r
    stem = Path(name).name
    stem = stem.removesuffix(".skeleton")
    if not lines or not lines[0].strip():
        raise SkeletonFormatError(source, 1, "empty file: expected the frame count")

    num_frames = _parse_count(lines, 0, source, "frame count")
    # Walk the structure: collect (frame, slot, body line index) for every body.
    entries: list[tuple[int, int, int]] = []
    i = 1
    n_lines = len(lines)
    for t in range(num_frames):
        if i >= n_lines:
            raise SkeletonFormatError(source, i + 1, f"file ends before frame {t + 1} of {num_frames}")
        nb = _parse_count(lines, i, source, f"body count of frame {t + 1}")
        if nb > np.iinfo(np.int16).max:
            raise SkeletonFormatError(source, i + 1, f"body count {nb} of frame {t + 1} is not plausible")
        i += 1
        for s in range(nb):
            if i + 1 >= n_lines:
                raise SkeletonFormatError(
                    source, min(i + 1, n_lines) + 1, f"file ends inside body {s + 1} of frame {t + 1}"
                )
            nj = _parse_count(lines, i + 1, source, "joint count")
            if nj != NUM_JOINTS:
                raise SkeletonFormatError(source, i + 2, f"joint count is {nj}, expected {NUM_JOINTS}")
            if i + 2 + NUM_JOINTS > n_lines:
                raise SkeletonFormatError(
                    source, n_lines + 1, f"file ends inside the joints of body {s + 1} of frame {t + 1}"
                )
            entries.append((t, s, i))
            i += 2 + NUM_JOINTS
    trailing = [k for k in range(i, n_lines) if lines[k].strip()]
    if trailing:
        raise SkeletonFormatError(source, trailing[0] + 1, f"unexpected content after the last of {num_frames} frames")

    n_entries = len(entries)
    body_lines = [lines[e[2]] for e in entries]
    joint_lines = [lines[e[2] + 2 + j] for e in entries for j in range(NUM_JOINTS)]
    joint_values = _to_floats(joint_lines, JOINT_FIELDS)
    if joint_values is None:
        _raise_bad_line(
            lines, [e[2] + 2 + j for e in entries for j in range(NUM_JOINTS)], JOINT_FIELDS, source, "joint"
        )
    bad_rows = np.flatnonzero((~np.isfinite(joint_values)).any(axis=1))
    if len(bad_rows):
        k = int(bad_rows[0])
        e = entries[k // NUM_JOINTS]
        raise SkeletonFormatError(
            source,
            e[2] + 3 + k % NUM_JOINTS,
            f"non-finite joint value (NaN or infinite) in joint {k % NUM_JOINTS + 1} of body "
            f"{e[1] + 1} of frame {e[0] + 1}",
        )
    info_tokens = [ln.split() for ln in body_lines]
    bad = [k for k, tok in enumerate(info_tokens) if len(tok) != BODY_FIELDS]
    if bad:
        k = bad[0]
        raise SkeletonFormatError(
            source, entries[k][2] + 1, f"body line has {len(info_tokens[k])} values, expected {BODY_FIELDS}"
        )
    try:
        ids = [int(tok[0]) for tok in info_tokens]
        info_values = np.array([tok[1:] for tok in info_tokens], dtype=np.float64).reshape(n_entries, BODY_FIELDS - 1)
    except ValueError:
        _raise_bad_body_line(lines, [e[2] for e in entries], source)
    bad_rows = np.flatnonzero((~np.isfinite(info_values)).any(axis=1))
    if len(bad_rows):
        k = int(bad_rows[0])
        raise SkeletonFormatError(
            source,
            entries[k][2] + 1,
            f"non-finite value (NaN or infinite) in the body line "
            f"of body {entries[k][1] + 1} of frame {entries[k][0] + 1}",
        )

    # Group by body ID, in order of first appearance.
    track_of: dict[int, int] = {}
    for body_id in ids:
        track_of.setdefault(body_id, len(track_of))
    n_tracks = len(track_of)
    needed = n_tracks * num_frames * _BYTES_PER_TRACK_FRAME
    limit = track_memory_limit(len(text))
    if needed > limit:
        raise SkeletonFormatError(
            source,
            None,
            f"{n_tracks} distinct body IDs over {num_frames} frames would need "
            f"{needed / 2**20:.0f} MiB of track arrays, more than the "
            f"{limit / 2**20:.0f} MiB allowed for a {len(text)}-byte file "
            "(max(64 MiB, 32 x file size)); the body IDs are damaged",
        )
    joints = np.zeros((n_tracks, num_frames, NUM_JOINTS, JOINT_FIELDS), dtype=np.float64)
    body_info = np.zeros((n_tracks, num_frames, BODY_FIELDS - 1), dtype=np.float64)
    slot = np.full((n_tracks, num_frames), -1, dtype=np.int16)
    if n_entries:
        tr = np.fromiter((track_of[b] for b in ids), dtype=np.int64, count=n_entries)
        fr = np.fromiter((e[0] for e in entries), dtype=np.int64, count=n_entries)
        sl = np.fromiter((e[1] for e in entries), dtype=np.int16, count=n_entries)
        if np.any(slot[tr, fr] >= 0) or len(set(zip(tr.tolist(), fr.tolist()))) != n_entries:
            dup = _first_duplicate(tr, fr)
            raise SkeletonFormatError(
                source, entries[dup][2] + 1, f"body ID {ids[dup]} appears twice in frame {entries[dup][0] + 1}"
            )
        joints[tr, fr] = joint_values.reshape(n_entries, NUM_JOINTS, JOINT_FIELDS)
        body_info[tr, fr] = info_values
        slot[tr, fr] = sl
    return SkeletonSequence(name=stem, body_ids=list(track_of), joints=joints, body_info=body_info, slot=slot)


def _parse_count(lines: list[bytes], i: int, source, what: str) -> int:
    raw = lines[i].strip()
    try:
        value = int(raw)
    except ValueError:
        raise SkeletonFormatError(source, i + 1, f"expected an integer {what}, found {raw[:40]!r}") from None
    if value < 0:
        raise SkeletonFormatError(source, i + 1, f"negative {what} {value}")
    return value


def _to_floats(lines: list[bytes], width: int) -> np.ndarray | None:
    """All ``lines`` as one float64 ``[len(lines), width]`` array, or None if any line is off."""
    if not lines:
        return np.zeros((0, width))
    try:  # numpy's C text parser; blank lines are skipped by loadtxt, so the shape check catches them
        values = np.loadtxt(io.BytesIO(b"\n".join(lines)), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None
    return values if values.shape == (len(lines), width) else None


def _raise_bad_line(lines, indices, width, source, what):
    for k in indices:
        tok = lines[k].split()
        if len(tok) != width:
            raise SkeletonFormatError(source, k + 1, f"{what} line has {len(tok)} values, expected {width}")
        for v in tok:
            try:
                float(v)
            except ValueError:
                raise SkeletonFormatError(
                    source, k + 1, f"non-numeric {what} value {v.decode(errors='replace')!r}"
                ) from None
    raise SkeletonFormatError(source, None, f"unparseable {what} lines")  # pragma: no cover - defensive


def _raise_bad_body_line(lines, indices, source):
    for k in indices:
        tok = lines[k].split()
        try:
            int(tok[0])
            [float(v) for v in tok[1:]]
        except ValueError:
            raise SkeletonFormatError(
                source, k + 1, f"non-numeric body line {lines[k].decode(errors='replace')[:60]!r}"
            ) from None
    raise SkeletonFormatError(source, None, "unparseable body lines")  # pragma: no cover - defensive


def _first_duplicate(tracks: np.ndarray, frames: np.ndarray) -> int:
    seen = set()
    for k, key in enumerate(zip(tracks.tolist(), frames.tolist())):
        if key in seen:
            return k
        seen.add(key)
    return 0  # pragma: no cover - only called when a duplicate exists


# --------------------------------------------------------------------------- writing


def write_skeleton(path: str | os.PathLike, seq: SkeletonSequence, newline: str = "\r\n") -> None:
    """Write ``seq`` as a ``.skeleton`` file that :func:`read_skeleton` reads back identically.

    Values are printed with 7 significant digits (``%.7G``), the precision of the
    Kinect SDK dumps, so a file read and written again is byte-identical to the
    original apart from the line ends. ``newline`` defaults to CRLF like NTU.
    """
    B, T = seq.slot.shape
    if seq.joints.shape != (B, T, NUM_JOINTS, JOINT_FIELDS):
        raise ValueError(f"joints must be [{B}, {T}, 25, 12], got {list(seq.joints.shape)}")
    if not np.isfinite(seq.joints).all():
        raise ValueError(f"{path}: sequence {seq.name} has non-finite joint values")
    # Format every joint line of every present body in one go (the writer is on the synthesis hot path).
    order = np.argsort(np.where(seq.slot >= 0, seq.slot, np.iinfo(np.int16).max), axis=0, kind="stable")  # [B, T]
    counts = (seq.slot >= 0).sum(0)
    rows_b = [order[k, t] for t in range(T) for k in range(counts[t])]
    rows_t = [t for t in range(T) for _ in range(counts[t])]
    jvals = seq.joints[rows_b, rows_t].reshape(-1, JOINT_FIELDS) if rows_b else np.zeros((0, JOINT_FIELDS))
    joint_text = _format_rows(jvals, "%.7G " * (JOINT_FIELDS - 1) + "%d")
    info = seq.body_info[rows_b, rows_t] if rows_b else np.zeros((0, BODY_FIELDS - 1))
    info_fmt = " ".join(["%d"] * 6 + ["%.7G"] * 2 + ["%d"])
    out = [str(T)]
    k = 0
    for t in range(T):
        out.append(str(int(counts[t])))
        for _ in range(counts[t]):
            out.append(f"{seq.body_ids[rows_b[k]]} " + info_fmt % tuple(info[k]))
            out.append(str(NUM_JOINTS))
            out.extend(joint_text[k * NUM_JOINTS : (k + 1) * NUM_JOINTS])
            k += 1
    Path(path).write_text(newline.join(out) + newline, encoding="ascii", newline="")


def _format_rows(values: np.ndarray, fmt: str) -> list[str]:
    """Each row of ``values`` ``[n, k]`` printed with ``fmt`` (k fields): one ``%`` over all rows, then split
    (0.6× the time of one ``%`` per row)."""
    if len(values) == 0:
        return []
    return ((fmt + "\n") * len(values) % tuple(values.ravel().tolist())).split("\n")[:-1]


def sequence_from_positions(
    name: str, positions: np.ndarray, body_ids: list[int] | None = None, present: np.ndarray | None = None
) -> SkeletonSequence:
    """Build a :class:`SkeletonSequence` from 3-D positions alone (e.g. for synthetic data).

    Args:
        positions: ``[B, T, 25, 3]`` metres, camera space.
        body_ids: one ID per track (defaults to Kinect-like 17-digit IDs).
        present: bool ``[B, T]``; defaults to frames where the body is not all zero.

    The depth and colour pixel coordinates are projected with Kinect v2-like
    intrinsics, orientations are identity and every joint is "tracked" (2).
    """
    positions = np.asarray(positions, dtype=np.float64)
    B, T = positions.shape[:2]
    if positions.shape[2:] != (NUM_JOINTS, 3):
        raise ValueError(f"positions must be [B, T, 25, 3], got {list(positions.shape)}")
    if present is None:
        present = np.abs(positions).sum(axis=(2, 3)) > 0
    if body_ids is None:
        body_ids = [72057594037927936 + 1000 + b for b in range(B)]
    joints = np.zeros((B, T, NUM_JOINTS, JOINT_FIELDS))
    joints[..., 0:3] = positions
    z = np.maximum(positions[..., 2], 0.1)
    joints[..., 3] = 256.0 + 365.0 * positions[..., 0] / z  # depth camera, ~365 px focal length
    joints[..., 4] = 212.0 - 365.0 * positions[..., 1] / z
    joints[..., 5] = 960.0 + 1060.0 * positions[..., 0] / z  # colour camera, ~1060 px focal length
    joints[..., 6] = 540.0 - 1060.0 * positions[..., 1] / z
    joints[..., 7] = 1.0
    joints[..., 11] = 2
    joints[~present] = 0.0
    body_info = np.zeros((B, T, BODY_FIELDS - 1))
    body_info[..., 8] = 2  # body trackingState
    body_info[~present] = 0.0
    slot = np.where(present, np.cumsum(present, axis=0) - 1, -1).astype(np.int16)
    return SkeletonSequence(name=name, body_ids=list(body_ids), joints=joints, body_info=body_info, slot=slot)


# --------------------------------------------------------------------------- body selection

#: Length rule (NTU authors' ``get_raw_denoised_data.py``, used by pyskl): a track must be present in
#: more than 11 frames, i.e. at least this many.
MIN_BODY_FRAMES = 12
#: Spread rule (same script): a frame is "wide" when its x-spread exceeds ``SPREAD_RATIO`` × its y-spread;
#: a track wide in at least ``SPREAD_THRESHOLD`` of its frames is not a person (a chair, a table).
SPREAD_RATIO = 0.8
SPREAD_THRESHOLD = 0.69754
#: Flicker rule (ours, see :func:`select_main_bodies`): a person's track covers at least this fraction of
#: the observed frames between its first and last appearance ...
MIN_SPAN_COVERAGE = 0.8
#: ... and its centre (mean of the 25 joints) moves at most this far between consecutive frames, metres
#: (median over its pairs of consecutive present frames; 0.3 m a frame is 9 m/s at 30 fps).
MAX_MEDIAN_STEP_M = 0.3

#: Rule codes of :attr:`BodySelection.rules` for a dropped track.
DROP_RULES = ("short", "spread", "flicker", "jump", "less_motion")
#: Rule codes for a kept track: ranked by motion among several candidates, the only candidate left by the
#: rules, or kept although a rule would drop it (every candidate failed that rule; see select_main_bodies).
KEEP_RULES = ("most_motion", "only_candidate", "rescued_short", "rescued_spread", "rescued_flicker")


@dataclass
class BodySelection:
    """Which tracks :func:`select_main_bodies` kept and why, and why the others were dropped.

    Attributes:
        positions: float32 ``[max_bodies, T, 25, 3]``, kept tracks in rank order (body 0 first), zero padded.
        kept: indices into the sequence's tracks, body 0 first.
        dropped: ``{track index: reason}`` for every track not kept (a sentence with the measured value).
        kept_reasons: ``{track index: reason}`` for every kept track.
        rules: ``{track index: code}`` for every track: one of :data:`DROP_RULES` or :data:`KEEP_RULES`.
    """

    positions: np.ndarray
    kept: list[int]
    dropped: dict[int, str] = field(default_factory=dict)
    kept_reasons: dict[int, str] = field(default_factory=dict)
    rules: dict[int, str] = field(default_factory=dict)


def body_motion(positions: np.ndarray, present: np.ndarray) -> np.ndarray:
    """Sum over x, y, z of the joint-position variance over each track's present frames (NTU FAQ).

    Args:
        positions: ``[B, T, 25, 3]``; present: bool ``[B, T]``. Returns ``[B]`` (square metres).
    """
    out = np.zeros(len(positions))
    for b in range(len(positions)):
        p = positions[b][present[b]]
        if len(p) > 1:
            out[b] = p.reshape(len(p), -1, 3).var(axis=0).sum()
    return out


def spread_noise_ratio(positions: np.ndarray, present: np.ndarray, ratio: float = SPREAD_RATIO) -> np.ndarray:
    """Fraction of each track's frames whose x-spread exceeds ``ratio`` × y-spread, ``[B]``.

    Non-human "bodies" (chairs, tables) are wider than tall; the NTU authors' script (and pyskl)
    drop a track when this fraction is at least :data:`SPREAD_THRESHOLD` (0.69754).
    """
    spread = positions.max(axis=2) - positions.min(axis=2)  # [B, T, 3]
    wide = spread[..., 0] > ratio * spread[..., 1]
    n = np.maximum(present.sum(1), 1)
    return (wide & present).sum(1) / n


def track_steadiness(positions: np.ndarray, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How steadily each track is seen and how far it jumps: ``(span_coverage [B], median_step [B])``.

    Args:
        positions: ``[B, T, 25, 3]`` metres; present: bool ``[B, T]``.

    Returns:
        span_coverage: the fraction of the *observed* frames (frames in which any track is
            present; frames the sensor lost entirely do not count) between the track's first and
            last appearance in which it is present. 1.0 for a track seen without a gap; about
            ``p`` for a track that appears in a random fraction ``p`` of the frames.
        median_step: the median distance (metres) its centre, the mean of its joints, moves
            between consecutive frames ``t, t+1`` in which it is present in both; 0 if there is
            no such pair.
    """
    B = len(positions)
    observed = present.any(axis=0)
    seen = present[:, observed]  # [B, T_obs]
    coverage = np.ones(B)
    step = np.zeros(B)
    centre = positions.mean(axis=2)  # [B, T, 3]
    for b in range(B):
        idx = np.flatnonzero(seen[b])
        if len(idx):
            coverage[b] = len(idx) / (idx[-1] - idx[0] + 1)
        pairs = present[b, 1:] & present[b, :-1]
        if pairs.any():
            moves = np.linalg.norm(centre[b, 1:] - centre[b, :-1], axis=-1)[pairs]
            step[b] = float(np.median(moves))
    return coverage, step


def select_main_bodies(
    seq: SkeletonSequence,
    max_bodies: int = 2,
    denoise_spread: bool = True,
    spread_threshold: float = SPREAD_THRESHOLD,
    min_frames: int = MIN_BODY_FRAMES,
    denoise_flicker: bool = True,
    min_span_coverage: float = MIN_SPAN_COVERAGE,
    max_median_step: float = MAX_MEDIAN_STEP_M,
) -> BodySelection:
    """Reduce a file's tracks to its (at most) ``max_bodies`` actors, body 0 first; report every decision.

    The rules run in this order, each on the tracks the previous ones left (*candidates*); the
    first three follow the NTU authors' preprocessing (``get_raw_denoised_data.py``, used by pyskl),
    the flicker rule is ours:

    1. **Length**: drop a track present in fewer than ``min_frames`` frames (12: "more than 11"),
       except the longest track(s) of the file: a short clip still gives a body.
    2. **Spread** (``denoise_spread``): drop a track whose x-spread exceeds 0.8 × its y-spread in at
       least ``spread_threshold`` of its frames (wider than tall: a chair, a table).
    3. **Flicker** (``denoise_flicker``): drop a track that is present in fewer than
       ``min_span_coverage`` of the observed frames of its own span (it appears and disappears:
       reason ``flicker``), or whose centre moves more than ``max_median_step`` metres between
       consecutive frames (median over its consecutive present pairs: reason ``jump``); see
       :func:`track_steadiness`. Why: the motion ranking of step 4 is a variance over a track's
       present frames, so a spurious detection that comes and goes and jumps around has by far
       the largest "motion" and would become body 0; a person is tracked without gaps (the Kinect
       SDK gives a new body ID after losing someone) and moves less than 9 m/s. Frames in which
       the sensor saw no body at all do not count as gaps.
    4. **Motion**: rank the remaining tracks by :func:`body_motion` (NTU FAQ: most motion is the
       actor), keep the first ``max_bodies``, drop the rest (``less_motion``).

    No rule leaves a file without a body: rule 1 keeps the longest track(s) even when they are short
    (rule code ``rescued_short``), and when rule 2 or 3 would drop every candidate, the one it judges
    best (the least wide; the best covered, then the smallest step; ties: more frames, then file
    order) is kept, with the rule code ``rescued_spread`` / ``rescued_flicker``; the reason is in
    :attr:`BodySelection.kept_reasons`.
    Only a file with no body in any frame gives none. ``denoise_spread=False, min_frames=1,
    denoise_flicker=False`` is the former default (most motion wins).

    Args:
        max_bodies: tracks kept (2 for NTU training).
        denoise_spread, spread_threshold: rule 2.
        min_frames: rule 1 (1 disables it).
        denoise_flicker, min_span_coverage, max_median_step: rule 3.
    """
    if max_bodies < 1:
        raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
    positions = seq.positions
    present = seq.present
    counts = present.sum(1)
    dropped: dict[int, str] = {}
    kept_reasons: dict[int, list[str]] = {}  # rescues, per track
    rules: dict[int, str] = {}
    candidates = [b for b in range(seq.num_bodies) if counts[b] > 0]
    for b in range(seq.num_bodies):
        if counts[b] == 0:  # cannot come from a parsed file (a track exists because it is somewhere)
            dropped[b], rules[b] = "present in no frame", "short"

    # 1. length: never below the longest track
    if candidates:
        longest = max(int(counts[b]) for b in candidates)
        short = [b for b in candidates if counts[b] < min_frames and counts[b] < longest]
        for b in short:
            dropped[b], rules[b] = f"present in {counts[b]} frames (< {min_frames})", "short"
        candidates = [b for b in candidates if b not in short]
        for b in candidates:
            if counts[b] < min_frames:
                rules[b] = "rescued_short"
                kept_reasons[b] = [
                    (f"present in only {counts[b]} frames (< {min_frames}), but no track of the file is longer")
                ]

    # 2. spread
    if denoise_spread and len(candidates) > 1:
        noise = spread_noise_ratio(positions, present)
        wide = [b for b in candidates if noise[b] >= spread_threshold]
        if len(wide) == len(candidates):  # every candidate is wide: keep the least wide
            best = min(candidates, key=lambda b: (noise[b], -counts[b], b))
            wide.remove(best)
            rules[best] = "rescued_spread"
            kept_reasons.setdefault(best, []).append(
                f"wider than tall in {noise[best]:.0%} of its frames, like every other track: the least wide is kept"
            )
        for b in wide:
            dropped[b], rules[b] = (
                (f"spread denoising: wider than tall in {noise[b]:.0%} of its frames (>= {spread_threshold:.3%})"),
                "spread",
            )
        candidates = [b for b in candidates if b not in wide]

    # 3. flicker and jumps
    if denoise_flicker and len(candidates) > 1:
        coverage, step = track_steadiness(positions, present)
        unsteady = {}
        for b in candidates:
            if coverage[b] < min_span_coverage:
                unsteady[b] = (
                    "flicker",
                    (
                        f"flickering: present in {coverage[b]:.0%} of the observed frames "
                        f"of its span (< {min_span_coverage:.0%})"
                    ),
                )
            elif step[b] > max_median_step:
                unsteady[b] = (
                    "jump",
                    (f"jumping: its centre moves {step[b]:.2f} m a frame (median; > {max_median_step:g} m)"),
                )
        if len(unsteady) == len(candidates):  # every candidate is unsteady: keep the steadiest
            best = min(candidates, key=lambda b: (-coverage[b], step[b], -counts[b], b))
            rules[best] = "rescued_flicker"
            kept_reasons.setdefault(best, []).append(
                f"{unsteady.pop(best)[1]}, like every other track: the steadiest is kept"
            )
        for b, (rule, reason) in unsteady.items():
            dropped[b], rules[b] = reason, rule
        candidates = [b for b in candidates if b not in unsteady]

    # 4. motion
    motion = body_motion(positions, present)
    candidates.sort(key=lambda b: (-motion[b], b))
    kept = candidates[:max_bodies]
    for b in candidates[max_bodies:]:
        dropped[b], rules[b] = f"less motion ({motion[b]:.4g}) than the {max_bodies} kept tracks", "less_motion"
    reasons = {}
    for rank, b in enumerate(kept):
        if len(candidates) == 1:
            why = "the only track" if seq.num_bodies == 1 else f"the only track left by the rules (of {seq.num_bodies})"
        else:
            why = f"motion {motion[b]:.4g}, rank {rank + 1} of {len(candidates)} candidates"
        if b in kept_reasons:  # rescued by a rule: the rule code stays rescued_*
            why = "; ".join([*kept_reasons[b], why])
        else:
            rules[b] = "only_candidate" if len(candidates) == 1 else "most_motion"
        reasons[b] = why
    out = np.zeros((max_bodies,) + positions.shape[1:], dtype=np.float32)
    for k, b in enumerate(kept):
        out[k] = positions[b]
    return BodySelection(positions=out, kept=kept, dropped=dropped, kept_reasons=reasons, rules=rules)


def read_missing_list(path: str | os.PathLike) -> set[str]:
    """Sample names in an official "samples with missing skeletons" list (prose header lines skipped)."""
    names = set()
    for line in Path(path).read_text(encoding="utf-8", errors="replace").splitlines():
        match = _NAME_RE.fullmatch(line.strip())
        if match:
            names.add(line.strip())
    return names
