"""The data-module base of ``mocapkit train`` / ``eval``: a train / val / test split and its loaders.

A subclass sets ``train_idx``, ``val_idx``, ``test_idx`` (sample indices), ``batch_size``,
``eval_batch_size`` and ``num_workers``, names its batch ``collate_fn``, and implements
``dataset(part)``, ``num_classes``, ``class_names`` and ``describe()`` (which can start from
:meth:`SplitDataModule.split_description`). Skeleton data modules build on
:class:`~mocapkit.datasets.skeleton_datamodule.SkeletonDataModule`, the GEI data module on this directly.
"""
from __future__ import annotations

import lightning as L
import numpy as np
from torch.utils.data import DataLoader


class SplitDataModule(L.LightningDataModule):
    """Loaders over ``dataset(part)`` for ``part`` in train / val / test, batched with ``collate_fn``."""

    train_idx: np.ndarray
    val_idx: np.ndarray
    test_idx: np.ndarray
    batch_size: int
    eval_batch_size: int
    num_workers: int
    collate_fn = None  # a subclass sets its batch collation (staticmethod)

    def dataset(self, part: str):  # pragma: no cover - implemented by subclasses
        raise NotImplementedError

    def sample_counts(self) -> dict[str, int]:
        return {"train": len(self.train_idx), "val": len(self.val_idx), "test": len(self.test_idx)}

    def split_description(self, subjects: np.ndarray) -> dict:
        """Subjects on each side of the split (``subjects``: per-sample IDs) and the sample counts."""
        return {"train_subjects": sorted(set(subjects[self.train_idx].tolist())),
                "val_subjects": sorted(set(subjects[self.val_idx].tolist())),
                "test_subjects": sorted(set(subjects[self.test_idx].tolist())),
                "sample_counts": self.sample_counts()}

    def _loader(self, part: str, shuffle: bool) -> DataLoader:
        return DataLoader(self.dataset(part), batch_size=self.batch_size if part == "train" else self.eval_batch_size,
                          shuffle=shuffle, num_workers=self.num_workers, collate_fn=self.collate_fn,
                          persistent_workers=self.num_workers > 0, drop_last=False)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", shuffle=False)
