"""Training data of the learned Kinect correctors (``mocapkit train experiment=kinect_corrector_bigru``): windows of
(simulated Kinect, mocap) clip pairs of a mocap folder.

:class:`KinectPairsDataModule` turns every motion file in a per-performer sub-folder of ``root`` into a (Kinect,
mocap) pair through the calibrated Kinect v1 simulator
(:func:`~mocapkit.datasets.synthetic.kinect_noise.simulate_pairs`, ``fps`` frames per second, Kinect-20 joints;
**the run's seed is the simulation seed**, as the cell's seed is in the Kinect benchmark,
:mod:`mocapkit.kinect.benchmark`). Performers are held out for testing as the benchmark's protocols hold them out
(``test_groups``: sub-folder names), and a seeded fraction of the training performers' clips is kept for
validation, so checkpoint selection never sees a test performer.

Every part is cut into windows as :class:`~mocapkit.kinect.learned.LearnedKinectCorrector` cuts its training
pairs (:func:`~mocapkit.kinect.learned.kinect_windows`: ``window`` frames, stride ``window // 4``, a short pair
padded); batches are the dicts of :func:`~mocapkit.kinect.learned.window_loader` (``positions`` the simulated
Kinect, ``clean`` the mocap, ``missing``, ``corrupted``). Training windows are shuffled every epoch, validation
and test windows come in order.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
from torch.utils.data import DataLoader

from mocapkit.kinect.learned import kinect_skeleton, kinect_windows, mean_bone_lengths, window_loader


class KinectPairsDataModule(L.LightningDataModule):
    """Windows of (simulated Kinect, mocap) pairs for the learned Kinect correctors (module docstring).

    Args:
        root: a folder of motion files, one sub-folder per performer (``../shared/data/hdm05_cuts11``).
        test_groups: performers (sub-folder names) held out for testing; None: the first in name order.
        train_groups: performers to train on; None: every one not held out.
        noise: the simulator's calibration (a :data:`~mocapkit.datasets.synthetic.kinect_noise.NOISE_PRESETS`
            name, as the benchmark's ``noise``).
        fps: the simulated Kinect's frame rate.
        window: frames per window; untracked_as_missing: joints not TRACKED go to the network as missing
            (:class:`~mocapkit.kinect.learned.LearnedKinectCorrector`).
        val_fraction: fraction of the training performers' clips kept for validation (seeded by ``split_seed``;
            0: none).
        batch_size, eval_batch_size, num_workers: the loaders'.
        split_seed: the seed of the validation draw.
        seed: the run's seed (``mocapkit train`` passes it): the simulation seed.
    """

    def __init__(
        self,
        root: str | None = None,
        test_groups: list | None = None,
        train_groups: list | None = None,
        noise: str = "mean_error",
        fps: float = 30.0,
        window: int = 64,
        untracked_as_missing: bool = False,
        val_fraction: float = 0.1,
        batch_size: int = 32,
        eval_batch_size: int = 64,
        num_workers: int = 0,
        split_seed: int = 0,
        seed: int = 0,
    ):
        super().__init__()
        if int(window) < 4:
            raise ValueError(f"data.window={window}: at least 4 frames")
        if not 0.0 <= float(val_fraction) < 1.0:
            raise ValueError(f"data.val_fraction={val_fraction}: a fraction in [0, 1)")
        self.window, self.untracked_as_missing = int(window), bool(untracked_as_missing)
        self.batch_size, self.eval_batch_size = int(batch_size), int(eval_batch_size)
        self.num_workers = int(num_workers)
        self.root, self.noise, self.seed = None if root is None else str(root), noise, int(seed)
        self.fps = float(fps)
        self.parts, self.groups = self._simulate(
            root, noise, self.fps, test_groups, train_groups, float(val_fraction), int(split_seed)
        )
        if not self.parts["train"][1]:
            raise ValueError(f"data.root={root}: no training clip (groups {self.groups})")

    def _simulate(self, root, noise, fps, test_groups, train_groups, val_fraction, split_seed):
        """``(parts, groups)``: the simulated pairs of every file under ``root`` split into train / val / test."""
        from mocapkit.datasets.formats.motion_io import find_motion_files
        from mocapkit.datasets.mocap.folders import held_out_groups
        from mocapkit.datasets.synthetic.kinect_noise import KinectNoiseConfig, simulate_pairs

        if root is None:
            raise ValueError(
                "data.root is not set: give a mocap folder with one sub-folder per performer (e.g. "
                "data.root=../shared/data/hdm05_cuts11)"
            )
        folder = Path(root)
        if not folder.is_dir():
            raise ValueError(f"data.root={root}: not a folder")
        try:
            config = KinectNoiseConfig.preset(noise)
        except ValueError as exc:
            raise ValueError(f"data.noise={noise!r}: {exc}") from None
        files = sorted(f for f in find_motion_files(folder) if f.parent != folder)
        if not files:
            raise ValueError(f"data.root={root}: no motion files in per-performer sub-folders")
        group_of = {f: f.parent.name for f in files}
        train, test = held_out_groups(sorted(set(group_of.values())), test_groups, train_groups, "mocap", root)
        train_files = [f for f in files if group_of[f] in train]
        order = np.random.default_rng(split_seed).permutation(len(train_files))
        n_val = max(1, round(val_fraction * len(train_files))) if val_fraction > 0 else 0
        val_set = set(order[:n_val].tolist())
        chosen = {
            "train": [f for i, f in enumerate(train_files) if i not in val_set],
            "val": [f for i, f in enumerate(train_files) if i in val_set],
            "test": [f for f in files if group_of[f] in test],
        }
        print(
            f"[mocapkit] simulating Kinect pairs of {sum(map(len, chosen.values()))} clips under {root} "
            f"(noise {noise}, seed {self.seed})",
            flush=True,
        )
        pairs, _ = simulate_pairs(
            [f for part in chosen.values() for f in part], config, seed=self.seed, fps=fps, progress=True
        )
        by_file = {p.path: p for p in pairs}
        parts = {
            part: (
                [by_file[f].noisy for f in chosen_files],
                [by_file[f].clean for f in chosen_files],
                [by_file[f].state for f in chosen_files],
            )
            for part, chosen_files in chosen.items()
        }
        self.files = {part: [str(f) for f in chosen_files] for part, chosen_files in chosen.items()}
        return parts, {"train": train, "test": test}

    # ------------------------------------------------------------------ what the model needs
    def label_spaces(self) -> dict:
        """``{"skeleton": {...}}``: the Kinect-20 layout with the training pairs' mean bone lengths, and the
        windowing a corrector predicts with (``window``, ``untracked_as_missing``)."""
        skeleton = kinect_skeleton(mean_bone_lengths(self.parts["train"][1]), self.fps)
        return {
            "skeleton": {
                **skeleton,
                "window": self.window,
                "untracked_as_missing": self.untracked_as_missing,
                "train_groups": self.groups["train"],
            }
        }

    @property
    def class_names(self) -> list[str]:
        return []

    def windows(self, part: str) -> dict[str, np.ndarray]:
        """The windows of ``part`` (``train``, ``val`` or ``test``; :func:`~mocapkit.kinect.learned.kinect_windows`)."""
        if not hasattr(self, "_windows"):
            self._windows = {
                name: kinect_windows(*pairs, self.window, self.untracked_as_missing)
                for name, pairs in self.parts.items()
            }
        return self._windows[part]

    def sample_counts(self) -> dict[str, int]:
        return {part: len(self.windows(part)["positions"]) for part in ("train", "val", "test")}

    def describe(self) -> dict:
        return {
            "split": f"groups: train {self.groups['train']}, test {self.groups['test']}",
            "root": self.root,
            "noise": self.noise,
            "fps": self.fps,
            "window": self.window,
            "simulation_seed": self.seed,
            "clips": {part: len(pairs[1]) for part, pairs in self.parts.items()},
            "sample_counts": self.sample_counts(),
        }

    # ------------------------------------------------------------------ loaders
    def _loader(self, part: str) -> DataLoader:
        train = part == "train"
        return window_loader(
            self.windows(part), self.batch_size if train else self.eval_batch_size, train, self.num_workers
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train")

    def val_dataloader(self) -> DataLoader:
        return self._loader("val")

    def test_dataloader(self) -> DataLoader:
        return self._loader("test")


__all__ = ["KinectPairsDataModule"]
