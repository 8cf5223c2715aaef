"""Optimiser and learning-rate schedule from Hydra configs, and the stage steps, shared by every LightningModule here.

A module stores the ``optimizer`` and ``scheduler`` configs (``_partial_: true`` dicts) in its
hyper-parameters; :class:`ConfiguredOptimization` turns them into ``configure_optimizers`` and
makes resumed runs keep the *configured* schedule parameters (e.g. a longer ``T_max``).
"""

from __future__ import annotations

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf


def as_plain_dict(cfg) -> dict:
    """A config node (DictConfig or mapping) as a plain, resolved dict: what a checkpoint stores in its hyper-parameters."""
    return OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)


class ConfiguredOptimization:
    """Mixin for a LightningModule whose ``hparams`` hold ``optimizer`` and ``scheduler`` (or None) configs."""

    def configure_optimizers(self):
        optimizer = instantiate(self.hparams.optimizer)(params=self.parameters())
        if not self.hparams.scheduler:
            return optimizer
        scheduler = instantiate(self.hparams.scheduler)(optimizer=optimizer)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "epoch"}}

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        """On resume, the schedule's configured parameters (e.g. ``T_max``) come from the current
        config, its progress (``last_epoch``, learning rates) from the checkpoint."""
        configured = {k: v for k, v in (self.hparams.scheduler or {}).items() if not k.startswith("_")}
        for state in checkpoint.get("lr_schedulers", []):
            state.update({k: v for k, v in configured.items() if k in state})


class StagedSteps:
    """Mixin: ``training_step`` / ``validation_step`` / ``test_step`` as one ``_step(batch, stage)`` of the module
    (``stage`` is ``"train"``, ``"val"`` or ``"test"``; the training step returns the loss)."""

    def training_step(self, batch: dict, batch_idx: int):
        return self._step(batch, "train")

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "test")
