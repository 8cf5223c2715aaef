"""Lightning data module over a prepared GEI cache (CASIA-B layout), for the multi-task gait CNN.

Batches are dicts::

    geis         float32 [B, 1, H, W]   GEI in [0, 1] (uint8 / 255)
    subjects     int64   [B]            subject label: index into ``subject_names``; -1 outside the label space
    subject_ids  int64   [B]            CASIA-B subject ID (1-based)
    views        int64   [B]            view label 0..10 (index into ``casia_b.VIEWS``)
    conditions   int64   [B]            condition label 0 nm, 1 bg, 2 cl
    sequences    int64   [B]            repetition within the condition (1-based, e.g. 5 for nm-05)
    indices      int64   [B]            GEI index in the cache

Protocols (:mod:`mocapkit.datasets.casia_b.splits`):

* ``closed_set`` (the thesis's hold-out): per (subject, view), one random ``nm``, ``bg`` and ``cl``
  sequence is tested (drawn with ``holdout_seed``); every subject is in the label space.
* ``cross_subject`` (OpenGait's split): the lowest subject IDs train, the rest test; the label
  space is the training subjects only, and the test set is every GEI of the test subjects
  (label -1; the gait evaluation picks gallery and probes).

Validation is a ``val_fraction`` of the training *sequences* (all cycles of a sequence together),
drawn with the run ``seed``, never from the test side. The GEIs are read into memory once as uint8
(about 0.8 GB for all of CASIA-B at 124×124 with 4 cycles per sequence, a quarter of float32) and
scaled to [0, 1] per sample.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from mocapkit.datasets.casia_b.cache import GEICache
from mocapkit.datasets.casia_b.splits import (
    PROTOCOLS,
    protocol_split,
    sequence_validation_split,
)
from mocapkit.datasets.datamodule import SplitDataModule, data_loader
from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS


class GEIShift:
    """Training augmentation: a random translation of up to ``shift`` pixels horizontally and ``shift_y``
    vertically (zero fill). No horizontal flip: mirroring a GEI changes its view (0° ↔ 180°).

    Offsets come from torch's global generator, which Lightning's ``seed_everything`` seeds and
    which every data-loader worker reseeds per epoch, so workers and epochs draw different shifts.

    Args:
        shift: largest horizontal shift in pixels (uniform integer in ``[-shift, shift]``).
        shift_y: largest vertical shift in pixels; None: the same as ``shift``.
    """

    def __init__(self, shift: int = 2, shift_y: int | None = None):
        self.shift = int(shift)
        self.shift_y = self.shift if shift_y is None else int(shift_y)
        if self.shift < 0 or self.shift_y < 0:
            raise ValueError(f"data.augment: shifts must be ≥ 0, got shift={shift}, shift_y={shift_y}")

    def __call__(self, gei: torch.Tensor) -> torch.Tensor:
        """``gei`` ``[1, H, W]`` → the shifted copy, same shape."""
        dx = int(torch.randint(-self.shift, self.shift + 1, ()))
        dy = int(torch.randint(-self.shift_y, self.shift_y + 1, ()))
        if dx == 0 and dy == 0:
            return gei
        out = torch.zeros_like(gei)
        h, w = gei.shape[-2:]
        out[..., max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)] = gei[
            ..., max(-dy, 0) : h + min(-dy, 0), max(-dx, 0) : w + min(-dx, 0)
        ]
        return out


class GEIDataset(Dataset):
    """The GEIs ``indices`` of a cache; ``geis`` holds their uint8 pixels ``[n, H, W]`` in the same order.

    Items are dicts of a ``gei`` float32 ``[1, H, W]`` tensor and ints ``subject`` (label), ``subject_id``,
    ``view``, ``condition``, ``sequence``, ``index``; :func:`gei_collate` stacks them into a batch.
    """

    def __init__(
        self,
        geis: np.ndarray,
        indices: np.ndarray,
        subject_labels: np.ndarray,
        cache: GEICache,
        augment: GEIShift | None = None,
    ):
        self.indices = np.asarray(indices, dtype=np.int64)
        if len(geis) != len(self.indices):
            raise ValueError(f"{len(geis)} GEIs for {len(self.indices)} indices")
        self.geis = torch.from_numpy(np.ascontiguousarray(geis))
        view_lookup = {v: k for k, v in enumerate(VIEWS)}
        self.subject_labels = torch.from_numpy(subject_labels[self.indices].astype(np.int64))
        self.subject_ids = torch.from_numpy(cache.subjects[self.indices].astype(np.int64))
        self.views = torch.tensor([view_lookup[int(v)] for v in cache.views[self.indices]], dtype=torch.int64)
        self.conditions = torch.from_numpy(cache.conditions[self.indices].astype(np.int64))
        self.sequences = torch.from_numpy(cache.sequences[self.indices].astype(np.int64))
        self.augment = augment

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> dict:
        gei = self.geis[k].unsqueeze(0).to(torch.float32) / 255.0
        if self.augment is not None:
            gei = self.augment(gei)
        return {
            "gei": gei,
            "subject": self.subject_labels[k],
            "subject_id": self.subject_ids[k],
            "view": self.views[k],
            "condition": self.conditions[k],
            "sequence": self.sequences[k],
            "index": int(self.indices[k]),
        }


class SubjectBatchSampler(Sampler[list[int]]):
    """Training batches of ``subjects_per_batch`` subjects × ``batch_size // subjects_per_batch`` GEIs each (the
    P × K batches of metric learning: every GEI has positives in its batch).

    An epoch has ``len(labels) // batch_size`` batches; each draws its subjects without replacement and each
    subject's GEIs without replacement (with replacement when the subject has fewer). Random numbers come from
    torch's global generator (seeded by the run seed). One process: under DDP every process would draw the same
    batches.

    Args:
        labels: the subject label of each training item ``[n]`` (dataset positions; labels ≥ 0).
        batch_size: items per batch; subjects_per_batch: subjects per batch (divides ``batch_size``).
    """

    def __init__(self, labels: np.ndarray, batch_size: int, subjects_per_batch: int):
        labels = np.asarray(labels, dtype=np.int64)
        subjects = np.unique(labels)
        if subjects_per_batch < 2 or batch_size % subjects_per_batch or batch_size // subjects_per_batch < 2:
            raise ValueError(
                f"data.subjects_per_batch={subjects_per_batch} must be at least 2 and divide "
                f"data.batch_size={batch_size} into at least 2 GEIs per subject"
            )
        if len(subjects) < subjects_per_batch:
            raise ValueError(
                f"data.subjects_per_batch={subjects_per_batch}: the training part has only {len(subjects)} subjects"
            )
        self.members = [torch.from_numpy(np.flatnonzero(labels == s)) for s in subjects]
        self.batch_size, self.subjects_per_batch = int(batch_size), int(subjects_per_batch)
        self.per_subject = self.batch_size // self.subjects_per_batch
        self.batches = max(1, len(labels) // self.batch_size)

    def __len__(self) -> int:
        return self.batches

    def __iter__(self):
        for _ in range(self.batches):
            batch = []
            for s in torch.randperm(len(self.members))[: self.subjects_per_batch].tolist():
                members = self.members[s]
                if len(members) >= self.per_subject:
                    picked = members[torch.randperm(len(members))[: self.per_subject]]
                else:
                    picked = members[torch.randint(len(members), (self.per_subject,))]
                batch += picked.tolist()
            yield batch


def gei_collate(items: list[dict]) -> dict:
    """Stack :class:`GEIDataset` items into the batch dict of the module docstring (plural keys)."""
    return {
        "geis": torch.stack([it["gei"] for it in items]),
        "subjects": torch.stack([it["subject"] for it in items]),
        "subject_ids": torch.stack([it["subject_id"] for it in items]),
        "views": torch.stack([it["view"] for it in items]),
        "conditions": torch.stack([it["condition"] for it in items]),
        "sequences": torch.stack([it["sequence"] for it in items]),
        "indices": torch.tensor([it["index"] for it in items], dtype=torch.int64),
    }


class GaitDataModule(SplitDataModule):
    """Train / validation / test loaders over a GEI cache for one CASIA-B protocol.

    Args:
        root: the GEI cache folder (``mocapkit prepare casia-b --out ROOT``).
        protocol: ``closed_set`` (the thesis's hold-out) or ``cross_subject`` (OpenGait's split).
        holdout_seed: ``closed_set``: the draw of the held-out sequences (apart from the run seed, so every
            run of a comparison sees the same test set).
        num_train_subjects: ``cross_subject``: training subjects (None: 74 of 124, or the same proportion).
        val_fraction: share of the training sequences held out for validation (drawn with ``seed``).
        batch_size, eval_batch_size: training and evaluation batch sizes.
        num_workers: data-loader workers.
        augment: keyword arguments of :class:`GEIShift` for the training set (None or {} = off).
        seed: the run seed (the validation draw).
        subjects_per_batch: None (shuffled batches) or the subjects of each training batch
            (:class:`SubjectBatchSampler`: ``batch_size // subjects_per_batch`` GEIs each), for a metric loss.

    Attributes:
        cache: the :class:`GEICache`. train_idx, val_idx, test_idx: sorted GEI indices.
        num_subjects, subject_names (= class_names): the subject label space. num_views, num_conditions.
        height, width: GEI size.
    """

    collate_fn = staticmethod(gei_collate)

    def __init__(
        self,
        root: str,
        protocol: str = "closed_set",
        holdout_seed: int = 0,
        num_train_subjects: int | None = None,
        val_fraction: float = 0.1,
        batch_size: int = 32,
        eval_batch_size: int | None = 128,
        num_workers: int = 0,
        augment: dict | None = None,
        seed: int = 0,
        subjects_per_batch: int | None = None,
    ):
        super().__init__()
        if root is None:
            raise ValueError("data.root is not set: give the GEI cache folder written by `mocapkit prepare casia-b`")
        if protocol not in PROTOCOLS:
            raise ValueError(f"data.protocol={protocol!r} is unknown; choose one of {', '.join(PROTOCOLS)}")
        if protocol != "cross_subject" and num_train_subjects is not None:
            raise ValueError(
                f"data.num_train_subjects={num_train_subjects} is only used by protocol=cross_subject, not {protocol!r}"
            )
        self.root = Path(root)
        self.protocol = protocol
        self.holdout_seed, self.seed = int(holdout_seed), int(seed)
        self.batch_size = int(batch_size)
        self.eval_batch_size = int(eval_batch_size or batch_size)
        self.num_workers = int(num_workers)
        self.subjects_per_batch = None if subjects_per_batch is None else int(subjects_per_batch)
        unknown = sorted(set(augment or {}) - {"shift", "shift_y"})
        if unknown:
            raise ValueError(
                f"data.augment: unknown keys {unknown}; GEIs take only shift and shift_y "
                "(no flip: mirroring changes the view)"
            )
        self.augment = GEIShift(**augment) if augment else None
        self.cache = GEICache(self.root)
        if len(self.cache) == 0:
            raise ValueError(f"GEI cache {self.root} is empty (0 GEIs); see its report.txt for skipped sequences")
        self.height, self.width = self.cache.height, self.cache.width
        bad_views = sorted(set(np.unique(self.cache.views).tolist()) - set(VIEWS))
        bad_conditions = sorted(set(np.unique(self.cache.conditions).tolist()) - set(range(len(CONDITIONS))))
        if bad_views or bad_conditions or self.cache.subjects.min() < 1:
            raise ValueError(
                f"{self.root}: index.npz holds views {bad_views} (expected {list(VIEWS)}), conditions "
                f"{bad_conditions} (expected 0..{len(CONDITIONS) - 1}) or subject IDs < 1"
            )
        subjects = self.cache.subjects.astype(np.int64)
        ids = np.unique(subjects)

        # the one split code of every gait method, learned or classical (mocapkit.evaluation.compare uses it too)
        train, self.test_idx, self.train_subjects, self.test_subjects = protocol_split(
            self.cache, protocol, holdout_seed=self.holdout_seed, num_train_subjects=num_train_subjects
        )
        self.label_subjects = np.asarray(self.train_subjects, dtype=np.int64)  # the subject label space

        lookup = np.full(int(ids.max()) + 1, -1, dtype=np.int64)
        lookup[self.label_subjects] = np.arange(len(self.label_subjects))
        self.subject_labels = lookup[subjects]
        keys = np.stack([subjects, self.cache.conditions, self.cache.sequences, self.cache.views], axis=1)
        self.train_idx, self.val_idx = sequence_validation_split(train, keys, val_fraction, self.seed)
        self.test_idx = np.asarray(self.test_idx, dtype=np.int64)
        if len(self.train_idx) == 0:
            raise ValueError(
                f"{self.root}: protocol={protocol} leaves no training GEIs {self.sample_counts()}; "
                "the cache needs more than one sequence per (subject, view, condition) for closed_set"
            )
        self._datasets: dict[str, GEIDataset] = {}

    # ------------------------------------------------------------------ label spaces

    @property
    def num_subjects(self) -> int:
        return len(self.label_subjects)

    @property
    def num_classes(self) -> int:
        """The subject classes (the name the generic training loop prints)."""
        return self.num_subjects

    @property
    def num_views(self) -> int:
        return len(VIEWS)

    @property
    def num_conditions(self) -> int:
        return len(CONDITIONS)

    @property
    def subject_names(self) -> list[str]:
        return [f"{s:03d}" for s in self.label_subjects]

    @property
    def class_names(self) -> list[str]:
        return self.subject_names

    def label_spaces(self) -> dict:
        """What the gait LightningModule needs from the data: label-space sizes, subject names, GEI size."""
        return {
            "num_subjects": self.num_subjects,
            "num_views": self.num_views,
            "num_conditions": self.num_conditions,
            "subject_names": self.subject_names,
            "input_size": [self.height, self.width],
        }

    # ------------------------------------------------------------------ reports

    def describe(self) -> dict:
        """The protocol for reports: split name, subjects on each side, label space, sample counts."""
        if self.protocol == "closed_set":
            split = f"casia-b closed_set (holdout seed {self.holdout_seed})"
        else:
            split = (
                f"casia-b cross_subject ({len(self.train_subjects)} train / {len(self.test_subjects)} test subjects)"
            )
        return {
            "split": split,
            "protocol": self.protocol,
            "data_root": str(self.root),
            "per": self.cache.meta.get("per"),
            "gei_size": [self.height, self.width],
            **self.split_description(self.cache.subjects),
            "label_space": self.subject_names,
            "views": list(VIEWS),
            "conditions": list(CONDITIONS),
        }

    # ------------------------------------------------------------------ loaders

    def dataset(self, part: str) -> GEIDataset:
        """The ``"train"``, ``"val"`` or ``"test"`` part (augmentation only on train), read into memory once."""
        if part not in self._datasets:
            indices = {"train": self.train_idx, "val": self.val_idx, "test": self.test_idx}[part]
            geis = np.asarray(self.cache.all_geis[indices], dtype=np.uint8)  # fancy indexing copies out of the memmap
            self._datasets[part] = GEIDataset(
                geis, indices, self.subject_labels, self.cache, self.augment if part == "train" else None
            )
        return self._datasets[part]

    def train_dataloader(self) -> DataLoader:
        """Shuffled batches, or P × K batches (:class:`SubjectBatchSampler`) with ``subjects_per_batch``."""
        if self.subjects_per_batch is None:
            return super().train_dataloader()
        if self.trainer is not None and self.trainer.world_size > 1:
            raise ValueError(
                f"data.subjects_per_batch={self.subjects_per_batch} draws its batches in one process; "
                f"with {self.trainer.world_size} processes every one would train on the same batches: "
                "use data.subjects_per_batch=null under DDP"
            )
        sampler = SubjectBatchSampler(self.subject_labels[self.train_idx], self.batch_size, self.subjects_per_batch)
        return data_loader(self, self.dataset("train"), batch_sampler=sampler, collate_fn=self.collate_fn)

    def predict_dataloader(self) -> DataLoader:
        """The test part (what ``trainer.predict`` embeds for the gallery/probe evaluation)."""
        return self._loader("test", shuffle=False)
