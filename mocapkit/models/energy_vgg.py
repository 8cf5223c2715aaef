"""The VGG-style 3D motion CNN of thesis §6.2, and the skeleton classifier built on it.

``EnergyVGG`` is torchvision's VGG trunk with the thesis's changes: the fifth
max-pool is replaced by adaptive max pooling (what RoI pooling over the whole
image amounts to), so any input size works, and a new head
``FC-hidden → ReLU → Dropout → FC-hidden → ReLU → Dropout → FC-classes``.

``EnergyImageClassifier`` chains :class:`~mocapkit.models.energy_image.EnergyImage`
and a CNN, so it maps raw skeletons ``[N, M, T, J, 3]`` to logits: this is the
module that is trained, evaluated and exported to ONNX.

Builders follow torchvision's pattern: ``energy_vgg(arch="vgg16", ...)`` and
``energy_image_vgg(...)`` for the whole classifier.
"""

from __future__ import annotations

import torch
from torch import nn
from torchvision import models as tv_models
from torchvision.models.vgg import cfgs as VGG_CFGS
from torchvision.models.vgg import make_layers

from mocapkit.models.energy_image import EnergyImage
from mocapkit.models.ops import Dropout

#: torchvision layer configurations by architecture name.
VGG_ARCHS = {"vgg11": "A", "vgg13": "B", "vgg16": "D", "vgg19": "E"}

#: ImageNet statistics, used to standardise the [0, 1] energy image.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class EnergyVGG(nn.Module):
    """VGG trunk + adaptive max pooling + a new classifier head. Images ``[N, 3, H, W]`` → logits ``[N, classes]``.

    Args:
        features: a VGG ``features`` stack *without* its final max-pool.
        out_channels: channels of the last convolution.
        num_classes: size of the output layer.
        pool_size: side of the adaptive max pooling (7 = VGG/RoI pooling in the thesis).
        hidden: width of the two hidden FC layers (4096 in the thesis).
        dropout: dropout after each hidden FC layer (0.5 in the thesis).
    """

    def __init__(
        self,
        features: nn.Sequential,
        out_channels: int,
        num_classes: int,
        pool_size: int = 7,
        hidden: int = 4096,
        dropout: float = 0.5,
    ):
        super().__init__()
        self.features = features
        self.pool = nn.AdaptiveMaxPool2d(pool_size)
        self.classifier = nn.Sequential(
            nn.Linear(out_channels * pool_size * pool_size, hidden),
            nn.ReLU(inplace=True),
            Dropout(dropout),
            nn.Linear(hidden, hidden),
            nn.ReLU(inplace=True),
            Dropout(dropout),
            nn.Linear(hidden, num_classes),
        )
        linears = [m for m in self.classifier if isinstance(m, nn.Linear)]
        for layer in linears[:-1]:
            # hidden layers: MatConvNet's "improved Xavier", Gaussian with std sqrt(2 / fan_out) (the thesis trained with MatConvNet)
            nn.init.kaiming_normal_(layer.weight, mode="fan_out", nonlinearity="relu")
            nn.init.zeros_(layer.bias)
        # output layer: N(0, 0.01) as torchvision's VGG; fan-out scaling would give logits of std ~1
        # per hidden unit, i.e. a huge initial loss with few classes
        nn.init.normal_(linears[-1].weight, 0.0, 0.01)
        nn.init.zeros_(linears[-1].bias)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        x = self.pool(self.features(images))
        return self.classifier(torch.flatten(x, 1))


def energy_vgg(
    arch: str = "vgg16",
    num_classes: int = 60,
    batch_norm: bool = False,
    width: float = 1.0,
    pool_size: int = 7,
    hidden: int = 4096,
    dropout: float = 0.5,
    weights: str | None = None,
) -> EnergyVGG:
    """Build an :class:`EnergyVGG` from torchvision's VGG configurations.

    Args:
        arch: ``"vgg11"``, ``"vgg13"``, ``"vgg16"`` (the thesis) or ``"vgg19"``.
        batch_norm: use the ``_bn`` variant.
        width: channel multiplier (1.0 = torchvision's VGG; 0.25 for the CPU-sized default).
        weights: torchvision weights name (e.g. ``"IMAGENET1K_V1"``) to initialise the trunk,
            and the two hidden FC layers when ``pool_size=7`` and ``hidden=4096``. Downloads on
            first use; needs ``width=1``.
    """
    if arch not in VGG_ARCHS:
        raise ValueError(f"unknown VGG architecture {arch!r}; choose from {sorted(VGG_ARCHS)}")
    if width <= 0:
        raise ValueError(f"width must be positive, got {width}")
    cfg = [v if v == "M" else max(8, int(round(v * width))) for v in VGG_CFGS[VGG_ARCHS[arch]]]
    cfg = cfg[:-1]  # the fifth max-pool is replaced by adaptive max pooling
    out_channels = cfg[-1]
    if weights is None:
        features = make_layers(cfg, batch_norm=batch_norm)
        return EnergyVGG(features, out_channels, num_classes, pool_size, hidden, dropout)
    if width != 1.0:
        raise ValueError("pretrained weights need width=1.0")
    name = f"{arch}_bn" if batch_norm else arch
    pretrained = tv_models.get_model(name, weights=weights)
    features = nn.Sequential(*list(pretrained.features.children())[:-1])
    model = EnergyVGG(features, out_channels, num_classes, pool_size, hidden, dropout)
    if pool_size == 7 and hidden == 4096:
        for ours, theirs in ((0, 0), (3, 3)):
            model.classifier[ours].load_state_dict(pretrained.classifier[theirs].state_dict())
    return model


class EnergyImageClassifier(nn.Module):
    """Raw skeletons ``[N, M, T, J, 3]`` (metres; zero = absent) → class logits ``[N, classes]``.

    The energy image is standardised with ImageNet statistics before the CNN,
    so pretrained trunks see the input range they were trained on.
    """

    def __init__(self, energy: EnergyImage, cnn: nn.Module):
        super().__init__()
        self.energy = energy
        # channels-last convolutions (weights and images): 1.4x faster training steps on CPU in float32 and bf16
        # (bench/RESULTS.md, Training throughput); same parameter names, shapes and values
        self.cnn = cnn.to(memory_format=torch.channels_last)
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    @property
    def layout(self):
        """The skeleton layout the model expects (joints and their order)."""
        return self.energy.layout

    def images(self, skeletons: torch.Tensor) -> torch.Tensor:
        """The energy images ``[N, 3, H, W]`` in ``[0, 1]``."""
        return self.energy(skeletons)

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        images = (self.energy(skeletons) - self.mean) / self.std
        return self.cnn(images.contiguous(memory_format=torch.channels_last))


def energy_image_vgg(
    num_classes: int,
    arch: str = "vgg16",
    batch_norm: bool = False,
    width: float = 1.0,
    pool_size: int = 7,
    hidden: int = 4096,
    dropout: float = 0.5,
    weights: str | None = None,
    energy: dict | None = None,
) -> EnergyImageClassifier:
    """Build the whole skeleton classifier: :class:`EnergyImage` (options in ``energy``) + :func:`energy_vgg`."""
    return EnergyImageClassifier(
        EnergyImage(**(energy or {})),
        energy_vgg(arch, num_classes, batch_norm, width, pool_size, hidden, dropout, weights),
    )
