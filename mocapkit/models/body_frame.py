"""Where body 0 is and how big it is: the reference frame both skeleton models normalise their input with.

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
against the median on validation subjects (README, *NTU-style synthetic set*).

The median is computed by sorting (absent frames are sorted last and not counted), which exports to ONNX
(TopK), unlike ``torch.median``; with an even count it is the mean of the two middle values.
"""
from __future__ import annotations

import torch


def masked_median(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Median of ``values`` over dim 1 where ``mask`` is True: ``[N, T, C]``, bool ``[N, T]`` → ``[N, C]``.

    Rows with no True entry give 0. Differentiable (through sort and gather) and ONNX-exportable.
    """
    mask = mask.to(torch.bool)
    channels = values.shape[-1]
    high = torch.full_like(values, torch.finfo(values.dtype).max)
    ordered, _ = torch.sort(torch.where(mask.unsqueeze(-1), values, high), dim=1)   # absent frames last
    count = mask.sum(dim=1, keepdim=True)                                            # [N, 1]
    lower = ((count - 1).clamp(min=0) // 2).unsqueeze(-1).expand(-1, 1, channels)
    upper = (count // 2).unsqueeze(-1).expand(-1, 1, channels)                      # = lower for odd counts
    median = 0.5 * (torch.gather(ordered, 1, lower) + torch.gather(ordered, 1, upper))  # [N, 1, C]
    return torch.where(count.unsqueeze(-1) > 0, median, torch.zeros_like(median)).squeeze(1)


def body0_origin(skeletons: torch.Tensor, present: torch.Tensor, joint: int) -> torch.Tensor:
    """Median position of body 0's ``joint`` over its present frames: ``[N, M, T, J, C]``, ``[N, M, T]`` → ``[N, C]``."""
    return masked_median(skeletons[:, 0, :, joint, :], present[:, 0])


def body0_first(skeletons: torch.Tensor, present: torch.Tensor, joint: int) -> torch.Tensor:
    """Position of body 0's ``joint`` in its first present frame (0 where body 0 is never present):
    ``[N, M, T, J, C]``, ``[N, M, T]`` → ``[N, C]``. The origin before the medians; an option of the energy image
    (``origin="first"``), whose picture then shows the motion relative to where it started."""
    body0 = present[:, 0].to(torch.bool)                                                   # [N, T]
    first = torch.argmax(body0.to(torch.int64), dim=1)                                     # 0 when never present
    index = first.view(-1, 1, 1).expand(-1, 1, skeletons.shape[-1])
    position = torch.gather(skeletons[:, 0, :, joint, :], 1, index).squeeze(1)             # [N, C]
    return torch.where(body0.any(dim=1, keepdim=True), position, torch.zeros_like(position))


def body0_start(skeletons: torch.Tensor, present: torch.Tensor, joint: int, frames: int = 5) -> torch.Tensor:
    """Median position of body 0's ``joint`` over its first ``frames`` present frames, ``[N, C]``: where the motion
    started, like :func:`body0_first`, but a glitch in fewer than half of those frames does not move it (the
    energy image's ``origin="start"``)."""
    body0 = present[:, 0].to(torch.bool)                                                   # [N, T]
    early = body0 & (torch.cumsum(body0.to(torch.int64), dim=1) <= int(frames))
    return masked_median(skeletons[:, 0, :, joint, :], early)


def body0_size(skeletons: torch.Tensor, present: torch.Tensor, lower: int, upper: int,
               floor: float = 1e-3) -> torch.Tensor:
    """Median distance between body 0's ``lower`` and ``upper`` joints over its present frames, ``[N]``.

    At least ``floor`` (metres), so a sample without body 0 divides by ``floor`` instead of 0.
    """
    length = (skeletons[:, 0, :, upper, :] - skeletons[:, 0, :, lower, :]).norm(dim=-1, keepdim=True)  # [N, T, 1]
    return masked_median(length, present[:, 0]).squeeze(-1).clamp(min=floor)
