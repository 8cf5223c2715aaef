"""Lightning data module over a prepared NTU-style cache (``mocapkit prepare ntu``).

Batches are dicts::

    skeletons  float32 [B, M, T, 25, 3]   metres; zero-padded to the longest sample in the batch
    labels     int64   [B]                0-based action
    lengths    int64   [B]                frames before padding
    indices    int64   [B]                sample index in the cache
    subjects   int64   [B]

Padding frames are all zero, which every model here treats as "no body".
"""
from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from mocapkit.datasets.ntu_cache import NTUCache
from mocapkit.datasets.protocols import split_indices, validation_split
from mocapkit.datasets.skeleton_augment import SkeletonAugment


def uniform_frame_indices(length: int, max_frames: int) -> np.ndarray:
    """Indices of ``min(length, max_frames)`` frames spread evenly over ``length`` frames."""
    if length <= max_frames:
        return np.arange(length)
    return np.linspace(0, length - 1, max_frames).round().astype(np.int64)


class SkeletonDataset(Dataset):
    """Samples ``indices`` of an :class:`NTUCache`, at most ``max_frames`` frames each."""

    def __init__(self, cache: NTUCache, indices: np.ndarray, max_frames: int = 300,
                 augment: SkeletonAugment | None = None):
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
        if self.augment is not None:
            skeleton = self.augment(skeleton)
        return {"skeleton": skeleton, "label": int(self.cache.labels[i]), "index": i,
                "subject": int(self.cache.subjects[i])}


def pad_collate(items: list[dict]) -> dict:
    """Stack samples of different lengths, zero-padding the frame axis."""
    longest = max(it["skeleton"].shape[1] for it in items)
    first = items[0]["skeleton"]
    skeletons = first.new_zeros((len(items), first.shape[0], longest) + tuple(first.shape[2:]))
    for b, it in enumerate(items):
        skeletons[b, :, : it["skeleton"].shape[1]] = it["skeleton"]
    return {
        "skeletons": skeletons,
        "labels": torch.tensor([it["label"] for it in items]),
        "lengths": torch.tensor([it["skeleton"].shape[1] for it in items]),
        "indices": torch.tensor([it["index"] for it in items]),
        "subjects": torch.tensor([it["subject"] for it in items]),
    }


class NTUDataModule(L.LightningDataModule):
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

    def __init__(self, root: str, split: str = "ntu60_xsub", train_subjects: list[int] | None = None,
                 test_subjects: list[int] | None = None, val_fraction: float = 0.2, val_by_subject: bool = True,
                 batch_size: int = 32, eval_batch_size: int | None = None, num_workers: int = 0,
                 max_frames: int = 300, augment: dict | None = None, seed: int = 0):
        super().__init__()
        if root is None:
            raise ValueError("data.root is not set: give a prepared cache folder, e.g. data.root=data/ntu_cache")
        self.root = Path(root)
        self.split = split
        self.train_subjects = list(train_subjects) if train_subjects is not None else None
        self.test_subjects = list(test_subjects) if test_subjects is not None else None
        self.val_fraction = val_fraction
        self.val_by_subject = val_by_subject
        self.batch_size = batch_size
        self.eval_batch_size = eval_batch_size or batch_size
        self.num_workers = num_workers
        self.max_frames = max_frames
        self.augment = SkeletonAugment(**augment) if augment else None
        self.seed = seed
        self.cache = NTUCache(self.root)
        train, test = split_indices(self.cache, split, train_subjects=self.train_subjects,
                                    test_subjects=self.test_subjects)
        self.train_idx, self.val_idx = validation_split(train, self.cache.subjects, val_fraction=val_fraction,
                                                        seed=seed, by_subject=val_by_subject)
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

    def sample_counts(self) -> dict[str, int]:
        return {"train": len(self.train_idx), "val": len(self.val_idx), "test": len(self.test_idx)}

    def describe(self) -> dict:
        """The split for reports: its name, the subjects on each side and the sample counts.

        Every data module used with ``mocapkit train`` / ``eval`` provides this, together with
        ``num_classes``, ``class_names``, ``sample_counts()`` and the three data loaders.
        """
        subjects = self.cache.subjects
        return {"split": self.split, "data_root": str(self.root),
                "train_subjects": sorted(set(subjects[self.train_idx].tolist())),
                "val_subjects": sorted(set(subjects[self.val_idx].tolist())),
                "test_subjects": sorted(set(subjects[self.test_idx].tolist())),
                "sample_counts": self.sample_counts()}

    def dataset(self, part: str) -> SkeletonDataset:
        """The ``"train"``, ``"val"`` or ``"test"`` part (augmentation only on train)."""
        indices = {"train": self.train_idx, "val": self.val_idx, "test": self.test_idx}[part]
        return SkeletonDataset(self.cache, indices, self.max_frames, self.augment if part == "train" else None)

    def _loader(self, part: str, shuffle: bool) -> DataLoader:
        return DataLoader(self.dataset(part), batch_size=self.batch_size if part == "train" else self.eval_batch_size,
                          shuffle=shuffle, num_workers=self.num_workers, collate_fn=pad_collate,
                          persistent_workers=self.num_workers > 0, drop_last=False)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", shuffle=False)
