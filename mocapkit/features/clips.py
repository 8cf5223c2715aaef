"""Sliding-window clips of a skeleton sequence and their non-negative features (Wang 2017 thesis §6.3).

The recognition pipeline of the thesis cuts each sequence of ``S`` frames into overlapping
clips of ``M`` frames with stride ``M/2``, clusters the clips and describes a sequence by the
histogram of its clips' clusters. The thesis leaves the clip features, the clip count and the normalisation open; the choices below
are ours (each stated where it is made), implemented once, in numpy (:func:`clip_features`, the reference,
used by the classical pipeline) and in torch (:func:`clip_features_torch`, batched and
ONNX-exportable, used inside :mod:`mocapkit.models.clip_bow`); the tests check that both agree.

**Windows.** ``clip_windows(S, M, stride)`` gives ``⌊(S − M)/stride⌋ + 1`` clips (stride ``M // 2``
by default) starting at ``0, stride, 2·stride, ...``. A sequence shorter than one window gives one
clip ``[0, M)`` whose missing frames repeat the last frame of the sequence (edge padding, so the
clip shows the final pose held rather than a jump to zeros).

**Sequence length.** Frames are present when any joint is non-zero; trailing all-zero frames are
padding (as in zero-padded batches) and do not count, so ``S`` is the index of the last present
frame plus one. All-zero frames *inside* a sequence (untracked frames) stay and encode as zeros.

**Features of one clip** (``d = 2 · frames_per_clip · J · 3``):

1. normalise the whole sequence: subtract the root joint (``layout.parents.index(-1)``, the hip
   centre) of the first present frame, divide by the body size = the mean pelvis-to-neck length over
   the frames where both are tracked (1.0 when never), and set untracked joints (all three
   coordinates zero in the input) to zero;
2. subsample the window to ``frames_per_clip`` frames at offsets ``round(linspace(0, M − 1, f))``
   (:func:`clip_frame_offsets`, shared by both implementations);
3. non-negative encoding by splitting signs: ``[max(y, 0), max(−y, 0)]``, flattened as
   ``[sign, frame, joint, xyz]`` (positive part first). Both halves are ≥ 0 and ``y = y⁺ − y⁻``
   is recoverable, unlike a constant shift whose offset NMF would have to model.
"""

from __future__ import annotations

import numpy as np
import torch

from mocapkit.motion.geometry import body_origin, body_size
from mocapkit.motion.layouts import LANDMARKS, SkeletonLayout, get_layout


def _check_window(window: int, stride: int | None) -> tuple[int, int]:
    window = int(window)
    if window < 1:
        raise ValueError(f"window must be at least 1 frame, got {window}")
    stride = window // 2 if stride is None else int(stride)
    if stride < 1:
        raise ValueError(
            f"stride must be at least 1 frame, got {stride} (window {window}; "
            "the default stride window // 2 needs window >= 2)"
        )
    return window, stride


def clip_count(length: int, window: int = 30, stride: int | None = None) -> int:
    """Number of clips of a sequence of ``length`` frames: ``⌊(S − M)/stride⌋ + 1``, and 1 when ``S < M``."""
    window, stride = _check_window(window, stride)
    if length < 1:
        raise ValueError(f"a sequence needs at least one frame, got length {length}")
    return 1 if length < window else (length - window) // stride + 1


def clip_windows(length: int, window: int = 30, stride: int | None = None) -> np.ndarray:
    """Start/stop frames ``[num_clips, 2]`` (int64, stop exclusive) of the sliding windows.

    ``stride`` defaults to ``window // 2``. A sequence shorter than ``window`` gives the single
    window ``[0, window)``; its frames past the end are edge padding (the last frame repeated).
    """
    window, stride = _check_window(window, stride)
    starts = np.arange(clip_count(length, window, stride), dtype=np.int64) * stride
    return np.stack([starts, starts + window], axis=1)


def clip_frame_offsets(window: int = 30, frames_per_clip: int = 10) -> np.ndarray:
    """The ``frames_per_clip`` frame offsets (int64) sampled inside a window: ``round(linspace(0, M − 1, f))``."""
    if not 1 <= frames_per_clip <= window:
        raise ValueError(f"frames_per_clip must be between 1 and the window ({window}), got {frames_per_clip}")
    return np.round(np.linspace(0, window - 1, frames_per_clip)).astype(np.int64)


def feature_dim(num_joints: int, frames_per_clip: int = 10) -> int:
    """Length ``d`` of one clip's feature vector: ``2 · frames_per_clip · num_joints · 3``."""
    return 2 * frames_per_clip * num_joints * 3


def body_joints(layout: SkeletonLayout | str) -> tuple[int, int, int]:
    """``(root, pelvis, neck)`` joint indices of a layout: the origin and the body-size segment."""
    layout = get_layout(layout)
    landmarks = LANDMARKS.get(layout.name)
    if not landmarks:
        raise ValueError(f"clip features need the pelvis and neck landmarks of layout {layout.name!r}")
    return layout.parents.index(-1), layout.index(landmarks["pelvis"]), layout.index(landmarks["neck"])


# ---------------------------------------------------------------------------------------------- numpy


def normalise_sequence(positions: np.ndarray, layout: SkeletonLayout | str = "msr20") -> tuple[np.ndarray, int]:
    """Centred, size-normalised joints ``[T, J, 3]`` (float32, untracked joints zero) and the length ``S``.

    ``S`` is the last present frame + 1 (trailing all-zero frames are padding).

    Raises:
        ValueError: wrong shape, non-finite values, or no tracked joint at all.
    """
    positions = np.asarray(positions, dtype=np.float32)
    layout = get_layout(layout)
    if positions.ndim != 3 or positions.shape[1:] != (layout.num_joints, 3):
        raise ValueError(
            f"positions must be [frames, {layout.num_joints}, 3] for layout {layout.name!r}, "
            f"got {list(positions.shape)}"
        )
    if not np.isfinite(positions).all():
        frame = int(np.flatnonzero(~np.isfinite(positions).all(axis=(1, 2)))[0])
        raise ValueError(f"positions contain NaN or inf (first at frame {frame}); missing joints must be zeros")
    root, pelvis, neck = body_joints(layout)
    joint_present = np.abs(positions).sum(-1) > 0  # [T, J]
    frame_present = joint_present.any(1)
    if not frame_present.any():
        raise ValueError("positions are all zero: no tracked joint, no clip features")
    length = int(np.flatnonzero(frame_present)[-1]) + 1
    origin = body_origin(positions, frame_present, root, statistic="first")
    # the mean segment (the networks take the median), 1 where pelvis and neck are never seen together
    scale = body_size(
        positions,
        joint_present[:, pelvis] & joint_present[:, neck],
        pelvis,
        neck,
        statistic="mean",
        floor=1e-3,
        default=1.0,
    )
    normalised = (positions - origin) / np.float32(scale) * joint_present[..., None]
    return normalised.astype(np.float32), length


def clip_features(
    positions: np.ndarray,
    window: int = 30,
    stride: int | None = None,
    frames_per_clip: int = 10,
    layout: SkeletonLayout | str = "msr20",
) -> np.ndarray:
    """Non-negative features ``[num_clips, d]`` (float32) of one sequence ``positions [T, J, 3]`` in metres.

    ``d = 2 · frames_per_clip · J · 3``; zeros mark untracked joints. See the module docstring for
    the normalisation, the windows and the sign-split encoding.
    """
    normalised, length = normalise_sequence(positions, layout)
    offsets = clip_frame_offsets(window, frames_per_clip)
    clips = []
    for start, _ in clip_windows(length, window, stride):
        frames = np.minimum(start + offsets, length - 1)  # edge padding
        clip = normalised[frames]  # [f, J, 3]
        clips.append(np.concatenate([np.maximum(clip, 0).ravel(), np.maximum(-clip, 0).ravel()]))
    return np.stack(clips).astype(np.float32)


def sequence_clip_features(
    sequences,
    window: int = 30,
    stride: int | None = None,
    frames_per_clip: int = 10,
    layout: SkeletonLayout | str = "msr20",
    names=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Clip features of many sequences stacked: ``(features [sum num_clips, d], sequence_of_clip [sum num_clips])``.

    ``names`` (optional, one per sequence) only serve error messages, which then name the sequence.
    """
    features, owner = [], []
    for i, positions in enumerate(sequences):
        try:
            f = clip_features(positions, window, stride, frames_per_clip, layout)
        except ValueError as exc:
            label = names[i] if names is not None else f"sequence {i}"
            raise ValueError(f"{label}: {exc}") from exc
        features.append(f)
        owner.append(np.full(len(f), i, dtype=np.int64))
    return np.concatenate(features), np.concatenate(owner)


# ---------------------------------------------------------------------------------------------- torch


class ClipFeatures(torch.nn.Module):
    """Batched, ONNX-exportable clip features: skeletons ``[B, T, J, 3]`` → ``(features [B, N, d], valid [B, N])``.

    ``N = ⌈T / stride⌉`` columns start at ``0, stride, ...``; column ``n`` is a real clip of sample ``b``
    when it fits in the sample's own length (or is the first clip), so zero-padding a batch adds only
    invalid columns and leaves every valid clip unchanged. Same definition as :func:`clip_features`.
    """

    def __init__(
        self,
        layout: SkeletonLayout | str = "msr20",
        window: int = 30,
        stride: int | None = None,
        frames_per_clip: int = 10,
    ):
        super().__init__()
        self.layout = get_layout(layout)
        self.window, self.stride = _check_window(window, stride)
        self.frames_per_clip = int(frames_per_clip)
        self.root, self.pelvis, self.neck = body_joints(self.layout)
        self.register_buffer(
            "offsets", torch.from_numpy(clip_frame_offsets(self.window, self.frames_per_clip)), persistent=False
        )
        self.out_features = feature_dim(self.layout.num_joints, self.frames_per_clip)

    def forward(self, skeletons: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, t, j, c = skeletons.shape
        joint_present = skeletons.abs().sum(-1) > 0  # [B, T, J]
        frame_present = joint_present.any(-1)  # [B, T]
        frame_number = torch.arange(1, t + 1, device=skeletons.device).expand(b, t)
        length = (frame_number * frame_present).amax(1).clamp(min=1)  # [B]; all-zero → 1
        first = torch.argmax(frame_present.to(torch.int64), dim=1)  # first present frame
        origin = skeletons[torch.arange(b, device=skeletons.device), first, self.root]  # [B, 3]
        both = (joint_present[:, :, self.pelvis] & joint_present[:, :, self.neck]).to(skeletons.dtype)
        segment = (skeletons[:, :, self.neck] - skeletons[:, :, self.pelvis]).norm(dim=-1)
        count = both.sum(1)
        scale = torch.where(count > 0, (segment * both).sum(1) / count.clamp(min=1.0), torch.ones_like(count))
        scale = scale.clamp(min=1e-3)
        y = (skeletons - origin[:, None, None]) / scale[:, None, None, None] * joint_present[..., None]

        starts = torch.arange(0, t, self.stride, device=skeletons.device)  # [N]
        frames = starts[:, None] + self.offsets[None]  # [N, f]
        frames = torch.minimum(frames[None], (length - 1)[:, None, None])  # [B, N, f] edge padding
        n = starts.shape[0]
        gathered = torch.gather(
            y.reshape(b, t, j * c), 1, frames.reshape(b, -1, 1).expand(-1, -1, j * c)
        )  # [B, N*f, J*3]
        clips = gathered.reshape(b, n, self.frames_per_clip * j * c)
        features = torch.cat([clips.clamp(min=0), (-clips).clamp(min=0)], dim=-1)
        valid = (starts[None] + self.window <= length[:, None]) | (starts[None] == 0)
        valid = valid & frame_present.any(1, keepdim=True)
        return features * valid[..., None].to(features.dtype), valid


def clip_features_torch(
    skeletons: torch.Tensor,
    layout: SkeletonLayout | str = "msr20",
    window: int = 30,
    stride: int | None = None,
    frames_per_clip: int = 10,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Functional form of :class:`ClipFeatures`: ``[B, T, J, 3]`` → ``(features [B, N, d], valid [B, N] bool)``."""
    module = ClipFeatures(layout, window, stride, frames_per_clip).to(skeletons.device)
    return module(skeletons)
