"""Lightning module of the learned motion refiners (:mod:`mocapkit.models.refiners`).

Training batches come from :class:`~mocapkit.refinement.datamodule.MocapRefinementDataModule`
(corrupted windows and their clean originals). The loss is computed in the network's normalised
frame (the window's centre, heading and body size; :class:`~mocapkit.models.refiners.PoseNormalizer`),
on the clean window brought into that same frame:

- ``corrupted``: mean Euclidean error over the entries the corruption removed or perturbed;
- ``clean``: the same over the untouched observed entries (weight ``clean_weight``: keep what is right);
- ``bone``: mean absolute bone-length error of the output against the clean window (``bone_weight``);
- ``velocity``: mean Euclidean error of frame-to-frame velocities against the clean window (``velocity_weight``).

Logged metrics (torchmetrics, synchronised across processes): ``<stage>/loss`` and ``<stage>/mje_cm``, the
mean 3-D joint error over corrupted entries in centimetres (in the data's units ×100: metres → cm), which
``best.ckpt`` follows (lowest).
"""

from __future__ import annotations

import lightning as L
import torch
from hydra.utils import instantiate
from torch import nn
from torchmetrics import MeanMetric

from mocapkit.models.ops import vector_length
from mocapkit.train.optimization import (
    ConfiguredOptimization,
    StagedSteps,
    as_plain_dict,
)

STAGES = ("train", "val", "test")


class MotionRefinementModule(ConfiguredOptimization, StagedSteps, L.LightningModule):
    """Trains a refiner network (positions ``[B, T, J, 3]`` + missing ``[B, T, J]`` → positions).

    Args:
        model: Hydra config of the network (``mocapkit.models.refiners``); ``skeleton`` is passed to it.
        optimizer, scheduler: Hydra configs (``_partial_: true``), as the other modules.
        skeleton: the layout and training statistics from the data module (``joint_names``, ``parents``,
            ``up_axis``, ``hips``, ``bone_lengths``, ``fps``, ``window``, ``train_groups``).
        clean_weight, bone_weight, velocity_weight: loss weights (module docstring).
    """

    def __init__(
        self,
        model: dict,
        optimizer: dict,
        skeleton: dict,
        scheduler: dict | None = None,
        clean_weight: float = 0.1,
        bone_weight: float = 0.1,
        velocity_weight: float = 0.5,
    ):
        super().__init__()
        model, optimizer = as_plain_dict(model), as_plain_dict(optimizer)
        scheduler = as_plain_dict(scheduler) if scheduler is not None else None
        skeleton = as_plain_dict(skeleton)
        self.save_hyperparameters(
            {
                "model": model,
                "optimizer": optimizer,
                "scheduler": scheduler,
                "skeleton": skeleton,
                "clean_weight": clean_weight,
                "bone_weight": bone_weight,
                "velocity_weight": velocity_weight,
            }
        )
        network_args = {k: skeleton[k] for k in ("joint_names", "parents", "up_axis", "hips", "bone_lengths", "fps")}
        self.model = instantiate(model, **network_args)
        self.mje = nn.ModuleDict({f"{stage}_mje": MeanMetric() for stage in STAGES})
        parents = skeleton["parents"]
        self._child = [j for j, p in enumerate(parents) if p >= 0]
        self._parent = [parents[j] for j in self._child]

    def forward(self, positions: torch.Tensor, missing: torch.Tensor) -> torch.Tensor:
        return self.model(positions, missing)

    def losses(self, batch: dict) -> tuple[torch.Tensor, dict, torch.Tensor]:
        """``(total loss, {name: value}, output positions [B, T, J, 3] in the data's units)``."""
        refined, stats = self.model.normalised_forward(batch["positions"], batch["missing"])
        target = self.model.normalizer(batch["clean"], stats)
        error = vector_length(refined - target)  # [B,T,J]
        corrupted = batch["corrupted"].to(error.dtype)
        clean = (~batch["corrupted"] & ~batch["missing"]).to(error.dtype)
        parts = {
            "corrupted": (error * corrupted).sum() / corrupted.sum().clamp_min(1),
            "clean": (error * clean).sum() / clean.sum().clamp_min(1),
        }
        bone = lambda x: vector_length(x[:, :, self._child] - x[:, :, self._parent])
        parts["bone"] = (bone(refined) - bone(target)).abs().mean()
        parts["velocity"] = vector_length(refined.diff(dim=1) - target.diff(dim=1)).mean()
        hp = self.hparams
        total = (
            parts["corrupted"]
            + hp.clean_weight * parts["clean"]
            + hp.bone_weight * parts["bone"]
            + hp.velocity_weight * parts["velocity"]
        )
        return total, parts, self.model.normalizer.inverse(refined, stats)

    def _step(self, batch: dict, stage: str) -> torch.Tensor:
        loss, parts, output = self.losses(batch)
        size = len(batch["positions"])
        error_cm = 100.0 * vector_length(output - batch["clean"])
        weight = batch["corrupted"].to(error_cm.dtype)
        metric = self.mje[f"{stage}_mje"]
        metric.update(error_cm.detach(), weight)
        on_step = stage == "train"
        self.log(f"{stage}/loss", loss, on_step=on_step, on_epoch=True, prog_bar=True, batch_size=size, sync_dist=True)
        for name, value in parts.items():
            self.log(f"{stage}/loss_{name}", value, on_step=False, on_epoch=True, batch_size=size, sync_dist=True)
        self.log(f"{stage}/mje_cm", metric, on_step=False, on_epoch=True, prog_bar=True)
        return loss
