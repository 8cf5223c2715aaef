"""Lightning data module over a prepared NTU-style cache (``mocapkit prepare ntu``).

Batches are the dicts of :mod:`mocapkit.datasets.datamodule`
(``skeletons`` ``[B, 2, T, 25, 3]`` zero-padded, ``labels``, ``lengths``,
``indices``, ``subjects``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from mocapkit.datasets.augment import SkeletonAugment
from mocapkit.datasets.datamodule import SkeletonDataModule
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.splits import split_indices
from mocapkit.datasets.splits import validation_split
from mocapkit.motion.frames import uniform_frame_indices


class SkeletonDataset(Dataset):
    """Samples ``indices`` of an :class:`NTUCache`, at most ``max_frames`` frames each."""

    def __init__(
        self, cache: NTUCache, indices: np.ndarray, max_frames: int = 300, augment: SkeletonAugment | None = None
    ):
        self.cache = cache
        self.indices = np.asarray(indices, dtype=np.int64)
        self.max_frames = int(max_frames)
        self.augment = augment

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> dict:
        i = int(self.indices[k])
        positions = self.cache.positions(i)
        positions = positions[:, uniform_frame_indices(positions.shape[1], self.max_frames)]
        skeleton = torch.from_numpy(np.ascontiguousarray(positions, dtype=np.float32))
        if self.augment is not None:  # the view changes on the whole batch (SkeletonDataModule)
            skeleton = self.augment.crop_frames(skeleton)
        return {
            "skeleton": skeleton,
            "label": int(self.cache.labels[i]),
            "index": i,
            "subject": int(self.cache.subjects[i]),
        }


class NTUDataModule(SkeletonDataModule):
    """Train / validation / test loaders for one evaluation protocol.

    Args:
        root: a prepared cache folder.
        split: ``ntu60_xsub``, ``ntu60_xview``, ``ntu120_xsub``, ``ntu120_xset`` or ``custom``.
        train_subjects, test_subjects: subject IDs for ``split="custom"``.
        val_fraction: share of the training side used for validation (whole subjects when
            ``val_by_subject``); validation never contains a test subject.
        max_frames: longer samples are subsampled uniformly to this many frames.
        augment: keyword arguments of :class:`SkeletonAugment` for the training set (None = off).
    """

    def __init__(
        self,
        root: str,
        split: str = "ntu60_xsub",
        train_subjects: list[int] | None = None,
        test_subjects: list[int] | None = None,
        val_fraction: float = 0.2,
        val_by_subject: bool = True,
        batch_size: int = 32,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        max_frames: int = 300,
        augment: dict | None = None,
        seed: int = 0,
    ):
        super().__init__()
        if root is None:
            raise ValueError("data.root is not set: give a prepared cache folder, e.g. data.root=data/ntu_cache")
        self.root = Path(root)
        self.split = split
        self.train_subjects = list(train_subjects) if train_subjects is not None else None
        self.test_subjects = list(test_subjects) if test_subjects is not None else None
        self.val_fraction = val_fraction
        self.val_by_subject = val_by_subject
        self._set_loading(batch_size, eval_batch_size, num_workers, max_frames, augment)
        self.seed = seed
        self.cache = NTUCache(self.root)
        train, test = split_indices(
            self.cache, split, train_subjects=self.train_subjects, test_subjects=self.test_subjects
        )
        self.train_idx, self.val_idx = validation_split(
            train, self.cache.subjects, val_fraction=val_fraction, seed=seed, by_subject=val_by_subject
        )
        self.test_idx = test

    @property
    def num_classes(self) -> int:
        return self.cache.num_classes

    @property
    def class_names(self) -> list[str]:
        """Names from the cache (``classes.txt`` of the source), else ``A001``, ``A002``, ..."""
        if self.cache.class_names:
            return list(self.cache.class_names)
        return [f"A{k + 1:03d}" for k in range(self.num_classes)]

    def describe(self) -> dict:
        """The split for reports: its name, the subjects on each side and the sample counts."""
        return {"split": self.split, "data_root": str(self.root), **self.split_description(self.cache.subjects)}

    def dataset(self, part: str) -> SkeletonDataset:
        """The ``"train"``, ``"val"`` or ``"test"`` part (augmentation only on train)."""
        indices = {"train": self.train_idx, "val": self.val_idx, "test": self.test_idx}[part]
        return SkeletonDataset(self.cache, indices, self.max_frames, self.augment if part == "train" else None)
