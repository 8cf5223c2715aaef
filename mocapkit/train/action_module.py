"""Lightning module for action recognition from skeleton sequences.

The network, optimiser and learning-rate schedule are Hydra configs
(``_target_`` dicts) stored in the checkpoint's hyper-parameters, so
``ActionRecognitionModule.load_from_checkpoint(path)`` rebuilds the exact model.
"""
from __future__ import annotations

import lightning as L
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from mocapkit.train.optimization import ConfiguredOptimization


def _as_dict(cfg) -> dict:
    return OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)


class ActionRecognitionModule(ConfiguredOptimization, L.LightningModule):
    """Cross-entropy training of ``model`` (skeletons ``[B, M, T, J, 3]`` → logits ``[B, C]``).

    Args:
        model: Hydra config of the network; ``num_classes`` is passed at instantiation.
        optimizer: Hydra config of a ``torch.optim`` optimiser with ``_partial_: true``.
        scheduler: Hydra config of a ``torch.optim.lr_scheduler`` with ``_partial_: true``, or None.
        num_classes: output classes.
        class_names: names for reports (optional).
        label_smoothing: cross-entropy label smoothing.
    """

    def __init__(self, model: dict, optimizer: dict, num_classes: int, scheduler: dict | None = None,
                 class_names: list[str] | None = None, label_smoothing: float = 0.0):
        super().__init__()
        model, optimizer = _as_dict(model), _as_dict(optimizer)
        scheduler = _as_dict(scheduler) if scheduler is not None else None
        self.save_hyperparameters({"model": model, "optimizer": optimizer, "scheduler": scheduler,
                                   "num_classes": num_classes, "class_names": class_names,
                                   "label_smoothing": label_smoothing})
        self.model = instantiate(model, num_classes=num_classes)

    @classmethod
    def from_config(cls, cfg: DictConfig, datamodule) -> ActionRecognitionModule:
        """The module for a composed training config and its data module (``num_classes``, ``class_names``)."""
        return cls(model=cfg.model, optimizer=cfg.optimizer, scheduler=cfg.scheduler or None,
                   num_classes=datamodule.num_classes, class_names=datamodule.class_names,
                   label_smoothing=cfg.label_smoothing)

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        return self.model(skeletons)

    def _step(self, batch: dict, stage: str) -> torch.Tensor:
        logits = self(batch["skeletons"])
        loss = F.cross_entropy(logits, batch["labels"], label_smoothing=self.hparams.label_smoothing)
        acc = (logits.argmax(1) == batch["labels"]).float().mean()
        on_step = stage == "train"
        self.log(f"{stage}/loss", loss, on_step=on_step, on_epoch=True, prog_bar=True, batch_size=len(logits))
        self.log(f"{stage}/acc", acc, on_step=False, on_epoch=True, prog_bar=True, batch_size=len(logits))
        return loss

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        return self._step(batch, "train")

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "test")

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        return {"logits": self(batch["skeletons"]), "labels": batch["labels"], "indices": batch["indices"],
                "subjects": batch["subjects"]}
