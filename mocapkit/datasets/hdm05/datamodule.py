"""Lightning data module for action recognition on a folder of HDM05 clips, held-out performers first.

The folder is laid out as the real cuts (``<actor>/HDM_<actor>.asf`` and
``<actor>/HDM_<actor>_<class>_<nnn>_120.amc``, e.g. ``../shared/data/hdm05_cuts11``) or as the synthetic
generator writes it (``<class>_<actor>_<nnn>.amc`` beside ``HDM_<actor>.asf``, ``mocapkit synth hdm05``); the
files are found by :func:`~mocapkit.datasets.mocap.folders.list_clips`. Classes are read from the file names
(``labels=file``: every distinct class name is a class) or merged to HDM05's 65 or 25 classes
(:mod:`mocapkit.datasets.mocap.hdm05_classes`). Every clip is read once, resampled to ``fps`` and kept in memory.

Performers: ``test_actors`` are held out (default: the first performer of the folder, sorted: one fold of
leave-one-performer-out; the comparison ``mocapkit compare hdm05_recognition`` runs every fold), the model trains
on ``train_actors`` (default: every other performer) and validation comes from the training performers only
(``val_fraction`` of their clips, or of the performers themselves with ``val_by_subject``; ``val_fraction=0``: no
validation, the run keeps its last checkpoint).

Batches (as every skeleton data module, :mod:`mocapkit.datasets.datamodule`)::

    skeletons  float32 [B, 1, T, 31, 3]  metres, y up, the cmu31 joint order; zero-padded to the longest sample
    labels     int64   [B]               0-based class (sorted class names)
    lengths    int64   [B]               frames before padding
    indices    int64   [B]               clip index in the sorted listing
    subjects   int64   [B]               performer index (sorted performer names, ``performers``)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from mocapkit.datasets.datamodule import SkeletonDataModule
from mocapkit.datasets.mocap.folders import (
    MocapFolderError,
    held_out_groups,
    list_clips,
    read_clips,
)
from mocapkit.datasets.mocap.hdm05_classes import merge_25, merge_65
from mocapkit.datasets.splits import validation_split
from mocapkit.motion.layouts import CMU31

#: ``labels=``: how a file's class name becomes a label.
LABEL_SETS = {"file": lambda name: name, "65": merge_65, "25": merge_25}


class HDM05ActionDataModule(SkeletonDataModule):
    """Train / validation / test loaders over an HDM05 folder, one performer fold (see the module docstring).

    Args:
        root: the folder of clips (real or synthetic layout).
        test_actors: held-out performers (a name or a list); None: the folder's first performer.
        train_actors: training performers; None: every performer not held out.
        labels: ``file`` (the class in the file name), ``65`` or ``25`` (HDM05's merged class sets).
        fps: frames per second the clips are resampled to (HDM05 is captured at 120).
        val_fraction, val_by_subject: validation from the training performers only: that share of their clips
            (seeded by the run ``seed``), or of the performers themselves; 0: no validation.
        batch_size, eval_batch_size, num_workers: the loaders'. max_frames: longer clips are subsampled uniformly.
        augment: keyword arguments of :class:`~mocapkit.datasets.augment.SkeletonAugment` for training (None: off).
        layout: the batches' joint order; always ``cmu31`` (model configs read it as ``data.layout``).
        seed: the run's seed (validation draw).

    Raises:
        MocapFolderError: no HDM05 clip under ``root``, an unreadable file (named), a clip without the cmu31
            joints, or performers that the folder does not have.
    """

    def __init__(
        self,
        root: str,
        test_actors=None,
        train_actors=None,
        labels: str = "file",
        fps: float = 30.0,
        val_fraction: float = 0.15,
        val_by_subject: bool = False,
        batch_size: int = 16,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        max_frames: int = 32,
        augment: dict | None = None,
        layout: str = "cmu31",
        seed: int = 0,
    ):
        super().__init__()
        if root is None:
            raise MocapFolderError(
                "data.root is not set: give a folder of HDM05 clips, e.g. data.root=../shared/data/hdm05_cuts11"
            )
        if layout != "cmu31":
            raise ValueError(f"HDM05 skeletons use the cmu31 layout, got data.layout={layout!r}")
        if labels not in LABEL_SETS:
            raise ValueError(f"data.labels={labels!r}: one of {list(LABEL_SETS)}")
        self.root, self.layout, self.labels_from, self.fps, self.seed = Path(root), layout, labels, float(fps), seed
        self._set_loading(batch_size, eval_batch_size, num_workers, max_frames, augment)
        self.clips = list_clips("hdm05", self.root)
        self.performers = sorted({c["group"] for c in self.clips})
        self.train_actors, self.test_actors = held_out_groups(
            self.performers, test_actors, train_actors, "hdm05", self.root
        )
        names = [LABEL_SETS[labels](c["class"]) for c in self.clips]
        self._class_names = sorted(set(names))
        lookup = {name: k for k, name in enumerate(self._class_names)}
        self.labels = np.array([lookup[n] for n in names], dtype=np.int64)
        self.subjects = np.array([self.performers.index(c["group"]) for c in self.clips], dtype=np.int64)
        actor_of = np.array([c["group"] for c in self.clips])
        train = np.flatnonzero(np.isin(actor_of, self.train_actors))
        self.test_idx = np.flatnonzero(np.isin(actor_of, self.test_actors))
        self.train_idx, self.val_idx = validation_split(
            train, self.subjects, val_fraction=val_fraction, seed=seed, by_subject=val_by_subject
        )
        self.sequences = [
            self._positions(m, c["path"]) for m, c in zip(read_clips(self.clips, fps=self.fps), self.clips)
        ]

    @staticmethod
    def _positions(motion, path) -> torch.Tensor:
        """``[T, 31, 3]`` float32 metres in the cmu31 order; missing samples are zeros."""
        missing = [j for j in CMU31.joint_names if j not in motion.joint_names]
        if missing:
            raise MocapFolderError(f"{path}: the skeleton lacks the cmu31 joints {missing[:5]}")
        selected = motion.select(list(CMU31.joint_names))
        return torch.from_numpy(np.ascontiguousarray(np.nan_to_num(selected.filled(0.0)), dtype=np.float32))

    @property
    def num_classes(self) -> int:
        return len(self._class_names)

    @property
    def class_names(self) -> list[str]:
        return list(self._class_names)

    def describe(self) -> dict:
        """The fold for reports: performers on each side, the label set, counts."""
        return {
            "split": f"hdm05_test_{'+'.join(self.test_actors)}",
            "data_root": str(self.root),
            "labels": self.labels_from,
            "fps": self.fps,
            "performers": self.performers,
            "train_actors": self.train_actors,
            "test_actors": self.test_actors,
            **self.split_description(np.asarray(self.performers)[self.subjects]),
        }
