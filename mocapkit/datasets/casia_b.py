"""The CASIA-B silhouette layout: ``<subject>/<condition>-<nn>/<view>/<frame>.png``.

CASIA-B (Yu, Tan & Tan, ICPR 2006) has 124 subjects (``001``..``124``), each
walking 10 times past 11 cameras: 6 normal walks (``nm-01``..``nm-06``), 2 with
a bag (``bg-01``, ``bg-02``) and 2 in a coat (``cl-01``, ``cl-02``); the cameras
sit at azimuths 0°..180° in 18° steps (folder names ``000``..``180``). Each
``<view>`` folder holds one binary silhouette PNG per frame, e.g.
``001-nm-01-090-045.png``; frames sort by the trailing number.

This module holds the layout's vocabulary (shared by the reader, the
synthetic generator, the GEI preparation and the protocols) and the reader.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

from mocapkit.datasets.format_errors import MotionFormatError

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
