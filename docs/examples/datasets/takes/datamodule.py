"""Lightning data module over a folder of motion takes named ``<action>_<performer>_<take>.<ext>``.

Any file :func:`~mocapkit.datasets.formats.motion_io.read_motion` reads whose skeleton is one of the named layouts
(:data:`mocapkit.motion.layouts.LAYOUTS`: Kinect v1 and v2 files, CMU/HDM05 ASF/AMC). Every take is read once,
resampled to ``fps`` and put on one skeleton ``layout`` (by joint name, or through the shared body landmarks from
another layout); the ``test_performers`` are held out and validation comes from the training performers' takes. Batches are those of
every skeleton data module (:mod:`mocapkit.datasets.datamodule`)::

    skeletons  float32 [B, 1, T, J, 3]   metres, the layout's joint order; zero-padded to the longest take
    labels     int64   [B]               0-based action (sorted action names)
    lengths, indices, subjects  int64 [B]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from mocapkit.datasets.datamodule import SkeletonDataModule
from mocapkit.datasets.formats.motion_io import find_motion_files, read_motion
from mocapkit.datasets.splits import validation_split
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import SkeletonLayout, get_layout


def parse_take_name(path: Path) -> tuple[str, str]:
    """``(action, performer)`` of ``<action>_<performer>_<take>.<ext>``; a ValueError names the file otherwise."""
    parts = path.stem.split("_")
    if len(parts) != 3:
        raise ValueError(f"{path}: expected a name <action>_<performer>_<take>.<ext>")
    return parts[0], parts[1]


def on_layout(motion: Motion, target: SkeletonLayout) -> Motion:
    """``motion`` with the joints of ``target`` in its order: by name on the same layout, else through the body
    landmarks the two layouts share (:meth:`~mocapkit.motion.container.Motion.map_layout`)."""
    if motion.layout_name == target.name:
        return motion.select(list(target.joint_names))
    return motion.map_layout(target)


class TakesDataModule(SkeletonDataModule):
    """Train / validation / test loaders over a folder of takes (see the module docstring).

    Args:
        root: the folder (searched recursively). layout: the batches' joint order (``ntu25``, ``msr20``, ``cmu31``).
        test_performers: held out (a list); None: the first performer, sorted. fps: takes are resampled to it.
        val_fraction: share of the training performers' takes held out for validation (seeded by ``seed``).
        batch_size, eval_batch_size, num_workers, max_frames, augment: as every skeleton data module.
    """

    def __init__(
        self,
        root: str,
        layout: str = "cmu31",
        test_performers: list[str] | None = None,
        fps: float = 30.0,
        val_fraction: float = 0.2,
        batch_size: int = 16,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        max_frames: int = 32,
        augment: dict | None = None,
        seed: int = 0,
    ):
        super().__init__()
        self.root, self.layout, self.seed = Path(root), layout, seed
        self._set_loading(batch_size, eval_batch_size, num_workers, max_frames, augment)
        paths = [p for p in find_motion_files(self.root) if p.suffix.lower() != ".asf"]
        if not paths:
            raise ValueError(f"data.root={str(self.root)!r}: no motion file found")
        names = [parse_take_name(p) for p in paths]
        self.actions = sorted({action for action, _ in names})
        self.performers = sorted({performer for _, performer in names})
        test = list(test_performers) if test_performers else self.performers[:1]
        unknown = sorted(set(test) - set(self.performers))
        if unknown:
            raise ValueError(f"data.test_performers: {unknown} not in {self.root} (performers: {self.performers})")
        self.labels = np.array([self.actions.index(a) for a, _ in names], dtype=np.int64)
        self.subjects = np.array([self.performers.index(p) for _, p in names], dtype=np.int64)
        is_test = np.isin([p for _, p in names], test)
        self.test_idx = np.flatnonzero(is_test)
        self.train_idx, self.val_idx = validation_split(
            np.flatnonzero(~is_test), self.subjects, val_fraction=val_fraction, seed=seed, by_subject=False
        )
        target = get_layout(layout)
        # [T, J, 3] float32 metres per take, missing samples as zeros (every model treats zeros as absent)
        self.sequences = [torch.from_numpy(on_layout(read_motion(p).resample(fps), target).filled(0.0)) for p in paths]

    @property
    def num_classes(self) -> int:
        return len(self.actions)

    @property
    def class_names(self) -> list[str]:
        return list(self.actions)

    def describe(self) -> dict:
        """The split for reports (``eval/metrics.json``)."""
        return {
            "split": "held-out performers",
            "data_root": str(self.root),
            **self.split_description(np.asarray(self.performers)[self.subjects]),
        }
