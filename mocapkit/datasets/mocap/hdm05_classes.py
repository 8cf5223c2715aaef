"""HDM05: clip names, the 130 / 65 / 25 class labellings and cross-actor splits.

HDM05 (Müller et al. 2007) has five actors ``bd bk dg mm tr``,
120 Hz ASF/AMC and C3D files, and a "cuts" subset of clips in **130** motion
classes, named ``<class>_<actor>_<nnn>`` (the official files:
``HDM_<actor>_<class>_<nnn>_120.amc``). The class tables live in
``mocapkit/datasets/mocap/data/hdm05_classes.tsv`` (one row per 130-class name with its
65- and 25-class merge; the file header cites the sources). The merge rules, which
the data file follows and the tests check:

- **65 classes** (:func:`merge_65`, the literature's 10-fold protocol): drop the
  repetition / hop / step count (``1Reps``, ``2hops``, ``4Steps``), which hand, elbow
  or foot starts (``LHandStart``, ``RelbowStart``, ``Lstart``, ``3Rstart``), the start
  pose of on-place jogging/running (``StartAir``/``StartFloor``) and the height of the
  two throws (``throwSittingHighR``/``LowR``). The acting limb, direction and target
  are kept: ``punchLFront1Reps`` and ``punchLFront2Reps`` → ``punchLFront``, but
  ``punchRFront`` stays apart. This reproduces the 65-group table of public loaders.
- **25 classes** (:func:`merge_25`, the thesis's merge, whose table the thesis does
  not give; thesis-wang-2017 §8 item 1 asks to derive it from the stems): the leading
  lower-case word of the name, so every count, side, start, direction and target
  variant of a stem is merged (``punch…`` → ``punch``, ``walkRightCircle…`` → ``walk``,
  ``staircaseUp/Down`` → ``staircase``). That gives exactly 25 classes, written with
  the longest camelCase prefix their 65-class names share (``sitDown``, ``rotateArms``).

Label indices are 0-based, in the order of first appearance in the (alphabetical)
130-class list. Splits return int64 index arrays into the list of clips given.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

ACTORS = ("bd", "bk", "dg", "mm", "tr")
FPS = 120.0
DATA_FILE = Path(__file__).with_name("data") / "hdm05_classes.tsv"

_OFFICIAL_RE = re.compile(r"^HDM_(?P<actor>[a-z]{2})_(?P<cls>[A-Za-z0-9]+)_(?P<take>\d+)(?:_(?P<fps>\d+))?$")
_SHORT_RE = re.compile(r"^(?P<cls>[A-Za-z0-9]+)_(?P<actor>[a-z]{2})_(?P<take>\d+)$")


# --------------------------------------------------------------------------- names


@dataclass(frozen=True)
class HDM05ClipName:
    """The fields of an HDM05 cut-clip name.

    Attributes:
        cls: the 130-class name, e.g. ``"punchLFront1Reps"``.
        actor: one of :data:`ACTORS`.
        take: the clip number ``nnn`` (1-based as written).
        fps: the frame-rate suffix of official names (``_120``), else None.
    """

    cls: str
    actor: str
    take: int
    fps: int | None = None

    def __str__(self) -> str:
        return f"{self.cls}_{self.actor}_{self.take:03d}"

    @property
    def class65(self) -> str:
        return merge_65(self.cls)

    @property
    def class25(self) -> str:
        return merge_25(self.cls)


def parse_clip_name(name: str | os.PathLike, strict: bool = True) -> HDM05ClipName:
    """Parse ``<class>_<actor>_<nnn>`` or ``HDM_<actor>_<class>_<nnn>[_<fps>]`` (a path or with an extension).

    Args:
        strict: also require the class to be one of the 130 and the actor one of :data:`ACTORS`.

    Raises:
        ValueError: the name does not have either form (or, strict, an unknown class/actor).
    """
    stem = Path(name).name
    for ext in (".amc", ".c3d", ".bvh", ".npz", ".npy", ".mat"):
        if stem.lower().endswith(ext):
            stem = stem[: -len(ext)]
            break
    m = _OFFICIAL_RE.match(stem) or _SHORT_RE.match(stem)
    if m is None:
        raise ValueError(f"{stem!r} is not an HDM05 clip name (<class>_<actor>_<nnn> or HDM_<actor>_<class>_<nnn>_120)")
    fps = m.groupdict().get("fps")
    clip = HDM05ClipName(cls=m["cls"], actor=m["actor"], take=int(m["take"]), fps=int(fps) if fps else None)
    if strict:
        if clip.actor not in ACTORS:
            raise ValueError(f"{stem!r}: unknown HDM05 actor {clip.actor!r}; known: {ACTORS}")
        if clip.cls not in class_index_map(130):
            raise ValueError(f"{stem!r}: {clip.cls!r} is not one of the 130 HDM05 classes")
    return clip


# --------------------------------------------------------------------------- merges


def merge_65(cls: str) -> str:
    """The 65-class name of a 130-class name (module docstring for the rule), e.g. ``punchLFront2Reps`` → ``punchLFront``."""
    s = re.sub(r"\d+(Reps|hops|Steps)", "", cls)  # repetition / hop / step counts
    s = re.sub(r"\d*[LR](Hand|elbow)?[Ss]tart$", "", s)  # which hand/elbow/foot starts
    s = re.sub(r"Start(Air|Floor)", "", s)  # start pose of on-place jog/run
    s = re.sub(r"^(throw(?:Sitting|Standing))(?:High|Low)R$", r"\1R", s)  # height of the two throws
    return s


def merge_25_stem(cls: str) -> str:
    """The leading lower-case word of a class name (``walkRightCircle4StepsLstart`` → ``walk``)."""
    m = re.match(r"[a-z]+", cls)
    if m is None:
        raise ValueError(f"{cls!r} does not start with a lower-case word")
    return m.group(0)


def merge_25(cls: str) -> str:
    """The thesis-style 25-class name of a 130- (or 65-) class name, e.g. ``punchLFront2Reps`` → ``punch``."""
    stem = merge_25_stem(cls)
    names = _stem_names()
    if stem not in names:
        raise ValueError(f"{cls!r}: stem {stem!r} is not one of the 25 HDM05 stems")
    return names[stem]


@cache
def _table() -> tuple[tuple[str, str, str], ...]:
    rows = []
    for line in DATA_FILE.read_text(encoding="utf-8").splitlines():
        if not line.strip() or line.startswith(("#", "class130\t")):
            continue
        parts = line.split("\t")
        if len(parts) != 3:
            raise ValueError(f"{DATA_FILE}: malformed row {line!r}")
        rows.append(tuple(parts))
    return tuple(rows)


@cache
def _stem_names() -> dict[str, str]:
    return {merge_25_stem(c130): c25 for c130, _, c25 in _table()}


def class_table() -> list[tuple[str, str, str]]:
    """The data file's rows: ``(class130, class65, class25)`` for each of the 130 classes."""
    return list(_table())


def class_names(scheme: int = 130) -> tuple[str, ...]:
    """The class names of a labelling (``130``, ``65`` or ``25``), in label order."""
    col = {130: 0, 65: 1, 25: 2}.get(scheme)
    if col is None:
        raise ValueError(f"scheme must be 130, 65 or 25, got {scheme!r}")
    return tuple(dict.fromkeys(row[col] for row in _table()))


@cache
def class_index_map(scheme: int = 130) -> dict[str, int]:
    """130-class name → 0-based label in ``scheme`` (130, 65 or 25)."""
    col = {130: 0, 65: 1, 25: 2}[scheme]
    index = {n: i for i, n in enumerate(class_names(scheme))}
    return {row[0]: index[row[col]] for row in _table()}


def labels(classes: list[str], scheme: int = 130) -> np.ndarray:
    """int64 ``[N]`` labels of 130-class names (or clip names / :class:`HDM05ClipName`) under ``scheme``."""
    mapping = class_index_map(scheme)
    out = np.empty(len(classes), dtype=np.int64)
    for i, c in enumerate(classes):
        name = c.cls if isinstance(c, HDM05ClipName) else str(c)
        if name not in mapping:
            name = parse_clip_name(name).cls
        out[i] = mapping[name]
    return out
