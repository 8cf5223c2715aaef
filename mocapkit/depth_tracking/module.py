"""The LightningModule :class:`~mocapkit.depth_tracking.regressor.DepthJointRegressor` trains in ``fit``: normalised
depth crops ``[B, 1, S, S]`` → the 16 tracked joints ``[B, 16, 3]`` relative to each crop's 3-D centre (metres),
an L1 or squared-error loss in metres, Adam."""

from __future__ import annotations

import lightning as L
import torch

from mocapkit.models.depth_pose_cnn import depth_pose_cnn

#: The training losses: per-coordinate absolute error or squared error, metres (m²).
LOSSES = ("l1", "mse")


class DepthPoseModule(L.LightningModule):
    """A :func:`~mocapkit.models.depth_pose_cnn.depth_pose_cnn` network and its training step.

    Args:
        network: the builder's keyword arguments (``joints``, ``input_size``, ``width``, ...).
        lr: Adam's learning rate.
        loss: one of :data:`LOSSES`.

    A batch is ``(crops [B, 1, S, S] float32, joints [B, J, 3] float32 metres from the crop centre)``; the step logs
    ``train/loss`` (shown by Lightning's progress bar when the trainer has one).
    """

    def __init__(self, network: dict | None = None, lr: float = 1e-3, loss: str = "l1"):
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"DepthPoseModule: loss must be one of {list(LOSSES)}, got {loss!r}")
        self.save_hyperparameters()
        self.model = depth_pose_cnn(**dict(network or {}))

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        return self.model(crops)

    def training_step(self, batch, batch_idx):
        crops, joints = batch
        error = self.model(crops) - joints
        loss = error.abs().mean() if self.hparams.loss == "l1" else error.square().mean()
        self.log("train/loss", loss, prog_bar=True, batch_size=len(crops))
        return loss

    def configure_optimizers(self):
        return torch.optim.Adam(self.parameters(), lr=float(self.hparams.lr))


__all__ = ["LOSSES", "DepthPoseModule"]
