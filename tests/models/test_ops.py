"""mocapkit.models.ops: the vector length and dropout written out for speed compute what torch's own compute."""

import pytest
import torch

from mocapkit.models.ops import ELU, dropout, vector_length


@pytest.mark.parametrize("dim", [-1, 1])
def test_vector_length_matches_torch_in_values_and_gradient_zeros_included(dim):
    torch.manual_seed(0)
    base = torch.randn(4, 3, 7, 5)
    base[0, :, 2, 1] = 0.0  # a zero vector along dim 1
    base[1, 1, 3, :] = 0.0  # and along dim -1
    x = base.permute(0, 2, 3, 1) if dim == -1 else base  # strided, as the refiners' losses see it
    x = x.detach().requires_grad_()
    mine, theirs = vector_length(x, dim), torch.linalg.vector_norm(x, dim=dim)
    torch.testing.assert_close(mine, theirs)
    weight = torch.randn_like(theirs)
    g_mine = torch.autograd.grad((mine * weight).sum(), x)[0]
    g_theirs = torch.autograd.grad((theirs * weight).sum(), x)[0]
    assert torch.isfinite(g_mine).all()
    torch.testing.assert_close(g_mine, g_theirs)


def test_dropout_keeps_one_minus_p_scaled_and_is_identity_outside_training():
    torch.manual_seed(0)
    x = torch.ones(200_000)
    out = dropout(x, 0.1)
    kept = out != 0
    assert abs(float(kept.float().mean()) - 0.9) < 0.005  # binomial sd 0.0007
    torch.testing.assert_close(out[kept], torch.full_like(out[kept], 1 / 0.9))
    assert dropout(x, 0.1, training=False) is x and dropout(x, 0.0) is x
    assert float(dropout(x, 1.0).abs().sum()) == 0.0
    half = dropout(x.bfloat16(), 0.5)
    assert half.dtype == torch.bfloat16 and abs(float((half != 0).float().mean()) - 0.5) < 0.01
    y = torch.randn(50, requires_grad=True)
    out = dropout(y, 0.5)
    (grad,) = torch.autograd.grad(out.sum(), y)
    torch.testing.assert_close(grad, (out != 0).float() * 2.0)


def test_elu_matches_torch_in_values_and_gradient_and_exports_as_elu(tmp_path):
    x = torch.cat([torch.linspace(-30, 30, 1001), torch.tensor([0.0, 1e-8, -1e-8, 200.0, -200.0])]).requires_grad_()
    mine, theirs = ELU()(x), torch.nn.functional.elu(x)
    torch.testing.assert_close(mine, theirs, atol=2e-7, rtol=1e-6)
    g_mine, g_theirs = (torch.autograd.grad(y.sum(), x)[0] for y in (mine, theirs))
    assert torch.isfinite(g_mine).all()
    torch.testing.assert_close(g_mine, g_theirs, atol=2e-7, rtol=1e-6)
    onnx = pytest.importorskip("onnx")
    path = tmp_path / "elu.onnx"
    torch.onnx.export(torch.nn.Sequential(torch.nn.Linear(4, 4), ELU()), (torch.randn(2, 4),), str(path), dynamo=False)
    assert "Elu" in [node.op_type for node in onnx.load(str(path)).graph.node]
