"""The "3D energy image": skeleton sequences → time-averaged occupancy maps on three planes.

Thesis §6.2 names a "motion histogram map / 3D energy image" but gives no
recipe. This module implements **our reconstruction**:

1. Normalise: centre every body on body 0's spine base where the motion starts
   (``origin``: in its first present frame by default, or the median over its
   first 5 or all of its present frames), divide by body size (the median spine
   length of body 0, so glitch frames do not shrink the image), and optionally
   turn the scene so body 0's hips face the camera (``align``)
   (:mod:`mocapkit.models.body_frame`, shared with the graph network).
2. Take every joint of every present frame of every body, plus optional
   points sampled along the bones (``bone_samples``), and project them onto the
   xy (front), zy (side) and xz (top) planes.
3. Accumulate occupancy histograms on an ``size × size`` grid covering
   ``[-extent, extent]`` body-size units, each point weighted by
   ``1 / (number of present frames)`` (the time average, as in a Gait Energy
   Image) and optionally by ``t / T`` (``temporal_weighting="linear"``).
4. Stack the three planes as channels and scale each channel to ``[0, 1]``.

The histogram is a scatter-add of every point's weight into its nearest pixel
or, bilinearly, into its four neighbours (``splat``), optionally followed by a
separable Gaussian blur (``smoothing``). It costs O(points), is vectorised
over the batch, differentiable with bilinear splatting, and exports to ONNX
(ScatterElements with add), so a deployed model takes raw skeletons.

Skeletons on the CPU that need no gradient (training and evaluation data) take a compiled path instead: one
numba loop over the points (:func:`_splat_rows`) adds the same shares to the same pixels, 2.4–3× faster than the
~20 tensor operations of the vectorised form (whole image, demo batches of 32 and 64). Both paths give the same image to float rounding
(``tests/models/test_fast_equivalence.py``).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from numba import njit
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
#: The planes' horizontal and vertical axes as index lists (:meth:`EnergyImage.splat`).
PLANE_COLUMNS, PLANE_ROWS = [h for h, _ in PLANES.values()], [v for _, v in PLANES.values()]
_COLUMN_AXES, _ROW_AXES = np.array(PLANE_COLUMNS, dtype=np.int64), np.array(PLANE_ROWS, dtype=np.int64)
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

    #: Body-frames splatted per :meth:`splat` call (512 was the fastest of 128-2048 and all at once, on the demo's
    #: training and validation batches).
    ROWS_PER_BLOCK = 512

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
        self.layout = layout = get_layout(layout)  # a name ("msr20" from data.layout) or a layout
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

    def points(self, axes: torch.Tensor) -> torch.Tensor:
        """Joints plus points sampled along the bones, axis-major: ``[..., 3, J]`` → ``[..., 3, P]``
        (``P = J + bones × bone_samples``; the bone points ordered bone by bone)."""
        if self.bone_samples == 0:
            return axes
        child = axes[..., self.bone_child]  # [..., 3, nb]
        parent = axes[..., self.bone_parent]
        along = parent.unsqueeze(-1) + (child - parent).unsqueeze(-1) * self.bone_fractions  # [..., 3, nb, K]
        return torch.cat((axes, along.flatten(-2)), dim=-1)

    def splat(self, bordered: torch.Tensor, axes: torch.Tensor, weight: torch.Tensor, sample: torch.Tensor) -> None:
        """Add points to the three planes' weighted 2-D histograms, in one scatter.

        ``bordered`` ``[N * 3 * W * W]``: the histograms with a 2-pixel border (``W = size + 4``), flat, added to in
        place; ``axes`` ``[R, 3, P]``: the x, y, z of the ``P`` points of ``R`` body-frames; ``weight`` ``[R]``: each
        body-frame's weight; ``sample`` ``[R]``: the batch sample it belongs to.

        Each point adds its weight to the nearest pixel (``splat="nearest"``) or to its four neighbours with
        bilinear shares (``splat="bilinear"``); points outside the grid are dropped. A point's corner column
        clamped to ``[-2, size]`` puts every share that falls outside the grid into the border (cut off by the
        caller), so no corner needs its own bounds test or clamp: the four corners are the offsets 0, 1, W and
        W+1 of one index.
        """
        size, extent = self.size, self.extent
        wide = size + 4  # the bordered grid's side
        to_pixels = size / (2 * extent)
        # each plane's column and row coordinate of every point, pixel centres at integers, row 0 at the top
        u = (axes[:, PLANE_COLUMNS] + extent) * to_pixels - 0.5  # [R, 3, P]
        v = (extent - axes[:, PLANE_ROWS]) * to_pixels - 0.5
        shift = 0.5 if self.splat_mode == "nearest" else 0.0
        u0, v0 = torch.floor(u + shift), torch.floor(v + shift)
        plane_start = torch.arange(3, device=axes.device).view(1, 3, 1) * (wide * wide)
        sample_start = (sample * (3 * wide * wide)).view(-1, 1, 1)
        cell = ((v0.clamp(-2, size) + 2) * wide + (u0.clamp(-2, size) + 2)).long() + (sample_start + plane_start)
        w = weight.view(-1, 1, 1)
        if self.splat_mode == "nearest":
            index, share = cell, w.expand_as(u)
        else:  # the four corners as leading axes (top/bottom, left/right): broadcast, no gathering copies
            fu, fv = u - u0, v - v0
            across = torch.stack((w * (1 - fu), w * fu))  # [2, R, 3, P]
            down = torch.stack((1 - fv, fv))
            share = across * down.unsqueeze(1)  # [2, 2, R, 3, P]
            corner = torch.tensor([[0, 1], [wide, wide + 1]], device=axes.device).view(2, 2, 1, 1, 1)
            index = cell + corner
        bordered.scatter_add_(0, index.flatten(), share.flatten())

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
        coords = self.normalize(skeletons, present)  # [N, M, T, J, 3]
        n, m, t = present.shape
        frame_present = present.any(dim=1).to(coords.dtype)  # [N, T]
        weight = present.to(coords.dtype) / frame_present.sum(1).clamp(min=1.0).view(-1, 1, 1)  # [N, M, T]
        if self.temporal_weighting == "linear":
            weight = weight * (torch.arange(1, t + 1, device=coords.device, dtype=coords.dtype) / t)
        sample = torch.arange(n, device=coords.device).view(-1, 1, 1).expand(n, m, t)
        rows, weight, sample = coords.flatten(0, 2), weight.flatten(), sample.flatten()  # one row per body-frame
        wide = self.size + 4
        if torch.onnx.is_in_onnx_export():  # every row at once: the graph's shapes must not depend on the data
            blocks = [slice(None)]
        else:
            # absent bodies and padding frames weigh 0: leave them out (most of an NTU batch)
            kept = present.flatten().nonzero().squeeze(1)
            rows, weight, sample = rows.index_select(0, kept), weight[kept], sample[kept]
            if rows.device.type == "cpu" and not rows.requires_grad:  # data: the compiled loop
                return self._finish(self._splat_compiled(rows, weight, sample, n))
            # splat the rest in blocks, so that the corners' indices and shares stay small (cache-sized, and below
            # the size that glibc maps and unmaps afresh for every call)
            blocks = [slice(start, start + self.ROWS_PER_BLOCK) for start in range(0, len(kept), self.ROWS_PER_BLOCK)]
        bordered = torch.zeros(n * 3 * wide * wide, dtype=rows.dtype, device=rows.device)
        for block in blocks:
            self.splat(bordered, self.points(rows[block].transpose(1, 2)), weight[block], sample[block])
        return self._finish(bordered.view(n, 3, wide, wide)[:, :, 2:-2, 2:-2])

    def _finish(self, hist: torch.Tensor) -> torch.Tensor:
        """Histograms ``[N, 3, size, size]`` → blurred images, each plane scaled to a peak of 1."""
        image = self.smooth(hist)
        peak = image.amax(dim=(2, 3), keepdim=True)
        return image / peak.clamp(min=1e-8)

    def _splat_compiled(self, rows: torch.Tensor, weight: torch.Tensor, sample: torch.Tensor, n: int) -> torch.Tensor:
        """:meth:`splat` of every point of ``rows`` ``[R, J, 3]`` (with the bone points) by :func:`_splat_rows`:
        the histograms ``[n, 3, size, size]`` (float32, CPU, no gradient). One thread: split over two, the loop
        ran 1.8x faster on its own but the whole image at most 1.1x (2 cores; torch's threads, just used by the
        steps before it, likely still spin on the other)."""
        wide = self.size + 4
        bordered = np.zeros(n * 3 * wide * wide, dtype=np.float32)
        bad = _splat_rows(
            bordered,
            rows.detach().to(torch.float32).contiguous().numpy(),
            weight.detach().to(torch.float32).contiguous().numpy(),
            sample.contiguous().numpy(),
            self.bone_child.numpy(),
            self.bone_parent.numpy(),
            self.bone_fractions.numpy(),
            _COLUMN_AXES,
            _ROW_AXES,
            self.size,
            self.extent,
            self.splat_mode == "nearest",
        )
        if bad:
            raise ValueError(f"energy image: {bad} skeleton points are not finite (NaN or infinite coordinates)")
        return torch.from_numpy(bordered).view(n, 3, wide, wide)[:, :, 2:-2, 2:-2]


@njit(cache=True)
def _splat_rows(  # pragma: no cover - compiled by numba
    bordered, rows, weight, sample, bone_child, bone_parent, fractions, column_axes, row_axes, size, extent, nearest
):
    """:meth:`EnergyImage.splat` as one loop: adds every joint and bone point of ``rows`` ``[R, J, 3]`` to the
    bordered histograms ``bordered`` (flat float32, ``[N, 3, size + 4, size + 4]``), with the same float32
    arithmetic; the number of points left out because a coordinate is not finite (0 for valid input)."""
    wide = size + 4
    to_pixels = np.float32(size / (2 * extent))  # the scalars as the tensor path's float32 operations see them
    ext, half, one = np.float32(extent), np.float32(0.5), np.float32(1.0)
    low, high = np.float32(-2.0), np.float32(size)
    n_rows, n_joints = rows.shape[0], rows.shape[1]
    n_bones, n_fractions = bone_child.shape[0], fractions.shape[0]
    point = np.empty(3, dtype=np.float32)
    bad = 0
    for r in range(n_rows):
        w = weight[r]
        base = sample[r] * 3 * wide * wide
        for k in range(n_joints + n_bones * n_fractions):
            if k < n_joints:
                for axis in range(3):
                    point[axis] = rows[r, k, axis]
            else:  # a point along a bone: parent + (child - parent) * fraction
                b, f = divmod(k - n_joints, n_fractions)
                for axis in range(3):
                    parent = rows[r, bone_parent[b], axis]
                    point[axis] = parent + (rows[r, bone_child[b], axis] - parent) * fractions[f]
            for plane in range(3):
                u = (point[column_axes[plane]] + ext) * to_pixels - half
                v = (ext - point[row_axes[plane]]) * to_pixels - half
                if not (np.isfinite(u) and np.isfinite(v)):
                    bad += 1
                    continue
                u0 = np.floor(u + half) if nearest else np.floor(u)
                v0 = np.floor(v + half) if nearest else np.floor(v)
                cell = (
                    base
                    + plane * wide * wide
                    + int(min(max(v0, low), high) + 2) * wide
                    + int(min(max(u0, low), high) + 2)
                )
                if nearest:
                    bordered[cell] += w
                else:
                    fu, fv = u - u0, v - v0
                    left, right = w * (one - fu), w * fu
                    bordered[cell] += left * (one - fv)
                    bordered[cell + 1] += right * (one - fv)
                    bordered[cell + wide] += left * fv
                    bordered[cell + wide + 1] += right * fv
    return bad
