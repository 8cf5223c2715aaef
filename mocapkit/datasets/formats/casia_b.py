"""The CASIA-B silhouette layout: ``<subject>/<condition>-<nn>/<view>/<frame>.png``.

CASIA-B (Yu, Tan & Tan, ICPR 2006) has 124 subjects (``001``..``124``), each
walking 10 times past 11 cameras: 6 normal walks (``nm-01``..``nm-06``), 2 with
a bag (``bg-01``, ``bg-02``) and 2 in a coat (``cl-01``, ``cl-02``); the cameras
sit at azimuths 0°..180° in 18° steps (folder names ``000``..``180``). Each
``<view>`` folder holds one binary silhouette PNG per frame, e.g.
``001-nm-01-090-045.png``; frames sort by the trailing number.

This module holds the layout's vocabulary (shared by the reader, the
synthetic generator, the GEI preparation and the protocols) and the reader:

* :func:`list_casia_b` walks a root folder and returns a :class:`CasiaBListing`:
  one :class:`GaitSequence` per ``<view>`` folder (frames naturally sorted), the
  layout problems it met (odd folder names, empty view folders, stray files) and,
  through :meth:`CasiaBListing.missing`, every expected sequence that is absent.
* :func:`read_silhouette` reads one PNG as a binary ``uint8 [H, W]`` mask (0 / 255).
* :func:`read_sequence` reads a whole view folder as ``uint8 [T, H, W]``.

Real CASIA-B quirks the reader tolerates: ``Thumbs.db`` and other non-PNG files
(ignored, reported), empty or missing view folders (reported), frame names of any
shape as long as the stem ends with a number, a few gray (JPEG-like) pixels near
the edges (thresholded at 128), all-black frames (kept: the GEI builder drops them).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes

#: Walking conditions, in label order (the condition task's classes).
CONDITIONS: tuple[str, ...] = ("nm", "bg", "cl")
#: Sequences per condition and subject in CASIA-B.
SEQUENCES_PER_CONDITION: dict[str, int] = {"nm": 6, "bg": 2, "cl": 2}
#: Camera azimuths in degrees, in label order (the view task's classes).
VIEWS: tuple[int, ...] = tuple(range(0, 181, 18))
#: Subjects in the real set.
NUM_SUBJECTS = 124


class SilhouetteFormatError(MotionFormatError):
    """An unreadable, non-binary or otherwise unusable silhouette PNG or sequence folder.

    ``line`` is always None; ``frame`` is the frame number from the file name where known.
    """


@dataclass(frozen=True, order=True)
class GaitSequenceKey:
    """One CASIA-B sequence: subject (1-based), condition (``nm``/``bg``/``cl``), repetition (1-based), view (degrees)."""

    subject: int
    condition: str
    sequence: int
    view: int

    @property
    def name(self) -> str:
        """The sequence's relative folder, e.g. ``"001/nm-01/090"``."""
        return f"{self.subject:03d}/{self.condition}-{self.sequence:02d}/{self.view:03d}"

    @property
    def condition_label(self) -> int:
        return CONDITIONS.index(self.condition)

    @property
    def view_label(self) -> int:
        return VIEWS.index(self.view)

    def frame_name(self, frame: int) -> str:
        """CASIA-B's frame file name, e.g. ``"001-nm-01-090-045.png"`` (frame 1-based)."""
        return f"{self.subject:03d}-{self.condition}-{self.sequence:02d}-{self.view:03d}-{frame:03d}.png"


def parse_sequence_folder(relative: str | os.PathLike) -> GaitSequenceKey:
    """Parse ``"<subject>/<condition>-<nn>/<view>"`` (a path relative to the root) into a key.

    Raises:
        ValueError: the path does not follow the layout (the message names it).
    """
    parts = os.fspath(relative).replace("\\", "/").strip("/").split("/")
    if len(parts) != 3:
        raise ValueError(f"{relative}: expected <subject>/<condition>-<nn>/<view>")
    subject, walk, view = parts
    condition, _, number = walk.partition("-")
    if not (subject.isdigit() and number.isdigit() and view.isdigit() and condition in CONDITIONS):
        raise ValueError(f"{relative}: expected <subject>/<condition>-<nn>/<view> with condition in {CONDITIONS}")
    if int(view) not in VIEWS:
        raise ValueError(f"{relative}: view {view} is not one of {VIEWS}")
    return GaitSequenceKey(int(subject), condition, int(number), int(view))


# --------------------------------------------------------------------------- listing

#: The layout, as said in error messages.
EXPECTED_LAYOUT = (
    "<root>/<subject>/<condition>-<nn>/<view>/<frame>.png, e.g. 001/nm-01/090/001-nm-01-090-045.png "
    f"(conditions {CONDITIONS}, views 000..180 in steps of 18)"
)
#: Root-level files that document a data set (README.txt, a config .json) rather than break its layout.
_ROOT_DOC_SUFFIXES = (".txt", ".md", ".json")
_TRAILING_INT = re.compile(r"(\d+)\D*$")


def frame_number(path: str | os.PathLike) -> int | None:
    """The last integer in a frame file's stem (``001-nm-01-090-045.png`` -> 45), or None if it has none."""
    match = _TRAILING_INT.search(Path(path).stem)
    return int(match.group(1)) if match else None


@dataclass(frozen=True)
class GaitSequence:
    """One view folder: the silhouettes of one walk seen by one camera.

    Attributes:
        key: subject, condition, repetition and view.
        folder: the ``<view>`` folder.
        frames: its PNG files sorted by frame number (natural order); empty for an empty folder.
    """

    key: GaitSequenceKey
    folder: Path
    frames: tuple[Path, ...]

    @property
    def num_frames(self) -> int:
        return len(self.frames)


@dataclass
class CasiaBListing:
    """What :func:`list_casia_b` found under a root folder.

    Attributes:
        root: the folder listed.
        sequences: every view folder that follows the layout (empty ones included), sorted by key.
        problems: one line per thing that does not follow the layout: odd folder names, empty view
            folders, stray (non-PNG) files and PNGs without a frame number; each is left out of
            ``sequences`` (an empty view folder is listed there, with no frames).
        subjects: the subjects asked for (``subjects=`` of :func:`list_casia_b`), or None for all found.
    """

    root: Path
    sequences: list[GaitSequence] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    subjects: tuple[int, ...] | None = None

    def missing(
        self, expected_conditions: dict[str, int] = SEQUENCES_PER_CONDITION, views: Iterable[int] = VIEWS
    ) -> list[str]:
        """Every expected ``"<subject>/<condition>-<nn>/<view>"`` with no view folder, sorted.

        Expected: for each subject found (or asked for), ``nn`` = 1..``expected_conditions[c]`` of each
        condition and every view. Empty view folders are not missing (they are in :attr:`problems`).
        """
        present = {s.key for s in self.sequences}
        subjects = sorted(set(self.subjects) if self.subjects is not None else {k.subject for k in present})
        absent = []
        for subject in subjects:
            for condition in CONDITIONS:
                for number in range(1, expected_conditions.get(condition, 0) + 1):
                    for view in views:
                        key = GaitSequenceKey(subject, condition, number, int(view))
                        if key not in present:
                            absent.append(key)
        return [k.name for k in sorted(absent)]

    def __len__(self) -> int:
        return len(self.sequences)


def _scan_view_folder(folder: Path, relative: str, problems: list[str]) -> tuple[Path, ...]:
    """The sorted PNG frames of one view folder; other entries go to ``problems``."""
    numbered = []
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        path = Path(entry.path)
        if entry.is_dir():
            problems.append(f"{relative}/{entry.name}: unexpected folder inside a view folder (ignored)")
        elif path.suffix.lower() != ".png":
            problems.append(f"{relative}/{entry.name}: stray file, not a PNG (ignored)")
        else:
            number = frame_number(path)
            if number is None:
                problems.append(f"{relative}/{entry.name}: PNG without a frame number in its name (ignored)")
            else:
                numbered.append((number, entry.name, path))
    numbered.sort()
    if not numbered:
        problems.append(f"{relative}: empty view folder (no PNG frames)")
    return tuple(p for _, _, p in numbered)


def list_casia_b(root: str | os.PathLike, subjects: Iterable[int] | None = None) -> CasiaBListing:
    """List the sequences of a CASIA-B style silhouette folder.

    Args:
        root: the folder holding ``<subject>`` folders (``001``, ``002``, ...).
        subjects: only these subject numbers (1-based); default all subject folders found.

    Returns:
        a :class:`CasiaBListing`; nothing that does not fit the layout is dropped without a line in
        ``problems`` (root-level ``.txt`` / ``.md`` / ``.json`` files, e.g. a README, are documentation
        and are not reported).

    Raises:
        FileNotFoundError: ``root`` does not exist or is not a folder.
        ValueError: no sequence (view folder) at all was found; the message gives the expected layout.
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: CASIA-B root folder not found")
    wanted = None if subjects is None else tuple(sorted({int(s) for s in subjects}))
    listing = CasiaBListing(root=root, subjects=wanted)
    problems = listing.problems
    for subject_entry in sorted(os.scandir(root), key=lambda e: e.name):
        name = subject_entry.name
        if not subject_entry.is_dir():
            if Path(name).suffix.lower() not in _ROOT_DOC_SUFFIXES:
                problems.append(f"{name}: stray file at the root (ignored)")
            continue
        if not name.isdigit():
            problems.append(f"{name}: not a subject folder (expected a number like 001; ignored)")
            continue
        if wanted is not None and int(name) not in wanted:
            continue
        for walk_entry in sorted(os.scandir(subject_entry.path), key=lambda e: e.name):
            walk_rel = f"{name}/{walk_entry.name}"
            if not walk_entry.is_dir():
                problems.append(f"{walk_rel}: stray file in a subject folder (ignored)")
                continue
            view_entries = sorted(os.scandir(walk_entry.path), key=lambda e: e.name)
            if not view_entries:
                problems.append(f"{walk_rel}: empty condition folder (no view folders)")
            for view_entry in view_entries:
                relative = f"{walk_rel}/{view_entry.name}"
                if not view_entry.is_dir():
                    problems.append(f"{relative}: stray file in a condition folder (ignored)")
                    continue
                try:
                    key = parse_sequence_folder(relative)
                except ValueError as exc:
                    problems.append(f"{exc} (ignored)")
                    continue
                frames = _scan_view_folder(Path(view_entry.path), relative, problems)
                listing.sequences.append(GaitSequence(key, Path(view_entry.path), frames))
    if not listing.sequences:
        which = "" if wanted is None else f" for subjects {list(wanted)}"
        raise ValueError(f"{root}: no CASIA-B sequence found{which}; expected {EXPECTED_LAYOUT}")
    listing.sequences.sort(key=lambda s: s.key)
    return listing


# --------------------------------------------------------------------------- reading

#: A frame is not a silhouette when more than this fraction of its pixels is clearly gray.
#: Largest silhouette PNG read (bytes) and frame (pixels); CASIA-B frames are 320x240, a few KB each.
MAX_SILHOUETTE_BYTES = 64 << 20
MAX_SILHOUETTE_PIXELS = 4096 * 4096
MAX_GRAY_FRACTION = 0.05
#: "Clearly gray": strictly between these values (JPEG-like ringing near edges stays outside).
GRAY_LOW, GRAY_HIGH = 32, 223
#: Foreground is value >= this.
THRESHOLD = 128


def read_silhouette(path: str | os.PathLike) -> np.ndarray:
    """Read one silhouette PNG as a binary mask.

    Accepts 8-bit grayscale, 1-bit, palette, gray+alpha and RGB(A) PNGs (converted to 8-bit gray;
    alpha is ignored) and 16-bit grayscale (scaled to 8 bits). Values are thresholded at 128.

    Returns:
        uint8 ``[H, W]`` with values 0 (background) and 255 (foreground).

    Raises:
        SilhouetteFormatError: the file cannot be decoded, or more than 5 % of its pixels are
            strictly between 32 and 223 (not a binary silhouette). ``frame`` is the file name's number.
    """
    import io

    from PIL import Image, UnidentifiedImageError

    frame = frame_number(path)
    data = read_file_bytes(
        path, lambda p, msg: SilhouetteFormatError(p, None, msg, frame=frame), max_bytes=MAX_SILHOUETTE_BYTES
    )
    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.width * image.height > MAX_SILHOUETTE_PIXELS:
                raise SilhouetteFormatError(
                    path,
                    None,
                    f"{image.width}x{image.height} pixels: more than the "
                    f"{MAX_SILHOUETTE_PIXELS} a silhouette frame may have",
                    frame=frame,
                )
            image.load()
            if image.mode in ("I;16", "I;16B", "I;16L", "I"):
                pixels = np.asarray(image, dtype=np.int64)
                pixels = np.clip(pixels // 257 if pixels.max(initial=0) > 255 else pixels, 0, 255).astype(np.uint8)
            elif image.mode in ("1", "L", "P", "LA", "PA", "RGB", "RGBA", "RGBX", "CMYK", "YCbCr"):
                pixels = np.asarray(image if image.mode == "L" else image.convert("L"), dtype=np.uint8)
            else:
                raise SilhouetteFormatError(path, None, f"unsupported image mode {image.mode!r}", frame=frame)
    except SilhouetteFormatError:
        raise
    except (
        OSError,
        SyntaxError,
        ValueError,
        UnidentifiedImageError,
        Image.DecompressionBombError,
        MemoryError,
    ) as exc:  # MemoryError: a damaged chunk length asking PIL for gigabytes
        raise SilhouetteFormatError(path, None, f"unreadable image: {type(exc).__name__} {exc}", frame=frame) from None
    if pixels.ndim != 2 or pixels.size == 0:
        raise SilhouetteFormatError(path, None, f"not a 2-D image (shape {pixels.shape})", frame=frame)
    gray = np.count_nonzero((pixels > GRAY_LOW) & (pixels < GRAY_HIGH)) / pixels.size
    if gray > MAX_GRAY_FRACTION:
        raise SilhouetteFormatError(
            path,
            None,
            f"not a binary silhouette: {100 * gray:.1f}% gray pixels "
            f"(values strictly between {GRAY_LOW} and {GRAY_HIGH})",
            frame=frame,
        )
    return np.where(pixels >= THRESHOLD, np.uint8(255), np.uint8(0))


def read_sequence(sequence: GaitSequence) -> np.ndarray:
    """Read every frame of a sequence, in order.

    Returns:
        uint8 ``[T, H, W]``, values 0 / 255; all-black frames are kept.

    Raises:
        SilhouetteFormatError: the folder has no frames, a frame is unreadable or not binary, or a
            frame's size differs from the first frame's (naming that file and frame).
    """
    if not sequence.frames:
        raise SilhouetteFormatError(sequence.folder, None, "empty view folder: no PNG frames")
    first = read_silhouette(sequence.frames[0])
    out = np.empty((len(sequence.frames), *first.shape), dtype=np.uint8)
    out[0] = first
    for t, path in enumerate(sequence.frames[1:], start=1):
        mask = read_silhouette(path)
        if mask.shape != first.shape:
            raise SilhouetteFormatError(
                path,
                None,
                f"frame size {mask.shape[1]}x{mask.shape[0]} (WxH) differs from the sequence's first "
                f"frame {sequence.frames[0].name} ({first.shape[1]}x{first.shape[0]})",
                frame=frame_number(path),
            )
        out[t] = mask
    return out
