"""Today's energy image before the fast splat (2026-12-06), kept verbatim as the reference of
tests/models/test_fast_equivalence.py and of bench/bench_training.py's "today" column."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from mocapkit.models.body_frame import body0_first, body0_origin, body0_size, body0_start, turn_about_up
from mocapkit.motion.layouts import (
    LANDMARKS,
    NTU25,
    SkeletonLayout,
    get_layout,
)

#: Planes as (horizontal axis, vertical axis) over (x, y, z); vertical axes grow upwards.
PLANES = {"xy": (0, 1), "zy": (2, 1), "xz": (0, 2)}
#: Where the image is centred on body 0's reference joint (:class:`EnergyImage` ``origin``): name → locator.
ORIGINS = {"median": body0_origin, "first": body0_first, "start": body0_start}


class EnergyImage(nn.Module):
    """Skeletons ``[N, M, T, J, 3]`` (metres, zeros where a body is absent) → images ``[N, 3, size, size]``.

    Args:
        layout: skeleton topology or its name (``"ntu25"``, ``"msr20"``, ``"cmu31"``); gives the bones
            and, through the shared body landmarks, the default reference joints.
        size: grid resolution in pixels (64 for the CPU default, 224 for the thesis configuration).
        extent: half-width of the grid in body-size units (spine lengths), or in metres when ``scale=False``.
        bone_samples: points sampled along each bone in addition to the joints (0 = joints only).
        splat: ``"nearest"`` (exact hard binning) or ``"bilinear"`` (each point shared by 4 pixels).
        smoothing: standard deviation in pixels of a Gaussian blur of each plane (0 = none).
        temporal_weighting: ``"none"`` or ``"linear"`` (frame ``t`` weighted by ``(t+1)/T``, later = brighter).
        scale: divide by the median spine length of body 0 (``True``) or keep metres (``False``).
        align: rotate about the vertical axis so body 0's mean hip line is parallel to x.
        center_joint: joint of body 0 whose position is the origin (default: the layout root).
        origin: ``"first"`` (its position in body 0's first present frame: the picture shows the motion relative
            to where it started; the default, chosen on validation subjects), ``"start"`` (its median over body 0's
            first 5 present frames: where it started, robust to a glitch frame there; 1.9 points lower on
            validation) or ``"median"`` (its median over all of body 0's present frames, robust to glitch frames
            anywhere, 7.4 points lower: the image loses where the motion began; docs/decisions.md#energy-image-origin).
        spine: ``(lower, upper)`` joints whose distance is the body size (default: pelvis → neck landmarks,
            SpineBase → SpineShoulder on NTU-25).
        hips: ``(left, right)`` joints used by ``align`` (default: the hip landmarks).
    """

    def __init__(
        self,
        layout: SkeletonLayout | str = NTU25,
        size: int = 64,
        extent: float = 3.0,
        bone_samples: int = 0,
        splat: str = "bilinear",
        smoothing: float = 0.0,
        temporal_weighting: str = "none",
        scale: bool = True,
        align: bool = False,
        center_joint: int | None = None,
        spine: tuple[int, int] | None = None,
        hips: tuple[int, int] | None = None,
        origin: str = "first",
    ):
        super().__init__()
        if origin not in ORIGINS:
            raise ValueError(f"energy image origin must be one of {tuple(ORIGINS)}, got {origin!r}")
        if splat not in ("nearest", "bilinear"):
            raise ValueError(f"energy image splat must be 'nearest' or 'bilinear', got {splat!r}")
        if temporal_weighting not in ("none", "linear"):
            raise ValueError(f"temporal_weighting must be 'none' or 'linear', got {temporal_weighting!r}")
        if size < 4 or extent <= 0 or bone_samples < 0 or smoothing < 0:
            raise ValueError(
                f"invalid energy image geometry: size={size}, extent={extent}, "
                f"bone_samples={bone_samples}, smoothing={smoothing}"
            )
        self.layout = get_layout(layout)
        self.size = int(size)
        self.extent = float(extent)
        self.bone_samples = int(bone_samples)
        self.splat_mode = splat
        self.smoothing = float(smoothing)
        self.temporal_weighting = temporal_weighting
        self.scale = bool(scale)
        self.align = bool(align)
        self.origin = origin
        self.center_joint = layout.parents.index(-1) if center_joint is None else int(center_joint)
        landmark = LANDMARKS.get(layout.name, {})
        if (spine is None or hips is None) and not landmark:
            raise ValueError(
                f"layout {layout.name!r} has no landmark table: give spine=(lower, upper) and hips=(left, right)"
            )
        self.spine = (
            tuple(spine) if spine is not None else (layout.index(landmark["pelvis"]), layout.index(landmark["neck"]))
        )
        self.hips = (
            tuple(hips) if hips is not None else (layout.index(landmark["l_hip"]), layout.index(landmark["r_hip"]))
        )
        bones = torch.tensor(layout.bones, dtype=torch.long).reshape(-1, 2)
        self.register_buffer("bone_child", bones[:, 0].clone(), persistent=False)
        self.register_buffer("bone_parent", bones[:, 1].clone(), persistent=False)
        fractions = torch.arange(1, self.bone_samples + 1, dtype=torch.float32) / (self.bone_samples + 1)
        self.register_buffer("bone_fractions", fractions, persistent=False)
        radius = max(1, math.ceil(3 * self.smoothing))
        offsets = torch.arange(-radius, radius + 1, dtype=torch.float32)
        blur = torch.exp(-0.5 * (offsets / max(self.smoothing, 1e-6)) ** 2)
        self.register_buffer("blur_kernel", blur / blur.sum(), persistent=False)

    def extra_repr(self) -> str:
        return (
            f"size={self.size}, extent={self.extent}, bone_samples={self.bone_samples}, splat={self.splat_mode}, smoothing={self.smoothing}, "
            f"temporal_weighting={self.temporal_weighting}, scale={self.scale}, align={self.align}, origin={self.origin}"
        )

    # ------------------------------------------------------------------ steps

    def normalize(self, skeletons: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        """Centre, scale and optionally align. ``[N, M, T, J, 3]`` → same shape, body-size units."""
        body0 = present[:, 0].to(skeletons.dtype)  # [N, T]
        center = ORIGINS[self.origin](skeletons, present, self.center_joint)  # [N, 3]
        out = skeletons - center.view(-1, 1, 1, 1, 3)
        if self.align:
            hip = skeletons[:, 0, :, self.hips[1], :] - skeletons[:, 0, :, self.hips[0], :]  # [N, T, 3]
            hip = (hip * body0.unsqueeze(-1)).sum(1)  # [N, 3]
            # heading of body 0's summed hip line (along="+x"); its (cos, sin) through atan2 with +1e-12, not
            # heading_cos_sin, as the trained models saw it
            angle = torch.atan2(hip[:, 2], hip[:, 0] + 1e-12)
            c, s = torch.cos(angle).view(-1, 1, 1, 1), torch.sin(angle).view(-1, 1, 1, 1)
            out = torch.stack(turn_about_up([out[..., 0], out[..., 1], out[..., 2]], c, s, "y"), dim=-1)
        if self.scale:
            length = body0_size(skeletons, present, *self.spine)  # [N], median
            out = out / length.view(-1, 1, 1, 1, 1)
        return out

    def points(self, coords: torch.Tensor) -> torch.Tensor:
        """Joints plus points sampled along the bones: ``[N, M, T, J, 3]`` → ``[N, M, T, P, 3]``."""
        if self.bone_samples == 0:
            return coords
        child = coords[:, :, :, self.bone_child, :]  # [N, M, T, nb, 3]
        parent = coords[:, :, :, self.bone_parent, :]
        f = self.bone_fractions.view(1, 1, 1, 1, -1, 1)
        along = parent.unsqueeze(4) + (child - parent).unsqueeze(4) * f  # [N, M, T, nb, K, 3]
        along = along.flatten(3, 4)
        return torch.cat((coords, along), dim=3)

    def splat(self, horizontal: torch.Tensor, vertical: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
        """Weighted 2-D histogram. ``horizontal``, ``vertical``, ``weight``: ``[N, P]`` → ``[N, size, size]``.

        Each point adds its weight to the nearest pixel (``splat="nearest"``) or
        to its four neighbours with bilinear shares (``splat="bilinear"``);
        points outside the grid are dropped.
        """
        size = self.size
        to_pixels = size / (2 * self.extent)
        u = (horizontal + self.extent) * to_pixels - 0.5  # column; pixel centres at integers
        v = (self.extent - vertical) * to_pixels - 0.5  # row 0 is the top
        if self.splat_mode == "nearest":
            u0, v0 = torch.floor(u + 0.5), torch.floor(v + 0.5)
            corners = [(u0, v0, weight)]
        else:
            u0, v0 = torch.floor(u), torch.floor(v)
            fu, fv = u - u0, v - v0
            corners = [
                (u0, v0, weight * (1 - fu) * (1 - fv)),
                (u0 + 1, v0, weight * fu * (1 - fv)),
                (u0, v0 + 1, weight * (1 - fu) * fv),
                (u0 + 1, v0 + 1, weight * fu * fv),
            ]
        hist = torch.zeros(u.shape[0], size * size, dtype=u.dtype, device=u.device)
        for cu, cv, cw in corners:
            inside = (cu >= 0) & (cu <= size - 1) & (cv >= 0) & (cv <= size - 1)
            index = (cv.clamp(0, size - 1) * size + cu.clamp(0, size - 1)).long()
            hist = hist.scatter_add(1, index, cw * inside.to(cw.dtype))
        return hist.view(-1, size, size)

    def smooth(self, image: torch.Tensor) -> torch.Tensor:
        """Separable Gaussian blur with ``smoothing`` pixels of standard deviation (identity when 0)."""
        if self.smoothing <= 0:
            return image
        k = self.blur_kernel.to(image.dtype)
        r = k.numel() // 2
        channels = image.shape[1]
        image = F.conv2d(image, k.view(1, 1, 1, -1).expand(channels, 1, 1, -1), padding=(0, r), groups=channels)
        return F.conv2d(image, k.view(1, 1, -1, 1).expand(channels, 1, -1, 1), padding=(r, 0), groups=channels)

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        if skeletons.dim() != 5 or skeletons.shape[-1] != 3 or skeletons.shape[-2] != self.layout.num_joints:
            raise ValueError(f"expected skeletons [N, M, T, {self.layout.num_joints}, 3], got {list(skeletons.shape)}")
        skeletons = skeletons.float()
        present = skeletons.abs().sum(dim=(-1, -2)) > 0  # [N, M, T]
        coords = self.points(self.normalize(skeletons, present))  # [N, M, T, P, 3]
        n, m, t, p, _ = coords.shape
        frame_present = present.any(dim=1).to(coords.dtype)  # [N, T]
        weight = present.to(coords.dtype) / frame_present.sum(1).clamp(min=1.0).view(-1, 1, 1)
        if self.temporal_weighting == "linear":
            ramp = torch.arange(1, t + 1, device=coords.device, dtype=coords.dtype) / t
            weight = weight * ramp
        weight = weight.unsqueeze(-1).expand(n, m, t, p).reshape(n, -1)  # [N, M*T*P]
        flat = coords.reshape(n, -1, 3)
        planes = [self.splat(flat[..., a], flat[..., b], weight) for a, b in PLANES.values()]
        image = self.smooth(torch.stack(planes, dim=1))  # [N, 3, H, W]
        peak = image.amax(dim=(2, 3), keepdim=True)
        return image / peak.clamp(min=1e-8)


def reference_like(energy: nn.Module) -> EnergyImage:
    """Today's :class:`EnergyImage` with the same options as ``energy`` (a :class:`mocapkit.models.energy_image.EnergyImage`)."""
    return EnergyImage(
        energy.layout,
        energy.size,
        energy.extent,
        energy.bone_samples,
        energy.splat_mode,
        energy.smoothing,
        energy.temporal_weighting,
        energy.scale,
        energy.align,
        energy.center_joint,
        energy.spine,
        energy.hips,
        energy.origin,
    )
