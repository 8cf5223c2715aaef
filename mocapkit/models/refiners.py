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
   entries are corrected too: that is how noise is removed. With ``pose_frame`` it also sees every frame's
   guess in that frame's own body frame (root-centred, hip line turned onto the first horizontal axis) and
   predicts the correction there, turned back per frame (:meth:`_Refiner.corrected`).

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

from mocapkit.models.body_frame import heading_cos_sin, turn_about_up
from mocapkit.models.gru import gru_forward
from mocapkit.models.ops import dropout
from mocapkit.motion.geometry import horizontal_axes


def _masked_mean(
    values: torch.Tensor, weights: torch.Tensor, dims: tuple[int, ...]
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(Σ w·v / Σ w, Σ w)`` over ``dims`` (0 where ``Σ w = 0``); ``weights`` broadcast against ``values``."""
    total = (weights * values).sum(dims, keepdim=True)
    count = weights.sum(dims, keepdim=True)
    return total / count.clamp_min(1e-6), count


def coordinate_mask(observed: torch.Tensor) -> torch.Tensor:
    """``observed [B, T, J]`` as a mask of the coordinates' shape ``[B, T, J, 3]``, built by concatenation: a
    ``torch.where`` whose condition broadcasts over the trailing axis of 3, or an expand to it, runs several times
    slower in onnxruntime (bench/RESULTS.md#onnx-runtime-costs)."""
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

    ``statistics``, ``forward`` and ``inverse`` take positions ``[B, T, J, 3]``; the ``*_cf`` methods they wrap
    work **coordinate-first**, ``[B, 3, T, J]`` with masks ``[B, 1, T, J]``, which is how the refiners call them:
    in that layout a coordinate is a contiguous block and masks broadcast over a leading axis, where the
    ``[..., 3]`` layout makes onnxruntime gather, slice and broadcast over a trailing axis of 3, several times
    slower (bench/RESULTS.md#onnx-runtime-costs). The statistics are ``(centre [B,3,1,1], cos [B,1,1,1], sin [B,1,1,1],
    scale [B,1,1,1])``, the same in both.
    """

    def __init__(
        self,
        parents: Sequence[int],
        up_axis: str = "y",
        hips: Sequence[int] | None = None,
        bone_lengths: Sequence[float] | None = None,
        unit: float = 0.1,
    ):
        super().__init__()
        self.unit = float(unit)
        parents = [int(p) for p in parents]
        self.root = parents.index(-1)
        self.child = [j for j, p in enumerate(parents) if p >= 0]
        self.parent = [parents[j] for j in self.child]
        self.up_axis = up_axis
        self.horizontal = list(horizontal_axes(up_axis))
        self.hips = None if hips is None else (int(hips[0]), int(hips[1]))
        lengths = (
            torch.ones(len(parents)) if bone_lengths is None else torch.as_tensor(bone_lengths, dtype=torch.float32)
        )
        self.register_buffer("bone_lengths", lengths[self.child].clone())  # [bones]
        # bones as products with [J, bones] matrices: +1 at the child, −1 at the parent (the bone vector, exact: one
        # subtraction), and 1 at both (observed ends: 2 where the bone is seen) — one small matrix product each
        # instead of gathers over the joint axis
        ends = torch.zeros(len(parents), len(self.child))
        ends[self.child, range(len(self.child))] = 1.0
        vector = ends.clone()
        vector[self.parent, range(len(self.child))] = -1.0
        ends[self.parent, range(len(self.child))] = 1.0
        self.register_buffer("bone_vector", vector, persistent=False)
        self.register_buffer("bone_ends", ends, persistent=False)

    def statistics(self, positions: torch.Tensor, observed: torch.Tensor):
        """The statistics of each window of ``positions [B, T, J, 3]`` (observed entries only)."""
        return self.statistics_cf(positions.permute(0, 3, 1, 2), observed.unsqueeze(1))

    def forward(self, positions: torch.Tensor, stats) -> torch.Tensor:
        return self.forward_cf(positions.permute(0, 3, 1, 2), stats).permute(0, 2, 3, 1)

    def inverse(self, normalised: torch.Tensor, stats) -> torch.Tensor:
        return self.inverse_cf(normalised.permute(0, 3, 1, 2), stats).permute(0, 2, 3, 1)

    def statistics_cf(self, coords: torch.Tensor, seen: torch.Tensor):
        """``(centre [B,3,1,1], cos [B,1,1,1], sin [B,1,1,1], scale [B,1,1,1])`` of each window of ``coords``
        ``[B, 3, T, J]``, from the entries where ``seen`` (bool ``[B, 1, T, J]``)."""
        w = seen.to(coords.dtype)  # [B,1,T,J]
        r = self.root
        root_mean, root_count = _masked_mean(coords[..., r : r + 1], w[..., r : r + 1], (2, 3))
        all_mean, _ = _masked_mean(coords, w, (2, 3))
        centre = torch.where(root_count > 0, root_mean, all_mean)  # [B,3,1,1]
        h1, h2 = self.horizontal
        if self.hips is None:
            cos = torch.ones_like(centre[:, :1])
            sin = torch.zeros_like(centre[:, :1])
        else:
            left, right = self.hips
            both = w[..., left] * w[..., right]  # [B,1,T]
            line, _ = _masked_mean(coords[..., right] - coords[..., left], both, (2,))  # [B,3,1]
            cos, sin = heading_cos_sin(line[:, h1 : h1 + 1], line[:, h2 : h2 + 1])  # [B,1,1]
            cos, sin = cos.unsqueeze(-1), sin.unsqueeze(-1)  # [B,1,1,1]
        vectors = torch.matmul(coords, self.bone_vector)  # [B,3,T,bones]
        length = torch.sqrt((vectors * vectors).sum(1))  # [B,T,bones]
        bone_w = (torch.matmul(w[:, 0], self.bone_ends) > 1.5).to(coords.dtype)  # both ends seen
        length = torch.where(bone_w > 0, length, 0.0)
        mean_len, count = _masked_mean(length, bone_w, (1,))  # [B,1,bones]
        known = (count > 0).to(coords.dtype)
        ratio = (mean_len * known).sum(-1) / (self.bone_lengths * known).sum(-1).clamp_min(1e-6)  # [B,1]
        ratio = torch.where(known.sum(-1) > 0, ratio, 1.0)
        scale = (ratio * self.unit).reshape(-1, 1, 1, 1)
        return centre, cos, sin, scale

    def turn_cf(self, coords: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
        """``coords [B, 3, T, J]`` turned about the up axis by ``cos``, ``sin`` (``[B, 1, 1 | T, 1]``); the inverse
        turn is ``(cos, −sin)``."""
        return torch.cat(turn_about_up(coords.split(1, dim=1), cos, sin, self.up_axis), dim=1)

    def forward_cf(self, coords: torch.Tensor, stats) -> torch.Tensor:
        """``coords [B, 3, T, J]`` normalised with ``stats`` (centred, turned, scaled)."""
        centre, cos, sin, scale = stats
        return self.turn_cf(coords - centre, cos, sin) / scale

    def inverse_cf(self, normalised: torch.Tensor, stats) -> torch.Tensor:
        """The inverse of :meth:`forward_cf`."""
        centre, cos, sin, scale = stats
        return self.turn_cf(normalised * scale, cos, -sin) + centre


def observed_neighbours(observed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(prev, next)``, int64 ``[B, 1, T, J]``: for every frame, the nearest observed frame at or before it (−1
    when none) and strictly after it (``T`` when none), per joint, of ``observed`` bool ``[B, T, J]``.

    From a sort and a cumulative count (``O(T log T)``, no loops, no ``cummax``), so that it exports to ONNX: the
    k-th observed frame of a joint is ``order[k]``, and the frames observed up to ``t`` count ``seen[t]``.
    """
    T = observed.shape[1]
    frames = torch.arange(T, device=observed.device).view(1, 1, T, 1)
    seen_here = observed.unsqueeze(1)  # [B,1,T,J]
    counted = seen_here.to(torch.int64)
    order = torch.argsort(torch.where(seen_here, frames, frames + T), dim=2)  # observed frames first, in time order
    seen = torch.cumsum(counted, dim=2)  # observed frames ≤ t
    before_t = seen - counted  # observed frames < t
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
            gaps, docs/decisions.md#refiner-first-guess).
        extrapolate: before the first / after the last observation, the nearest observed value moved on by the
            observed frame step there for at most this many frames, then held (0: held from the start; a joint
            lost at the end of a take otherwise freezes mid-motion).

    Returns:
        ``[B, T, J, 3]``: ``x`` where observed; inside a gap the cubic Hermite curve through the gap's end
        values with one-sided difference tangents (``tangents`` where the frame beyond an end is not observed);
        before the first / after the last observation as ``extrapolate`` says; 0 for a joint never observed.

    The work is done coordinate-first by :func:`cubic_fill_cf`.
    """
    return cubic_fill_cf(x.permute(0, 3, 1, 2), observed, tangents, extrapolate).permute(0, 2, 3, 1)


def cubic_fill_cf(
    x: torch.Tensor, observed: torch.Tensor, tangents: str = "chord", extrapolate: int = 6
) -> torch.Tensor:
    """:func:`cubic_fill` of coordinate-first ``x`` ``[B, 3, T, J]`` (``observed`` bool ``[B, T, J]``) →
    ``[B, 3, T, J]``. Masks are ``[B, 1, T, J]`` and the four neighbour frames of every entry come from one
    gather per coordinate: an exported graph pays per operator, and onnxruntime broadcasts a mask over a leading
    axis several times faster than over a trailing axis of 3 (bench/RESULTS.md#onnx-runtime-costs).
    """
    T = x.shape[2]
    frames = torch.arange(T, device=x.device).view(1, 1, T, 1)
    seen_here = observed.unsqueeze(1)  # [B,1,T,J]
    prev, nxt = observed_neighbours(observed)
    has_prev, has_next = prev >= 0, nxt < T
    prev_c, next_c = prev.clamp(0, T - 1), nxt.clamp(0, T - 1)
    before_prev, after_next = (prev_c - 1).clamp(0, T - 1), (next_c + 1).clamp(0, T - 1)
    index = torch.cat([prev_c, next_c, before_prev, after_next], dim=2)  # [B,1,4T,J]
    # one gather per coordinate: expanding the int64 index to the three coordinates costs more than the gathers
    ends = torch.cat([torch.gather(c, 2, index) for c in x.split(1, dim=1)], dim=1)  # [B,3,4T,J]
    p0, p1, q0, q1 = ends[:, :, :T], ends[:, :, T : 2 * T], ends[:, :, 2 * T : 3 * T], ends[:, :, 3 * T :]
    beyond = torch.gather(seen_here, 2, index[:, :, 2 * T :])  # [B,1,2T,J]
    span = (nxt - prev).clamp_min(1).to(x.dtype)  # [B,1,T,J]
    # the choices below are products with 0/1 masks (m·a + (1 − m)·b, exact for the finite values here) rather than
    # torch.where: onnxruntime's Where costs about four of its Mul (bench/RESULTS.md#onnx-runtime-costs)
    known0 = (beyond[:, :, :T] & (prev_c > 0)).to(x.dtype)
    known1 = (beyond[:, :, T:] & (next_c < T - 1)).to(x.dtype)
    step0, step1 = known0 * (p0 - q0), known1 * (q1 - p1)  # observed frame steps (0: unknown)
    if tangents == "chord":  # a tangent whose neighbour is missing
        unknown = (p1 - p0) / span
        m0, m1 = step0 + (1 - known0) * unknown, step1 + (1 - known1) * unknown
    else:
        m0, m1 = step0, step1
    u = ((frames - prev).to(x.dtype) / span).clamp(0, 1)
    u2, u3 = u * u, u * u * u
    hermite = (
        (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * span * m0 + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * span * m1
    )
    after = p0 + step0 * (frames - prev).clamp(max=extrapolate).to(x.dtype)  # past the last observation
    before = p1 - step1 * (nxt - frames).clamp(max=extrapolate).to(x.dtype)  # before the first
    before_ok, after_ok = has_prev.to(x.dtype), has_next.to(x.dtype)
    inside = before_ok * after_ok
    held = before_ok * after + (1 - before_ok) * before
    fill = inside * hermite + (1 - inside) * held
    seen = seen_here.to(x.dtype)
    return seen * x + (1 - seen) * (fill * (1 - (1 - before_ok) * (1 - after_ok)))  # 0 for a joint never seen


#: Scale of the guess and of its temporal detail in the networks' input features (:meth:`_Refiner.features`).
FEATURE_SCALE = (0.1, 5.0)


def temporal_detail(x: torch.Tensor, dim: int = 1) -> torch.Tensor:
    """``x_t − (x_{t−1} + x_{t+1}) / 2`` along frames (axis ``dim``; the end frames use their one neighbour): what a
    noisy sample or a spike stands out by, handed to the networks so that denoising is an easy function to learn."""
    T = x.shape[dim]
    prev = torch.cat([x.narrow(dim, 0, 1), x.narrow(dim, 0, T - 1)], dim=dim)
    nxt = torch.cat([x.narrow(dim, 1, T - 1), x.narrow(dim, T - 1, 1)], dim=dim)
    return x - 0.5 * (prev + nxt)


class _Refiner(nn.Module):
    """Shared input and output handling: normalise, first guess, correct, denormalise (module docstring)."""

    def __init__(
        self,
        joint_names: Sequence[str],
        parents: Sequence[int],
        up_axis: str = "y",
        hips: Sequence[int] | None = None,
        bone_lengths: Sequence[float] | None = None,
        fps: float | None = None,
        tangents: str = "chord",
        extrapolate: int = 6,
        pose_frame: bool = False,
    ):
        super().__init__()
        self.set_first_guess(tangents, extrapolate)
        self.pose_frame = bool(pose_frame)
        self.joint_names = tuple(joint_names)
        self.parents = tuple(int(p) for p in parents)
        self.up_axis, self.fps = up_axis, None if fps is None else float(fps)
        if len(self.joint_names) != len(self.parents):
            raise ValueError(f"{len(self.joint_names)} joint names but {len(self.parents)} parents")
        self.num_joints = len(self.joint_names)
        self.normalizer = PoseNormalizer(self.parents, up_axis, hips, bone_lengths)
        depth = [0] * self.num_joints
        for j in range(self.num_joints):  # depth of every joint (parents may come later)
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
        """:meth:`first_guess_cf` of ``x [B, T, J, 3]`` → ``[B, T, J, 3]``."""
        return self.first_guess_cf(x.permute(0, 3, 1, 2), observed).permute(0, 2, 3, 1)

    def first_guess_cf(self, x: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        """:func:`cubic_fill_cf` of ``x [B, 3, T, J]``, then a joint never observed in the window takes the guess of
        its nearest ancestor that is observed in it (the root's when none is), found by pointer jumping: each joint's
        pointer moves to its parent where the joint is never observed, and ``ancestor_rounds`` compositions of the
        pointers reach the nearest observed ancestor — a few gathers instead of a loop over the joints (a graph of
        ``J`` small operators once exported)."""
        guess = cubic_fill_cf(x, observed, self.tangents, self.extrapolate)  # [B,3,T,J]
        J = guess.shape[3]
        never = ~observed.any(dim=1, keepdim=True)  # [B,1,J]
        own = torch.arange(J, device=guess.device).view(1, 1, J)
        source = torch.where(never, self.parent_or_self.view(1, 1, J), own)  # [B,1,J]
        for _ in range(self.ancestor_rounds):
            source = torch.gather(source, 2, source)
        # joint j takes the guess of joint source[j]: a product with the 0/1 matrix [i == source[j]] (exact: one
        # term of each sum is 1·guess, the others 0) runs as one small matrix product where a gather over the
        # coordinates' layout cost ~0.1 ms in onnxruntime (bench/RESULTS.md#onnx-runtime-costs)
        pick = (source.view(-1, J, 1) == own.view(1, 1, J)).to(guess.dtype)  # [B,J(to),J(from)]
        return torch.matmul(guess, pick.transpose(1, 2).unsqueeze(1))

    def correction(self, guess: torch.Tensor, observed: torch.Tensor, body: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, 3, T, J]`` correction of the normalised first guess ``guess [B, 3, T, J]`` (subclasses); with
        ``body`` (``pose_frame``) the correction is in the frames' body frames."""
        raise NotImplementedError

    @property
    def feature_channels(self) -> int:
        """Channels per joint of :meth:`features`: 7, or 10 with ``pose_frame``."""
        return 10 if self.pose_frame else 7

    @staticmethod
    def features(guess: torch.Tensor, observed: torch.Tensor, body: torch.Tensor | None = None) -> torch.Tensor:
        """Coordinate-first features ``[B, 7, T, J]`` of the guess ``[B, 3, T, J]``: the guess scaled to metres-like
        values (×0.1: a body spans about ±1), its temporal detail ×5 (2 cm of noise ≈ 1) and the observed flag;
        inputs of order 1 keep the GRU's gates and the attention out of saturation. With ``body`` (the guess in
        every frame's own body frame, :meth:`body_frame`) its three coordinates ×0.1 follow: ``[B, 10, T, J]``.
        The networks read them per frame, joint-major (:func:`per_joint`)."""
        parts = [
            FEATURE_SCALE[0] * guess,
            FEATURE_SCALE[1] * temporal_detail(guess, dim=2),
            observed.unsqueeze(1).to(guess.dtype),
        ]
        if body is not None:
            parts.append(FEATURE_SCALE[0] * body)
        return torch.cat(parts, dim=1)

    def body_frame(self, guess: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(root [B, 3, T, 1], cos [B, 1, T, 1], sin [B, 1, T, 1])`` of every frame of the normalised guess
        ``[B, 3, T, J]``: the frame's root and the turn about the up axis that lays its hip line (left → right) along
        the first horizontal axis (no turn where the hips are unknown or the line is vertical). ``pose_frame``
        networks read each frame in this frame and correct it there (:meth:`corrected`): where a missing joint is,
        given the others of its frame, is then one function of them whichever way the body faces."""
        n = self.normalizer
        root = guess[..., n.root : n.root + 1]
        if n.hips is None:
            return root, torch.ones_like(root[:, :1]), torch.zeros_like(root[:, :1])
        left, right = n.hips
        line = guess[..., right : right + 1] - guess[..., left : left + 1]  # [B,3,T,1]
        h1, h2 = n.horizontal
        return (root, *heading_cos_sin(line[:, h1 : h1 + 1], line[:, h2 : h2 + 1]))

    def corrected(self, guess: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
        """The first guess ``[B, 3, T, J]`` (normalised) plus the network's correction; with ``pose_frame`` the
        network also reads the guess in every frame's body frame and its correction is turned back from it."""
        if not self.pose_frame:
            return guess + self.correction(guess, observed)
        root, cos, sin = self.body_frame(guess)
        local = self.correction(guess, observed, self.normalizer.turn_cf(guess - root, cos, sin))
        return guess + self.normalizer.turn_cf(local, cos, -sin)

    def forward(self, positions: torch.Tensor, missing: torch.Tensor) -> torch.Tensor:
        refined, stats = self._refine_cf(positions, missing)
        return self.normalizer.inverse_cf(refined, stats).permute(0, 2, 3, 1)

    def normalised_forward(self, positions: torch.Tensor, missing: torch.Tensor):
        """``(refined [B, T, J, 3], stats)`` with ``refined`` still normalised: what the training loss compares."""
        refined, stats = self._refine_cf(positions, missing)
        return refined.permute(0, 2, 3, 1), stats

    def _refine_cf(self, positions: torch.Tensor, missing: torch.Tensor):
        """``(refined [B, 3, T, J] normalised, stats)``: everything from the one transpose of the input on runs
        coordinate-first (:class:`PoseNormalizer`)."""
        observed = ~missing.bool()
        seen = observed.unsqueeze(1)  # [B,1,T,J]
        # missing entries (NaN allowed) are zeroed before the transpose, with a mask of the input's own shape
        # built by concatenation: masked after it, onnxruntime moves the transpose below the Where and broadcasts
        # the mask over the trailing axis of 3 (0.4 ms on 300 frames); an Expand to that shape costs 0.2 ms
        # (bench/RESULTS.md#onnx-runtime-costs)
        clean = torch.where(coordinate_mask(observed), positions, 0.0).permute(0, 3, 1, 2)  # [B,3,T,J]
        stats = self.normalizer.statistics_cf(clean, seen)
        x = seen.to(clean.dtype) * self.normalizer.forward_cf(clean, stats)  # 0 where missing (finite)
        return self.corrected(self.first_guess_cf(x, observed), observed), stats


def per_joint(features: torch.Tensor) -> torch.Tensor:
    """Coordinate-first ``[B, C, T, J]`` → per frame ``[B, T, J·C]`` (joint-major, as the networks' input layers
    were trained)."""
    B, C, T, J = features.shape
    return features.permute(0, 2, 3, 1).reshape(B, T, J * C)


def coordinate_first(out: torch.Tensor, J: int) -> torch.Tensor:
    """A network's per-frame output ``[B, T, J·3]`` (joint-major) → ``[B, 3, T, J]``."""
    B, T = out.shape[:2]
    return out.reshape(B, T, J, 3).permute(0, 3, 1, 2)


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
        pose_frame: also read every frame in its own body frame and correct it there
            (:meth:`~_Refiner.corrected`; no gain, off by default: docs/decisions.md#refiner-training-options-left-off).
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        parents: Sequence[int],
        up_axis: str = "y",
        hips: Sequence[int] | None = None,
        bone_lengths: Sequence[float] | None = None,
        fps: float | None = None,
        hidden: int = 128,
        layers: int = 2,
        dropout: float = 0.1,
        tangents: str = "chord",
        extrapolate: int = 6,
        pose_frame: bool = False,
    ):
        super().__init__(joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate, pose_frame)
        J = self.num_joints
        # LayerNorm before the GRU: without it the GRU's output collapsed to ~0 within an epoch in some runs
        # (mean |h| 2e-5 on validation windows, the correction constant from then on: docs/decisions.md#bigru-layernorm)
        self.inp = nn.Sequential(nn.Linear(self.feature_channels * J, hidden), nn.LayerNorm(hidden), nn.GELU())
        self.gru = nn.GRU(
            hidden,
            hidden,
            num_layers=layers,
            batch_first=True,
            bidirectional=True,
            dropout=dropout if layers > 1 else 0.0,
        )
        self.out = nn.Linear(2 * hidden, 3 * J)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def correction(self, guess: torch.Tensor, observed: torch.Tensor, body: torch.Tensor | None = None) -> torch.Tensor:
        hidden = gru_forward(self.gru, self.inp(per_joint(self.features(guess, observed, body))))
        return coordinate_first(self.out(hidden), self.num_joints)


def encoder_layer_forward(layer: nn.TransformerEncoderLayer, h: torch.Tensor) -> torch.Tensor:
    """What the pre-norm, batch-first ``layer(h)`` computes, written out: for training and ONNX export.

    ``h`` ``[N, L, dim]`` → ``[N, L, dim]`` with the layer's own weights and dropout rates (dropout in training
    mode only, drawn by :func:`mocapkit.models.ops.dropout`). Why not ``layer(h)``: in training torch's attention
    runs a "safe" softmax (a test of every row for all ``-inf``, a third of the attention's time here) and
    ``bernoulli_`` dropout (bench/RESULTS.md#training-throughput); the exported ``nn.MultiheadAttention`` works
    sequence-first and reshapes through shape arithmetic (six transposes and about twenty shape operators per
    layer). Here queries, keys and values come from one projection and one permute, the scale goes onto the
    queries (``[N, heads, L, dim/heads]``) rather than onto the ``L × L`` scores, and the output takes one
    transpose (bench/RESULTS.md#onnx-runtime-costs).
    """
    if not layer.norm_first:
        raise ValueError("encoder_layer_forward writes out the pre-norm layer (norm_first=True) only")
    attention = layer.self_attn
    training = layer.training
    N, L, dim = h.shape
    heads = attention.num_heads
    x = layer.norm1(h)
    # the projections on [N·L, dim] matrices: onnxruntime then adds the bias inside the matrix product (Gemm)
    qkv = nn.functional.linear(x.reshape(N * L, dim), attention.in_proj_weight, attention.in_proj_bias)
    q, k, v = qkv.reshape(N, L, 3, heads, dim // heads).permute(2, 0, 3, 1, 4)  # 3 × [N, heads, L, dim/heads]
    scores = torch.matmul(q * (dim // heads) ** -0.5, k.transpose(-2, -1))  # [N, heads, L, L]
    weights = dropout(torch.softmax(scores, dim=-1), attention.dropout, training)
    mixed = torch.matmul(weights, v).transpose(1, 2).reshape(N * L, dim)
    h = h + dropout(attention.out_proj(mixed).reshape(N, L, dim), layer.dropout1.p, training)
    hidden = dropout(layer.activation(layer.linear1(layer.norm2(h))), layer.dropout.p, training)
    return h + dropout(layer.linear2(hidden), layer.dropout2.p, training)


def _sinusoid(T: int, dim: int, device, dtype) -> torch.Tensor:
    position = torch.arange(T, device=device, dtype=dtype).unsqueeze(1)
    freq = torch.exp(torch.arange(0, dim, 2, device=device, dtype=dtype) * (-math.log(10000.0) / dim))
    angles = position * freq  # [T, dim/2]
    return torch.stack([torch.sin(angles), torch.cos(angles)], dim=-1).reshape(T, dim)


class MaskedTransformerRefiner(_Refiner):
    """Masked-autoencoder transformer; see the module docstring.

    Args:
        joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate, pose_frame: as
            :class:`BiGRURefiner`.
        tokens: ``"frames"`` (a token per frame, joints as features) or ``"joints"`` (a token per joint and
            frame, attention over the joints of a frame and then over the frames of a joint in every layer).
        dim: token width. layers: encoder layers (``"joints"``: pairs of joint / frame layers). heads: attention
            heads. ff: feed-forward width. dropout: in the encoder layers.
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        parents: Sequence[int],
        up_axis: str = "y",
        hips: Sequence[int] | None = None,
        bone_lengths: Sequence[float] | None = None,
        fps: float | None = None,
        tokens: str = "frames",
        dim: int = 128,
        layers: int = 3,
        heads: int = 4,
        ff: int = 256,
        dropout: float = 0.1,
        tangents: str = "chord",
        extrapolate: int = 6,
        pose_frame: bool = False,
    ):
        super().__init__(joint_names, parents, up_axis, hips, bone_lengths, fps, tangents, extrapolate, pose_frame)
        if tokens not in ("frames", "joints"):
            raise ValueError(f"tokens must be 'frames' or 'joints', got {tokens!r}")
        J = self.num_joints
        self.tokens, self.dim = tokens, dim
        self.mask_token = nn.Parameter(torch.zeros(J, 3))  # replaces missing coordinates
        layer = lambda: nn.TransformerEncoderLayer(
            dim, heads, ff, dropout, activation="gelu", batch_first=True, norm_first=True
        )
        if tokens == "frames":
            self.embed = nn.Linear((3 + self.feature_channels) * J, dim)
            self.blocks = nn.ModuleList(layer() for _ in range(layers))
            self.out = nn.Linear(dim, 3 * J)
        else:
            self.embed = nn.Linear(3 + self.feature_channels, dim)
            self.joint_embedding = nn.Parameter(torch.zeros(J, dim))
            nn.init.normal_(self.joint_embedding, std=0.02)
            self.blocks = nn.ModuleList(layer() for _ in range(2 * layers))  # joint, frame, joint, frame, ...
            self.out = nn.Linear(dim, 3)
        self.norm = nn.LayerNorm(dim)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def correction(self, guess: torch.Tensor, observed: torch.Tensor, body: torch.Tensor | None = None) -> torch.Tensor:
        B, _, T, J = guess.shape
        mask_token = self.mask_token.to(guess.dtype).t().reshape(1, 3, 1, J)
        seen = observed.unsqueeze(1).to(guess.dtype)  # a 0/1 blend: cheaper than Where
        tokenised = seen * (FEATURE_SCALE[0] * guess) + (1 - seen) * mask_token  # [B,3,T,J]
        inputs = torch.cat([tokenised, self.features(guess, observed, body)], dim=1)  # [B,10|13,T,J]
        pos = _sinusoid(T, self.dim, guess.device, guess.dtype)  # [T, dim]
        # written out in training (faster there) and for export; torch's own fused layer in inference
        written_out = self.training or torch.onnx.is_in_onnx_export()
        run = encoder_layer_forward if written_out else (lambda block, h: block(h))
        if self.tokens == "frames":
            h = self.embed(per_joint(inputs)) + pos
            for block in self.blocks:
                h = run(block, h)
            return coordinate_first(self.out(self.norm(h)), J)
        h = self.embed(inputs.permute(0, 2, 3, 1)) + self.joint_embedding + pos.unsqueeze(1)  # [B,T,J,dim]
        for i, block in enumerate(self.blocks):
            if i % 2 == 0:  # over the joints of a frame
                h = run(block, h.reshape(B * T, J, self.dim)).reshape(B, T, J, self.dim)
            else:  # over the frames of a joint
                h = run(block, h.permute(0, 2, 1, 3).reshape(B * J, T, self.dim))
                h = h.reshape(B, J, T, self.dim).permute(0, 2, 1, 3)
        return self.out(self.norm(h)).permute(0, 3, 1, 2)


def refine_bigru(**kwargs) -> BiGRURefiner:
    """The bidirectional GRU refiner (see :class:`BiGRURefiner` for the arguments)."""
    return BiGRURefiner(**kwargs)


def refine_transformer(**kwargs) -> MaskedTransformerRefiner:
    """The masked-autoencoder transformer refiner (see :class:`MaskedTransformerRefiner`)."""
    return MaskedTransformerRefiner(**kwargs)


__all__ = [
    "BiGRURefiner",
    "MaskedTransformerRefiner",
    "PoseNormalizer",
    "cubic_fill",
    "refine_bigru",
    "refine_transformer",
]
