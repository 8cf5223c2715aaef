"""Augmentation of skeleton sequences (torch): random crops and views for training, fixed views for testing.

Training augmentation has two halves: the temporal crop, one sample at a time where samples are read (their
lengths differ), and the change of view, on whole padded batches (one batched product; the skeleton data
modules apply it after the batch reached its device: :meth:`SkeletonAugment.change_view`).

Absent bodies and frames are stored as zeros, so every transform here keeps zeros as zeros. Random numbers come
from torch's global generator: the crops' in the data-loader workers, which Lightning seeds one by one
(``seed_everything(workers=True)``), the views' in the training process, which ``seed_everything`` seeds.
"""

from __future__ import annotations

import math

import torch


def temporal_crop(skeleton: torch.Tensor, keep: int, start: int) -> torch.Tensor:
    """Frames ``start … start + keep - 1`` of ``skeleton`` ``[M, T, J, 3]`` → ``[M, keep, J, 3]``."""
    return skeleton[:, start : start + keep]


def crop_length(frames: int, fraction: float, min_frames: int) -> int:
    """Frames a crop of ``fraction`` of a ``frames``-long clip keeps: never below ``min_frames``, and a clip of at
    most ``min_frames`` frames is kept whole."""
    return frames if frames <= min_frames else max(min_frames, round(fraction * frames))


def transform_about_centroid(skeleton: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """``skeleton`` ``[M, T, J, 3]`` mapped by the 3 × 3 ``matrix`` about the centroid of its present (non-zero)
    joints; absent joints stay zeros."""
    return transform_about_centroids(skeleton[None], matrix.to(skeleton)[None])[0]


def rotation_matrix(axis: int, angle: float) -> torch.Tensor:
    """The 3 × 3 rotation by ``angle`` radians about coordinate axis ``axis`` (0 = x, 1 = y, 2 = z)."""
    return rotation_matrices(axis, torch.tensor([float(angle)], dtype=torch.float64))[0]


def rotation_matrices(axis: int, angles: torch.Tensor) -> torch.Tensor:
    """Rotations by ``angles`` ``[B]`` radians about coordinate axis ``axis``: ``[B, 3, 3]``."""
    c, s = torch.cos(angles), torch.sin(angles)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    rot = torch.eye(3).repeat(len(angles), 1, 1)
    rot[:, i, i], rot[:, i, j], rot[:, j, i], rot[:, j, j] = c, -s, s, c
    return rot


def transform_about_centroids(skeletons: torch.Tensor, matrices: torch.Tensor) -> torch.Tensor:
    """Each sample of ``skeletons`` ``[B, M, T, J, 3]`` mapped by its own ``matrices`` ``[B, 3, 3]`` about the
    centroid of its present (non-zero) joints; absent joints stay zeros."""
    present = skeletons.abs().sum(-1, keepdim=True) > 0  # [B, M, T, J, 1]
    count = present.sum((1, 2, 3)).clamp(min=1)  # [B, 1]
    center = ((skeletons * present).sum((1, 2, 3)) / count).view(-1, 1, 1, 1, 3)
    moved = ((skeletons - center).flatten(1, 3) @ matrices.transpose(1, 2)).view_as(skeletons) + center
    return torch.where(present, moved, skeletons)


def rotate_about_vertical(skeleton: torch.Tensor, angle: float) -> torch.Tensor:
    """``skeleton`` ``[M, T, J, 3]`` (y up) rotated by ``angle`` radians about the vertical axis through the
    centroid of its present (non-zero) joints; absent joints stay zeros."""
    if angle == 0:
        return skeleton
    return transform_about_centroid(skeleton, rotation_matrix(1, angle))


def _check_fraction(name: str, values) -> tuple[float, ...]:
    values = tuple(float(v) for v in values)
    if not values or not all(0 < v <= 1 for v in values):
        raise ValueError(f"{name} must be fractions in (0, 1], got {list(values)}")
    return values


class SkeletonAugment:
    """Random temporal cropping and a random rigid-plus-scale change of view (training).

    The view change is pyskl's ``RandomRot`` / ``RandomScale`` pair, about the centroid of the present joints:
    a rotation about the vertical axis, tilts about the two horizontal axes, and an independent scale per
    axis (which changes body proportions: the networks normalise the overall size away, not the shape).

    Args:
        rotate_deg: maximum absolute rotation about the vertical (y) axis, degrees; 0 disables it.
        crop: ``(min, max)`` fraction of the frames kept by a random temporal crop; ``(1, 1)`` disables it.
        min_frames: never crop below this many frames.
        tilt_deg: maximum absolute rotation about each horizontal axis (x, then z), degrees; 0 disables it.
        scale: maximum relative change of each axis's scale (0.1: factors in [0.9, 1.1]); 0 disables it.
    """

    def __init__(
        self,
        rotate_deg: float = 0.0,
        crop: tuple[float, float] = (1.0, 1.0),
        min_frames: int = 8,
        tilt_deg: float = 0.0,
        scale: float = 0.0,
    ):
        lo, hi = crop
        if not 0 < lo <= hi <= 1:
            raise ValueError(f"augment.crop must satisfy 0 < min <= max <= 1, got {crop}")
        if not 0 <= scale < 1:
            raise ValueError(f"augment.scale must be in [0, 1), got {scale}")
        if rotate_deg < 0 or tilt_deg < 0:
            raise ValueError(f"augment.rotate_deg and augment.tilt_deg must be >= 0, got {rotate_deg}, {tilt_deg}")
        self.rotate_deg = float(rotate_deg)
        self.crop = (float(lo), float(hi))
        self.min_frames = int(min_frames)
        self.tilt_deg = float(tilt_deg)
        self.scale = float(scale)

    def __call__(self, skeleton: torch.Tensor) -> torch.Tensor:
        """One sample, cropped and seen from a random view: ``[M, T, J, 3]`` → ``[M, T', J, 3]``, ``T' <= T``."""
        return self.change_view(self.crop_frames(skeleton)[None])[0]

    @property
    def changes_view(self) -> bool:
        """Whether :meth:`change_view` does anything (a rotation, tilt or scale is configured)."""
        return self.rotate_deg > 0 or self.tilt_deg > 0 or self.scale > 0

    def crop_frames(self, skeleton: torch.Tensor) -> torch.Tensor:
        """The random temporal crop of one sample: ``[M, T, J, 3]`` → ``[M, T', J, 3]``, ``T' <= T``."""
        t = skeleton.shape[1]
        lo, hi = self.crop
        if lo < 1.0 and t > self.min_frames:
            keep = crop_length(t, lo + (hi - lo) * float(torch.rand(())), self.min_frames)
            skeleton = temporal_crop(skeleton, keep, int(torch.randint(0, t - keep + 1, ())))
        return skeleton

    def change_view(self, skeletons: torch.Tensor) -> torch.Tensor:
        """A random view per sample of a padded batch ``[B, M, T, J, 3]`` (same shape), on its device.

        Each sample gets its own matrix: the vertical rotation, then the tilts about x and z, then the scale,
        all about the centroid of the sample's present joints (each keeps that centroid, so one product
        about it is the sequence of them); padding and absent bodies stay zeros.
        """
        if not self.changes_view:
            return skeletons
        b, device = skeletons.shape[0], skeletons.device
        matrix = torch.eye(3).expand(b, 3, 3)
        if self.rotate_deg > 0:
            matrix = rotation_matrices(1, math.radians(self.rotate_deg) * (2 * torch.rand(b) - 1)) @ matrix
        if self.tilt_deg > 0:
            for axis in (0, 2):
                matrix = rotation_matrices(axis, math.radians(self.tilt_deg) * (2 * torch.rand(b) - 1)) @ matrix
        if self.scale > 0:
            matrix = torch.diag_embed(1 + self.scale * (2 * torch.rand(b, 3) - 1)) @ matrix
        return transform_about_centroids(skeletons, matrix.to(device=device, dtype=skeletons.dtype))


class TestTimeViews:
    """Fixed views of one test sample, whose predictions are averaged (test-time augmentation).

    Every crop fraction ``f < 1`` gives three crops of ``round(f * T)`` frames (at the start, the centre and the
    end of the clip), ``f = 1`` the whole clip; each crop is taken at every rotation. The views stay inside the
    training augmentation's range when ``crops`` and ``rotate_deg`` do (``SkeletonAugment``'s ``crop`` and
    ``rotate_deg``).

    Args:
        crops: fractions of the frames kept, each in (0, 1].
        rotate_deg: rotations about the vertical axis, degrees.
        min_frames: never crop below this many frames (a shorter clip is kept whole).
    """

    __test__ = False  # not a pytest class

    def __init__(self, crops=(1.0,), rotate_deg=(0.0,), min_frames: int = 8):
        self.crops = _check_fraction("eval.views.crops", crops)
        self.rotate_deg = tuple(float(a) for a in rotate_deg)
        if not self.rotate_deg:
            raise ValueError("eval.views.rotate_deg: give at least one angle (0 for none)")
        self.min_frames = int(min_frames)

    def __len__(self) -> int:
        return sum(1 if f >= 1 else 3 for f in self.crops) * len(self.rotate_deg)

    def __call__(self, skeleton: torch.Tensor) -> list[torch.Tensor]:
        """``[M, T, J, 3]`` → ``len(self)`` views ``[M, T', J, 3]`` (crops outer, rotations inner)."""
        t = skeleton.shape[1]
        crops = []
        for fraction in self.crops:
            keep = crop_length(t, fraction, self.min_frames)
            starts = [0] if fraction >= 1 else [0, (t - keep) // 2, t - keep]
            crops += [temporal_crop(skeleton, keep, start) for start in starts]
        return [rotate_about_vertical(crop, math.radians(angle)) for crop in crops for angle in self.rotate_deg]
