"""A spatial-temporal graph convolution network (ST-GCN family) for any skeleton layout.

Yan, Xiong & Lin, "Spatial temporal graph convolutional networks for skeleton-based
action recognition", AAAI 2018, sized for CPU and built from a layout's ``parents``,
so the same code runs on NTU-25, MSR-20 and CMU-31 skeletons.

* **Graph.** The bones of the kinematic tree plus self-loops, symmetrically normalised,
  ``Â = D^-1/2 (A + I) D^-1/2``, and split by Yan et al.'s spatial partitioning into three
  ``[J, J]`` matrices: *self* (the diagonal), *inward* (each joint gathers from its parent,
  the neighbour nearer the root/centre) and *outward* (from its children). The three sum to
  the symmetric ``Â``; inward is outward transposed. Each block also learns an additive
  correction of the three matrices (initialised to zero; ``adaptive``); ``topology="channelwise"`` adds
  CTR-GCN's per-sample, per-channel refinement (:class:`GraphConv`).
* **Temporal unit.** ``temporal="conv"``: one ``kernel_size`` convolution over frames (ST-GCN).
  ``temporal="multiscale"``: ST-GCN++'s multi-scale unit (Duan et al., "PYSKL: towards good practices for
  skeleton action recognition", ACM MM 2022) — six parallel branches on a sixth of the channels each (1×1 then a
  3-frame convolution at dilations 1, 2, 3, 4; 1×1 then a 3-frame max-pool; 1×1 alone), concatenated, BN, ReLU and
  a 1×1 convolution; the branches see the frame mask, so padding stays inert.
* **Input.** Skeletons ``[N, M, T, J, 3]`` as the data modules give them (zeros where a body or
  frame is absent). Optional pre-normalisation inside the model: centre on the median position of
  body 0's root joint over its present frames (``center``), divide by body 0's median pelvis-neck
  length (``scale``); medians, so glitch frames do not move or shrink the sequence
  (:mod:`mocapkit.models.body_frame`, shared with the energy image). Input streams (``streams``) are concatenated as channels: ``joint`` positions,
  ``velocity`` (frame differences) and ``bone`` vectors (joint minus parent).
* **Padding.** Features at absent frames are zeroed after every layer and the temporal pooling is
  a mean over present frames only, so zero-padded frames do not change the output (in eval mode).
* **Persons.** Each body goes through the network; the pooled features are averaged over the
  bodies that are present.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from mocapkit.models.body_frame import body0_origin, body0_size
from mocapkit.models.ops import Dropout
from mocapkit.motion.layouts import LANDMARKS, SkeletonLayout, get_layout

STREAMS = ("joint", "velocity", "bone", "bone_velocity")


def spatial_adjacency(layout: SkeletonLayout | str) -> torch.Tensor:
    """The partitioned, symmetric-normalised adjacency ``[3, J, J]`` (self, inward, outward) of a layout.

    ``A[k, i, j]`` is the weight with which joint ``i`` gathers joint ``j`` in partition ``k``:
    ``A[1, i, parent(i)]`` and ``A[2, parent(j), j]`` are ``1 / sqrt(d_i d_j)`` with ``d`` the degree
    including the self-loop; ``A[0]`` is the diagonal ``1 / d_i``. ``A.sum(0)`` is symmetric.
    """
    layout = get_layout(layout)
    j = layout.num_joints
    adj = torch.eye(j)
    for child, parent in layout.bones:
        adj[child, parent] = adj[parent, child] = 1.0
    d = adj.sum(1).rsqrt()
    norm = d[:, None] * adj * d[None, :]
    inward = torch.zeros(j, j)
    for child, parent in layout.bones:
        inward[child, parent] = 1.0
    outward = inward.T
    return torch.stack((norm * torch.eye(j), norm * inward, norm * outward))


TOPOLOGIES = ("shared", "channelwise")


class GraphConv(nn.Module):
    """Spatial graph convolution over ``K`` partitions: ``[N, C, T, J]`` → ``[N, C', T, J]``.

    ``topology="shared"``: every channel and sample gathers through the same ``[K, J, J]`` adjacency (plus the
    learned correction when ``adaptive``). ``topology="channelwise"``: CTR-GCN's channel-wise topology refinement
    (Chen et al., "Channel-wise topology refinement graph convolution for skeleton-based action recognition",
    ICCV 2021): per partition, two 1×1 convolutions to ``R = max(8, C / 8)`` channels, averaged over the present
    frames, give joint descriptors ``u_i, v_j``; ``tanh(u_i - v_j)`` lifted by a 1×1 convolution to ``C'`` channels
    is a per-sample, per-channel ``[C', J, J]`` correction, scaled by a learned ``alpha`` (initialised to 0, so
    training starts from the shared graph) and added to the partition's adjacency.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        adjacency: torch.Tensor,
        adaptive: bool = True,
        topology: str = "shared",
    ):
        super().__init__()
        if topology not in TOPOLOGIES:
            raise ValueError(f"unknown graph topology {topology!r}; choose from {TOPOLOGIES}")
        self.k = adjacency.shape[0]
        self.register_buffer("adjacency", adjacency.clone())
        self.correction = nn.Parameter(torch.zeros_like(adjacency)) if adaptive else None
        self.conv = nn.Conv2d(in_channels, out_channels * self.k, kernel_size=1)
        self.out_channels = out_channels
        self.channelwise = topology == "channelwise"
        if self.channelwise:
            r = max(8, in_channels // 8)
            self.relation_in = nn.Conv2d(in_channels, 2 * self.k * r, kernel_size=1)  # u and v of each partition
            self.relation_out = nn.Conv2d(self.k * r, self.k * out_channels, kernel_size=1, groups=self.k)
            self.alpha = nn.Parameter(torch.zeros(1))
            self.relation_channels = r

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """``x`` ``[N, C, T, J]`` (zero at absent frames), ``mask`` ``[N, 1, T, 1]`` (1 = present; None: all)."""
        n, c, t, j = x.shape
        a = self.adjacency if self.correction is None else self.adjacency + self.correction
        # graph first in float32 only: under bf16 autocast the einsum form below was as fast or faster on this CPU
        # (bench/RESULTS.md, Training throughput)
        if not self.channelwise and c < self.out_channels and not torch.is_autocast_enabled(x.device.type):
            return self._graph_first(x, a)
        y = self.conv(x).view(n, self.k, self.out_channels, t, j)
        if not self.channelwise:
            return torch.einsum("nkctj,kij->ncti", y, a)
        frames = torch.full_like(x[:, :1, :, :1], 1.0) if mask is None else mask
        mean = (self.relation_in(x) * frames).sum(2) / frames.sum(2).clamp(min=1.0)  # [N, 2KR, J]
        u, v = mean.view(n, 2, self.k * self.relation_channels, j).unbind(1)
        relation = torch.tanh(u[..., :, None] - v[..., None, :])  # [N, KR, J, J]
        q = self.relation_out(relation).view(n, self.k, self.out_channels, j, j)
        return torch.einsum("nkctj,nkcij->ncti", y, a[None, :, None] + self.alpha * q)

    def _graph_first(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """The shared-topology product with the graph applied before the channels, for ``C < C'``.

        ``sum_k A_k (W_k x + b_k)`` equals ``sum_k W_k (A_k x) + sum_k b_k (A_k 1)``: the joints of the whole batch
        go through the three partitions in one matmul ``[N*C*T, J] @ [J, K*J]`` (the joints are the innermost
        axis, so no copy), then one batched matmul with the ``[C', K*C]`` weights mixes channels and partitions.
        With fewer input than output channels the ``K``-fold wider intermediate is the smaller one (the first
        block, 9 → 3 × 64, and each widening block); the output matches the einsum form to float rounding. Used
        in float32; under autocast the einsum form runs.
        """
        n, c, t, j = x.shape
        k, c_out = self.k, self.out_channels
        z = (x.reshape(-1, j) @ a.permute(2, 0, 1).reshape(j, k * j)).view(n, c, t, k, j)
        z = z.permute(0, 3, 1, 2, 4).reshape(n, k * c, t * j)  # [N, (partition, channel), T*J]
        weight = self.conv.weight.view(k, c_out, c).transpose(0, 1).reshape(c_out, k * c)
        bias = (self.conv.bias.view(k, c_out, 1) * a.sum(2).unsqueeze(1)).sum(0)  # [C', J]: b through the graph
        return (torch.matmul(weight, z).view(n, c_out, t, j) + bias.unsqueeze(1)).contiguous()


TEMPORAL_UNITS = ("conv", "multiscale")


class MultiScaleTemporalConv(nn.Module):
    """ST-GCN++'s multi-scale temporal unit: ``[N, C, T, J]`` (zero at absent frames) → ``[N, C', T / stride, J]``.

    Six branches, each on about ``C' / 6`` channels (the first takes the remainder): 1×1 conv → BN → ReLU, then a
    3-frame convolution with dilation 1, 2, 3 or 4, or a 3-frame max-pool, or nothing (the 1×1 branch, strided);
    concatenated → BN → ReLU → 1×1 conv. The branch activations are multiplied by the frame mask before the
    temporal step, so absent frames contribute the zeros that a convolution's own padding would.
    """

    DILATIONS = (1, 2, 3, 4)

    def __init__(self, in_channels: int, out_channels: int, stride: int = 1):
        super().__init__()
        branches = len(self.DILATIONS) + 2
        mid = out_channels // branches
        if mid < 1:
            raise ValueError(f"the multi-scale temporal unit needs at least {branches} channels, got {out_channels}")
        widths = [out_channels - mid * (branches - 1)] + [mid] * (branches - 1)
        self.squeeze = nn.ModuleList(
            nn.Sequential(nn.Conv2d(in_channels, w, 1), nn.BatchNorm2d(w), nn.ReLU()) for w in widths
        )
        temporal = [nn.Conv2d(w, w, (3, 1), (stride, 1), (d, 0), (d, 1)) for w, d in zip(widths, self.DILATIONS)]
        temporal.append(nn.MaxPool2d((3, 1), (stride, 1), (1, 0)))
        temporal.append(nn.Conv2d(widths[-1], widths[-1], 1, (stride, 1)))
        self.temporal = nn.ModuleList(temporal)
        self.mix = nn.Sequential(nn.BatchNorm2d(out_channels), nn.ReLU(), nn.Conv2d(out_channels, out_channels, 1))

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """``x`` ``[N, C, T, J]``, ``mask`` ``[N, 1, T, 1]`` (1 = present)."""
        out = [step(squeeze(x) * mask) for squeeze, step in zip(self.squeeze, self.temporal)]
        return self.mix(torch.cat(out, dim=1))


class STGCNBlock(nn.Module):
    """Graph convolution → BN → ReLU → temporal unit (stride) → BN, plus a residual, → ReLU."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        adjacency: torch.Tensor,
        stride: int = 1,
        kernel_size: int = 9,
        dropout: float = 0.0,
        residual: bool = True,
        adaptive: bool = True,
        temporal: str = "conv",
        topology: str = "shared",
    ):
        super().__init__()
        if temporal not in TEMPORAL_UNITS:
            raise ValueError(f"unknown temporal unit {temporal!r}; choose from {TEMPORAL_UNITS}")
        self.gcn = GraphConv(in_channels, out_channels, adjacency, adaptive, topology)
        self.bn1 = nn.BatchNorm2d(out_channels)
        if temporal == "conv":
            pad = (kernel_size - 1) // 2
            self.tcn = nn.Conv2d(out_channels, out_channels, (kernel_size, 1), (stride, 1), (pad, 0))
        else:
            self.tcn = MultiScaleTemporalConv(out_channels, out_channels, stride)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.dropout = Dropout(dropout)
        self.stride = stride
        if not residual:
            self.residual = None
        elif in_channels == out_channels and stride == 1:
            self.residual = nn.Identity()
        else:
            self.residual = nn.Sequential(
                nn.Conv2d(in_channels, out_channels, 1, (stride, 1)), nn.BatchNorm2d(out_channels)
            )

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x`` ``[N, C, T, J]`` (zero at absent frames), ``mask`` ``[N, 1, T, 1]`` → both downsampled."""
        y = F.relu(self.bn1(self.gcn(x, mask))) * mask
        y = self.tcn(y, mask) if isinstance(self.tcn, MultiScaleTemporalConv) else self.tcn(y)
        y = self.dropout(self.bn2(y))
        out_mask = mask[:, :, :: self.stride]
        if self.residual is not None:
            y = y + self.residual(x)
        return F.relu(y) * out_mask, out_mask


class STGCN(nn.Module):
    """Skeletons ``[N, M, T, J, in_channels]`` (zeros = absent) → logits ``[N, num_classes]``.

    Args:
        layout: a :class:`SkeletonLayout` or its name (``"ntu25"``, ``"msr20"``, ``"cmu31"``).
        num_classes: output classes.
        in_channels: coordinates per joint (3).
        channels: output channels of each block (CPU-sized default: 64, 64, 128, 128).
        strides: temporal stride of each block.
        kernel_size: temporal kernel (frames) of the ``conv`` temporal unit.
        streams: input features concatenated as channels, any of ``joint``, ``velocity`` (frame differences of
            the joints), ``bone`` (joint minus parent) and ``bone_velocity`` (frame differences of the bones).
        center: subtract the median position of body 0's root joint over its present frames.
        scale: divide by the median pelvis-neck length of body 0 (needs the layout's landmarks).
        adaptive: learn an additive correction of the adjacency in each block.
        dropout: dropout inside blocks; ``head_dropout``: before the classifier.
        temporal: the blocks' temporal unit, ``conv`` (ST-GCN) or ``multiscale`` (ST-GCN++; ``kernel_size`` unused).
        topology: ``shared`` (one adjacency per partition) or ``channelwise`` (CTR-GCN's refinement, see
            :class:`GraphConv`).
    """

    def __init__(
        self,
        layout: SkeletonLayout | str,
        num_classes: int,
        in_channels: int = 3,
        channels: tuple[int, ...] = (64, 64, 128, 128),
        strides: tuple[int, ...] = (1, 1, 2, 1),
        kernel_size: int = 9,
        streams: tuple[str, ...] = ("joint",),
        center: bool = True,
        scale: bool = False,
        adaptive: bool = True,
        dropout: float = 0.0,
        head_dropout: float = 0.0,
        temporal: str = "conv",
        topology: str = "shared",
    ):
        super().__init__()
        self.layout = get_layout(layout)
        streams = tuple(streams)
        unknown = [s for s in streams if s not in STREAMS]
        if unknown or not streams:
            raise ValueError(f"unknown input streams {unknown or streams}; choose from {STREAMS}")
        if len(channels) != len(strides) or not channels:
            raise ValueError(
                f"channels {list(channels)} and strides {list(strides)} must have the same, non-zero length"
            )
        self.num_joints = self.layout.num_joints
        self.in_channels = in_channels
        self.streams = streams
        self.center, self.scale = bool(center), bool(scale)
        self.root = self.layout.parents.index(-1)
        landmarks = LANDMARKS.get(self.layout.name)
        if self.scale and not landmarks:
            raise ValueError(f"scale=True needs the body landmarks of layout {self.layout.name!r}")
        self.spine = (
            (self.layout.index(landmarks["pelvis"]), self.layout.index(landmarks["neck"])) if landmarks else None
        )
        parents = [p if p >= 0 else j for j, p in enumerate(self.layout.parents)]
        self.register_buffer("parents", torch.tensor(parents, dtype=torch.long), persistent=False)
        features = in_channels * len(streams)
        self.data_bn = nn.BatchNorm1d(features * self.num_joints)
        adjacency = spatial_adjacency(self.layout)
        blocks, c_in = [], features
        for k, (c_out, stride) in enumerate(zip(channels, strides)):
            blocks.append(
                STGCNBlock(
                    c_in,
                    c_out,
                    adjacency,
                    stride,
                    kernel_size,
                    dropout,
                    residual=k > 0,
                    adaptive=adaptive,
                    temporal=temporal,
                    topology=topology,
                )
            )
            c_in = c_out
        self.blocks = nn.ModuleList(blocks)
        self.head_dropout = Dropout(head_dropout)
        self.fc = nn.Linear(c_in, num_classes)
        self.num_classes = num_classes

    # ------------------------------------------------------------------ steps

    def normalize(self, x: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        """Centre (and scale) as configured; absent frames stay zero. ``[N, M, T, J, C]``.

        Origin and size are medians over body 0's present frames (:mod:`mocapkit.models.body_frame`).
        """
        if not (self.center or self.scale):
            return x
        if self.center:
            x = x - body0_origin(x, present, self.root).view(-1, 1, 1, 1, x.shape[-1])
        if self.scale:
            lower, upper = self.spine  # centring cancels
            x = x / body0_size(x, present, lower, upper).view(-1, 1, 1, 1, 1)
        return x * present[..., None, None].to(x.dtype)

    def features(self, x: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        """The input streams concatenated: ``[N, M, T, J, C]`` → ``[N, M, T, J, C * len(streams)]``."""
        out = []
        both = (present[:, :, 1:] & present[:, :, :-1])[..., None, None].to(x.dtype)

        def velocity(y):  # forward difference, zero where either frame is absent and at the last frame
            return torch.cat(((y[:, :, 1:] - y[:, :, :-1]) * both, torch.zeros_like(y[:, :, :1])), dim=2)

        for stream in self.streams:
            if stream == "joint":
                out.append(x)
            elif stream == "bone":
                out.append(x - x[:, :, :, self.parents])
            elif stream == "velocity":
                out.append(velocity(x))
            else:
                out.append(velocity(x - x[:, :, :, self.parents]))
        return torch.cat(out, dim=-1)

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        n, m, t, j, c = skeletons.shape
        present = skeletons.abs().sum(dim=(-1, -2)) > 0  # [N, M, T]
        x = self.features(self.normalize(skeletons, present), present)
        c = x.shape[-1]
        # data BN over (joint, channel), as in ST-GCN; padded frames are re-zeroed below
        x = x.permute(0, 1, 3, 4, 2).reshape(n * m, j * c, t)
        x = self.data_bn(x).view(n * m, j, c, t).permute(0, 2, 3, 1)  # [NM, C, T, J]
        mask = present.reshape(n * m, 1, t, 1).to(x.dtype)
        x = x * mask
        for block in self.blocks:
            x, mask = block(x, mask)
        pooled = x.sum(dim=(2, 3)) / (mask.sum(dim=(2, 3)) * j).clamp(min=1.0)  # [NM, C]
        pooled = pooled.view(n, m, -1)
        body = present.any(dim=2).to(x.dtype).unsqueeze(-1)  # [N, M, 1]
        pooled = (pooled * body).sum(1) / body.sum(1).clamp(min=1.0)
        return self.fc(self.head_dropout(pooled))


def stgcn(
    num_classes: int,
    layout: SkeletonLayout | str = "ntu25",
    in_channels: int = 3,
    channels: tuple[int, ...] | list[int] = (64, 64, 128, 128),
    strides: tuple[int, ...] | list[int] = (1, 1, 2, 1),
    kernel_size: int = 9,
    streams: tuple[str, ...] | list[str] = ("joint",),
    center: bool = True,
    scale: bool = False,
    adaptive: bool = True,
    dropout: float = 0.0,
    head_dropout: float = 0.0,
    temporal: str = "conv",
    topology: str = "shared",
) -> STGCN:
    """Hydra builder of :class:`STGCN` (``configs/model/stgcn.yaml``); lists are accepted for tuples."""
    return STGCN(
        layout,
        num_classes,
        in_channels,
        tuple(channels),
        tuple(strides),
        kernel_size,
        tuple(streams),
        center,
        scale,
        adaptive,
        dropout,
        head_dropout,
        temporal,
        topology,
    )


class MultiStreamSTGCN(nn.Module):
    """One :class:`STGCN` per input stream, late fusion: skeletons ``[N, M, T, J, 3]`` → logits ``[N, C]``.

    In training mode the forward pass returns the members' logits stacked, ``[S, N, C]``, so that
    :class:`~mocapkit.recognition.module.ActionRecognitionModule` trains each member on its own
    cross-entropy (as if trained apart, the way pyskl trains its stream ensembles); in eval mode (evaluation,
    prediction, ONNX export) it returns their mean ``[N, C]``.

    Args:
        streams: one list of input streams per member, e.g. ``[[joint], [bone], [velocity], [bone_velocity]]``.
        kwargs: the :class:`STGCN` arguments every member shares (layout, channels, strides, ...).
    """

    def __init__(self, layout: SkeletonLayout | str, num_classes: int, streams, **kwargs):
        super().__init__()
        streams = [tuple([s] if isinstance(s, str) else s) for s in streams]
        if not streams:
            raise ValueError("MultiStreamSTGCN needs at least one member's streams, e.g. [[joint], [bone]]")
        self.streams = streams
        self.members = nn.ModuleList(STGCN(layout, num_classes, streams=member, **kwargs) for member in streams)
        self.layout = self.members[0].layout  # read by the ONNX export (joint count, metadata)
        self.num_classes = num_classes

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        logits = torch.stack([member(skeletons) for member in self.members])
        return logits if self.training else logits.mean(0)


def stgcn_ensemble(
    num_classes: int,
    layout: SkeletonLayout | str = "ntu25",
    streams=(("joint",), ("bone",), ("velocity",), ("bone_velocity",)),
    in_channels: int = 3,
    channels: tuple[int, ...] | list[int] = (64, 64, 128, 128),
    strides: tuple[int, ...] | list[int] = (1, 1, 2, 1),
    kernel_size: int = 9,
    center: bool = True,
    scale: bool = False,
    adaptive: bool = True,
    dropout: float = 0.0,
    head_dropout: float = 0.0,
    temporal: str = "conv",
    topology: str = "shared",
) -> MultiStreamSTGCN:
    """Hydra builder of :class:`MultiStreamSTGCN` (``configs/model/stgcn_ensemble.yaml``)."""
    return MultiStreamSTGCN(
        layout,
        num_classes,
        streams,
        in_channels=in_channels,
        channels=tuple(channels),
        strides=tuple(strides),
        kernel_size=kernel_size,
        center=center,
        scale=scale,
        adaptive=adaptive,
        dropout=dropout,
        head_dropout=head_dropout,
        temporal=temporal,
        topology=topology,
    )
