"""Training-time augmentation of skeleton sequences (torch, one sample at a time).

Absent bodies and frames are stored as zeros, so every transform here keeps
zeros as zeros. Random numbers come from torch's global generator, which
Lightning seeds per data-loader worker (``seed_everything(workers=True)``).
"""
from __future__ import annotations

import math

import torch


class SkeletonAugment:
    """Random rotation about the vertical axis and random temporal cropping.

    Args:
        rotate_deg: maximum absolute rotation about the vertical (y) axis, degrees;
            the rotation is about the centroid of the present joints. 0 disables it.
        crop: ``(min, max)`` fraction of the frames kept by a random temporal crop;
            ``(1, 1)`` disables it.
        min_frames: never crop below this many frames.
    """

    def __init__(self, rotate_deg: float = 0.0, crop: tuple[float, float] = (1.0, 1.0), min_frames: int = 8):
        lo, hi = crop
        if not 0 < lo <= hi <= 1:
            raise ValueError(f"augment.crop must satisfy 0 < min <= max <= 1, got {crop}")
        self.rotate_deg = float(rotate_deg)
        self.crop = (float(lo), float(hi))
        self.min_frames = int(min_frames)

    def __call__(self, skeleton: torch.Tensor) -> torch.Tensor:
        """``[M, T, J, 3]`` → ``[M, T', J, 3]`` with ``T' <= T``."""
        skeleton = self._crop(skeleton)
        if self.rotate_deg > 0:
            skeleton = self._rotate(skeleton)
        return skeleton

    def _crop(self, skeleton: torch.Tensor) -> torch.Tensor:
        t = skeleton.shape[1]
        lo, hi = self.crop
        if lo >= 1.0 or t <= self.min_frames:
            return skeleton
        ratio = lo + (hi - lo) * float(torch.rand(()))
        keep = max(self.min_frames, int(round(ratio * t)))
        start = int(torch.randint(0, t - keep + 1, ()))
        return skeleton[:, start:start + keep]

    def _rotate(self, skeleton: torch.Tensor) -> torch.Tensor:
        present = skeleton.abs().sum(-1, keepdim=True) > 0                      # [M, T, J, 1]
        if not present.any():
            return skeleton
        center = (skeleton * present).sum((0, 1, 2)) / present.sum()
        angle = math.radians(self.rotate_deg) * (2 * float(torch.rand(())) - 1)
        c, s = math.cos(angle), math.sin(angle)
        rot = skeleton.new_tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        rotated = (skeleton - center) @ rot.T + center
        return torch.where(present, rotated, skeleton)
