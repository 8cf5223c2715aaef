"""A small CNN regressing full-body joint positions from one normalised depth crop (the learned baseline of the
depth-tracking task, :mod:`mocapkit.depth_tracking.regressor`)::

    crop   [B, 1, S, S]   depth minus the crop centre's depth, divided by a fixed scale; background a constant
    block k (k = 0 .. blocks-1): 3×3 conv stride 2 → BN → ReLU → 3×3 conv → BN → ReLU,
           channels width · min(2^k, 8)                       [B, C_k, ⌈S / 2^(k+1)⌉, ...]
    flatten → Linear(hidden) → ReLU → Dropout → Linear(3 J)   [B, J, 3] metres from the crop centre

With the defaults (S = 96, width 16, 5 blocks: 16-32-64-128-128 channels) the last map is 128 × 3 × 3; it is
flattened rather than pooled globally, so the head knows *where* in the crop each feature fired (a hand's position is
the answer, not only its presence). About 0.9 M parameters and 32 MMAC per crop: a 32-crop Adam step takes about
0.1 s on one CPU thread, so 1000 steps train in a couple of minutes (width 32: 3 M parameters, 3.5× slower).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from mocapkit.models.ops import Dropout


class DepthPoseCNN(nn.Module):
    """Depth crops ``[B, 1, S, S]`` → joints ``[B, J, 3]`` (metres, relative to the crop's 3-D centre).

    Args:
        joints: J, joints predicted (16: :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS`).
        width: channels of the first block; block k has ``width · min(2^k, 8)``.
        blocks: convolution blocks, each halving the crop (5: 96 → 3).
        input_size: S, the crop's side in pixels; fixes the flatten size.
        hidden: width of the head's hidden layer.
        dropout: dropout probability before the output layer.

    Attributes:
        features: the convolution blocks (``nn.Sequential``).
        head: ``Flatten → Linear → ReLU → Dropout → Linear(3 J)``; its last layer is ``head[-1]``.
    """

    def __init__(
        self,
        joints: int = 16,
        width: int = 16,
        blocks: int = 5,
        input_size: int = 96,
        hidden: int = 256,
        dropout: float = 0.0,
    ):
        super().__init__()
        for name, value, minimum in (
            ("joints", joints, 1),
            ("width", width, 1),
            ("blocks", blocks, 1),
            ("input_size", input_size, 8),
            ("hidden", hidden, 1),
        ):
            if not isinstance(value, int) or isinstance(value, bool) or value < minimum:
                raise ValueError(f"depth_pose_cnn: {name} must be an integer ≥ {minimum}, got {value!r}")
        if not 0.0 <= float(dropout) < 1.0:
            raise ValueError(f"depth_pose_cnn: dropout must be in [0, 1), got {dropout!r}")
        self.joints, self.input_size = joints, input_size
        layers: list[nn.Module] = []
        channels, side = 1, input_size
        for k in range(blocks):
            out = width * min(2**k, 8)
            layers += [
                nn.Conv2d(channels, out, 3, stride=2, padding=1, bias=False),
                nn.BatchNorm2d(out),
                nn.ReLU(inplace=True),
                nn.Conv2d(out, out, 3, padding=1, bias=False),
                nn.BatchNorm2d(out),
                nn.ReLU(inplace=True),
            ]
            channels, side = out, math.ceil(side / 2)
        self.features = nn.Sequential(*layers)
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(channels * side * side, hidden),
            nn.ReLU(inplace=True),
            Dropout(float(dropout)),
            nn.Linear(hidden, 3 * joints),
        )

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        if crops.dim() != 4 or tuple(crops.shape[1:]) != (1, self.input_size, self.input_size):
            raise ValueError(
                f"expected depth crops [batch, 1, {self.input_size}, {self.input_size}], got {list(crops.shape)}"
            )
        return self.head(self.features(crops)).view(-1, self.joints, 3)

    def start_at(self, mean_pose: torch.Tensor, scale: float = 0.1) -> None:
        """Start the output at ``mean_pose`` ``[J, 3]`` (the output layer's bias; its weights scaled by ``scale``),
        so an untrained network predicts the training set's mean pose and training learns the deviations."""
        last = self.head[-1]
        with torch.no_grad():
            last.bias.copy_(torch.as_tensor(mean_pose, dtype=last.bias.dtype).reshape(-1))
            last.weight.mul_(float(scale))


def depth_pose_cnn(
    joints: int = 16,
    width: int = 16,
    blocks: int = 5,
    input_size: int = 96,
    hidden: int = 256,
    dropout: float = 0.0,
) -> DepthPoseCNN:
    """Hydra builder of :class:`DepthPoseCNN`: normalised depth crops ``[B, 1, input_size, input_size]`` → joints
    ``[B, joints, 3]`` metres from the crop centre."""
    return DepthPoseCNN(joints, width, blocks, input_size, hidden, dropout)


__all__ = ["DepthPoseCNN", "depth_pose_cnn"]
