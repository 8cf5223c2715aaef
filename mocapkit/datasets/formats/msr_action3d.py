"""MSR Action3D skeleton files: the text reader.

Files (Li, Zhang & Liu, CVPR-W 2010; shared/data/SOURCES.md) are named
``aAA_sSS_eEE_skeleton3D.txt`` (action, subject, take; 1-based). They have no
header and 20 rows of 4 whitespace-separated numbers per frame, at 15 fps, in
MSR's own joint order (:data:`~mocapkit.motion.layouts.MSR20`):

* ``_skeleton3D.txt`` ("Real3D"): ``x y z c`` with x y z in metres (y up, z the
  depth from the camera, about 2-3 m) and c a confidence in [0, 1];
* ``_skeleton.txt`` (screen): ``u v d c`` with u v in pixels of the 320x240 depth
  image (v grows downwards) and d a depth value in undocumented units.

A joint whose three coordinates are all zero is missing (NaN in the
:class:`~mocapkit.motion.container.Motion`, True in ``missing``); 19 of the
567 Real3D files have such frames, and ``a13_s09_e02`` is zero throughout
(``metadata["all_zero"]``; :class:`MSRAction3D` leaves it out, with the
reason in ``excluded``).

Left and right (checked on all 567 Real3D files): Li et al. asked subjects to
use the right arm or leg for one-limb actions. In the one-arm actions a01-a07
(high arm wave ... draw x) the wrist on row 11 (``WristRight``, index 10) moves
more than the one on row 10 in 185 of 187 sequences, and in the kicks a14/a15
the ankle on row 17 (``AnkleRight``, index 16) moves more in 49 of 50. The
second joint of each pair also has the larger x (row 2 minus row 1 > 0 in
99% of files, median +0.35 m), i.e. x grows towards the subject's right. So
the second joint of each pair is the right one, as :data:`MSR20` has it.

The data set (:class:`~mocapkit.datasets.msr_action3d.dataset.MSRAction3D`) and its protocols
(:mod:`mocapkit.datasets.msr_action3d.splits`) live in :mod:`mocapkit.datasets.msr_action3d`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes
from mocapkit.motion.container import Motion, all_coordinates
from mocapkit.motion.layouts import MSR20

JOINTS_PER_FRAME = 20
FPS = 15.0

_NAME = re.compile(r"^a(\d+)_s(\d+)_e(\d+)_skeleton(3D)?\.txt$", re.IGNORECASE)


class MSRFormatError(MotionFormatError):
    """A malformed MSR Action3D skeleton file; the message names the file and the line."""


@dataclass(frozen=True)
class MSRSampleName:
    """``aAA_sSS_eEE`` of a file name (1-based IDs) and its coordinate kind."""

    action: int
    subject: int
    take: int
    kind: str  # "real3d" or "screen"

    @property
    def stem(self) -> str:
        return f"a{self.action:02d}_s{self.subject:02d}_e{self.take:02d}"


def parse_msr_name(path: str | Path) -> MSRSampleName:
    """Action, subject and take of ``aAA_sSS_eEE_skeleton3D.txt`` (or ``_skeleton.txt``)."""
    name = Path(path).name
    match = _NAME.match(name)
    if not match:
        raise ValueError(f"{name!r} is not an MSR Action3D skeleton file name (aAA_sSS_eEE_skeleton3D.txt)")
    action, subject, take, real = match.groups()
    return MSRSampleName(int(action), int(subject), int(take), "real3d" if real else "screen")


def _parse_rows(path: Path, text: str) -> np.ndarray:
    """The float32 ``[rows, 4]`` array of a file; errors name the line (1-based, counting blank lines).

    NaN, infinite values and values beyond the float32 range are errors naming the line.
    """
    lines = text.splitlines()
    rows, numbers = [], []
    for number, line in enumerate(lines, start=1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != 4:
            raise MSRFormatError(path, number, f"expected 4 numbers (x y z c), got {len(fields)}: {line.strip()!r}")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise MSRFormatError(path, number, f"not a number in {line.strip()!r}") from None
        numbers.append(number)
    if not rows:
        raise MSRFormatError(path, 1, "the file holds no skeleton rows")
    if len(rows) % JOINTS_PER_FRAME:
        complete = len(rows) // JOINTS_PER_FRAME
        first_of_partial = numbers[complete * JOINTS_PER_FRAME]
        raise MSRFormatError(
            path,
            first_of_partial,
            f"frame {complete + 1} is incomplete: the file has {len(rows)} rows, "
            f"not a multiple of {JOINTS_PER_FRAME} (the last {len(rows) % JOINTS_PER_FRAME} rows, from line "
            f"{first_of_partial} on, are left over)",
        )
    values = np.asarray(rows, dtype=np.float64)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise MSRFormatError(path, numbers[int(np.argmax(bad))], "non-finite value (NaN or infinite)")
    # Positions are stored as float32: a value beyond its range would silently become inf.
    big = (np.abs(values) > np.finfo(np.float32).max).any(axis=1)
    if big.any():
        row = int(np.argmax(big))
        raise MSRFormatError(
            path,
            numbers[row],
            f"value {values[row][np.abs(values[row]) > np.finfo(np.float32).max][0]:g} "
            "is beyond the float32 range (about 3.4e38)",
        )
    return values.astype(np.float32)


def read_msr_skeleton(path: str | Path, kind: str = "auto") -> Motion:
    """Read one MSR Action3D skeleton file as a :class:`Motion` on the :data:`MSR20` layout.

    Args:
        path: an ``aAA_sSS_eEE_skeleton3D.txt`` (Real3D, metres) or ``_skeleton.txt`` (screen) file.
        kind: ``"real3d"``, ``"screen"`` or ``"auto"`` (from the file name; Real3D if the name says nothing).

    Returns:
        ``positions`` ``[frames, 20, 3]`` (metres for Real3D; ``u, v, d`` as stored for screen files,
        see ``source_units``), NaN where a joint is all zeros; ``metadata`` holds ``confidence``
        ``[frames, 20]``, ``action`` / ``subject`` / ``take`` (when the name parses), ``coordinates``
        and ``all_zero`` (True when every value of the file is zero: a known defect, not an error).

    Raises:
        MSRFormatError: a row without 4 numbers, a non-numeric value, or a row count that is
            not a multiple of 20; the message names the file and the line.
    """
    path = Path(path)
    try:
        sample = parse_msr_name(path)
    except ValueError:
        sample = None
    if kind == "auto":
        kind = sample.kind if sample is not None else "real3d"
    if kind not in ("real3d", "screen"):
        raise ValueError(f"kind must be 'real3d', 'screen' or 'auto', got {kind!r}")
    text = read_file_bytes(path, lambda p, message: MSRFormatError(p, None, message))
    values = _parse_rows(path, text.decode("ascii", errors="replace"))
    frames = values.reshape(-1, JOINTS_PER_FRAME, 4)
    coords = frames[..., :3]
    confidence = frames[..., 3]
    missing = all_coordinates(coords == 0)
    all_zero = bool((frames == 0).all())
    metadata = {
        "confidence": confidence,
        "all_zero": all_zero,
        "coordinates": kind,
        "missing_frames": int(missing.all(axis=1).sum()),
    }
    if sample is not None:
        metadata.update(action=sample.action, subject=sample.subject, take=sample.take)
    if kind == "real3d":
        units, up = "m", "y"
    else:
        units, up = "u, v: pixels of the 320x240 depth image (v grows downwards); d: depth, units undocumented", "y"
        metadata["v_down"] = True
    positions = np.where(missing[..., None], np.float32(np.nan), coords)
    return Motion(
        positions=positions,
        joint_names=MSR20.joint_names,
        parents=MSR20.parents,
        fps=FPS,
        missing=missing,
        source_units=units,
        up_axis=up,
        name=sample.stem if sample else path.stem,
        source=str(path),
        layout_name=MSR20.name,
        metadata=metadata,
    )
