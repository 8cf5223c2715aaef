"""The multi-task gait CNN: Table 6.1 layer by layer, other input sizes, single-task mode, outputs."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from mocapkit.models.gait_cnn import ChannelWindowLRN, MultiTaskGaitCNN, multitask_gait_cnn
from tests.models import reference_gait_cnn

#: Thesis Table 6.1 at 124×124: (layer, channels, spatial size).
TABLE_6_1 = [("c1", 24, 114), ("pool1", 24, 57), ("c2", 32, 52), ("pool2", 32, 26), ("c3", 40, 22), ("pool3", 40, 11)]


def _recorded_shapes(model: nn.Module, x: torch.Tensor) -> dict[str, tuple[int, ...]]:
    """Output shapes of the trunk's conv and pool layers and of every Linear, recorded with forward hooks."""
    shapes, hooks = {}, []
    for name, module in model.named_modules():
        if isinstance(module, (nn.Conv2d, nn.MaxPool2d, nn.Linear)):
            hooks.append(
                module.register_forward_hook(
                    lambda mod, inp, out, name=name: shapes.__setitem__(name, tuple(out.shape))
                )
            )
    with torch.no_grad():
        model(x)
    for hook in hooks:
        hook.remove()
    return shapes


def test_trunk_and_heads_match_table_6_1_at_124x124():
    model = MultiTaskGaitCNN(num_subjects=124).eval()
    shapes = _recorded_shapes(model, torch.rand(2, 1, 124, 124))
    for layer, channels, size in TABLE_6_1:
        assert shapes[f"trunk.{layer}"] == (2, channels, size, size), layer
        assert model.feature_map_sizes()[layer] == (channels, size, size)
    kernels = {name: m.kernel_size for name, m in model.trunk.named_children() if isinstance(m, nn.Conv2d)}
    assert kernels == {"c1": (11, 11), "c2": (6, 6), "c3": (5, 5)}
    for name, m in model.trunk.named_children():
        if isinstance(m, nn.Conv2d):
            assert m.stride == (1, 1) and m.padding == (0, 0), name
        if isinstance(m, nn.MaxPool2d):
            assert m.kernel_size == 2 and m.stride == 2, name
    # conv -> ReLU -> LRN -> pool, three times
    kinds = (nn.Conv2d, nn.ReLU, nn.LocalResponseNorm, nn.MaxPool2d) * 3
    assert len(model.trunk) == 12 and all(isinstance(m, kind) for m, kind in zip(model.trunk, kinds))
    assert model.flat_features == 40 * 11 * 11
    assert shapes["shared_fc"] == (2, 512)
    expected_heads = {"subject": 124, "view": 11, "condition": 3}
    for task, classes in expected_heads.items():
        assert shapes[f"heads.{task}.0"] == (2, 128) and shapes[f"heads.{task}.3"] == (2, classes)
    assert list(model.heads) == ["subject", "view", "condition"]


def test_lrn_uses_alexnet_constants():
    lrns = [m for m in MultiTaskGaitCNN(10).modules() if isinstance(m, nn.LocalResponseNorm)]
    assert len(lrns) == 3
    for lrn in lrns:
        assert (lrn.size, lrn.alpha, lrn.beta, lrn.k) == (5, 1e-4, 0.75, 2.0)


@pytest.mark.parametrize("size", [5, 4, 1])
def test_channel_window_lrn_is_torchs_lrn(size):
    """The band-convolution LRN gives torch's values and gradients (float32), and under bf16 autocast torch's
    float32 window sums to bfloat16 rounding."""
    torch.manual_seed(size)
    x = (torch.randn(3, 9, 7, 6) * 3).requires_grad_()
    ours = ChannelWindowLRN(size, alpha=1e-2, beta=0.75, k=2.0)
    torchs = nn.LocalResponseNorm(size, alpha=1e-2, beta=0.75, k=2.0)
    target = torch.randn(3, 9, 7, 6)
    grads = []
    for module in (ours, torchs):
        out = module(x)
        (out * target).sum().backward()
        grads.append((out.detach(), x.grad.clone()))
        x.grad = None
    torch.testing.assert_close(grads[0][0], grads[1][0], rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(grads[0][1], grads[1][1], rtol=1e-5, atol=1e-6)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        a, b = ours(x.to(torch.bfloat16)), torchs(x.to(torch.bfloat16))
    assert a.dtype == b.dtype == torch.float32  # the window sums in float32, as torch's average pool
    torch.testing.assert_close(a, b, rtol=1e-6, atol=1e-6)


def test_the_network_with_torchs_lrn_gives_the_same_outputs():
    """Swapping torch's LRN back in (no parameters: the same state dict) changes nothing but the speed."""
    torch.manual_seed(0)
    model = MultiTaskGaitCNN(num_subjects=7, input_size=(64, 44)).eval()
    plain = MultiTaskGaitCNN(num_subjects=7, input_size=(64, 44)).eval()
    for name, m in plain.trunk.named_children():
        if isinstance(m, ChannelWindowLRN):
            setattr(plain.trunk, name, nn.LocalResponseNorm(m.size, alpha=m.alpha, beta=m.beta, k=m.k))
    plain.load_state_dict(model.state_dict())
    x = torch.rand(4, 1, 64, 44)
    with torch.no_grad():
        for task, out in model(x).items():
            torch.testing.assert_close(out, plain(x)[task], rtol=1e-5, atol=1e-6)


def test_the_channels_last_trunk_matches_and_loads_contiguous_weights():
    """The trunk runs channels-last; a contiguous copy of the same weights (a checkpoint written before) loads into it
    and gives the same outputs and gradients as the network run in the contiguous layout."""
    torch.manual_seed(0)
    model = MultiTaskGaitCNN(num_subjects=7, input_size=(64, 44))
    assert all(
        m.weight.is_contiguous(memory_format=torch.channels_last) and not m.weight.is_contiguous()
        for m in model.trunk
        if isinstance(m, nn.Conv2d) and m.in_channels > 1
    )
    plain_state = {k: v.contiguous() for k, v in model.state_dict().items()}
    contiguous = MultiTaskGaitCNN(num_subjects=7, input_size=(64, 44))
    contiguous.load_state_dict(plain_state)
    contiguous = reference_gait_cnn.make_contiguous(contiguous)  # the layout before
    model.load_state_dict(plain_state)  # a checkpoint of contiguous weights loads
    x, y = torch.rand(4, 1, 64, 44), torch.tensor([0, 3, 6, 1])
    model.eval(), contiguous.eval()  # no dropout: the same function
    out, ref = model(x), contiguous(x)
    assert set(ref) == set(out)
    for task in out:
        torch.testing.assert_close(out[task], ref[task], rtol=1e-4, atol=1e-5)  # other conv kernels: rounding
    torch.nn.functional.cross_entropy(out["subject"], y).backward()
    torch.nn.functional.cross_entropy(ref["subject"], y).backward()
    for (name, p), (_, q) in zip(model.named_parameters(), contiguous.named_parameters()):
        torch.testing.assert_close(p.grad, q.grad, rtol=1e-3, atol=1e-5, msg=lambda m, name=name: f"{name}: {m}")


def test_outputs_and_embedding():
    torch.manual_seed(0)
    model = multitask_gait_cnn(num_subjects=7, input_size=[64, 44], tasks=["subject", "view", "condition"]).eval()
    x = torch.rand(5, 1, 64, 44)
    with torch.no_grad():
        out = model(x)
    assert set(out) == {"subject", "view", "condition", "embedding"}
    assert out["subject"].shape == (5, 7) and out["view"].shape == (5, 11) and out["condition"].shape == (5, 3)
    assert out["embedding"].shape == (5, 512) and (out["embedding"] >= 0).all()  # after the ReLU
    # the embedding is the shared FC's ReLU output (before dropout)
    with torch.no_grad():
        expected = torch.relu(model.shared_fc(model.trunk(x).flatten(1)))
    torch.testing.assert_close(out["embedding"], expected)
    # dropout is active in training mode only: eval is deterministic, train is not
    with torch.no_grad():
        torch.testing.assert_close(model(x)["subject"], out["subject"])
        model.train()
        assert not torch.allclose(model(x)["subject"], out["subject"])
    # each sample is processed independently (batch 1 equals the row of batch 5)
    model.eval()
    with torch.no_grad():
        torch.testing.assert_close(model(x[2:3])["view"], out["view"][2:3], atol=1e-5, rtol=1e-5)


def test_opengait_64x44_input_size():
    model = MultiTaskGaitCNN(num_subjects=74, input_size=(64, 44)).eval()
    assert model.feature_map_sizes() == {
        "c1": (24, 54, 34),
        "pool1": (24, 27, 17),
        "c2": (32, 22, 12),
        "pool2": (32, 11, 6),
        "c3": (40, 7, 2),
        "pool3": (40, 3, 1),
    }
    assert model.flat_features == 120 and model.shared_fc.in_features == 120
    shapes = _recorded_shapes(model, torch.rand(3, 1, 64, 44))
    assert shapes["trunk.pool3"] == (3, 40, 3, 1) and shapes["heads.subject.3"] == (3, 74)


def test_single_task_has_one_head_and_the_same_trunk():
    multi, single = MultiTaskGaitCNN(20), MultiTaskGaitCNN(20, tasks=("subject",))
    assert list(single.heads) == ["subject"] and single.tasks == ("subject",)
    trunk = lambda m: [(n, p.shape) for n, p in m.named_parameters() if not n.startswith("heads.")]
    assert trunk(single) == trunk(multi)
    with torch.no_grad():
        out = single.eval()(torch.rand(2, 1, 124, 124))
    assert set(out) == {"subject", "embedding"}
    head_params = sum(p.numel() for p in multi.heads.parameters()) - sum(p.numel() for p in single.heads.parameters())
    assert head_params == 2 * (512 * 128 + 128) + (128 * 11 + 11) + (128 * 3 + 3)


def test_bad_arguments_and_inputs_are_named():
    with pytest.raises(ValueError, match="tasks"):
        MultiTaskGaitCNN(10, tasks=("subject", "gender"))
    with pytest.raises(ValueError, match="tasks"):
        MultiTaskGaitCNN(10, tasks=())
    with pytest.raises(ValueError, match="input_size=\\[32, 32\\] is too small"):
        MultiTaskGaitCNN(10, input_size=(32, 32))
    with pytest.raises(ValueError, match="expected GEIs \\[batch, 1, 124, 124\\], got \\[2, 1, 64, 44\\]"):
        MultiTaskGaitCNN(10)(torch.rand(2, 1, 64, 44))
