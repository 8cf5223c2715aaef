"""Training a bidirectional ``nn.GRU`` on CPU: the recurrence compiled, its backward pass written out.

torch's CPU GRU runs every frame as a handful of small operators and leaves the backward pass to autograd: about
twenty autograd nodes per frame and direction, most of the refiners' training step
(bench/RESULTS.md#training-throughput). :func:`gru_forward` trains with the same ``nn.GRU`` module's weights
(checkpoints and ONNX export unchanged), per layer:

* the inputs' part of the gates, ``W_i x + b_i``, for every frame and both directions in one ``Linear`` (in
  bfloat16 under autocast, as any ``Linear``; autograd takes its backward pass);
* the recurrence as one custom autograd function: both directions stepped over the frames in one numba loop
  (a ``[B, H] × [H, 3H]`` product and the gates per step and direction, the gates saved), and its backward pass
  stepped back through the frames with the gates' derivatives written out, the recurrent weights' gradient left
  to one product over all frames at the end. The recurrence runs in float32 whatever the autocast dtype: the
  products of a 16 × 128 state do not gain from bfloat16.

Off CPU, outside training or without gradients it calls the module itself (cuDNN on GPUs). The equations are
``nn.GRU``'s (gates in the order r, z, n)::

    r = σ(W_ir x + b_ir + W_hr h + b_hr)        z = σ(W_iz x + b_iz + W_hz h + b_hz)
    n = tanh(W_in x + b_in + r ⊙ (W_hn h + b_hn))      h' = (1 − z) ⊙ n + z ⊙ h
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit
from torch import nn

from mocapkit.models.ops import dropout


class _BidirectionalRecurrence(torch.autograd.Function):
    """The recurrence of one bidirectional layer from zero states: ``gi [B, T, 2, 3H]`` (``W_i x + b_i`` of every
    frame and direction) → ``[B, T, 2H]`` (forward direction first), with ``w_hh [2, 3H, H]``, ``b_hh [2, 3H]``."""

    @staticmethod
    @torch.amp.custom_fwd(device_type="cpu", cast_inputs=torch.float32)
    def forward(ctx, gi, w_hh, b_hh):
        B, T = gi.shape[:2]
        H = w_hh.shape[2]
        states = gi.new_empty(2, T + 1, B, H)  # [:, t]: the state before step t, each direction in its own order
        rz, n, hn = gi.new_empty(2, T, B, 2 * H), gi.new_empty(2, T, B, H), gi.new_empty(2, T, B, H)
        out = gi.new_empty(B, T, 2 * H)
        w_hh_t = w_hh.transpose(1, 2).contiguous()  # [2, H, 3H]
        arrays = (gi.contiguous(), w_hh_t, b_hh.contiguous(), states, rz, n, hn, out)
        _forward_frames(*(a.numpy() for a in arrays))
        ctx.save_for_backward(w_hh, states, rz, n, hn)
        return out

    @staticmethod
    @torch.amp.custom_bwd(device_type="cpu")
    def backward(ctx, grad_out):
        w_hh, states, rz, n, hn = ctx.saved_tensors
        B, T = grad_out.shape[:2]
        H = w_hh.shape[2]
        grad_gi = states.new_empty(B, T, 2, 3 * H)
        grad_gh = states.new_empty(2, T, B, 3 * H)  # d loss / d (W_h h + b_h), per step
        grad_b_hh = torch.zeros(2, 3 * H, dtype=torch.float64)  # summed in float64
        arrays = (grad_out.contiguous().to(states.dtype), w_hh.contiguous(), states, rz, n, hn, grad_gi, grad_gh)
        _backward_frames(*(a.numpy() for a in arrays), grad_b_hh.numpy())
        # the recurrent weights' gradient: one product over all steps and the batch
        grad_w_hh = torch.bmm(grad_gh.view(2, T * B, 3 * H).transpose(1, 2), states[:, :T].reshape(2, T * B, H))
        return grad_gi, grad_w_hh, grad_b_hh.to(states.dtype)


# e^x = 2^k · 2^f with k = round(x log2 e), |f| ≤ 1/2, 2^f = e^(f ln 2) by its Taylor series to degree 10
# (relative error 3e-13): a loop the compiler vectorises, where libm's scalar exp is not (5× slower here)
_LOG2E = 1.4426950408889634
_EXP2_TAYLOR = tuple(math.log(2.0) ** k / math.factorial(k) for k in range(11))


@njit(cache=True)
def _exp_in_place(values, scratch):  # pragma: no cover - compiled by numba
    """``values[:] = exp(values)`` for float64 ``values`` (NaN stays NaN; beyond ±693 the result saturates at
    2^±1000, which the gates' 1 / (1 + e) turn into 0 or 1 as exp would); ``scratch``: int64, as long."""
    c = _EXP2_TAYLOR
    for i in range(values.size):
        y = values[i] * _LOG2E
        clamped = min(max(y, -1000.0), 1000.0)
        k = math.floor(clamped + 0.5)
        f = clamped - k
        p = c[10]
        p = p * f + c[9]
        p = p * f + c[8]
        p = p * f + c[7]
        p = p * f + c[6]
        p = p * f + c[5]
        p = p * f + c[4]
        p = p * f + c[3]
        p = p * f + c[2]
        p = p * f + c[1]
        p = p * f + c[0]
        scratch[i] = (np.int64(k) + 1023) << 52  # the bits of the float64 2^k
        values[i] = p if y == y else y
    powers = scratch.view(np.float64)
    for i in range(values.size):
        values[i] *= powers[i]


@njit(cache=True)
def _forward_frames(gi, w_hh_t, b_hh, states, rz, n, hn, out):  # pragma: no cover - compiled by numba
    """The recurrence of both directions over the frames (float32 arrays, layouts of
    :meth:`_BidirectionalRecurrence.forward`); the reverse direction's step t reads frame ``T − 1 − t``."""
    B, T = gi.shape[0], gi.shape[1]
    H = w_hh_t.shape[1]
    gates = np.empty(B * 2 * H)  # float64: −(pre-activations of r and z), then their exponentials
    candidate = np.empty(B * H)  # −2 × the pre-activation of n, then its exponential
    scratch = np.empty(B * 2 * H, dtype=np.int64)
    states[:, 0] = 0.0
    for t in range(T):
        for d in range(2):
            frame = t if d == 0 else T - 1 - t
            gh = np.dot(states[d, t], w_hh_t[d])  # [B, 3H]: W_h h without its bias
            for b in range(B):
                for j in range(2 * H):
                    gates[b * 2 * H + j] = -(gi[b, frame, d, j] + gh[b, j] + b_hh[d, j])
            _exp_in_place(gates, scratch)
            for b in range(B):
                for j in range(H):
                    r = 1.0 / (1.0 + gates[b * 2 * H + j])
                    h_n = gh[b, 2 * H + j] + b_hh[d, 2 * H + j]
                    rz[d, t, b, j], rz[d, t, b, H + j] = r, 1.0 / (1.0 + gates[b * 2 * H + H + j])
                    hn[d, t, b, j] = h_n
                    candidate[b * H + j] = -2.0 * (gi[b, frame, d, 2 * H + j] + r * h_n)
            _exp_in_place(candidate, scratch)
            for b in range(B):
                for j in range(H):
                    new = 2.0 / (1.0 + candidate[b * H + j]) - 1.0  # tanh(x) = 2σ(2x) − 1
                    state = new + rz[d, t, b, H + j] * (states[d, t, b, j] - new)
                    n[d, t, b, j] = new
                    states[d, t + 1, b, j] = state
                    out[b, frame, d * H + j] = state


@njit(cache=True)
def _backward_frames(grad_out, w_hh, states, rz, n, hn, grad_gi, grad_gh, grad_b_hh):  # pragma: no cover - numba
    """Back through the frames, from ``d loss / d out``: the gradients of ``W_i x + b_i`` per frame (``grad_gi``,
    laid out as the forward's ``gi``), of ``W_h h + b_h`` per step (``grad_gh``) and of ``b_h`` (float64 sums)."""
    B, T = grad_out.shape[0], grad_out.shape[1]
    H = w_hh.shape[2]
    dh = np.zeros((2, B, H), dtype=grad_out.dtype)  # d loss / d state after the step being undone
    for t in range(T - 1, -1, -1):
        for d in range(2):
            frame = t if d == 0 else T - 1 - t
            for b in range(B):
                for j in range(H):
                    g = dh[d, b, j] + grad_out[b, frame, d * H + j]
                    r, z, new = rz[d, t, b, j], rz[d, t, b, H + j], n[d, t, b, j]
                    d_n = g * (1.0 - z) * (1.0 - new * new)  # through h' = (1 − z) n + z h and n = tanh(·)
                    d_z = g * (states[d, t, b, j] - new) * z * (1.0 - z)
                    d_r = d_n * hn[d, t, b, j] * r * (1.0 - r)
                    grad_gi[b, frame, d, j], grad_gi[b, frame, d, H + j], grad_gi[b, frame, d, 2 * H + j] = (
                        d_r,
                        d_z,
                        d_n,
                    )
                    grad_gh[d, t, b, j], grad_gh[d, t, b, H + j], grad_gh[d, t, b, 2 * H + j] = d_r, d_z, d_n * r
                    grad_b_hh[d, j] += d_r
                    grad_b_hh[d, H + j] += d_z
                    grad_b_hh[d, 2 * H + j] += d_n * r
                    dh[d, b, j] = g * z
            dh[d] += np.dot(grad_gh[d, t], w_hh[d])  # through W_h h: [B, 3H] × [3H, H]


def _written_out(gru: nn.GRU, x: torch.Tensor) -> bool:
    """Whether :func:`gru_forward` trains ``gru`` with the hand-written backward pass."""
    return (
        gru.training
        and torch.is_grad_enabled()
        and x.device.type == "cpu"
        and not torch.onnx.is_in_onnx_export()
        and gru.bidirectional
        and gru.batch_first
        and gru.bias
        and x.dim() == 3
    )


def gru_forward(gru: nn.GRU, x: torch.Tensor) -> torch.Tensor:
    """``gru(x)[0]`` from zero states for a batch-first ``x [B, T, I]`` → ``[B, T, 2H]``.

    A bidirectional ``gru`` training on CPU runs the hand-written layers above (dropout between layers as
    ``nn.GRU`` applies it, drawn by :func:`mocapkit.models.ops.dropout`); everything else calls ``gru`` itself.
    """
    if not _written_out(gru, x):
        return gru(x)[0]
    h = x
    for layer in range(gru.num_layers):
        if layer > 0:
            h = dropout(h, gru.dropout, training=True)
        w_ih, w_hh, b_ih, b_hh = (
            torch.stack([getattr(gru, f"{name}_l{layer}"), getattr(gru, f"{name}_l{layer}_reverse")])
            for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
        )  # [2, ...]: forward and reverse direction
        # the inputs' part of every frame, both directions, in one product (bfloat16 under autocast, as a Linear)
        gi = nn.functional.linear(h, w_ih.flatten(0, 1), b_ih.flatten()).unflatten(-1, (2, -1))  # [B, T, 2, 3H]
        h = _BidirectionalRecurrence.apply(gi, w_hh, b_hh)
    return h


__all__ = ["gru_forward"]
