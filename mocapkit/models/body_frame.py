"""The torch side of :mod:`mocapkit.motion.geometry`: headings, turns about the up axis, and where body 0 is and
how big it is — the body frame the networks normalise their input with, inside the graph (ONNX-exportable).

Same conventions and names as the numpy module, side by side:

* ``AXES``, ``horizontal_axes(up)``: the same objects (imported from there);
* ``hip_line_heading(..., along="+x")`` → :func:`heading_cos_sin`: the heading's ``(cos, sin)``, from the
  line's two horizontal coordinates by normalising the line (no ``atan2`` in the graph);
* ``turn_about_up(positions, angle, up)`` → :func:`turn_about_up` on the three coordinate tensors, from
  ``(cos, sin)``; ``(cos, −sin)`` turns back;
* ``body_origin(..., "first")`` → :func:`body0_first`; ``body_origin(..., "median")`` → :func:`body0_origin`;
  ``body_size(..., "median")`` → :func:`body0_size` (for body 0 of a batch ``[N, M, T, J, 3]``).

Only ``along="+x"`` (the hip line onto the first horizontal axis) occurs in the networks: the refiners'
``PoseNormalizer`` and ``pose_frame``, and the energy image's ``align``.

**Body 0's origin and size.**

:class:`~mocapkit.models.stgcn.STGCN` (``center`` / ``scale``) and
:class:`~mocapkit.models.energy_image.EnergyImage` take raw skeletons ``[N, M, T, J, 3]`` (metres, zeros
where a body is absent) and express them relative to body 0:

* **origin**: the per-coordinate **median** of body 0's reference joint (the root, SpineBase on NTU-25)
  over the frames where body 0 is present;
* **size**: the **median** over the same frames of body 0's pelvis-to-neck distance (metres).

Medians, not the first present frame or a mean: files from the wild leave glitches in the kept bodies (a
one-frame detection before the real track, a frame where the skeleton jumps, frames without any body),
and one such frame used to move the whole sequence (the origin was body 0's root *in its first present
frame*) or shrink it (a mean length). A median ignores up to half of the frames being wrong. For a body
standing in place the median root is where the first frame's root was; for a body that walks it is the
middle of its path.

The energy image is the exception for the origin: its picture of a whole clip keeps where the motion *started*
only if it is centred there, so it takes body 0's root in its first present frame (:func:`body0_first`) by
default, or the median over its first few frames (:func:`body0_start`, robust to a glitch there); both chosen
against the median on validation subjects (docs/decisions.md#energy-image-origin).

The median is computed by sorting (absent frames are sorted last and not counted), which exports to ONNX
(TopK), unlike ``torch.median``; with an even count it is the mean of the two middle values.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from mocapkit.motion.geometry import AXES, horizontal_axes


def heading_cos_sin(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(cos, sin)`` of the heading of the horizontal direction ``(a, b)`` (the first and second horizontal
    coordinates of a hip line, any shape): the turn about the up axis that lays it along the first horizontal axis
    (``hip_line_heading(..., along="+x")`` of :mod:`mocapkit.motion.geometry`); no turn (1, 0) where it vanishes."""
    norm = torch.sqrt(a * a + b * b)
    ok = norm > 1e-6
    return torch.where(ok, a / norm.clamp_min(1e-6), 1.0), torch.where(ok, b / norm.clamp_min(1e-6), 0.0)


def turn_about_up(
    coords: Sequence[torch.Tensor], cos: torch.Tensor, sin: torch.Tensor, up: str = "y"
) -> list[torch.Tensor]:
    """The three coordinate tensors ``coords`` (x, y, z; any broadcastable shapes) turned about the ``up`` axis by
    the heading whose ``cos``, ``sin`` are given: ``h1' = c·h1 + s·h2``, ``h2' = −s·h1 + c·h2``, as
    ``turn_about_up(..., along="+x")`` of :mod:`mocapkit.motion.geometry`; ``(cos, −sin)`` turns back."""
    h1, h2 = horizontal_axes(up)
    vertical = AXES[up]
    a, b = coords[h1], coords[h2]
    turned = {h1: cos * a + sin * b, h2: -sin * a + cos * b, vertical: coords[vertical]}
    return [turned[0], turned[1], turned[2]]


def masked_median(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Median of ``values`` over dim 1 where ``mask`` is True: ``[N, T, C]``, bool ``[N, T]`` → ``[N, C]``.

    Rows with no True entry give 0. Differentiable (through sort and gather) and ONNX-exportable.
    """
    mask = mask.to(torch.bool)
    channels = values.shape[-1]
    high = torch.full_like(values, torch.finfo(values.dtype).max)
    ordered, _ = torch.sort(torch.where(mask.unsqueeze(-1), values, high), dim=1)  # absent frames last
    count = mask.sum(dim=1, keepdim=True)  # [N, 1]
    lower = ((count - 1).clamp(min=0) // 2).unsqueeze(-1).expand(-1, 1, channels)
    upper = (count // 2).unsqueeze(-1).expand(-1, 1, channels)  # = lower for odd counts
    median = 0.5 * (torch.gather(ordered, 1, lower) + torch.gather(ordered, 1, upper))  # [N, 1, C]
    return torch.where(count.unsqueeze(-1) > 0, median, torch.zeros_like(median)).squeeze(1)


def body0_origin(skeletons: torch.Tensor, present: torch.Tensor, joint: int) -> torch.Tensor:
    """Median position of body 0's ``joint`` over its present frames: ``[N, M, T, J, C]``, ``[N, M, T]`` → ``[N, C]``."""
    return masked_median(skeletons[:, 0, :, joint, :], present[:, 0])


def body0_first(skeletons: torch.Tensor, present: torch.Tensor, joint: int) -> torch.Tensor:
    """Position of body 0's ``joint`` in its first present frame (0 where body 0 is never present):
    ``[N, M, T, J, C]``, ``[N, M, T]`` → ``[N, C]``. The origin before the medians; an option of the energy image
    (``origin="first"``), whose picture then shows the motion relative to where it started."""
    body0 = present[:, 0].to(torch.bool)  # [N, T]
    first = torch.argmax(body0.to(torch.int64), dim=1)  # 0 when never present
    index = first.view(-1, 1, 1).expand(-1, 1, skeletons.shape[-1])
    position = torch.gather(skeletons[:, 0, :, joint, :], 1, index).squeeze(1)  # [N, C]
    return torch.where(body0.any(dim=1, keepdim=True), position, torch.zeros_like(position))


def body0_start(skeletons: torch.Tensor, present: torch.Tensor, joint: int, frames: int = 5) -> torch.Tensor:
    """Median position of body 0's ``joint`` over its first ``frames`` present frames, ``[N, C]``: where the motion
    started, like :func:`body0_first`, but a glitch in fewer than half of those frames does not move it (the
    energy image's ``origin="start"``)."""
    body0 = present[:, 0].to(torch.bool)  # [N, T]
    early = body0 & (torch.cumsum(body0.to(torch.int64), dim=1) <= int(frames))
    return masked_median(skeletons[:, 0, :, joint, :], early)


def body0_size(
    skeletons: torch.Tensor, present: torch.Tensor, lower: int, upper: int, floor: float = 1e-3
) -> torch.Tensor:
    """Median distance between body 0's ``lower`` and ``upper`` joints over its present frames, ``[N]``.

    At least ``floor`` (metres), so a sample without body 0 divides by ``floor`` instead of 0.
    """
    length = (skeletons[:, 0, :, upper, :] - skeletons[:, 0, :, lower, :]).norm(dim=-1, keepdim=True)  # [N, T, 1]
    return masked_median(length, present[:, 0]).squeeze(-1).clamp(min=floor)
