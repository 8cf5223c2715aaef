"""MSR Action3D: the data set (all skeleton files of a folder, read once) and its action vocabulary.

The file format is read by :func:`mocapkit.datasets.formats.msr_action3d.read_msr_skeleton`; the
evaluation protocols are in :mod:`mocapkit.datasets.msr_action3d.splits`.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.msr_action3d import MSRFormatError, MSRSampleName, parse_msr_name, read_msr_skeleton
from mocapkit.motion.container import Motion

log = logging.getLogger(__name__)

#: The 20 actions in file order (a01 ... a20), as named by Li et al. 2010.
ACTION_NAMES: tuple[str, ...] = (
    "high arm wave",
    "horizontal arm wave",
    "hammer",
    "hand catch",
    "forward punch",
    "high throw",
    "draw x",
    "draw tick",
    "draw circle",
    "hand clap",
    "two hand wave",
    "side-boxing",
    "bend",
    "forward kick",
    "side kick",
    "jogging",
    "tennis swing",
    "tennis serve",
    "golf swing",
    "pick up & throw",
)

#: The three 8-action subsets (1-based action IDs) of Li, Zhang & Liu, "Action recognition based on
#: a bag of 3D points", CVPR-W 2010, Table 1 (AS1 / AS2 / AS3). The same lists are used by the public
#: re-implementations we checked (several independent Python loaders hold
#: ``AS1 = [2, 3, 5, 6, 10, 13, 18, 20]``, ``AS2 = [1, 4, 7, 8, 9, 11, 12, 14]``,
#: ``AS3 = [6, 14, 15, 16, 17, 18, 19, 20]``).
ACTION_SUBSETS: dict[str, tuple[int, ...]] = {
    "AS1": (2, 3, 5, 6, 10, 13, 18, 20),
    "AS2": (1, 4, 7, 8, 9, 11, 12, 14),
    "AS3": (6, 14, 15, 16, 17, 18, 19, 20),
}


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
        return {
            "listed": self.listed,
            "kept": len(self),
            "excluded": dict(self.excluded),
            "frames": int(sum(m.num_frames for m in self.motions)),
            "per_subject": {int(s): int((self.subjects == s).sum()) for s in np.unique(self.subjects)},
            "per_action": {int(a): int((self.actions == a).sum()) for a in np.unique(self.actions)},
        }
