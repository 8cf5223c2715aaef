"""Training data of the learned refiners: windows of clean real mocap, corrupted on the fly.

:class:`MocapRefinementDataModule` reads a folder of HDM05, CMU or Bandai clips
(:mod:`mocapkit.datasets.mocap.folders`), or takes a list of motions (a refiner's ``fit``), holds out
**groups** (performers) for testing, keeps a seeded fraction of the training groups' *clips* for validation
(checkpoint selection never sees a test performer), and serves windows of ``window`` frames:

- training: ``windows_per_epoch`` windows per epoch, each from a clip drawn in proportion to its length and
  a uniform start, corrupted by :func:`~mocapkit.refinement.corruptions.training_corruption` (every protocol
  of the benchmark, levels drawn), a fresh draw every time;
- validation / test: up to ``eval_windows_per_clip`` evenly spaced windows of every clip, each with a fixed
  (seeded) corruption, the same in every epoch.

Clips shorter than ``window`` frames give no window (counted in :meth:`describe`). Batches are dicts::

    positions  float32 [B, W, J, 3]   corrupted positions, metres (0 where missing)
    missing    bool    [B, W, J]      True where the corrupted window has no observation
    clean      float32 [B, W, J, 3]   the clean window, metres
    corrupted  bool    [B, W, J]      entries the corruption removed or perturbed
"""

from __future__ import annotations

from dataclasses import replace

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from mocapkit.datasets.datamodule import data_loader
from mocapkit.datasets.mocap.folders import (
    MocapFolderError,
    held_out_groups,
    list_clips,
    read_clips,
)
from mocapkit.motion.layouts import hip_joints


def _window(motion, start: int, length: int):
    return replace(
        motion,
        positions=motion.positions[start : start + length],
        missing=motion.missing[start : start + length],
        rotations=None,
    )


def _item(clean, corruption) -> dict:
    corrupted = corruption.motion
    return {
        "positions": torch.from_numpy(np.nan_to_num(corrupted.filled(0.0)).astype(np.float32)),
        "missing": torch.from_numpy(corrupted.missing.copy()),
        "clean": torch.from_numpy(clean.positions.astype(np.float32)),
        "corrupted": torch.from_numpy(corruption.corrupted.copy()),
    }


class RandomWindows(Dataset):
    """``count`` windows of ``length`` frames from ``motions``, freshly corrupted at every access; with probability
    ``mirror`` a window is first replaced by its mirror image (:meth:`~mocapkit.motion.container.Motion.
    mirrored`: left and right swapped), which doubles the poses the network sees."""

    def __init__(
        self, motions: list, length: int, count: int, seed: int = 0, corruption: dict | None = None, mirror: float = 0.0
    ):
        self.motions = [m for m in motions if m.num_frames >= length]
        self.length, self.count, self.seed, self.calls, self.mirror = length, count, seed, 0, float(mirror)
        self.corruption = dict(corruption or {})
        spans = np.asarray([m.num_frames - length + 1 for m in self.motions], dtype=np.float64)
        self.weights = spans / spans.sum() if len(spans) else spans

    def __len__(self) -> int:
        return self.count if self.motions else 0

    def __getitem__(self, index: int) -> dict:
        from mocapkit.refinement.corruptions import training_corruption

        self.calls += 1
        rng = np.random.default_rng([self.seed, self.calls, index])
        motion = self.motions[rng.choice(len(self.motions), p=self.weights)]
        start = int(rng.integers(motion.num_frames - self.length + 1))
        clean = _window(motion, start, self.length)
        if self.mirror > 0 and rng.random() < self.mirror:  # no draw at 0: the stream of earlier runs is kept
            clean = clean.mirrored()
        return _item(clean, training_corruption(clean, rng, **self.corruption))


class FixedWindows(Dataset):
    """Evenly spaced windows of every motion, each with a seeded corruption (the same at every access)."""

    def __init__(self, motions: list, length: int, per_clip: int, seed: int = 0, corruption: dict | None = None):
        self.corruption = dict(corruption or {})
        self.items = []
        for i, motion in enumerate(motions):
            if motion.num_frames < length:
                continue
            starts = np.unique(np.linspace(0, motion.num_frames - length, per_clip).round().astype(int))
            self.items += [(i, int(s)) for s in starts]
        self.motions, self.length, self.seed = motions, length, seed

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        from mocapkit.refinement.corruptions import training_corruption

        clip, start = self.items[index]
        clean = _window(self.motions[clip], start, self.length)
        return _item(clean, training_corruption(clean, np.random.default_rng([self.seed, 1, index]), **self.corruption))


class MocapRefinementDataModule(L.LightningDataModule):
    """Corrupted windows of real mocap for the refiners; see the module docstring.

    Args:
        dataset: ``"hdm05"``, ``"cmu"`` or ``"bandai"`` (file patterns and groups: :mod:`~mocapkit.datasets.mocap.
            folders`). root: its folder (None with ``motions``).
        test_groups: groups (performers) held out for testing; None: the first group in sorted order.
        train_groups: groups to train on; None: every group not held out.
        extra: more training data of the same skeleton layout, ``[{dataset, root}]`` (every clip trains; e.g.
            CMU beside HDM05, which share the ASF skeleton).
        motions: instead of ``dataset`` / ``root``: clean motions (all of one layout) to train on (no test part).
        fps: resample every clip to this rate (None: keep the data's; it must be one rate).
        window: frames per window. windows_per_epoch: training windows per epoch.
        val_fraction: fraction of the training groups' clips kept for validation (seeded by ``split_seed``).
        eval_windows_per_clip: windows per validation / test clip.
        batch_size, eval_batch_size, num_workers: the loaders'.
        split_seed: seed of the validation draw and the fixed corruptions.
        seed: the run's seed (``mocapkit train`` passes it): the stream of training windows and corruptions.
        corruption: keyword arguments of :func:`~mocapkit.refinement.corruptions.training_corruption`
            (``whole_joint_rate``, ``weights``: protocol → relative weight), for every part.
        mirror: probability that a training window is mirrored left-right (:class:`RandomWindows`; 0: never).
            Validation and test windows are never mirrored.
    """

    def __init__(
        self,
        dataset: str | None = "hdm05",
        root: str | None = None,
        test_groups: list | None = None,
        train_groups: list | None = None,
        extra: list | None = None,
        motions: list | None = None,
        fps: float | None = None,
        window: int = 120,
        windows_per_epoch: int = 4096,
        val_fraction: float = 0.1,
        eval_windows_per_clip: int = 2,
        batch_size: int = 32,
        eval_batch_size: int = 64,
        num_workers: int = 0,
        split_seed: int = 0,
        seed: int = 0,
        corruption: dict | None = None,
        mirror: float = 0.0,
    ):
        super().__init__()
        if not 0.0 <= float(mirror) <= 1.0:
            raise ValueError(f"data.mirror={mirror}: a probability in [0, 1]")
        self.mirror = float(mirror)
        if int(window) < 8:
            raise ValueError(f"data.window={window}: at least 8 frames")
        if not 0.0 < float(val_fraction) < 1.0:
            raise ValueError(f"data.val_fraction={val_fraction}: a fraction in (0, 1)")
        self.window, self.windows_per_epoch = int(window), int(windows_per_epoch)
        self.eval_windows_per_clip, self.split_seed, self.seed = int(eval_windows_per_clip), int(split_seed), int(seed)
        self.batch_size, self.eval_batch_size, self.num_workers = (
            int(batch_size),
            int(eval_batch_size),
            int(num_workers),
        )
        self.dataset_name, self.root = dataset, None if root is None else str(root)
        self.corruption = dict(corruption or {})
        if set(self.corruption) - {"whole_joint_rate", "weights"}:
            raise ValueError(
                f"data.corruption: unknown key(s) {sorted(set(self.corruption) - {'whole_joint_rate', 'weights'})}"
                "; it takes whole_joint_rate and weights"
            )
        if motions is not None:
            all_motions = [
                m if m.metadata.get("group") else replace(m, metadata={**m.metadata, "group": "train"}) for m in motions
            ]
            if fps is not None:
                all_motions = [m.resample(float(fps)) for m in all_motions]
        else:
            if root is None:
                raise ValueError(
                    f"data.root is not set: give the {dataset} folder (e.g. data.root=../shared/data/hdm05_cuts11)"
                )
            print(f"[mocapkit] reading {dataset} clips under {root}", flush=True)
            all_motions = read_clips(list_clips(dataset, root), fps, progress=True)
        if not all_motions:
            raise ValueError("no training motion")
        groups = sorted({m.metadata["group"] for m in all_motions})
        train, test = held_out_groups(groups, [] if motions is not None else test_groups, train_groups, dataset, root)
        self.groups = {"train": train, "test": test}
        train_motions = [m for m in all_motions if m.metadata["group"] in train]
        self.test_motions = [m for m in all_motions if m.metadata["group"] in test]
        rng = np.random.default_rng(self.split_seed)
        order = rng.permutation(len(train_motions))
        n_val = max(1, round(float(val_fraction) * len(train_motions)))
        val_set = set(order[:n_val].tolist())
        self.val_motions = [m for i, m in enumerate(train_motions) if i in val_set]
        self.train_motions = [m for i, m in enumerate(train_motions) if i not in val_set]
        self.extra_sources = []
        for source in extra or []:
            more = read_clips(list_clips(source["dataset"], source["root"]), fps, progress=True)
            if more[0].joint_names != all_motions[0].joint_names:
                raise MocapFolderError(
                    f"data.extra {source['dataset']} under {source['root']}: joints "
                    f"{list(more[0].joint_names)[:4]}... differ from the training data's; extra "
                    "data must share the skeleton layout"
                )
            self.train_motions += more
            self.extra_sources.append({**source, "clips": len(more)})
        rates = {float(m.fps) for m in [*self.train_motions, *self.val_motions]}
        if len(rates) > 1:
            raise MocapFolderError(f"the training clips mix frame rates {sorted(rates)}: set data.fps to resample them")
        self.fps = rates.pop()
        self.reference = all_motions[0]
        if self.mirror > 0:
            try:
                _window(self.reference, 0, 1).mirrored()
            except ValueError as error:
                raise MocapFolderError(f"data.mirror={self.mirror}: {error}") from None

    # ------------------------------------------------------------------ what the model needs
    def label_spaces(self) -> dict:
        """``{"skeleton": {...}}``: the layout and training statistics the refiner network is built with."""
        ref = self.reference
        if ref.parents is None:
            raise MocapFolderError(f"{ref.source or ref.name}: no joint hierarchy; learned refiners need a skeleton")
        lengths = np.zeros(ref.num_joints)
        child = [j for j, p in enumerate(ref.parents) if p >= 0]
        parent = [ref.parents[j] for j in child]
        sums, counts = np.zeros(len(child)), np.zeros(len(child))
        for m in self.train_motions:
            seen = ~m.missing[:, child] & ~m.missing[:, parent]
            length = np.linalg.norm(m.positions[:, child] - m.positions[:, parent], axis=-1)
            sums += np.where(seen, length, 0).sum(0)
            counts += seen.sum(0)
        lengths[child] = sums / np.maximum(counts, 1)
        return {
            "skeleton": {
                "joint_names": list(ref.joint_names),
                "parents": list(ref.parents),
                "up_axis": ref.up_axis,
                "hips": hip_joints(ref.joint_names, ref.layout_name),
                "bone_lengths": [float(v) for v in lengths],
                "fps": self.fps,
                "window": self.window,
                "train_groups": self.groups["train"],
            }
        }

    @property
    def class_names(self) -> list[str]:
        return []

    def sample_counts(self) -> dict[str, int]:
        return {"train": len(self.dataset("train")), "val": len(self.dataset("val")), "test": len(self.dataset("test"))}

    def describe(self) -> dict:
        short = {
            part: sum(m.num_frames < self.window for m in motions)
            for part, motions in (("train", self.train_motions), ("val", self.val_motions), ("test", self.test_motions))
        }
        return {
            "split": f"groups: train {self.groups['train']}, test {self.groups['test']}",
            "dataset": self.dataset_name,
            "root": self.root,
            "fps": self.fps,
            "window": self.window,
            "clips": {"train": len(self.train_motions), "val": len(self.val_motions), "test": len(self.test_motions)},
            "clips_shorter_than_window": short,
            "extra": self.extra_sources,
            "mirror": self.mirror,
            "sample_counts": self.sample_counts(),
        }

    # ------------------------------------------------------------------ loaders
    def dataset(self, part: str) -> Dataset:
        if not hasattr(self, "_datasets"):
            self._datasets = {
                "train": RandomWindows(
                    self.train_motions, self.window, self.windows_per_epoch, self.seed, self.corruption, self.mirror
                ),
                "val": FixedWindows(
                    self.val_motions, self.window, self.eval_windows_per_clip, self.split_seed, self.corruption
                ),
                "test": FixedWindows(
                    self.test_motions, self.window, self.eval_windows_per_clip, self.split_seed + 1, self.corruption
                ),
            }
        return self._datasets[part]

    def _loader(self, part: str) -> DataLoader:
        return data_loader(
            self, self.dataset(part), batch_size=self.batch_size if part == "train" else self.eval_batch_size
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train")

    def val_dataloader(self) -> DataLoader:
        return self._loader("val")

    def test_dataloader(self) -> DataLoader:
        return self._loader("test")


__all__ = ["FixedWindows", "MocapRefinementDataModule", "RandomWindows"]
