"""The gait CNN as it ran before its channels-last trunk: contiguous weights and inputs throughout.

The reference of the layout test (tests/models/test_gait_cnn.py) and today's network of bench/bench_training.py.
"""

from __future__ import annotations

import functools

import torch


def contiguous_forward(model, geis: torch.Tensor) -> dict[str, torch.Tensor]:
    """:meth:`MultiTaskGaitCNN.forward` without the conversion to channels-last (the network in eval mode or not)."""
    embedding = torch.relu(model.shared_fc(model.trunk(geis).flatten(1)))
    out = {task: head(model.dropout(embedding)) for task, head in model.heads.items()}
    return {**out, "embedding": embedding}


def make_contiguous(model):
    """``model`` (a :class:`MultiTaskGaitCNN`) with its trunk's weights contiguous and :func:`contiguous_forward`
    as its forward; the same parameters."""
    model.trunk.to(memory_format=torch.contiguous_format)
    model.forward = functools.partial(contiguous_forward, model)
    return model
