"""Training data of the motion CVAE (``mocapkit train experiment=synthesis_cvae``): frame triples of the example clips
of one motion type.

:class:`SynthesisClipsDataModule` takes the clips ``mocapkit synthesize`` would train on: the AMC or BVH files
under ``root`` whose names contain ``motion_type`` (:func:`~mocapkit.synthesis.synthesize.find_clips`, sorted by
path), the first ``max_clips`` of them (BVH converted to ASF/AMC on one rest pose,
:func:`~mocapkit.synthesis.clips.as_amc_clips`). Validation clips are the **next** matching files, never a training
clip: ``ceil(val_fraction · max_clips)`` of them (0: no validation, the run keeps ``last.ckpt`` only).

The training clips become the CVAE's frames as :class:`~mocapkit.synthesis.cvae.CVAESynthesizer` makes them
(:func:`~mocapkit.synthesis.cvae.training_frames`: resampled to ``fps``, cut at fast angle flips, encoded,
standardised); the validation clips get the training standardisation. Batches are
``{"current": [B, F], "previous": [B, 2, F]}`` (:func:`~mocapkit.synthesis.cvae.frame_loader`), shuffled every
epoch for training.
"""

from __future__ import annotations

import math

import lightning as L
import numpy as np
from torch.utils.data import DataLoader

from mocapkit.synthesis.clips import SynthesisInputError, as_amc_clips, check_clips
from mocapkit.synthesis.cvae import CVAESynthesizer, frame_loader, training_frames
from mocapkit.synthesis.synthesize import find_clips, read_clip


class SynthesisClipsDataModule(L.LightningDataModule):
    """Frame triples of the example clips of one motion type (module docstring).

    Args:
        root: a folder of AMC (with their ASF) or BVH files, searched recursively (``../shared/data/hdm05_cuts11``).
        motion_type: the part of the file names that picks the motion type (``hopBothLegs1hops``); None: every file.
        max_clips: training clips (the first matching files; ``mocapkit synthesize --max-clips``).
        val_fraction: validation clips as a fraction of ``max_clips`` (rounded up), the matching files after the
            training ones; 0: none.
        fps: the model's frame rate (None: the clips' own); max_turn_speed: clips are cut at joint-angle flips
            faster than this (degrees per second; None: no cutting) — both as
            :class:`~mocapkit.synthesis.cvae.CVAESynthesizer`'s parameters of the same names.
        batch_size, eval_batch_size, num_workers: the loaders'.
        seed: the run's seed (``mocapkit train`` passes it; the order of the training triples follows the global
            seed).
    """

    def __init__(
        self,
        root: str | None = None,
        motion_type: str | None = None,
        max_clips: int = 10,
        val_fraction: float = 0.2,
        fps: float | None = 30.0,
        max_turn_speed: float | None = 5400.0,
        batch_size: int = 256,
        eval_batch_size: int = 1024,
        num_workers: int = 0,
        seed: int = 0,
    ):
        super().__init__()
        if root is None:
            raise ValueError(
                "data.root is not set: give a folder of AMC or BVH clips (e.g. data.root=../shared/data/"
                "hdm05_cuts11 data.motion_type=hopBothLegs1hops)"
            )
        if int(max_clips) < CVAESynthesizer.min_clips:
            raise ValueError(f"data.max_clips={max_clips}: at least {CVAESynthesizer.min_clips}")
        if not 0.0 <= float(val_fraction) <= 1.0:
            raise ValueError(f"data.val_fraction={val_fraction}: a fraction in [0, 1]")
        if fps is not None and not float(fps) > 0:
            raise ValueError(f"data.fps={fps}: a positive frame rate (or null: the clips' own)")
        self.root, self.motion_type, self.seed = str(root), motion_type, int(seed)
        self.batch_size, self.eval_batch_size = int(batch_size), int(eval_batch_size)
        self.num_workers = int(num_workers)
        files = find_clips([root], motion_type)
        n_val = math.ceil(float(val_fraction) * int(max_clips))
        self.files = {"train": files[: int(max_clips)], "val": files[int(max_clips) : int(max_clips) + n_val]}
        if n_val and not self.files["val"]:
            raise SynthesisInputError(
                f"data.val_fraction={val_fraction}: all {len(files)} clips matching "
                f"{motion_type!r} under {root} train (data.max_clips={max_clips}); none is left "
                f"for validation (set data.val_fraction=0 or lower data.max_clips)"
            )
        print(
            f"[mocapkit] reading {len(files[: int(max_clips) + n_val])} clip(s) matching {motion_type!r} under {root}",
            flush=True,
        )
        clips = as_amc_clips([read_clip(f) for f in [*self.files["train"], *self.files["val"]]])
        self.train_clips, self.val_clips = clips[: len(self.files["train"])], clips[len(self.files["train"]) :]
        check_clips(
            self.train_clips, CVAESynthesizer.min_clips, CVAESynthesizer.min_frames, what="SynthesisClipsDataModule"
        )
        self.fps = float(self.train_clips[0].fps) if fps is None else float(fps)
        self.frames = training_frames(self.train_clips, self.fps, max_turn_speed, what="SynthesisClipsDataModule")
        empty = (np.zeros((0,) + self.frames.current.shape[1:]), np.zeros((0,) + self.frames.previous.shape[1:]))
        self.parts = {
            "train": (self.frames.current, self.frames.previous),
            "val": self.frames.standardised(self.val_clips, what="SynthesisClipsDataModule")
            if self.val_clips
            else empty,
        }

    # ------------------------------------------------------------------ what the model needs
    def label_spaces(self) -> dict:
        """``{"frames": {...}}``: the features' rate, cutting and standardisation (the network's input width)."""
        return {"frames": self.frames.describe()}

    @property
    def class_names(self) -> list[str]:
        return []

    def sample_counts(self) -> dict[str, int]:
        return {"train": len(self.parts["train"][0]), "val": len(self.parts["val"][0]), "test": 0}

    def describe(self) -> dict:
        return {
            "split": f"{len(self.train_clips)} training clip(s), the next {len(self.val_clips)} for validation",
            "root": self.root,
            "motion_type": self.motion_type,
            "fps": self.fps,
            "files": {part: [str(f) for f in files] for part, files in self.files.items()},
            "sample_counts": self.sample_counts(),
        }

    # ------------------------------------------------------------------ loaders
    def train_dataloader(self) -> DataLoader:
        return frame_loader(*self.parts["train"], self.batch_size, shuffle=True, num_workers=self.num_workers)

    def val_dataloader(self) -> DataLoader:
        return frame_loader(*self.parts["val"], self.eval_batch_size, shuffle=False, num_workers=self.num_workers)


__all__ = ["SynthesisClipsDataModule"]
