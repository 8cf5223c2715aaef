"""The data-module base of ``mocapkit train`` / ``eval`` and what every skeleton data module shares.

:class:`SplitDataModule` holds a train / val / test split and its loaders. A subclass sets
``train_idx``, ``val_idx``, ``test_idx`` (sample indices), ``batch_size``, ``eval_batch_size`` and
``num_workers``, names its batch ``collate_fn``, and implements ``dataset(part)``,
``label_spaces()`` (the keyword arguments its LightningModule needs: class counts and names) and
``describe()`` (which can start from :meth:`SplitDataModule.split_description`).

:class:`SkeletonDataModule` adds frame sampling and padded batches. Skeleton batches are dicts::

    skeletons  float32 [B, M, T, J, 3]   metres; zero-padded to the longest sample in the batch
    labels     int64   [B]               0-based class
    lengths    int64   [B]               frames before padding
    indices    int64   [B]               sample index in the data set
    subjects   int64   [B]

Padding frames are all zero, which every model here treats as "no body". The GEI data module
(:mod:`mocapkit.datasets.casia_b.datamodule`) builds on :class:`SplitDataModule` directly.
"""

from __future__ import annotations

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from mocapkit.datasets.augment import SkeletonAugment, TestTimeViews
from mocapkit.motion.frames import uniform_frame_indices


def data_loader(datamodule: L.LightningDataModule, dataset: Dataset, **options) -> DataLoader:
    """``DataLoader(dataset, **options)`` with what every data module here shares: ``datamodule.num_workers``
    worker processes, kept from one epoch to the next, and pinned memory when the data module's Trainer runs on a
    CUDA device (the copy of a batch to the device then overlaps the step)."""
    trainer = datamodule.trainer  # None outside a Trainer
    on_gpu = trainer is not None and trainer.strategy.root_device.type == "cuda"
    workers = datamodule.num_workers
    return DataLoader(dataset, num_workers=workers, persistent_workers=workers > 0, pin_memory=on_gpu, **options)


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
        return {
            "train_subjects": sorted(set(subjects[self.train_idx].tolist())),
            "val_subjects": sorted(set(subjects[self.val_idx].tolist())),
            "test_subjects": sorted(set(subjects[self.test_idx].tolist())),
            "sample_counts": self.sample_counts(),
        }

    def _loader(self, part: str, shuffle: bool) -> DataLoader:
        return data_loader(
            self,
            self.dataset(part),
            batch_size=self.batch_size if part == "train" else self.eval_batch_size,
            shuffle=shuffle,
            collate_fn=self.collate_fn,
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", shuffle=False)


def pad_collate(items: list[dict]) -> dict:
    """Stack samples (``skeleton`` ``[M, T, J, 3]``, ``label``, ``index``, ``subject``), zero-padding the frame axis."""
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


class SequenceDataset(Dataset):
    """Samples ``indices`` of in-memory one-body sequences as skeletons ``[1, T, J, 3]``.

    Args:
        sequences: per sample index, float32 ``[T_i, J, 3]`` tensors (metres; zeros where missing); a list or
            a mapping holding at least ``indices``.
        indices: the samples of this part. labels, subjects: per sample index (``[n]`` arrays).
        max_frames: longer sequences are subsampled uniformly (:func:`uniform_frame_indices`).
        augment: applied to every sample read (training only), or None.
    """

    def __init__(
        self,
        sequences,
        indices: np.ndarray,
        labels: np.ndarray,
        subjects: np.ndarray,
        max_frames: int,
        augment: SkeletonAugment | None = None,
    ):
        self.sequences, self.indices = sequences, np.asarray(indices, dtype=np.int64)
        self.labels, self.subjects = labels, subjects
        self.max_frames, self.augment = int(max_frames), augment

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> dict:
        i = int(self.indices[k])
        seq = self.sequences[i]
        seq = seq[torch.from_numpy(uniform_frame_indices(seq.shape[0], self.max_frames))].unsqueeze(0)
        if self.augment is not None:  # the view changes on the whole batch (SkeletonDataModule)
            seq = self.augment.crop_frames(seq)
        return {"skeleton": seq, "label": int(self.labels[i]), "index": i, "subject": int(self.subjects[i])}


class ViewDataset(Dataset):
    """Every sample of ``dataset`` as ``len(views)`` consecutive items, one per fixed view of its skeleton.

    Item ``k`` is view ``k % len(views)`` of sample ``k // len(views)``, with that sample's label, index and
    subject, so predictions over an unshuffled loader come in groups of ``len(views)`` rows per sample.

    Args:
        dataset: a skeleton dataset whose items are dicts with ``"skeleton"`` ``[M, T, J, 3]``.
        views: the fixed views (:class:`~mocapkit.datasets.augment.TestTimeViews`).
    """

    def __init__(self, dataset: Dataset, views: TestTimeViews):
        self.dataset, self.views = dataset, views
        self._cached: tuple[int, list] | None = None  # the last sample's views: a loader reads them in a row

    def __len__(self) -> int:
        return len(self.dataset) * len(self.views)

    def __getitem__(self, k: int) -> dict:
        sample, view = divmod(k, len(self.views))
        if self._cached is None or self._cached[0] != sample:
            item = self.dataset[sample]
            self._cached = (sample, [{**item, "skeleton": v} for v in self.views(item["skeleton"])])
        return self._cached[1][view]


class SkeletonDataModule(SplitDataModule):
    """Base class of the skeleton data modules: batches padded by :func:`pad_collate`.

    A subclass provides ``num_classes`` and ``class_names``. A data module that holds its samples in memory
    sets ``sequences`` (per sample index, ``[T_i, J, 3]`` tensors), ``labels`` and ``subjects`` (per sample
    index) and inherits :meth:`dataset`; one that reads from disk (the NTU cache) overrides it.
    """

    collate_fn = staticmethod(pad_collate)
    sequences = None
    labels: np.ndarray
    subjects: np.ndarray

    def dataset(self, part: str) -> SequenceDataset:
        """The ``"train"``, ``"val"`` or ``"test"`` part of the in-memory ``sequences`` (augmentation only on
        train), built once."""
        if part not in self._parts:
            indices = {"train": self.train_idx, "val": self.val_idx, "test": self.test_idx}[part]
            self._parts[part] = SequenceDataset(
                self.sequences,
                indices,
                self.labels,
                self.subjects,
                self.max_frames,
                self.augment if part == "train" else None,
            )
        return self._parts[part]

    def augment_batch(self, batch: dict) -> dict:
        """A training batch seen from random views, one per sample (the datasets only crop:
        :class:`~mocapkit.datasets.augment.SkeletonAugment`); unchanged without augmentation."""
        if self.augment is not None:
            batch["skeletons"] = self.augment.change_view(batch["skeletons"])
        return batch

    def on_after_batch_transfer(self, batch: dict, dataloader_idx: int) -> dict:
        """Lightning's hook: training batches get :meth:`augment_batch` here, whole batches on their device."""
        if self.trainer is not None and self.trainer.training:
            return self.augment_batch(batch)
        return batch

    def views_dataloader(self, part: str, views: TestTimeViews) -> DataLoader:
        """An unshuffled loader over the ``"val"`` or ``"test"`` part in which every sample appears as
        ``len(views)`` consecutive items (:class:`ViewDataset`), for test-time augmentation."""
        return data_loader(
            self, ViewDataset(self.dataset(part), views), batch_size=self.eval_batch_size, collate_fn=self.collate_fn
        )

    def _set_loading(
        self, batch_size: int, eval_batch_size: int | None, num_workers: int, max_frames: int, augment: dict | None
    ) -> None:
        """Set the loader options every skeleton data module takes.

        ``eval_batch_size`` None means ``batch_size``; longer samples are subsampled to ``max_frames``
        frames; ``augment`` holds keyword arguments of :class:`SkeletonAugment` for the training set
        (None or empty: off).
        """
        self.batch_size = batch_size
        self.eval_batch_size = eval_batch_size or batch_size
        self.num_workers = num_workers
        self.max_frames = max_frames
        self.augment = SkeletonAugment(**augment) if augment else None
        self._parts: dict = {}  # the datasets built by dataset(part)

    def label_spaces(self) -> dict:
        """What the action LightningModule needs from the data: ``num_classes`` and ``class_names``."""
        return {"num_classes": self.num_classes, "class_names": list(self.class_names)}
