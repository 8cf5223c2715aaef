"""Learned motion refiners: networks that fill missing joints and denoise observed ones.

Both networks take raw joint positions and the missing mask and return refined positions; the
normalisation and its inverse are part of the network (so they are part of the ONNX graph too):

1. :class:`PoseNormalizer` — per sequence (window): centred on the mean observed root position,
   turned about the up axis so that the mean observed hip line (left → right hip) lies along the
   first horizontal axis, and divided by the body size (observed mean bone lengths against those
   of the training set) times a unit of 10 cm. Only observed entries enter the
   statistics; a missing root, missing hips or unobserved bones fall back to the other joints, no
   turn and the training lengths.
2. :func:`cubic_fill` — every missing entry gets a first guess: a cubic Hermite curve between the
   nearest observed frames before and after it (end tangents from one-sided differences, the gap's own slope
   where the frame beyond an end is missing too), the last observed step continued for a few frames and then
   held at the ends of the window; a joint missing in the whole window starts at the guess
   of its nearest ancestor observed in it (the root at the window's centre). The nearest observed frames come
   from a sort and a cumulative count per joint (``O(T log T)``, no loops, no ``cummax``), so it exports to ONNX
   as a few dozen operators.
3. A temporal network sees ``[first guess, its temporal detail (x_t − mean of the neighbours), observed mask]``
   per frame and predicts a correction of
   every entry (its last layer starts at zero: an untrained refiner *is* the cubic fill). Observed
   entries are corrected too: that is how noise is removed.

Networks (``joints`` J, frames T, batch B):

- :class:`BiGRURefiner`: a bidirectional GRU over frames (the Kucherenko 2018 / Holden 2018 family), its
  input projected and layer-normalised per frame.
- :class:`MaskedTransformerRefiner`: a masked-autoencoder transformer: missing coordinates are replaced by
  a learned mask token, each token is either a frame (joints as features, attention over frames) or a
  joint in a frame (factorised attention: over the joints of a frame, then over the frames of a joint);
  sinusoidal frame positions.

Input ``positions`` float ``[B, T, J, 3]`` in the training data's units (metres for everything
``read_motion`` returns), ``missing`` bool ``[B, T, J]`` (True = not observed; those positions are
ignored, NaN allowed); output float ``[B, T, J, 3]`` in the same units.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

AXES = {"x": 0, "y": 1, "z": 2}


def _masked_mean(values: torch.Tensor, weights: torch.Tensor, dims: tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor]:
    """``(Σ w·v / Σ w, Σ w)`` over ``dims`` (0 where ``Σ w = 0``); ``weights`` broadcast against ``values``."""
    total = (weights * values).sum(dims, keepdim=True)
    count = weights.sum(dims, keepdim=True)
    return total / count.clamp_min(1e-6), count


def coordinate_mask(observed: torch.Tensor) -> torch.Tensor:
    """``observed [B, T, J]`` as a mask of the coordinates' shape ``[B, T, J, 3]``, built by concatenation: a
    ``torch.where`` whose condition broadcasts over the trailing axis of 3 runs several times slower in
    onnxruntime (bench/RESULTS.md §13)."""
    seen = observed.unsqueeze(-1)
    return torch.cat([seen, seen, seen], dim=-1)


class PoseNormalizer(nn.Module):
    """Per-window normalisation of joint positions (see the module docstring) and its inverse.

    Args:
        parents: parent index of every joint (``-1`` for the root).
        up_axis: ``"x"``, ``"y"`` or ``"z"``.
        hips: ``(left, right)`` hip joint indices for the heading, or None (no turn).
        bone_lengths: mean length of every bone ``(j, parents[j])`` in the training data (``[J]``, 0 for the
            root), in the data's units; None: ones.
        unit: the normalised unit for a body of the training set's size, in the data's units (0.1: 10 cm, so that
            noise of a few centimetres and whole-body extents are both of order 1 for the network).
    """

    def __init__(self, parents: Sequence[int], up_axis: str = "y", hips: Sequence[int] | None = None,
                 bone_lengths: Sequence[float] | None = None, unit: float = 0.1):
        super().__init__()
        self.unit = float(unit)
        parents = [int(p) for p in parents]
        self.root = parents.index(-1)
        self.child = [j for j, p in enumerate(parents) if p >= 0]
        self.parent = [parents[j] for j in self.child]
        self.up = AXES[up_axis]
        self.horizontal = [a for a in range(3) if a != self.up]
        self.hips = None if hips is None else (int(hips[0]), int(hips[1]))
        lengths = torch.ones(len(parents)) if bone_lengths is None else torch.as_tensor(bone_lengths, dtype=torch.float32)
        self.register_buffer("bone_lengths", lengths[self.child].clone())       # [bones]

    def statistics(self, positions: torch.Tensor, observed: torch.Tensor):
        """``(centre [B,1,1,3], cos [B,1,1], sin [B,1,1], scale [B,1,1,1])`` of each window."""
        w = coordinate_mask(observed).to(positions.dtype)                           # [B,T,J,3]
        root_w = w[:, :, self.root:self.root + 1]
        root_mean, root_count = _masked_mean(positions[:, :, self.root:self.root + 1], root_w, (1, 2))
        all_mean, _ = _masked_mean(positions, w, (1, 2))
        centre = torch.where(root_count > 0, root_mean, all_mean)                   # [B,1,1,3]
        h1, h2 = self.horizontal
        if self.hips is None:
            cos = torch.ones_like(centre[..., 0])
            sin = torch.zeros_like(centre[..., 0])
        else:
            left, right = self.hips
            both = (w[:, :, left] * w[:, :, right])                                 # [B,T,1]
            line, _ = _masked_mean(positions[:, :, right] - positions[:, :, left], both, (1,))   # [B,1,3]
            a, b = line[..., h1], line[..., h2]
            norm = torch.sqrt(a * a + b * b)
            ok = norm > 1e-6
            cos = torch.where(ok, a / norm.clamp_min(1e-6), 1.0).unsqueeze(-1)   # [B,1,1]
            sin = torch.where(ok, b / norm.clamp_min(1e-6), 0.0).unsqueeze(-1)
        bone_w = w[:, :, self.child, 0] * w[:, :, self.parent, 0]                   # [B,T,bones]
        length = torch.linalg.vector_norm(positions[:, :, self.child] - positions[:, :, self.parent], dim=-1)
        length = torch.where(bone_w > 0, length, 0.0)
        mean_len, count = _masked_mean(length, bone_w, (1,))                        # [B,1,bones]
        seen = (count > 0).to(positions.dtype)
        ratio = (mean_len * seen).sum(-1) / (self.bone_lengths * seen).sum(-1).clamp_min(1e-6)   # [B,1]
        ratio = torch.where(seen.sum(-1) > 0, ratio, 1.0)
        scale = (ratio * self.unit).reshape(-1, 1, 1, 1)
        return centre, cos, sin, scale

    def _turn(self, coords: list[torch.Tensor], cos: torch.Tensor, sin: torch.Tensor) -> list[torch.Tensor]:
        """The three ``[B, T, J]`` coordinates turned about the up axis by the per-window ``cos``, ``sin``."""
        h1, h2 = self.horizontal
        a, b = coords[h1], coords[h2]
        turned = {h1: cos * a + sin * b, h2: -sin * a + cos * b, self.up: coords[self.up]}
        return [turned[0], turned[1], turned[2]]

    # both directions work on one coordinate at a time: the per-window centre and scale then broadcast over
    # frames and joints, which onnxruntime does several times faster than over a trailing axis of 3
    def forward(self, positions: torch.Tensor, stats) -> torch.Tensor:
        centre, cos, sin, scale = stats
        coords = [positions[..., k] - centre[..., k] for k in range(3)]
        return torch.stack([c / scale[..., 0] for c in self._turn(coords, cos, sin)], dim=-1)

    def inverse(self, normalised: torch.Tensor, stats) -> torch.Tensor:
        centre, cos, sin, scale = stats
        turned = self._turn([normalised[..., k] * scale[..., 0] for k in range(3)], cos, -sin)
        return torch.stack([c + centre[..., k] for k, c in enumerate(turned)], dim=-1)


def observed_neighbours(observed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(prev, next)``, int64 ``[B, 1, T, J]``: for every frame, the nearest observed frame at or before it (−1
    when none) and strictly after it (``T`` when none), per joint, of ``observed`` bool ``[B, T, J]``.

    From a sort and a cumulative count (``O(T log T)``, no loops, no ``cummax``), so that it exports to ONNX: the
    k-th observed frame of a joint is ``order[k]``, and the frames observed up to ``t`` count ``seen[t]``.
    """
    T = observed.shape[1]
    frames = torch.arange(T, device=observed.device).view(1, 1, T, 1)
    seen_here = observed.unsqueeze(1)                                        # [B,1,T,J]
    counted = seen_here.to(torch.int64)
    order = torch.argsort(torch.where(seen_here, frames, frames + T), dim=2)  # observed frames first, in time order
    seen = torch.cumsum(counted, dim=2)                                      # observed frames ≤ t
    before_t = seen - counted                                                # observed frames < t
    ranked = torch.gather(order, 2, torch.cat([seen - 1, before_t], dim=2).clamp(0, T - 1))
    prev = torch.where(seen > 0, ranked[:, :, :T], -1)
    nxt = torch.where(before_t < seen[:, :, -1:], ranked[:, :, T:], T)
    return prev, nxt


#: How :func:`cubic_fill` sets a gap end's tangent when the frame beyond that end is not observed either.
TANGENT_RULES = ("chord", "zero")


def cubic_fill(x: torch.Tensor, observed: torch.Tensor, tangents: str = "chord", extrapolate: int = 6) -> torch.Tensor:
    """First guess of every missing entry: cubic Hermite between the nearest observed frames.

    Args:
        x: ``[B, T, J, 3]`` (missing entries may hold anything finite).
        observed: bool ``[B, T, J]``.
        tangents: the tangent at a gap end whose outer neighbour frame is not observed: ``"chord"``, the gap's
            own slope (p1 − p0) / span (with both ends so, the fill is linear), or ``"zero"`` (the first
            networks' rule: it bends the curve by a quarter of a frame's motion on one-frame gaps next to other
            gaps, bench/RESULTS.md §13).
        extrapolate: before the first / after the last observation, the nearest observed value moved on by the
            observed frame step there for at most this many frames, then held (0: held from the start; a joint
            lost at the end of a take otherwise freezes mid-motion).

    Returns:
        ``[B, T, J, 3]``: ``x`` where observed; inside a gap the cubic Hermite curve through the gap's end
        values with one-sided difference tangents (``tangents`` where the frame beyond an end is not observed);
        before the first / after the last observation as ``extrapolate`` says; 0 for a joint never observed.

    Computed coordinate-first (``[B, 3, T, J]``, masks ``[B, 1, T, J]``) and with the four neighbour frames of
    every entry read by one gather: an exported graph pays per operator, and onnxruntime broadcasts a mask over a
    leading axis several times faster than over a trailing axis of 3 (bench/RESULTS.md §13).
    """
    T = x.shape[1]
    x = x.permute(0, 3, 1, 2)                                                # [B,3,T,J]
    frames = torch.arange(T, device=x.device).view(1, 1, T, 1)
    seen_here = observed.unsqueeze(1)                                        # [B,1,T,J]
    prev, nxt = observed_neighbours(observed)
    has_prev, has_next = prev >= 0, nxt < T
    prev_c, next_c = prev.clamp(0, T - 1), nxt.clamp(0, T - 1)
    before_prev, after_next = (prev_c - 1).clamp(0, T - 1), (next_c + 1).clamp(0, T - 1)
    index = torch.cat([prev_c, next_c, before_prev, after_next], dim=2)      # [B,1,4T,J]
    ends = torch.gather(x, 2, index.expand(-1, 3, -1, -1))                   # [B,3,4T,J]
    p0, p1, q0, q1 = ends[:, :, :T], ends[:, :, T:2 * T], ends[:, :, 2 * T:3 * T], ends[:, :, 3 * T:]
    beyond = torch.gather(seen_here, 2, index[:, :, 2 * T:])                 # [B,1,2T,J]
    span = (nxt - prev).clamp_min(1).to(x.dtype)                             # [B,1,T,J]
    known0, known1 = beyond[:, :, :T] & (prev_c > 0), beyond[:, :, T:] & (next_c < T - 1)
    step0, step1 = torch.where(known0, p0 - q0, 0.0), torch.where(known1, q1 - p1, 0.0)   # observed frame steps
    unknown = (p1 - p0) / span if tangents == "chord" else 0.0               # a tangent whose neighbour is missing
    m0, m1 = torch.where(known0, step0, unknown), torch.where(known1, step1, unknown)
    u = ((frames - prev).to(x.dtype) / span).clamp(0, 1)
    u2, u3 = u * u, u * u * u
    hermite = ((2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * span * m0
               + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * span * m1)
    after = p0 + step0 * (frames - prev).clamp(max=extrapolate).to(x.dtype)   # past the last observation
    before = p1 - step1 * (nxt - frames).clamp(max=extrapolate).to(x.dtype)   # before the first
    held = torch.where(has_prev, after, before)
    fill = torch.where(has_prev & has_next, hermite, held)
    fill = torch.where(has_prev | has_next, fill, 0.0)
    return torch.where(seen_here, x, fill).permute(0, 2, 3, 1)


#: Scale of the guess and of its temporal detail in the networks' input features (:meth:`_Refiner.features`).
FEATURE_SCALE = (0.1, 5.0)


def temporal_detail(x: torch.Tensor) -> torch.Tensor:
    """``x_t − (x_{t−1} + x_{t+1}) / 2`` along frames (dim 1; the end frames use their one neighbour): what a
    noisy sample or a spike stands out by, handed to the networks so that denoising is an easy function to learn."""
    prev = torch.cat([x[:, :1], x[:, :-1]], dim=1)
    nxt = torch.cat([x[:, 1:], x[:, -1:]], dim=1)
    return x - 0.5 * (prev + nxt)


class _Refiner(nn.Module):
    """Shared input and output handling: normalise, first guess, correct, denormalise (module docstring)."""

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], up_axis: str = "y",
                 hips: Sequence[int] | None = None, bone_lengths: Sequence[float] | None = None,
                 fps: float | None = None, tangents: str = "chord", extrapolate: int = 6):
        super().__init__()
        self.set_first_guess(tangents, extrapolate)
        self.joint_names = tuple(joint_names)
        self.parents = tuple(int(p) for p in parents)
        self.up_axis, self.fps = up_axis, None if fps is None else float(fps)
        if len(self.joint_names) != len(self.parents):
            raise ValueError(f"{len(self.joint_names)} joint names but {len(self.parents)} parents")
        self.num_joints = len(self.joint_names)
        self.normalizer = PoseNormalizer(self.parents, up_axis, hips, bone_lengths)
        depth = [0] * self.num_joints
        for j in range(self.num_joints):                      # depth of every joint (parents may come later)
            p, seen = self.parents[j], 0
            while p >= 0 and seen <= self.num_joints:
                depth[j], p, seen = depth[j] + 1, self.parents[p], seen + 1
        #: pointer-jumping rounds that reach a joint's farthest ancestor (2 ** rounds ≥ the tree's depth)
        self.ancestor_rounds = max(1, math.ceil(math.log2(max(depth) + 1)))
        parent_or_self = [p if p >= 0 else j for j, p in enumerate(self.parents)]
        self.register_buffer("parent_or_self", torch.tensor(parent_or_self, dtype=torch.int64), persistent=False)

    def set_first_guess(self, tangents: str = "chord", extrapolate: int = 6) -> None:
        """The first guess's rules (:func:`cubic_fill`); an inference-time setting, no weight depends on it."""
        if tangents not in TANGENT_RULES:
            raise ValueError(f"tangents must be one of {TANGENT_RULES}, got {tangents!r}")
        if isinstance(extrapolate, bool) or not isinstance(extrapolate, int) or extrapolate < 0:
            raise ValueError(f"extrapolate must be a frame count ≥ 0, got {extrapolate!r}")
        self.tangents, self.extrapolate = tangents, extrapolate

    def first_guess(self, x: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        """:func:`cubic_fill`, then a joint never observed in the window takes the guess of its nearest ancestor
        that is observed in it (the root's when none is), found by pointer jumping: each joint's pointer moves to
        its parent where the joint is never observed, and ``ancestor_rounds`` compositions of the pointers reach
        the nearest observed ancestor — a few gathers instead of a loop over the joints (a graph of ``J`` small
        operators once exported)."""
        guess = cubic_fill(x, observed, self.tangents, self.extrapolate)
        B, T, J, _ = guess.shape
        never = ~observed.any(dim=1, keepdim=True)                                   # [B,1,J]
        own = torch.arange(J, device=guess.device).view(1, 1, J)
        source = torch.where(never, self.parent_or_self.view(1, 1, J), own)           # [B,1,J]
        for _ in range(self.ancestor_rounds):
            source = torch.gather(source, 2, source)
        return torch.gather(guess, 2, source.unsqueeze(-1).expand(B, T, J, 3))

    def correction(self, guess: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        """``[B, T, J, 3]`` correction of the normalised first guess (subclasses)."""
        raise NotImplementedError

    @staticmethod
    def features(guess: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        """Per joint ``[B, T, J, 7]``: the guess scaled to metres-like values (×0.1: a body spans about ±1), its
        temporal detail ×5 (2 cm of noise ≈ 1) and the observed flag; inputs of order 1 keep the GRU's gates and
        the attention out of saturation."""
        return torch.cat([FEATURE_SCALE[0] * guess, FEATURE_SCALE[1] * temporal_detail(guess),
                          observed.unsqueeze(-1).to(guess.dtype)], dim=-1)

    def forward(self, positions: torch.Tensor, missing: torch.Tensor) -> torch.Tensor:
        refined, stats = self.normalised_forward(positions, missing)
        return self.normalizer.inverse(refined, stats)

    def normalised_forward(self, positions: torch.Tensor, missing: torch.Tensor):
        """``(refined, stats)`` with ``refined`` still normalised: what the training loss compares."""
        observed = ~missing.bool()
        seen = coordinate_mask(observed)
        clean = torch.where(seen, positions, 0.0)
        stats = self.normalizer.statistics(clean, observed)
        x = torch.where(seen, self.normalizer(clean, stats), 0.0)
        guess = self.first_guess(x, observed)
        return guess + self.correction(guess, observed), stats


class BiGRURefiner(_Refiner):
    """Bidirectional GRU over frames; see the module docstring.

    Args:
        joint_names, parents, up_axis, hips, bone_lengths, fps: the layout and training statistics
            (the data module supplies them; :class:`PoseNormalizer`).
        hidden: GRU units per direction. layers: stacked GRU layers. dropout: between layers.
        tangents, extrapolate: the first guess's rules for a gap end whose outer neighbour is missing and for the
            frames before the first / after the last observation (:func:`cubic_fill`). ``tangents="zero",
            extrapolate=0`` is the first guess of the runs trained before these options (their configs lack the
            keys: restore them with ``LearnedRefiner(first_guess={"tangents": "zero", "extrapolate": 0})``).
    """

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], up_axis: str = "y",
                 hips: Sequence[int] | None = None, bone_lengths: Sequence[float] | None = None,
                 fps: float | None = None, hidden: int = 128, layers: int = 2, dropout: float = 0.1,
                 tangents: str = "chord", extrapolate: int = 6):
        super().__init__(joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate)
        J = self.num_joints
        # LayerNorm before the GRU: without it the GRU's output collapsed to ~0 within an epoch in some runs
        # (mean |h| 2e-5 on validation windows, the correction constant from then on: bench/RESULTS.md §13)
        self.inp = nn.Sequential(nn.Linear(7 * J, hidden), nn.LayerNorm(hidden), nn.GELU())
        self.gru = nn.GRU(hidden, hidden, num_layers=layers, batch_first=True, bidirectional=True,
                          dropout=dropout if layers > 1 else 0.0)
        self.out = nn.Linear(2 * hidden, 3 * J)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def correction(self, guess: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        B, T, J, _ = guess.shape
        hidden, _ = self.gru(self.inp(self.features(guess, observed).reshape(B, T, 7 * J)))
        return self.out(hidden).reshape(B, T, J, 3)


def _sinusoid(T: int, dim: int, device, dtype) -> torch.Tensor:
    position = torch.arange(T, device=device, dtype=dtype).unsqueeze(1)
    freq = torch.exp(torch.arange(0, dim, 2, device=device, dtype=dtype) * (-math.log(10000.0) / dim))
    angles = position * freq                                                    # [T, dim/2]
    return torch.stack([torch.sin(angles), torch.cos(angles)], dim=-1).reshape(T, dim)


class MaskedTransformerRefiner(_Refiner):
    """Masked-autoencoder transformer; see the module docstring.

    Args:
        joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate: as :class:`BiGRURefiner`.
        tokens: ``"frames"`` (a token per frame, joints as features) or ``"joints"`` (a token per joint and
            frame, attention over the joints of a frame and then over the frames of a joint in every layer).
        dim: token width. layers: encoder layers (``"joints"``: pairs of joint / frame layers). heads: attention
            heads. ff: feed-forward width. dropout: in the encoder layers.
    """

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], up_axis: str = "y",
                 hips: Sequence[int] | None = None, bone_lengths: Sequence[float] | None = None,
                 fps: float | None = None, tokens: str = "frames", dim: int = 128, layers: int = 3, heads: int = 4,
                 ff: int = 256, dropout: float = 0.1, tangents: str = "chord", extrapolate: int = 6):
        super().__init__(joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate)
        if tokens not in ("frames", "joints"):
            raise ValueError(f"tokens must be 'frames' or 'joints', got {tokens!r}")
        J = self.num_joints
        self.tokens, self.dim = tokens, dim
        self.mask_token = nn.Parameter(torch.zeros(J, 3))                      # replaces missing coordinates
        layer = lambda: nn.TransformerEncoderLayer(dim, heads, ff, dropout, activation="gelu", batch_first=True,
                                                   norm_first=True)
        if tokens == "frames":
            self.embed = nn.Linear(10 * J, dim)
            self.blocks = nn.ModuleList(layer() for _ in range(layers))
            self.out = nn.Linear(dim, 3 * J)
        else:
            self.embed = nn.Linear(10, dim)
            self.joint_embedding = nn.Parameter(torch.zeros(J, dim))
            nn.init.normal_(self.joint_embedding, std=0.02)
            self.blocks = nn.ModuleList(layer() for _ in range(2 * layers))    # joint, frame, joint, frame, ...
            self.out = nn.Linear(dim, 3)
        self.norm = nn.LayerNorm(dim)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def correction(self, guess: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        B, T, J, _ = guess.shape
        mask_token = self.mask_token.to(guess.dtype).expand(B, T, J, 3)
        tokenised = torch.where(coordinate_mask(observed), FEATURE_SCALE[0] * guess, mask_token)
        per_joint = torch.cat([tokenised, self.features(guess, observed)], dim=-1)                     # [B,T,J,10]
        pos = _sinusoid(T, self.dim, guess.device, guess.dtype)                      # [T, dim]
        if self.tokens == "frames":
            h = self.embed(per_joint.reshape(B, T, 10 * J)) + pos
            for block in self.blocks:
                h = block(h)
            return self.out(self.norm(h)).reshape(B, T, J, 3)
        h = self.embed(per_joint) + self.joint_embedding + pos.unsqueeze(1)         # [B,T,J,dim]
        for i, block in enumerate(self.blocks):
            if i % 2 == 0:                                                           # over the joints of a frame
                h = block(h.reshape(B * T, J, self.dim)).reshape(B, T, J, self.dim)
            else:                                                                    # over the frames of a joint
                h = block(h.permute(0, 2, 1, 3).reshape(B * J, T, self.dim))
                h = h.reshape(B, J, T, self.dim).permute(0, 2, 1, 3)
        return self.out(self.norm(h))


def refine_bigru(**kwargs) -> BiGRURefiner:
    """The bidirectional GRU refiner (see :class:`BiGRURefiner` for the arguments)."""
    return BiGRURefiner(**kwargs)


def refine_transformer(**kwargs) -> MaskedTransformerRefiner:
    """The masked-autoencoder transformer refiner (see :class:`MaskedTransformerRefiner`)."""
    return MaskedTransformerRefiner(**kwargs)


__all__ = ["BiGRURefiner", "MaskedTransformerRefiner", "PoseNormalizer", "cubic_fill", "refine_bigru",
           "refine_transformer"]
