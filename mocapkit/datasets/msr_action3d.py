"""MSR Action3D skeletons: the text reader, the dataset listing and its evaluation protocols.

Files (Li, Zhang & Liu, CVPR-W 2010; shared/data/SOURCES.md) are named
``aAA_sSS_eEE_skeleton3D.txt`` (action, subject, take; 1-based). They have no
header and 20 rows of 4 whitespace-separated numbers per frame, at 15 fps, in
MSR's own joint order (:data:`~mocapkit.datasets.layouts.MSR20`):

* ``_skeleton3D.txt`` ("Real3D"): ``x y z c`` with x y z in metres (y up, z the
  depth from the camera, about 2-3 m) and c a confidence in [0, 1];
* ``_skeleton.txt`` (screen): ``u v d c`` with u v in pixels of the 320x240 depth
  image (v grows downwards) and d a depth value in undocumented units.

A joint whose three coordinates are all zero is missing (NaN in the
:class:`~mocapkit.datasets.motion.Motion`, True in ``missing``); 19 of the
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

Protocols (field-anchors §2):

* ``cross_subject``: subjects 1, 3, 5, 7, 9 train, 2, 4, 6, 8, 10 test (configurable);
* ``random_half``: a seeded random half of each action's sequences trains, the rest
  tests (the thesis's split for its 93.33 %; not comparable with cross-subject);
* ``subset``: ``AS1`` / ``AS2`` / ``AS3``, the 8-action subsets of Li et al. 2010
  (:data:`ACTION_SUBSETS`), combined with either split.
"""
from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.datasets.format_errors import MotionFormatError
from mocapkit.datasets.layouts import MSR20
from mocapkit.datasets.motion import Motion
from mocapkit.datasets.protocols import subject_masks

log = logging.getLogger(__name__)

JOINTS_PER_FRAME = 20
FPS = 15.0

#: The 20 actions in file order (a01 ... a20), as named by Li et al. 2010.
ACTION_NAMES: tuple[str, ...] = (
    "high arm wave", "horizontal arm wave", "hammer", "hand catch", "forward punch", "high throw",
    "draw x", "draw tick", "draw circle", "hand clap", "two hand wave", "side-boxing", "bend",
    "forward kick", "side kick", "jogging", "tennis swing", "tennis serve", "golf swing", "pick up & throw",
)

#: The three 8-action subsets (1-based action IDs) of Li, Zhang & Liu, "Action recognition based on
#: a bag of 3D points", CVPR-W 2010, Table 1 (AS1 / AS2 / AS3). The same lists are used by the public
#: re-implementations we checked (several independent Python loaders hold
#: ``AS1 = [2, 3, 5, 6, 10, 13, 18, 20]``, ``AS2 = [1, 4, 7, 8, 9, 11, 12, 14]``,
#: ``AS3 = [6, 14, 15, 16, 17, 18, 19, 20]``), and field-anchors §2 names the protocol.
ACTION_SUBSETS: dict[str, tuple[int, ...]] = {
    "AS1": (2, 3, 5, 6, 10, 13, 18, 20),
    "AS2": (1, 4, 7, 8, 9, 11, 12, 14),
    "AS3": (6, 14, 15, 16, 17, 18, 19, 20),
}

#: Cross-subject protocol (Li et al. 2010; Wang et al. CVPR'12): odd subjects train, even subjects test.
CROSS_SUBJECT_TRAIN: tuple[int, ...] = (1, 3, 5, 7, 9)
CROSS_SUBJECT_TEST: tuple[int, ...] = (2, 4, 6, 8, 10)

MSR_SPLITS = ("cross_subject", "random_half")

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
    """The ``[rows, 4]`` float array of a file; errors name the line (1-based, counting blank lines)."""
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
            path, first_of_partial, f"frame {complete + 1} is incomplete: the file has {len(rows)} rows, "
            f"not a multiple of {JOINTS_PER_FRAME} (the last {len(rows) % JOINTS_PER_FRAME} rows, from line "
            f"{first_of_partial} on, are left over)")
    values = np.asarray(rows, dtype=np.float64)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise MSRFormatError(path, numbers[int(np.argmax(bad))], "non-finite value")
    return values


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
    values = _parse_rows(path, path.read_text(encoding="ascii", errors="replace"))
    frames = values.reshape(-1, JOINTS_PER_FRAME, 4)
    coords = frames[..., :3].astype(np.float32)
    confidence = frames[..., 3].astype(np.float32)
    missing = (coords == 0).all(axis=-1)
    all_zero = bool((frames == 0).all())
    metadata = {"confidence": confidence, "all_zero": all_zero, "coordinates": kind,
                "missing_frames": int(missing.all(axis=1).sum())}
    if sample is not None:
        metadata.update(action=sample.action, subject=sample.subject, take=sample.take)
    if kind == "real3d":
        units, up = "m", "y"
    else:
        units, up = "u, v: pixels of the 320x240 depth image (v grows downwards); d: depth, units undocumented", "y"
        metadata["v_down"] = True
    positions = np.where(missing[..., None], np.float32(np.nan), coords)
    return Motion(positions=positions, joint_names=MSR20.joint_names, parents=MSR20.parents, fps=FPS,
                  missing=missing, source_units=units, up_axis=up, name=sample.stem if sample else path.stem,
                  source=str(path), layout_name=MSR20.name, metadata=metadata)


class MSRAction3D:
    """All skeleton files of an MSR Action3D folder, read into memory once.

    Defective sequences are left out with a logged reason (``excluded``: file name → reason):
    files whose values are all zero (``a13_s09_e02`` in the release), files whose name is not
    ``aAA_sSS_eEE_...`` and, with ``skip_bad=True``, files that do not parse.

    Attributes (one entry per kept sample, sorted by file name):
        names: ``aAA_sSS_eEE`` stems; ``files``: paths.
        actions, subjects, takes: 1-based int64 arrays.
        motions: the :class:`Motion` of each sample.
        listed: how many files the folder holds (kept + excluded).

    Args:
        root: the folder of ``*_skeleton3D.txt`` files (searched recursively).
        kind: ``"real3d"`` (``*_skeleton3D.txt``) or ``"screen"`` (``*_skeleton.txt``).
        skip_bad: leave out unreadable files (with the reason) instead of raising.
    """

    def __init__(self, root: str | Path, kind: str = "real3d", skip_bad: bool = False):
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"MSR Action3D folder not found: {self.root} (set data.root or MOCAPKIT_MSR_ROOT)")
        pattern = {"real3d": "*_skeleton3D.txt", "screen": "*_skeleton.txt"}[kind]
        paths = sorted(self.root.rglob(pattern), key=lambda p: p.name)
        if not paths:
            raise FileNotFoundError(f"no {pattern} files in {self.root}")
        self.listed = len(paths)
        self.excluded: dict[str, str] = {}
        kept: list[tuple[Path, MSRSampleName, Motion]] = []
        for path in paths:
            try:
                sample = parse_msr_name(path)
            except ValueError as exc:
                self._exclude(path.name, f"not an MSR Action3D file name: {exc}")
                continue
            try:
                motion = read_msr_skeleton(path, kind=kind)
            except MSRFormatError as exc:
                if not skip_bad:
                    raise
                self._exclude(path.name, f"unreadable: {exc}")
                continue
            if motion.metadata["all_zero"]:
                self._exclude(path.name, f"all values are zero ({motion.num_frames} frames): no skeleton was recorded")
                continue
            kept.append((path, sample, motion))
        self.files = [p for p, _, _ in kept]
        self.names = [s.stem for _, s, _ in kept]
        self.actions = np.array([s.action for _, s, _ in kept], dtype=np.int64)
        self.subjects = np.array([s.subject for _, s, _ in kept], dtype=np.int64)
        self.takes = np.array([s.take for _, s, _ in kept], dtype=np.int64)
        self.motions = [m for _, _, m in kept]

    def _exclude(self, name: str, reason: str) -> None:
        self.excluded[name] = reason
        log.warning("MSR Action3D: leaving out %s: %s", name, reason)

    def __len__(self) -> int:
        return len(self.motions)

    def positions(self, i: int, drop_missing_frames: bool = False) -> np.ndarray:
        """Sample ``i`` as float32 ``[frames, 20, 3]`` metres, zeros where a joint is missing.

        ``drop_missing_frames`` removes frames in which every joint is missing.
        """
        motion = self.motions[i]
        out = motion.filled(0.0)
        if drop_missing_frames:
            out = out[~motion.missing.all(axis=1)]
        return out

    def summary(self) -> dict:
        """Counts for reports: files listed, kept, excluded (with reasons), frames, per subject and action."""
        return {"listed": self.listed, "kept": len(self), "excluded": dict(self.excluded),
                "frames": int(sum(m.num_frames for m in self.motions)),
                "per_subject": {int(s): int((self.subjects == s).sum()) for s in np.unique(self.subjects)},
                "per_action": {int(a): int((self.actions == a).sum()) for a in np.unique(self.actions)}}


def msr_split_indices(data, split: str = "cross_subject", subset: str | None = None,
                      train_subjects=None, test_subjects=None, seed: int = 0,
                      train_fraction: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices ``(train_idx, test_idx)`` of an MSR Action3D protocol (sorted int64).

    Args:
        data: an :class:`MSRAction3D` or anything with per-sample ``actions`` and ``subjects`` arrays.
        split: ``"cross_subject"`` (``train_subjects`` / ``test_subjects``, default odd / even) or
            ``"random_half"`` (per action, a seeded random ``train_fraction`` trains, the rest tests).
        subset: None (all 20 actions) or ``"AS1"`` / ``"AS2"`` / ``"AS3"``; samples of other actions are unused.
        seed: the draw of ``random_half``.
    """
    if split not in MSR_SPLITS:
        raise ValueError(f"unknown MSR Action3D split {split!r}; known splits: {', '.join(MSR_SPLITS)}")
    actions, subjects = _ints(data, "actions"), _ints(data, "subjects")
    in_subset = np.isin(actions, subset_actions(subset)) if subset else np.ones(len(actions), dtype=bool)
    if split == "cross_subject":
        train, test = subject_masks(subjects, CROSS_SUBJECT_TRAIN if train_subjects is None else train_subjects,
                                    CROSS_SUBJECT_TEST if test_subjects is None else test_subjects,
                                    label="cross_subject")
        train, test = in_subset & train, in_subset & test
        return np.flatnonzero(train), np.flatnonzero(test)
    if train_subjects is not None or test_subjects is not None:
        raise ValueError("train_subjects / test_subjects are only used by split='cross_subject'")
    if not 0.0 < train_fraction < 1.0:
        raise ValueError(f"train_fraction must be between 0 and 1 (exclusive), got {train_fraction}")
    rng = np.random.default_rng(seed)
    train = []
    for action in np.unique(actions[in_subset]):      # sorted, so the draw depends on the seed only
        members = np.flatnonzero(in_subset & (actions == action))
        n_train = min(max(round(train_fraction * len(members)), 1), len(members) - 1)
        train.extend(rng.choice(members, size=n_train, replace=False).tolist())
    train_mask = np.zeros(len(actions), dtype=bool)
    train_mask[train] = True
    return np.flatnonzero(train_mask), np.flatnonzero(in_subset & ~train_mask)


def subset_actions(subset: str | None) -> tuple[int, ...]:
    """The 1-based action IDs of ``subset`` (None: all 20), sorted."""
    if subset is None:
        return tuple(range(1, len(ACTION_NAMES) + 1))
    if subset not in ACTION_SUBSETS:
        raise ValueError(f"unknown MSR Action3D subset {subset!r}; known: {', '.join(ACTION_SUBSETS)} or null")
    return tuple(sorted(ACTION_SUBSETS[subset]))


def _ints(data, key: str) -> np.ndarray:
    value = data.get(key) if isinstance(data, dict) else getattr(data, key, None)
    if value is None:
        raise KeyError(f"{type(data).__name__} has no per-sample {key!r} array")
    return np.asarray(value, dtype=np.int64)
