"""The VGG-style 3D motion CNN: thesis structure, variants, any input size."""

import pytest
import torch
from torch import nn

from mocapkit.models import EnergyImageClassifier, energy_image_vgg, energy_vgg


def count(module: nn.Module, kind: type) -> int:
    return sum(isinstance(m, kind) for m in module.modules())


def test_faithful_vgg16_matches_thesis_table_6_4():
    model = energy_vgg("vgg16", num_classes=60)
    convs = [m for m in model.features if isinstance(m, nn.Conv2d)]
    assert [c.out_channels for c in convs] == [64, 64, 128, 128, 256, 256, 256, 512, 512, 512, 512, 512, 512]
    assert all(c.kernel_size == (3, 3) and c.padding == (1, 1) for c in convs)
    assert count(model.features, nn.MaxPool2d) == 4  # the fifth is replaced by RoI/adaptive pooling
    assert isinstance(model.pool, nn.AdaptiveMaxPool2d) and model.pool.output_size == 7
    linears = [m for m in model.classifier if isinstance(m, nn.Linear)]
    assert [(l.in_features, l.out_features) for l in linears] == [(512 * 49, 4096), (4096, 4096), (4096, 60)]
    assert [m.p for m in model.classifier if isinstance(m, nn.Dropout)] == [0.5, 0.5]


@pytest.mark.parametrize(
    "arch,bn,convs", [("vgg11", False, 8), ("vgg11", True, 8), ("vgg13", True, 10), ("vgg19", False, 16)]
)
def test_variants(arch, bn, convs):
    model = energy_vgg(arch, num_classes=7, batch_norm=bn, width=0.125, pool_size=2, hidden=32)
    assert count(model, nn.Conv2d) == convs
    assert (count(model, nn.BatchNorm2d) > 0) == bn
    assert model(torch.rand(2, 3, 64, 64)).shape == (2, 7)


@pytest.mark.parametrize("size", [32, 64, 97])
def test_any_input_size_works(size):
    model = energy_vgg("vgg11", num_classes=5, batch_norm=True, width=0.125, pool_size=3, hidden=16).eval()
    assert model(torch.rand(1, 3, size, size)).shape == (1, 5)


def test_unknown_arch_and_pretrained_width_are_errors():
    with pytest.raises(ValueError, match="unknown VGG"):
        energy_vgg("vgg12")
    with pytest.raises(ValueError, match="width=1.0"):
        energy_vgg("vgg11", width=0.5, weights="IMAGENET1K_V1")


def test_classifier_takes_raw_skeletons_and_learns():
    torch.manual_seed(0)
    model = energy_image_vgg(
        2,
        arch="vgg11",
        batch_norm=True,
        width=0.125,
        pool_size=2,
        hidden=32,
        dropout=0.0,
        energy={"size": 32, "bone_samples": 1},
    )
    assert isinstance(model, EnergyImageClassifier)
    # two "classes": right arm raised vs left arm raised, on 16 bodies that differ in pose
    base = torch.randn(1, 1, 1, 25, 3) * 0.25 + torch.tensor([0.0, 0.0, 3.0])
    x = base + torch.randn(16, 1, 12, 25, 3) * 0.03
    x = torch.cat([x, torch.zeros_like(x)], dim=1)
    right_arm, left_arm = [9, 10, 11, 23, 24], [5, 6, 7, 21, 22]
    y = torch.tensor([0, 1] * 8)
    for k in range(16):
        x[k, 0, :, right_arm if y[k] == 0 else left_arm, 1] += 0.6
    opt = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.9)
    for _ in range(40):
        loss = nn.functional.cross_entropy(model(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    assert (model(x).argmax(1) == y).float().mean() >= 0.9
