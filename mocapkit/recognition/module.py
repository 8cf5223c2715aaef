"""Lightning module for action recognition from skeleton sequences.

The network, optimiser and learning-rate schedule are Hydra configs
(``_target_`` dicts) stored in the checkpoint's hyper-parameters, so
``ActionRecognitionModule.load_from_checkpoint(path)`` rebuilds the exact model.

Accuracies are ``torchmetrics`` metric objects, one per stage, logged as objects: Lightning
accumulates them over the epoch, synchronises them across processes (DDP) and resets them, so
``val/acc`` — the checkpoint monitor — is the accuracy over the whole validation set, not over
one process's shard. Losses are logged with ``sync_dist=True`` for the same reason.
"""

from __future__ import annotations

import lightning as L
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from torch import nn
from torchmetrics.classification import MulticlassAccuracy

from mocapkit.train.optimization import (
    ConfiguredOptimization,
    StagedSteps,
    as_plain_dict,
)

#: Stages with their own accuracy metric (each is accumulated, synchronised and reset per epoch).
STAGES = ("train", "val", "test")


class ActionRecognitionModule(ConfiguredOptimization, StagedSteps, L.LightningModule):
    """Cross-entropy training of ``model`` (skeletons ``[B, M, T, J, 3]`` → logits ``[B, C]``).

    A model may return its ensemble members' logits ``[S, B, C]`` in training mode
    (:class:`~mocapkit.models.stgcn.MultiStreamSTGCN`): the loss is then the sum of the members'
    cross-entropies (each member's gradient is what it would get alone) and the accuracy is the mean logits'.

    Args:
        model: Hydra config of the network; ``num_classes`` is passed at instantiation.
        optimizer: Hydra config of a ``torch.optim`` optimiser with ``_partial_: true``.
        scheduler: Hydra config of a ``torch.optim.lr_scheduler`` with ``_partial_: true``, or None.
        num_classes: output classes.
        class_names: names for reports (optional).
        label_smoothing: cross-entropy label smoothing.
    """

    def __init__(
        self,
        model: dict,
        optimizer: dict,
        num_classes: int,
        scheduler: dict | None = None,
        class_names: list[str] | None = None,
        label_smoothing: float = 0.0,
    ):
        super().__init__()
        model, optimizer = as_plain_dict(model), as_plain_dict(optimizer)
        scheduler = as_plain_dict(scheduler) if scheduler is not None else None
        self.save_hyperparameters(
            {
                "model": model,
                "optimizer": optimizer,
                "scheduler": scheduler,
                "num_classes": num_classes,
                "class_names": class_names,
                "label_smoothing": label_smoothing,
            }
        )
        self.model = instantiate(model, num_classes=num_classes)
        #: ``<stage>_acc`` → top-1 accuracy over the epoch (micro: correct / samples). Not keyed by stage
        #: alone: ``train`` is taken by ``nn.Module.train``.
        self.accuracy = nn.ModuleDict(
            {f"{stage}_acc": MulticlassAccuracy(num_classes, average="micro") for stage in STAGES}
        )

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        return self.model(skeletons)

    def _step(self, batch: dict, stage: str) -> torch.Tensor:
        logits = self(batch["skeletons"])
        if logits.dim() == 3:  # an ensemble in training mode: [members, B, C], each member on its own loss
            loss = torch.stack(
                [
                    F.cross_entropy(member, batch["labels"], label_smoothing=self.hparams.label_smoothing)
                    for member in logits
                ]
            ).sum()
            logits = logits.mean(0)
        else:
            loss = F.cross_entropy(logits, batch["labels"], label_smoothing=self.hparams.label_smoothing)
        accuracy = self.accuracy[f"{stage}_acc"]
        accuracy.update(logits.detach(), batch["labels"])
        on_step = stage == "train"
        self.log(
            f"{stage}/loss", loss, on_step=on_step, on_epoch=True, prog_bar=True, batch_size=len(logits), sync_dist=True
        )
        self.log(f"{stage}/acc", accuracy, on_step=False, on_epoch=True, prog_bar=True)
        return loss

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        return {
            "logits": self(batch["skeletons"]),
            "labels": batch["labels"],
            "indices": batch["indices"],
            "subjects": batch["subjects"],
        }
