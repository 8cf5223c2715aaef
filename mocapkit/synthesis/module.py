"""Lightning module of the autoregressive motion CVAE (:class:`~mocapkit.models.motion_vae.MotionVAE`).

Batches are ``{"current": [B, F], "previous": [B, 2, F]}`` of standardised pose features (``x_t`` and
``(x_{t−1}, x_{t−2})``; :func:`~mocapkit.synthesis.cvae.frame_loader`, from
:class:`~mocapkit.synthesis.cvae.CVAESynthesizer` or :class:`~mocapkit.synthesis.datamodule.SynthesisClipsDataModule`).
The loss is the negative ELBO per feature dimension with a KL weight:

- ``recon``: mean squared error of the reconstructed ``x_t`` (a unit-variance Gaussian likelihood, up to
  constants and a factor 2);
- ``kl``: ``KL(q(z | x_t, x_{t−1}) ‖ N(0, I))`` summed over ``z``, averaged over the batch, divided by ``F``;
- ``loss = recon + beta · kl``.

During training the conditioning frames get Gaussian noise of sd ``condition_noise`` (standardised units), so the
decoder learns to recover from its own small errors when it runs autoregressively. Logged: ``train/loss``,
``train/recon``, ``train/kl`` every step, and ``val/loss``, ``val/recon``, ``val/kl`` (no conditioning noise,
synchronised across processes) per validation epoch, which ``best.ckpt`` follows (lowest ``val/loss``);
``loss_curve`` keeps every training step's loss (Python floats) for the caller.
"""

from __future__ import annotations

import lightning as L
import torch
from hydra.utils import instantiate

from mocapkit.train.optimization import ConfiguredOptimization, as_plain_dict


class MotionVAEModule(ConfiguredOptimization, L.LightningModule):
    """Trains a :class:`~mocapkit.models.motion_vae.MotionVAE` (module docstring).

    Args:
        model: Hydra config of the network (``_target_: mocapkit.models.motion_vae.MotionVAE`` and its arguments).
        optimizer, scheduler: Hydra configs (``_partial_: true``), as the other modules.
        beta: weight of the KL term.
        condition_noise: sd of the noise on the conditioning frames during training (standardised units).
        frames: the pose features' rate, cutting and standardisation (:meth:`~mocapkit.synthesis.cvae.
            TrainingFrames.describe`: ``fps``, ``max_turn_speed``, ``features``, ``mean``, ``scale``; the data module
            adds it), kept in the checkpoint so that a run can sample
            (:meth:`~mocapkit.synthesis.cvae.CVAESynthesizer.from_checkpoint`); its ``features`` is the network's
            input width when ``model`` does not give one.
    """

    def __init__(
        self,
        model: dict,
        optimizer: dict,
        scheduler: dict | None = None,
        beta: float = 0.01,
        condition_noise: float = 0.05,
        frames: dict | None = None,
    ):
        super().__init__()
        model, optimizer = as_plain_dict(model), as_plain_dict(optimizer)
        scheduler = as_plain_dict(scheduler) if scheduler is not None else None
        frames = as_plain_dict(frames) if frames is not None else None
        if frames is not None and "features" not in model:
            model = {**model, "features": int(frames["features"])}
        self.save_hyperparameters(
            {
                "model": model,
                "optimizer": optimizer,
                "scheduler": scheduler,
                "beta": beta,
                "condition_noise": condition_noise,
                "frames": frames,
            }
        )
        self.model = instantiate(model)
        self.loss_curve: list[float] = []

    def losses(self, batch: dict) -> tuple[torch.Tensor, dict]:
        """``(total loss, {"recon", "kl"})`` of a batch (module docstring)."""
        previous = batch["previous"]
        if self.training and self.hparams.condition_noise > 0:
            previous = previous + self.hparams.condition_noise * torch.randn_like(previous)
        recon, mean, log_variance = self.model(batch["current"], previous)
        parts = {
            "recon": torch.mean((recon - batch["current"]) ** 2),
            "kl": torch.mean(torch.sum(0.5 * (mean**2 + log_variance.exp() - 1.0 - log_variance), dim=1))
            / self.model.features,
        }
        return parts["recon"] + self.hparams.beta * parts["kl"], parts

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        loss, parts = self.losses(batch)
        size = len(batch["current"])
        self.log("train/loss", loss, on_step=True, on_epoch=False, batch_size=size)
        for name, value in parts.items():
            self.log(f"train/{name}", value, on_step=True, on_epoch=False, batch_size=size)
        self.loss_curve.append(float(loss.detach()))
        return loss

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        loss, parts = self.losses(batch)
        size = len(batch["current"])
        self.log("val/loss", loss, on_step=False, on_epoch=True, prog_bar=True, batch_size=size, sync_dist=True)
        for name, value in parts.items():
            self.log(f"val/{name}", value, on_step=False, on_epoch=True, batch_size=size, sync_dist=True)


__all__ = ["MotionVAEModule"]
