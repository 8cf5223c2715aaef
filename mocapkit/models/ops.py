"""Element-wise operations written out because torch's own are slow on CPU for the shapes used here.

- :func:`vector_length`: the Euclidean length along one dimension, the same values and gradient as
  ``torch.linalg.vector_norm(x, dim=dim)``. torch's reduction is 15–20× slower on a strided dimension of size 3
  (the coordinates of ``[B, T, J, 3]`` permuted from the channel-first ``[B, 3, T, J]``: 15 ms against 0.7 ms,
  forward and backward, for a batch of 16 windows of 240 frames × 31 joints on one core).
- :func:`dropout` (and :class:`Dropout`, the module): ``nn.functional.dropout`` in training, its mask on CPU drawn
  as 16-bit integers by NumPy's PCG64 instead of torch's ``bernoulli_`` (a 32-bit Mersenne-Twister draw per
  entry): 10 ms against 25 ms for the 3.7 M attention weights of a batch of 16 windows of 240 frames, 4 heads. The
  same distribution up to ``p`` rounded to 1/65536, not the same random numbers.
- :class:`ELU`: ``nn.ELU()`` (α = 1) through ``exp``, which torch vectorises on CPU, instead of ``expm1``, which it
  does not: 3× faster forward and backward on the CVAE's ``[256, 256]`` activations; the same values to float32
  rounding (``eˣ − 1`` loses a few bits of relative precision near 0, about 1e-7 absolute). ONNX export writes
  ``nn.ELU``'s own operator.

Measured in bench/RESULTS.md#training-throughput.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class _VectorLength(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor, dim: int) -> torch.Tensor:
        length = x.square().sum(dim).sqrt()
        ctx.save_for_backward(x, length)
        ctx.dim = dim
        return length

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        x, length = ctx.saved_tensors
        # torch's rule for the norm's gradient: x / |x|, and 0 (a subgradient) where |x| = 0
        scale = (grad / length).masked_fill_(length == 0, 0.0)
        return x * scale.unsqueeze(ctx.dim), None


def vector_length(x: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """Euclidean length of ``x`` along ``dim`` (that dimension removed); gradient 0 where the length is 0."""
    return _VectorLength.apply(x, dim)


def dropout(x: torch.Tensor, p: float, training: bool = True) -> torch.Tensor:
    """``nn.functional.dropout(x, p, training)``, on CPU with the mask drawn by NumPy (see the module docstring).

    Each entry is kept with probability ``1 - p'`` and scaled by ``1 / (1 - p')``, ``p'`` being ``p`` rounded to
    1/65536 (0.1 → 0.1000061): the mask compares 16-bit uniform integers of NumPy's PCG64 with ``p' · 65536``,
    2.5× faster than torch's ``bernoulli_`` on CPU. The generator is seeded from torch's, so
    ``torch.manual_seed`` (and Lightning's ``seed_everything``) make the draws reproducible. On other devices and
    inside ``torch.compile``: torch's own dropout.
    """
    if not training or p == 0.0:
        return x
    if p >= 1.0:
        return x * 0.0
    if x.device.type != "cpu" or torch.compiler.is_compiling():  # NumPy would break a compiled graph
        return torch.nn.functional.dropout(x, p, training=True)
    threshold = round(p * 65536)
    seed = int(torch.randint(0, 2**62, (1,)))
    bits = np.random.Generator(np.random.PCG64(seed)).integers(0, 65536, x.numel(), dtype=np.uint16)
    # the scale goes into the mask: one product for autograd to save and backpropagate
    scaled_keep = torch.from_numpy(bits >= threshold).view(x.shape).to(x.dtype).mul_(65536 / (65536 - threshold))
    return x * scaled_keep


class Dropout(nn.Dropout):
    """``nn.Dropout`` drawing its mask by :func:`dropout` (the same parameters and state: a drop-in replacement)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return dropout(x, self.p, self.training)


class _ELU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        # max(x, 0) + exp(min(x, 0)) − 1: clamps, not boolean masks (torch's where and masked_fill are slower
        # than exp on CPU)
        out = torch.exp(x.clamp(max=0.0)).add_(x.clamp(min=0.0)).sub_(1.0)
        ctx.save_for_backward(out)
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (out,) = ctx.saved_tensors
        return grad * (out + 1.0).clamp_(max=1.0)  # 1 where x > 0, eˣ = out + 1 elsewhere (as torch's ELU)


class ELU(nn.Module):
    """``nn.ELU()`` (α = 1) through ``exp`` (see the module docstring); in ONNX export ``nn.ELU``'s own operator."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if torch.onnx.is_in_onnx_export() or x.device.type != "cpu":
            return nn.functional.elu(x)
        return _ELU.apply(x)


__all__ = ["ELU", "Dropout", "dropout", "vector_length"]
