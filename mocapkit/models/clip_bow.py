"""End-to-end NMF bag of clip words: skeletons → clip features → NMF layer → soft words → classifier.

A trainable version of the thesis's recognition pipeline (Wang 2017 thesis §6.3.4), built from the same
clip definition as the classical pipeline (:mod:`mocapkit.features.clips`):

1. **Clips.** Body 0 of skeletons ``[B, M, T, J, 3]`` (metres, zeros where absent or padded) is cut
   into windows of ``window`` frames with stride ``stride`` and each clip encoded as the
   non-negative sign-split normalised coordinates of ``frames_per_clip`` frames
   (:class:`~mocapkit.features.clips.ClipFeatures`). Sequences shorter than a window are edge-padded
   inside the model, so any length ≥ 1 frame works (the ONNX export uses ≥ 2).
2. **Clip encoder.** ``Linear → ReLU → Linear → softplus``: a non-negative ``encoder_hidden``-vector
   per clip (NMF needs non-negative input).
3. **NMF layer.** :class:`~mocapkit.models.nmf_layer.NMFLayer` codes ``[B, N, k]`` against a learned,
   shared dictionary of ``n_components`` words (``n_iter`` multiplicative updates, one-step gradient).
4. **Soft words.** ``softmax(log(codes + eps) / temperature)`` per clip, i.e. the codes raised to
   ``1/temperature`` and ℓ1-normalised: ``temperature = 1`` is the plain normalised code, smaller is
   harder (towards the arg-max word of the classical pipeline).
5. **Soft bag of words.** The mean of the soft words over the sample's *valid* clips (clips made
   only of batch padding are masked out), ``[B, k]``, sums to 1 like the classical histogram.
6. **Classifier.** Dropout and a linear layer on the histogram scaled by ``k`` (mean entry 1).

Zero-padding a batch does not change any sample's output (the padded clips are invalid, the NMF
layer zeroes their codes and, with ``graph_reg > 0``, keeps them out of the kNN graph).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from mocapkit.features.clips import ClipFeatures
from mocapkit.models.nmf_layer import NMFLayer
from mocapkit.models.ops import Dropout
from mocapkit.motion.layouts import LAYOUTS, SkeletonLayout


class ClipNMFBagOfWords(nn.Module):
    """Skeletons ``[B, M, T, J, 3]`` → logits ``[B, num_classes]`` through a soft NMF bag of clip words.

    Args: see :func:`clip_nmf_bow`.
    """

    def __init__(
        self,
        num_classes: int,
        layout: SkeletonLayout | str = "msr20",
        window: int = 30,
        stride: int = 15,
        frames_per_clip: int = 10,
        n_components: int = 64,
        n_iter: int = 10,
        one_step_grad: bool = True,
        graph_reg: float = 0.0,
        encoder_hidden: int = 128,
        temperature: float = 1.0,
        dropout: float = 0.0,
    ):
        super().__init__()
        if isinstance(layout, str) and layout not in LAYOUTS:
            raise ValueError(f"unknown skeleton layout {layout!r}; known: {sorted(LAYOUTS)}")
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        self.clips = ClipFeatures(layout, window, stride, frames_per_clip)
        self.layout = self.clips.layout
        self.encoder = nn.Sequential(
            nn.Linear(self.clips.out_features, encoder_hidden),
            nn.ReLU(),
            nn.Linear(encoder_hidden, encoder_hidden),
            nn.Softplus(),
        )
        self.nmf = NMFLayer(
            encoder_hidden, n_components, n_iter=n_iter, one_step_grad=one_step_grad, graph_reg=graph_reg
        )
        self.temperature = float(temperature)
        self.dropout = Dropout(dropout)
        self.fc = nn.Linear(n_components, num_classes)
        self.num_classes, self.n_components = num_classes, n_components

    def soft_words(self, skeletons: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-clip soft word assignments ``[B, N, k]`` (rows sum to 1 on valid clips) and the clip mask ``[B, N]``."""
        if skeletons.dim() != 5 or skeletons.shape[-2:] != (self.layout.num_joints, 3):
            raise ValueError(f"expected skeletons [B, M, T, {self.layout.num_joints}, 3], got {list(skeletons.shape)}")
        features, valid = self.clips(skeletons[:, 0])  # body 0
        encoded = self.encoder(features) * valid[..., None].to(features.dtype)
        codes = self.nmf(encoded, valid)
        words = F.softmax(torch.log(codes + self.nmf.eps) / self.temperature, dim=-1)
        return words * valid[..., None].to(words.dtype), valid

    def bag_of_words(self, skeletons: torch.Tensor) -> torch.Tensor:
        """Soft bag of words ``[B, k]``: the mean soft word over each sample's valid clips."""
        words, valid = self.soft_words(skeletons)
        count = valid.to(words.dtype).sum(1, keepdim=True).clamp(min=1.0)
        return words.sum(1) / count

    def forward(self, skeletons: torch.Tensor) -> torch.Tensor:
        histogram = self.bag_of_words(skeletons)
        return self.fc(self.dropout(histogram * self.n_components))


def clip_nmf_bow(
    num_classes: int,
    layout: SkeletonLayout | str = "msr20",
    window: int = 30,
    stride: int = 15,
    frames_per_clip: int = 10,
    n_components: int = 64,
    n_iter: int = 10,
    one_step_grad: bool = True,
    graph_reg: float = 0.0,
    encoder_hidden: int = 128,
    temperature: float = 1.0,
    dropout: float = 0.0,
) -> ClipNMFBagOfWords:
    """Hydra builder of :class:`ClipNMFBagOfWords` (``configs/model/clip_nmf_bow.yaml``).

    Args:
        num_classes: output classes.
        layout: skeleton layout (name or :class:`SkeletonLayout`); needs pelvis/neck landmarks.
        window, stride: clip length and step in frames (thesis: 30 and 15).
        frames_per_clip: frames sampled per clip (feature size ``2 · frames_per_clip · J · 3``).
        n_components: vocabulary size ``k`` of the NMF layer.
        n_iter: multiplicative updates per forward; ``one_step_grad``: back-propagate through the last only.
        graph_reg: λ of the kNN graph among a sequence's clips (0 = off).
        encoder_hidden: width of the clip encoder (and the NMF layer's input).
        temperature: soft-assignment temperature (1 = normalised codes).
        dropout: before the classifier.
    """
    return ClipNMFBagOfWords(
        num_classes,
        layout,
        window,
        stride,
        frames_per_clip,
        n_components,
        n_iter,
        one_step_grad,
        graph_reg,
        encoder_hidden,
        temperature,
        dropout,
    )
