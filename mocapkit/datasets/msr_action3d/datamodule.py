"""Lightning data module over the MSR Action3D skeleton files (read into memory once).

The same contract as :class:`~mocapkit.datasets.ntu.datamodule.NTUDataModule`: batches are dicts ::

    skeletons  float32 [B, 1, T, 20, 3]   metres (MSR20 joint order); zero-padded to the longest sample
    labels     int64   [B]                0-based index into the protocol's actions (class_names)
    lengths    int64   [B]                frames before padding
    indices    int64   [B]                sample index in the MSRAction3D listing
    subjects   int64   [B]

Missing joints and frames are zeros (every model here treats zeros as absent).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from mocapkit.datasets.datamodule import SkeletonDataModule
from mocapkit.datasets.msr_action3d.dataset import ACTION_NAMES, MSRAction3D
from mocapkit.datasets.msr_action3d.splits import msr_split_indices, subset_actions
from mocapkit.datasets.splits import validation_split


class MSRAction3DDataModule(SkeletonDataModule):
    """Train / validation / test loaders for one MSR Action3D protocol.

    Args:
        root: the folder of ``*_skeleton3D.txt`` files.
        split: ``cross_subject`` (default: subjects 1 3 5 7 9 train, 2 4 6 8 10 test) or ``random_half``
            (per action, a random half trains; drawn with ``split_seed``).
        subset: None (all 20 actions), ``AS1``, ``AS2`` or ``AS3`` (Li et al.'s 8-action subsets).
        train_subjects, test_subjects: override the cross-subject lists.
        split_seed: the draw of ``random_half`` (kept apart from the run seed so that every run of a
            comparison sees the same split).
        val_fraction, val_by_subject: validation comes from the training side only (whole training
            subjects when ``val_by_subject``; drawn with the run ``seed``).
        max_frames: longer samples are subsampled uniformly to this many frames.
        augment: keyword arguments of :class:`SkeletonAugment` for the training set (None = off).
        drop_missing_frames: remove frames in which no joint was tracked (default: keep them as zeros).
        layout: the skeleton layout of the batches; always ``msr20`` (configs read it as ``data.layout``).
    """

    def __init__(
        self,
        root: str,
        split: str = "cross_subject",
        subset: str | None = None,
        train_subjects: list[int] | None = None,
        test_subjects: list[int] | None = None,
        split_seed: int = 0,
        val_fraction: float = 0.2,
        val_by_subject: bool = True,
        batch_size: int = 32,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        max_frames: int = 128,
        augment: dict | None = None,
        drop_missing_frames: bool = False,
        layout: str = "msr20",
        seed: int = 0,
    ):
        super().__init__()
        if root is None:
            raise ValueError(
                "data.root is not set: give the MSR Action3D skeleton folder, "
                "e.g. data.root=../shared/data/msr_action3d"
            )
        if layout != "msr20":
            raise ValueError(f"MSR Action3D skeletons use the msr20 layout, got data.layout={layout!r}")
        self.root = Path(root)
        self.split, self.subset = split, subset
        self._set_loading(batch_size, eval_batch_size, num_workers, max_frames, augment)
        self.drop_missing_frames = drop_missing_frames
        self.layout = layout
        self.seed = seed
        self.data = MSRAction3D(self.root)
        self.actions = subset_actions(subset)
        lookup = {a: k for k, a in enumerate(self.actions)}
        self.labels = np.array([lookup.get(int(a), -1) for a in self.data.actions], dtype=np.int64)
        train, test = msr_split_indices(
            self.data, split, subset=subset, train_subjects=train_subjects, test_subjects=test_subjects, seed=split_seed
        )
        self.train_idx, self.val_idx = validation_split(
            train, self.data.subjects, val_fraction=val_fraction, seed=seed, by_subject=val_by_subject
        )
        self.test_idx = test
        self.subjects = np.asarray(self.data.subjects, dtype=np.int64)
        used = np.concatenate([self.train_idx, self.val_idx, self.test_idx])
        self.sequences = {
            int(i): torch.from_numpy(np.ascontiguousarray(self.data.positions(int(i), drop_missing_frames)))
            for i in used
        }

    @property
    def num_classes(self) -> int:
        return len(self.actions)

    @property
    def class_names(self) -> list[str]:
        return [f"a{a:02d} {ACTION_NAMES[a - 1]}" for a in self.actions]

    def describe(self) -> dict:
        """The protocol for reports: split, subset, subjects on each side, sample counts, exclusions."""
        subjects = self.data.subjects
        return {
            "split": self.split if not self.subset else f"{self.subset}_{self.split}",
            "subset": self.subset,
            "actions": list(self.actions),
            "data_root": str(self.root),
            "excluded": dict(self.data.excluded),
            **self.split_description(subjects),
        }
