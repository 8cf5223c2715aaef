"""Losses shared by the Lightning modules of more than one task.

:func:`contrastive_loss` trains the retrieval embeddings (:mod:`mocapkit.retrieval.module`: SupCon and
SimCLR) and the gait network's metric term (:mod:`mocapkit.gait.module`, ``metric_weight``).
"""

from __future__ import annotations

import torch


def contrastive_loss(embeddings: torch.Tensor, labels: torch.Tensor, temperature: float = 0.1) -> torch.Tensor:
    """Supervised contrastive loss (Khosla et al. 2020, ``L_out``) of unit-norm ``embeddings`` ``[N, D]``.

    For each anchor ``i`` with positives ``P(i)`` (the other rows of its label):
    ``-1/|P(i)| Σ_{p ∈ P(i)} log(exp(z_i·z_p/τ) / Σ_{a ≠ i} exp(z_i·z_a/τ))``, averaged over the anchors that have
    a positive. With ``labels`` = the clip index of each view this is SimCLR's NT-Xent.
    """
    n = embeddings.shape[0]
    logits = embeddings @ embeddings.T / temperature
    self_mask = torch.eye(n, dtype=torch.bool, device=embeddings.device)
    logits = logits.masked_fill(self_mask, float("-inf"))
    log_prob = logits - torch.logsumexp(logits, dim=1, keepdim=True)
    positives = (labels[:, None] == labels[None, :]) & ~self_mask
    count = positives.sum(1)
    has = count > 0
    if not has.any():
        return embeddings.sum() * 0.0
    mean_log_prob = log_prob.masked_fill(~positives, 0.0).sum(1)[has] / count[has]
    return -mean_log_prob.mean()
