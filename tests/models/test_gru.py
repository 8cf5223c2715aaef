"""mocapkit.models.gru: training a bidirectional nn.GRU through the compiled recurrence is training nn.GRU."""

import numpy as np
import pytest
import torch

from mocapkit.models.gru import _exp_in_place, gru_forward


def _gru(inputs=8, hidden=6, layers=2, dropout=0.0):
    torch.manual_seed(0)
    gru = torch.nn.GRU(inputs, hidden, num_layers=layers, batch_first=True, bidirectional=True, dropout=dropout)
    for p in gru.parameters():  # weights away from their small initial values: gates neither saturated nor linear
        p.data.mul_(3.0)
    return gru.train()


@pytest.mark.parametrize("layers", [1, 2])
def test_values_and_gradients_are_nn_grus(layers):
    gru = _gru(layers=layers)
    x = torch.randn(3, 13, 8, requires_grad=True)
    mine, theirs = gru_forward(gru, x), gru(x)[0]
    torch.testing.assert_close(mine, theirs, atol=1e-6, rtol=1e-5)
    weight = torch.randn_like(theirs)
    inputs = [x, *gru.parameters()]
    g_mine = torch.autograd.grad((mine * weight).sum(), inputs)
    g_theirs = torch.autograd.grad((theirs * weight).sum(), inputs)
    for a, b in zip(g_mine, g_theirs, strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-4)


def test_under_bf16_autocast_the_recurrence_stays_float32():
    """The input projection runs in bfloat16 as a Linear does under autocast; the recurrence and its output are
    float32, within bfloat16's rounding of the float32 module."""
    gru = _gru()
    x = torch.randn(2, 9, 8, requires_grad=True)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        mine = gru_forward(gru, x)
    assert mine.dtype == torch.float32
    torch.testing.assert_close(mine, gru(x)[0], atol=0.05, rtol=0.05)
    mine.sum().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in gru.parameters())


def test_outside_cpu_training_the_module_itself_runs():
    gru = _gru().eval()
    x = torch.randn(2, 5, 8)
    torch.testing.assert_close(gru_forward(gru, x), gru(x)[0], atol=0, rtol=0)  # the very same call
    with torch.no_grad():
        gru.train()
        torch.testing.assert_close(gru_forward(gru, x), gru(x)[0], atol=0, rtol=0)


def test_dropout_between_layers_drops_only_in_training():
    gru = _gru(dropout=0.5)
    x = torch.randn(4, 7, 8)
    first, second = gru_forward(gru, x), gru_forward(gru, x)
    assert not torch.allclose(first, second)
    torch.manual_seed(3)
    a = gru_forward(gru, x)
    torch.manual_seed(3)
    torch.testing.assert_close(gru_forward(gru, x), a, atol=0, rtol=0)  # seeded by torch: reproducible


def test_a_nan_input_gives_nan_not_a_silent_number():
    gru = _gru(layers=1)
    x = torch.randn(1, 6, 8)
    x[0, 2, 0] = float("nan")
    out = gru_forward(gru, x.requires_grad_())
    assert torch.isnan(out[0, 2:, :6]).all()  # the forward direction from the bad frame on
    assert torch.isnan(out[0, :3, 6:]).all()  # the reverse direction up to it


def test_the_vectorised_exp_is_exp():
    x = np.concatenate([np.linspace(-690, 690, 20001), [0.0, 1e-12, -1e-12, -0.5, 0.5]])
    values, scratch = x.copy(), np.empty(x.size, dtype=np.int64)
    _exp_in_place(values, scratch)
    np.testing.assert_allclose(values, np.exp(x), rtol=1e-12, atol=0)
    wild = np.array([-5000.0, 5000.0, np.nan])
    _exp_in_place(wild, np.empty(3, dtype=np.int64))
    assert wild[0] < 1e-300 and wild[1] > 1e300 and np.isnan(wild[2])


def test_a_float64_module_trains_in_float64():
    gru = _gru(layers=1).double()
    x = torch.randn(2, 6, 8, dtype=torch.float64, requires_grad=True)
    mine = gru_forward(gru, x)
    assert mine.dtype == torch.float64
    torch.testing.assert_close(mine, gru(x)[0])
    (g_mine,) = torch.autograd.grad(mine.sum(), x)
    (g_theirs,) = torch.autograd.grad(gru(x)[0].sum(), x)
    torch.testing.assert_close(g_mine, g_theirs)
