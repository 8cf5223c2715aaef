"""The fast graph convolution and energy image compute what the implementations before them computed.

The references are the modules as they were before the rewrite, kept verbatim in ``tests/models/reference_*.py``:
from the same weights the new modules give the same outputs and gradients (to float rounding), and a state_dict of
one loads into the other, so checkpoints keep loading.
"""

from __future__ import annotations

import pytest
import torch

from mocapkit.models import energy_image, stgcn
from mocapkit.recognition.export import example_skeletons
from tests.models import reference_energy_image, reference_stgcn

SMALL = {"channels": (16, 16, 32), "strides": (1, 2, 1), "kernel_size": 5}


def _pair(builder: str, **kwargs):
    """(today's module, the new one) with the same weights, both in training mode."""
    torch.manual_seed(0)
    new = getattr(stgcn, builder)(**kwargs)
    old = getattr(reference_stgcn, builder)(**kwargs)
    old.load_state_dict(new.state_dict())  # strict: same names and shapes
    with torch.no_grad():  # non-zero corrections and BN statistics, so every term of the maths is exercised
        for (name, p), (_, q) in zip(new.named_parameters(), old.named_parameters()):
            if "correction" in name or "alpha" in name:
                p.copy_(torch.randn_like(p) * 0.1)
                q.copy_(p)
    return old, new


def _layout_input(layout: str, batch: int = 3, frames: int = 24):
    joints = {"ntu25": 25, "msr20": 20, "cmu31": 31}[layout]
    return example_skeletons(batch, frames, joints=joints)


@pytest.mark.parametrize(
    "options",
    [
        {"streams": ("joint", "velocity", "bone")},  # 9 → 16: the graph-first path; 16 → 16 and 16 → 32
        {"streams": ("joint",), "adaptive": False},
        {"streams": ("joint", "bone"), "temporal": "multiscale", "channels": (12, 12, 24)},
        {"streams": ("joint",), "topology": "channelwise"},
        {"streams": ("joint",), "channels": (8, 4, 4), "strides": (1, 1, 1)},  # narrowing: the channels-first path
    ],
)
@pytest.mark.parametrize("layout", ["ntu25", "msr20", "cmu31"])
def test_stgcn_outputs_and_gradients_match_todays_module(options, layout):
    kwargs = {**SMALL, **options, "layout": layout, "num_classes": 7, "scale": True}
    old, new = _pair("stgcn", **kwargs)
    x = _layout_input(layout)
    y = torch.tensor([0, 3, 6])
    out_new, out_old = new(x), old(x)  # training mode, dropout 0: batch statistics in BN
    torch.testing.assert_close(out_new, out_old, rtol=1e-5, atol=1e-5)
    torch.nn.functional.cross_entropy(out_new, y).backward()
    torch.nn.functional.cross_entropy(out_old, y).backward()
    for (name, p), (_, q) in zip(new.named_parameters(), old.named_parameters()):
        torch.testing.assert_close(p.grad, q.grad, rtol=1e-4, atol=1e-5, msg=lambda m, name=name: f"{name}: {m}")
    new.eval(), old.eval()
    torch.testing.assert_close(new(x), old(x), rtol=1e-5, atol=1e-5)


def test_under_bf16_autocast_it_is_todays_computation():
    kwargs = {**SMALL, "layout": "ntu25", "num_classes": 7, "streams": ("joint", "velocity", "bone")}
    old, new = _pair("stgcn", **kwargs)
    x = _layout_input("ntu25")
    with torch.autocast("cpu", dtype=torch.bfloat16):
        torch.testing.assert_close(new(x), old(x), rtol=0, atol=0)


def test_the_ensemble_matches_and_old_state_dicts_load():
    kwargs = {**SMALL, "num_classes": 5, "streams": (("joint",), ("bone", "velocity"))}
    old, new = _pair("stgcn_ensemble", **kwargs)
    x = example_skeletons(2, 20)
    torch.testing.assert_close(new(x), old(x), rtol=1e-5, atol=1e-5)
    assert {k: v.shape for k, v in new.state_dict().items()} == {k: v.shape for k, v in old.state_dict().items()}
    new.load_state_dict(old.state_dict())  # a checkpoint of today's module loads, strict


def test_a_graph_convolution_on_its_own_matches_the_einsum_form():
    a = stgcn.spatial_adjacency("ntu25")
    for c_in, c_out in ((3, 24), (24, 24), (24, 8)):
        torch.manual_seed(c_in)
        new = stgcn.GraphConv(c_in, c_out, a)
        old = reference_stgcn.GraphConv(c_in, c_out, a)
        with torch.no_grad():
            new.correction.copy_(torch.randn_like(new.correction) * 0.2)
            new.conv.bias.copy_(torch.randn_like(new.conv.bias))
        old.load_state_dict(new.state_dict())
        x = torch.randn(4, c_in, 11, 25)
        torch.testing.assert_close(new(x), old(x), rtol=1e-5, atol=1e-5)
        # the maths itself, written out: sum_k A_k (W_k x + b_k), gathered over j for each i
        w = new.conv.weight.view(3, c_out, c_in)
        y = torch.einsum("kdc,nctj->nkdtj", w, x) + new.conv.bias.view(3, c_out, 1, 1)
        expected = torch.einsum("nkdtj,kij->ndti", y, new.adjacency + new.correction)
        torch.testing.assert_close(new(x), expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"splat": "nearest"},
        {"bone_samples": 2, "smoothing": 1.0, "temporal_weighting": "linear", "align": True},
        {"size": 24, "extent": 0.8},  # most points fall outside the grid: the border must drop them all
        {"size": 48, "origin": "median", "scale": False, "extent": 1.5},
    ],
)
def test_energy_image_is_todays_image(options):
    x = example_skeletons(8, 40)  # 640 body-frames: more than one block of the new module
    x[2, :, 10:14] = 0.0  # absent frames inside a sequence
    x[3, 0, :, :, 0] += 5.0  # far off to the side
    new = energy_image.EnergyImage(**options)
    old = reference_energy_image.EnergyImage(**options)
    torch.testing.assert_close(new(x), old(x), rtol=1e-6, atol=1e-6)  # images in [0, 1]: the sums' order differs
    torch.testing.assert_close(reference_energy_image.reference_like(new)(x), old(x), rtol=0, atol=0)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"splat": "nearest", "bone_samples": 3},
        {"size": 24, "extent": 0.8, "temporal_weighting": "linear"},  # most points fall off the grid
        {"layout": "msr20", "bone_samples": 2, "align": True},
    ],
)
def test_the_compiled_splat_is_the_tensor_splat(options):
    """Data needing no gradient takes the compiled loop; skeletons that need one take the tensor operations (also
    what ONNX exports): the same image either way."""
    joints = 20 if options.get("layout") == "msr20" else 25
    x = example_skeletons(8, 40, joints=joints)
    x[2, :, 10:14] = 0.0  # absent frames inside a sequence
    x[5, 1] = 0.0  # an absent second body
    energy = energy_image.EnergyImage(**options)
    compiled = energy(x)
    tensor = energy(x.clone().requires_grad_()).detach()
    assert compiled.amax() > 0
    torch.testing.assert_close(compiled, tensor, rtol=1e-6, atol=1e-6)


def test_the_compiled_splat_refuses_points_that_are_not_finite():
    """(A NaN makes its body-frame absent, as in the tensor path; an infinite coordinate reaches the splat.)"""
    x = example_skeletons(2, 10)
    x[1, 0, 3, 7, 2] = float("inf")
    with pytest.raises(ValueError, match="not finite"):
        energy_image.EnergyImage(bone_samples=1, align=False, scale=False)(x)


def test_energy_image_takes_a_layout_name():
    """``model.energy.layout`` is ``${data.layout}``, a name (experiment=msr3d_energy_vgg)."""
    from mocapkit.motion.layouts import get_layout

    named = energy_image.EnergyImage(layout="msr20")
    x = example_skeletons(2, 30, joints=20)
    torch.testing.assert_close(named(x), reference_energy_image.EnergyImage(layout=get_layout("msr20"))(x))


def test_energy_image_gradient_matches():
    """Bilinear splatting is differentiable in the coordinates; the gradient with respect to the skeletons is
    today's, absent bodies and padding frames (left out of the new histogram) included."""
    x = example_skeletons(3, 20)
    x[1, :, 15:] = 0.0  # padding frames
    x[2, 1] = 0.0  # an absent second body
    target = torch.rand(3, 3, 16, 16)
    options = {"size": 16, "extent": 1.5, "bone_samples": 1, "temporal_weighting": "linear", "align": True}
    grads = []
    for module in (energy_image.EnergyImage(**options), reference_energy_image.EnergyImage(**options)):
        skeletons = x.clone().requires_grad_()
        (module(skeletons) * target).sum().backward()
        grads.append(skeletons.grad)
    assert grads[0].abs().sum() > 0
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-5, atol=1e-6)


def test_the_channels_last_classifier_matches_and_loads_contiguous_weights():
    """The energy-image classifier runs its CNN channels-last; a contiguous copy of the same weights (a checkpoint
    written before) loads into it and gives the same logits and gradients."""
    from mocapkit.models.energy_vgg import energy_image_vgg

    torch.manual_seed(0)
    new = energy_image_vgg(6, arch="vgg11", batch_norm=True, width=0.125, hidden=32, energy={"size": 32})
    plain = {k: v.contiguous() for k, v in new.state_dict().items()}
    assert any(v.dim() == 4 and not v.is_contiguous() for v in new.state_dict().values())  # really channels-last
    new.load_state_dict(plain)
    x, y = example_skeletons(4, 30), torch.tensor([0, 1, 2, 5])
    new.eval()
    images = (reference_energy_image.reference_like(new.energy)(x) - new.mean) / new.std  # today's images
    torch.manual_seed(1)  # other initial weights, replaced by the same ones below
    contiguous = energy_image_vgg(6, arch="vgg11", batch_norm=True, width=0.125, hidden=32, energy={"size": 32}).eval()
    contiguous.cnn.to(memory_format=torch.contiguous_format)  # today's layout
    contiguous.load_state_dict(plain)
    torch.testing.assert_close(new(x), contiguous.cnn(images), rtol=1e-4, atol=1e-5)
    torch.nn.functional.cross_entropy(new(x), y).backward()
    torch.nn.functional.cross_entropy(contiguous.cnn(images), y).backward()
    for (name, p), (_, q) in zip(new.named_parameters(), contiguous.named_parameters()):
        torch.testing.assert_close(p.grad, q.grad, rtol=1e-3, atol=1e-5, msg=lambda m, name=name: f"{name}: {m}")
