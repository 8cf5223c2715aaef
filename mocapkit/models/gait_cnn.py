"""The multi-task gait CNN on Gait Energy Images (thesis §6.1, Table 6.1).

One shared trunk of three stages, each a valid convolution (stride 1, no padding)
→ ReLU → local response normalisation → 2×2 max-pool, then a shared fully
connected layer and one small head per task::

    GEI [B, 1, 124, 124]
    C1  11×11×24 → [B, 24, 114, 114] → pool → [B, 24, 57, 57]
    C2   6×6×32  → [B, 32,  52,  52] → pool → [B, 32, 26, 26]
    C3   5×5×40  → [B, 40,  22,  22] → pool → [B, 40, 11, 11]
    flatten → FC-512 (shared, "embedding") → per task: FC-128 → logits
              subject [B, num_subjects], view [B, 11], condition [B, 3]

The thesis leaves the nonlinearity and the LRN constants open (Wang 2017 thesis §6.1);
we use ReLU and AlexNet's LRN (size 5, α = 1e-4, β = 0.75, k = 2), and dropout 0.5 after
every fully connected layer but the logits. The softmax lives in the loss. Any input size
whose feature maps stay non-empty works, e.g. OpenGait's 64×44 (flatten size 40·3·1 = 120).
The single-task network (``tasks=("subject",)``) has the same trunk and one head.
"""

from __future__ import annotations

import contextlib
from collections import OrderedDict

import torch
import torch.nn.functional as F
from torch import nn

from mocapkit.models.ops import Dropout

#: The tasks a head can be built for, in output order.
TASKS: tuple[str, ...] = ("subject", "view", "condition")
#: Table 6.1's trunk: (name, output channels, kernel size) of each convolution.
CONV_STAGES: tuple[tuple[str, int, int], ...] = (("c1", 24, 11), ("c2", 32, 6), ("c3", 40, 5))
#: AlexNet's local response normalisation constants (Krizhevsky et al. 2012), our choice.
LRN_SIZE, LRN_ALPHA, LRN_BETA, LRN_K = 5, 1e-4, 0.75, 2.0


class ChannelWindowLRN(nn.LocalResponseNorm):
    """:class:`torch.nn.LocalResponseNorm` on ``[B, C, H, W]`` with the sum over each channel window taken by one
    1×1 convolution with a fixed band of weights (``1 / size`` where the input channel lies in the output
    channel's window), where torch pads and runs a 3-D average pool: the same values to float rounding, 2.4–3.2×
    faster forward and backward on CPU (tests/models/test_gait_cnn.py; bench/RESULTS.md, *Training throughput*).
    When a gradient is needed, :class:`_BandLRN` gives it in closed form, in fewer passes over the activations
    than autograd takes through the formula. Under autocast the window sum and the power run in float32, as
    torch's average pool does.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4:
            return super().forward(x)
        channel = torch.arange(x.shape[1], device=x.device)
        offset = channel.view(1, -1) - channel.view(-1, 1)  # [out, in]: input channel - output channel
        band = ((offset >= -(self.size // 2)) & (offset <= (self.size - 1) // 2)).float() / self.size
        closed_form = x.requires_grad and torch.is_grad_enabled() and not torch.onnx.is_in_onnx_export()
        with torch.no_grad() if closed_form else contextlib.nullcontext():  # _BandLRN differentiates the squares
            squares = x * x
        if torch.is_autocast_enabled(x.device.type):  # squared in x's dtype, as torch's LRN does, then float32
            with torch.autocast(x.device.type, enabled=False):
                return self._normalise(x.float(), squares.float(), band, closed_form)
        return self._normalise(x, squares, band.to(x.dtype), closed_form)

    def _normalise(self, x, squares, band, closed_form: bool) -> torch.Tensor:
        if closed_form:
            return _BandLRN.apply(x, squares, band, self.alpha, self.beta, self.k)
        return x / _band_denominator(squares, band, self.alpha, self.beta, self.k)[0]


def _band_denominator(squares, band, alpha, beta, k) -> tuple[torch.Tensor, torch.Tensor]:
    """``(d^β, d)`` with ``d = k + α · band · squares`` over channels (a 1×1 convolution)."""
    base = F.conv2d(squares, band[:, :, None, None]) * alpha + k
    return base.pow(beta), base


class _BandLRN(torch.autograd.Function):
    """``y = x / d^β``, ``d = k + α W x²`` (``W`` the ``[out, in]`` channel band), with the gradient in closed form:
    ``∂L/∂x = g / d^β − 2αβ · x · Wᵀ(g · y / d)``. Autograd through the formula takes about twice the passes over
    the activations (bench/RESULTS.md, *Training throughput*); the values are the same to float rounding
    (tests/models/test_gait_cnn.py checks them against torch's LRN)."""

    @staticmethod
    def forward(ctx, x, squares, band, alpha, beta, k):
        power, base = _band_denominator(squares, band, alpha, beta, k)
        y = x / power
        ctx.save_for_backward(x, band, y, power, base)
        ctx.scale = -2.0 * alpha * beta
        return y

    @staticmethod
    def backward(ctx, grad):
        x, band, y, power, base = ctx.saved_tensors
        with torch.autocast(grad.device.type, enabled=False):
            grad = grad.to(x.dtype)
            spread = F.conv2d(grad * y / base, band.t()[:, :, None, None])  # Wᵀ(g · y / d)
            return torch.addcmul(grad / power, x, spread, value=ctx.scale), None, None, None, None, None


class MultiTaskGaitCNN(nn.Module):
    """GEIs ``[B, 1, H, W]`` (float, 0..1) → ``{task: logits, "embedding": [B, embedding_dim]}``.

    Args:
        num_subjects: classes of the subject head (124 on CASIA-B's closed set).
        num_views: classes of the view head (11 CASIA-B cameras).
        num_conditions: classes of the condition head (nm / bg / cl).
        tasks: the heads, any non-empty subset of :data:`TASKS`; ``("subject",)`` is the single-task net.
        input_size: ``(H, W)`` of the GEIs; fixes the flatten size (124×124 in the thesis, 64×44 in OpenGait).
        embedding_dim: width of the shared FC layer (512).
        head_dim: width of each task's hidden FC layer (128).
        dropout: dropout probability after each hidden FC layer (0.5).

    Attributes:
        trunk: the convolutional stages (``nn.Sequential`` named ``c1, relu1, lrn1, pool1, ...``).
        shared_fc: the shared FC layer; its ReLU output is ``"embedding"``.
        heads: ``nn.ModuleDict`` task → ``Linear(embedding_dim, head_dim) → ReLU → Dropout → Linear(head_dim, classes)``.
        num_classes: task → number of classes.
    """

    def __init__(
        self,
        num_subjects: int,
        num_views: int = 11,
        num_conditions: int = 3,
        tasks: tuple[str, ...] = TASKS,
        input_size: tuple[int, int] = (124, 124),
        embedding_dim: int = 512,
        head_dim: int = 128,
        dropout: float = 0.5,
    ):
        super().__init__()
        tasks = tuple(tasks)
        unknown = [t for t in tasks if t not in TASKS]
        if not tasks or unknown or len(set(tasks)) != len(tasks):
            raise ValueError(f"tasks={list(tasks)}: choose a non-empty subset of {list(TASKS)} without repeats")
        self.num_classes = {"subject": int(num_subjects), "view": int(num_views), "condition": int(num_conditions)}
        self.num_classes = {t: self.num_classes[t] for t in tasks}
        bad = {t: n for t, n in self.num_classes.items() if n < 1}
        if bad:
            raise ValueError(f"every task needs at least one class, got {bad}")
        self.tasks = tasks
        self.input_size = (int(input_size[0]), int(input_size[1]))
        self.embedding_dim, self.head_dim = int(embedding_dim), int(head_dim)

        layers: OrderedDict[str, nn.Module] = OrderedDict()
        in_channels = 1
        for k, (name, channels, kernel) in enumerate(CONV_STAGES, start=1):
            layers[name] = nn.Conv2d(in_channels, channels, kernel, stride=1, padding=0)
            layers[f"relu{k}"] = nn.ReLU(inplace=True)
            layers[f"lrn{k}"] = ChannelWindowLRN(LRN_SIZE, alpha=LRN_ALPHA, beta=LRN_BETA, k=LRN_K)
            layers[f"pool{k}"] = nn.MaxPool2d(2)
            in_channels = channels
        self.trunk = nn.Sequential(layers)
        sizes = self.feature_map_sizes()
        channels, height, width = sizes["pool3"]
        if height < 1 or width < 1:
            raise ValueError(
                f"input_size={list(self.input_size)} is too small for Table 6.1's trunk: "
                f"the feature maps shrink to {sizes}"
            )
        self.flat_features = channels * height * width
        self.shared_fc = nn.Linear(self.flat_features, self.embedding_dim)
        self.dropout = Dropout(dropout)
        self.heads = nn.ModuleDict(
            {
                task: nn.Sequential(
                    nn.Linear(self.embedding_dim, self.head_dim),
                    nn.ReLU(inplace=True),
                    Dropout(dropout),
                    nn.Linear(self.head_dim, n),
                )
                for task, n in self.num_classes.items()
            }
        )
        self.reset_parameters()
        # channels-last convolutions (weights and GEIs): 1.2x faster training steps in float32 and 1.4x in bf16 on
        # CPU (bench/RESULTS.md, Training throughput); same parameter names, shapes and values
        self.trunk.to(memory_format=torch.channels_last)

    def reset_parameters(self) -> None:
        """He (Kaiming) normal weights for the ReLU layers, N(0, 0.01²) for the logits, zero biases.

        The thesis gives no initialisation. PyTorch's default shrinks the activations at every stage,
        and LRN with k = 2 divides small activations by another k^β ≈ 1.68 per stage, so the logits start
        flat and plain SGD at lr 0.01 stalls for many epochs. We use He initialisation with the conv
        weights scaled by k^β to cancel the LRN's constant gain; on our synthetic GEIs this roughly
        halves the steps before the loss starts to fall.
        """
        logits = {id(head[-1]) for head in self.heads.values()}
        for module in self.modules():
            if isinstance(module, (nn.Conv2d, nn.Linear)):
                if id(module) in logits:
                    nn.init.normal_(module.weight, std=0.01)
                else:
                    nn.init.kaiming_normal_(module.weight, nonlinearity="relu")
                    if isinstance(module, nn.Conv2d):
                        module.weight.data.mul_(LRN_K**LRN_BETA)
                nn.init.zeros_(module.bias)

    def feature_map_sizes(self) -> dict[str, tuple[int, int, int]]:
        """``(channels, height, width)`` after each conv and pool (``c1``, ``pool1``, ... ``pool3``), by arithmetic.

        Valid convolution: ``n - kernel + 1``; 2×2 max-pool: ``n // 2``.
        """
        height, width = self.input_size
        sizes = {}
        for k, (name, channels, kernel) in enumerate(CONV_STAGES, start=1):
            height, width = height - kernel + 1, width - kernel + 1
            sizes[name] = (channels, height, width)
            height, width = height // 2, width // 2
            sizes[f"pool{k}"] = (channels, height, width)
        return sizes

    def forward(self, geis: torch.Tensor) -> dict[str, torch.Tensor]:
        """``geis`` ``[B, 1, H, W]`` → ``{"subject": [B, S], "view": [B, 11], "condition": [B, 3], "embedding": [B, 512]}``
        (only the configured tasks). ``embedding`` is the shared FC's ReLU output, before dropout."""
        if geis.dim() != 4 or tuple(geis.shape[1:]) != (1, *self.input_size):
            raise ValueError(
                f"expected GEIs [batch, 1, {self.input_size[0]}, {self.input_size[1]}], got {list(geis.shape)}"
            )
        features = self.trunk(geis.contiguous(memory_format=torch.channels_last)).flatten(1)  # flattened as C, H, W
        embedding = torch.relu(self.shared_fc(features))
        hidden = self.dropout(embedding)
        out = {task: head(hidden) for task, head in self.heads.items()}
        out["embedding"] = embedding
        return out


def multitask_gait_cnn(
    num_subjects: int,
    num_views: int = 11,
    num_conditions: int = 3,
    tasks: tuple[str, ...] | list[str] = TASKS,
    input_size: tuple[int, int] | list[int] = (124, 124),
    embedding_dim: int = 512,
    head_dim: int = 128,
    dropout: float = 0.5,
) -> MultiTaskGaitCNN:
    """Hydra builder of :class:`MultiTaskGaitCNN` (``configs/model/gait_cnn.yaml``); lists are accepted for tuples."""
    return MultiTaskGaitCNN(
        num_subjects, num_views, num_conditions, tuple(tasks), tuple(input_size), embedding_dim, head_dim, dropout
    )
