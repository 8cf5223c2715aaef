"""An autoregressive conditional VAE over pose features (MVAE-style): the learned generator of the variation
synthesis benchmark (:class:`~mocapkit.synthesis.cvae.CVAESynthesizer`).

Frames are standardised per-frame feature vectors ``x_t`` ``[F]`` (:mod:`mocapkit.synthesis.representation`
features, each dimension z-scored over the training frames). The network has two parts:

- **encoder** ``q(z | x_t, x_{t−1})``: an MLP of ``[x_t, x_{t−1}]`` (``[B, 2F]``) to the mean and log-variance of
  a diagonal Gaussian over ``z`` (``[B, latent]`` each);
- **decoder** ``p(x_t | z, x_{t−1}, x_{t−2})``: an MLP of ``[z, x_{t−1}, x_{t−1} − x_{t−2}]`` (``[B, latent + 2F]``)
  to the change ``x_t − x_{t−1}``; the predicted frame is ``x_{t−1}`` plus that change (a unit-variance Gaussian
  around it in the loss).

Sampling runs the decoder autoregressively with ``z ~ N(0, I)`` at every step
(:meth:`MotionVAE.rollout`).
"""

from __future__ import annotations

import itertools

import torch
from torch import nn

from mocapkit.models.ops import ELU


def _mlp(inputs: int, hidden: int, outputs: int, layers: int) -> nn.Sequential:
    sizes = [inputs] + [hidden] * layers
    blocks: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        blocks += [nn.Linear(a, b), ELU()]  # nn.ELU's maths, 3× faster on CPU
    return nn.Sequential(*blocks, nn.Linear(sizes[-1], outputs))


class MotionVAE(nn.Module):
    """Conditional VAE of the next frame given the two previous ones (module docstring).

    Args:
        features: ``F``, the per-frame feature dimension.
        latent: dimension of ``z``.
        hidden: width of the hidden layers.
        layers: hidden layers of the encoder and of the decoder.
    """

    def __init__(self, features: int, latent: int = 16, hidden: int = 256, layers: int = 2):
        super().__init__()
        self.features = int(features)
        self.latent = int(latent)
        self.encoder = _mlp(2 * self.features, hidden, 2 * self.latent, layers)
        self.decoder = _mlp(self.latent + 2 * self.features, hidden, self.features, layers)

    def encode(self, current: torch.Tensor, previous: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(mean, log_variance)`` ``[B, latent]`` of ``q(z | x_t, x_{t−1})``; ``current`` ``[B, F]`` is ``x_t``,
        ``previous`` ``[B, 2, F]`` is ``(x_{t−1}, x_{t−2})``."""
        stats = self.encoder(torch.cat([current, previous[:, 0]], dim=-1))
        return stats[:, : self.latent], stats[:, self.latent :]

    def decode(self, z: torch.Tensor, previous: torch.Tensor) -> torch.Tensor:
        """The predicted ``x_t`` ``[B, F]`` from ``z`` ``[B, latent]`` and ``previous`` ``[B, 2, F]``."""
        last, before = previous[:, 0], previous[:, 1]
        return last + self.decoder(torch.cat([z, last, last - before], dim=-1))

    def forward(self, current: torch.Tensor, previous: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(reconstruction [B, F], mean [B, latent], log_variance [B, latent])`` with ``z`` drawn by the
        reparameterisation ``mean + exp(log_variance / 2) · ε``."""
        mean, log_variance = self.encode(current, previous)
        z = mean + torch.exp(0.5 * log_variance) * torch.randn_like(mean)
        return self.decode(z, previous), mean, log_variance

    @torch.no_grad()
    def rollout(
        self, start: torch.Tensor, frames: int, generator: torch.Generator | None = None, scale: float = 1.0
    ) -> torch.Tensor:
        """``[B, frames, F]``: ``start`` ``[B, 2, F]`` (``x_0, x_1``) continued autoregressively with
        ``z = scale · ε``, ``ε ~ N(0, I)`` drawn from ``generator`` at every step (``frames ≥ 2``; the first two rows
        are ``start``; ``scale`` 1 is the prior, above 1 samples further from the training frames)."""
        out = [start[:, 0], start[:, 1]]
        for _ in range(2, frames):
            z = scale * torch.randn(start.shape[0], self.latent, generator=generator, dtype=start.dtype)
            out.append(self.decode(z, torch.stack([out[-1], out[-2]], dim=1)))
        return torch.stack(out[:frames], dim=1)


__all__ = ["MotionVAE"]
