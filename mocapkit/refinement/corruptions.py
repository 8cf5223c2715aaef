"""Seeded corruption protocols for motion-refinement experiments: missing entries, gaps, noise and outliers.

One function, :func:`corrupt`, applies a named protocol from :data:`PROTOCOLS` to a clean
:class:`~mocapkit.motion.container.Motion` and returns a :class:`Corruption`: the corrupted motion plus
exactly which entries were removed or perturbed. An **entry** is one joint (marker) in one frame, all three
coordinates together (Wang 2017, thesis §8 item 7: mask at marker granularity).

Protocols (``level`` = the thesis's parameter; ``None`` takes the default in brackets):

=====================  =====================================  ============================================================
protocol               levels                                 what exactly happens
=====================  =====================================  ============================================================
``rdcrypt``            fraction [0.3]                         Gaussian noise, σ = 2 cm per coordinate, added to
                                                              ``round(level·n_obs)`` observed entries (thesis ch. 4.1)
``rdloss``             fraction [0.3]                         ``round(level·n_obs)`` observed entries removed (ch. 4.1)
``mxcrypt``            fraction [0.3]                         ``round(level·n_obs)`` removed, then σ = 2 cm noise on
                                                              ``round(level·rest)`` of the remaining observed (ch. 4.1)
``rgloss``             ``"10x60"`` [``"10x60"``]              10 distinct markers, each missing for 60 consecutive frames
                                                              (ch. 4.1 "regular loss")
``random_missing``     mr ∈ {0.2 … 0.6} [0.3]                 in every frame, ``round(mr·joints)`` markers drawn among the
                                                              frame's observed markers are removed (ch. 4.2)
``continuous_missing`` ml ∈ {20, 30, 40, 50, 60} [60]         10 distinct markers, each missing for ml consecutive
                                                              frames (ch. 4.2)
``missing_ratio``      0.1 / 0.2 / 0.3 [0.2]                  ``round(level·n_obs)`` observed entries removed (ch. 3)
``long_gaps``          ``"5x2s"``, ``"20x100"`` [``"5x2s"``]  N gaps of L frames (``"Ls"``: L seconds at the motion's
                                                              fps); each gap's marker drawn with replacement, so a marker
                                                              may get several gaps, which never overlap or touch
``swaps``              ``"3x0.25s"``, ``"3x1s"`` [first]      N stretches of L frames in which a marker's trajectory is
                                                              exchanged with that of a nearby marker (label swap)
``spikes``             fraction [0.01]                        ``round(level·n_obs)`` isolated single-frame jumps of
                                                              10–30 cm in a uniformly random direction
=====================  =====================================  ============================================================

``n_obs`` is the number of entries observed in the input. Conventions, the same for every protocol:

- **Already-missing entries are never counted as removed or perturbed.** Random-entry protocols draw only
  among observed entries; a gap that covers an already-missing entry removes the rest of the gap only.
- **Gaps do not touch the first or last frame**: a gap's frames lie in ``1 … frames−2`` so that interpolation
  baselines always have both ends (leading/trailing gaps are a different problem; the refiners report them).
  Spikes and swaps avoid the first and last frame as well. Random-entry protocols (``rdloss``, ``mxcrypt``,
  ``missing_ratio``, ``random_missing``, ``rdcrypt``) may hit any frame, as in the theses.
- Gap protocols need ``frames ≥ L + 2``; otherwise :class:`CorruptionError` names the motion and the protocol.
  More markers asked for than the motion has → all of its markers.
- Units: positions in metres (σ = 2 cm is 0.02 m; the thesis states σ = 2 in its cm-reported setting).
- Reproducible: everything is drawn from ``numpy.random.default_rng(seed)``.

The theses: Wang 2017 (PhD thesis, *Motion Capture Data Processing, Retrieval and Recognition*) §4.1.3 and
§4.2.3, §3.5; Lou 2012 (PhD thesis) ch. 2 for outliers (marker swaps) in optical mocap.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

import numpy as np

from mocapkit.motion.container import Motion, all_coordinates
from mocapkit.motion.frames import true_runs

#: Standard deviation of the Gaussian noise of rdcrypt / mxcrypt, metres (thesis: σ = 2, reported in cm).
NOISE_SIGMA_M = 0.02
#: Spike magnitude range, metres.
SPIKE_RANGE_M = (0.10, 0.30)
#: A swap partner must be at least this far (mean distance, metres) so that a swap changes something.
SWAP_MIN_DISTANCE_M = 0.05


class CorruptionError(ValueError):
    """A protocol that cannot be applied to a motion (too short, bad level); names the motion and the protocol."""


@dataclass(frozen=True, eq=False)
class Corruption:
    """A corrupted motion and what was done to it.

    Attributes:
        motion: the corrupted :class:`Motion` (removed entries NaN and in ``missing``; perturbed entries moved).
        removed: bool ``[frames, joints]``, entries this corruption removed (never entries missing before).
        perturbed: bool ``[frames, joints]``, observed entries whose value was changed (noise, swap, spike).
        protocol: the protocol name (a key of :data:`PROTOCOLS`).
        level: the level used (after defaults).
        description: human text with the counts and gap lengths in frames and in seconds at the motion's fps.
        seed: the seed of ``numpy.random.default_rng``.
        gaps: ``(joint, first_frame, length)`` of every gap of a gap protocol (empty for the others).
    """

    motion: Motion
    removed: np.ndarray
    perturbed: np.ndarray
    protocol: str
    level: object
    description: str
    seed: int = 0
    gaps: tuple[tuple[int, int, int], ...] = field(default=())

    @property
    def corrupted(self) -> np.ndarray:
        """bool ``[frames, joints]``: removed or perturbed (the "imperfect" entries, n_p of Wang eq. 4.16)."""
        return self.removed | self.perturbed


@dataclass(frozen=True)
class ProtocolInfo:
    """One entry of :data:`PROTOCOLS`."""

    name: str
    kind: str  # "missing", "noise", "mixed" or "outlier"
    source: str  # where the protocol comes from
    levels: tuple  # the levels of the source
    default: object
    summary: str


PROTOCOLS: dict[str, ProtocolInfo] = {
    p.name: p
    for p in [
        ProtocolInfo(
            "rdcrypt",
            "noise",
            "Wang 2017 §4.1.3",
            (0.3,),
            0.3,
            "Gaussian noise σ = 2 cm (per coordinate) on a fraction `level` of the observed entries",
        ),
        ProtocolInfo(
            "rdloss",
            "missing",
            "Wang 2017 §4.1.3",
            (0.3,),
            0.3,
            "a fraction `level` of the observed entries missing, drawn uniformly",
        ),
        ProtocolInfo(
            "mxcrypt",
            "mixed",
            "Wang 2017 §4.1.3",
            (0.3,),
            0.3,
            "a fraction `level` of the observed entries missing, then σ = 2 cm noise on a fraction `level` "
            "of the remaining observed entries",
        ),
        ProtocolInfo(
            "rgloss",
            "missing",
            "Wang 2017 §4.1.3",
            ("10x60",),
            "10x60",
            "10 distinct markers, each missing for 60 consecutive frames",
        ),
        ProtocolInfo(
            "random_missing",
            "missing",
            "Wang 2017 §4.2.3",
            (0.2, 0.3, 0.4, 0.5, 0.6),
            0.3,
            "in every frame, round(mr·joints) of the frame's observed markers missing, drawn per frame",
        ),
        ProtocolInfo(
            "continuous_missing",
            "missing",
            "Wang 2017 §4.2.3",
            (20, 30, 40, 50, 60),
            60,
            "10 distinct markers, each missing for ml consecutive frames",
        ),
        ProtocolInfo(
            "missing_ratio",
            "missing",
            "Wang 2017 §3.5",
            (0.1, 0.2, 0.3),
            0.2,
            "a fraction `level` of the observed entries missing, drawn uniformly",
        ),
        ProtocolInfo(
            "long_gaps",
            "missing",
            "biomechanics practice",
            ("5x2s", "20x100"),
            "5x2s",
            "N gaps of L frames ('Ls' = L seconds); markers drawn with replacement, gaps of one marker "
            "never overlap or touch",
        ),
        ProtocolInfo(
            "swaps",
            "outlier",
            "marker mislabelling (Lou 2012 ch. 2)",
            ("3x0.25s", "3x1s"),
            "3x0.25s",
            "N stretches of L frames in which a marker and a nearby marker exchange trajectories",
        ),
        ProtocolInfo(
            "spikes",
            "outlier",
            "single-frame outliers",
            (0.005, 0.01, 0.02),
            0.01,
            "a fraction `level` of the observed entries jump 10–30 cm for one frame (isolated)",
        ),
    ]
}


# ---------------------------------------------------------------------------------------------------- helpers


def _label(motion: Motion) -> str:
    return motion.source or motion.name or "motion"


def _seconds(frames: int, fps: float) -> str:
    return f"{frames} frames = {frames / fps:.3g} s at {fps:g} fps"


def _parse_gaps(level, protocol: str, fps: float, label: str) -> tuple[int, int]:
    """``"NxL"`` / ``"NxLs"`` → (count, length in frames)."""
    match = re.fullmatch(r"\s*(\d+)\s*[x×]\s*(\d+(?:\.\d*)?)\s*(s?)\s*", str(level))
    if not match:
        raise CorruptionError(
            f"{label}: {protocol} level must look like '5x2s' (5 × 2 seconds) or '20x100' "
            f"(20 × 100 frames), got {level!r}"
        )
    count, length = int(match.group(1)), float(match.group(2))
    frames = round(float(length * fps)) if match.group(3) else round(float(length))
    if match.group(3) == "" and length != int(length):
        raise CorruptionError(f"{label}: {protocol} gap length {length} frames is not whole; use 's' for seconds")
    if count < 1 or frames < 1:
        raise CorruptionError(
            f"{label}: {protocol} level {level!r} asks for no gap (count and length must be ≥ 1 "
            f"frame; {length}{match.group(3)} at {fps:g} fps is {frames} frames)"
        )
    return count, frames


def _fraction(level, protocol: str, label: str, upper: float = 1.0) -> float:
    try:
        value = float(level)
    except (TypeError, ValueError):
        raise CorruptionError(f"{label}: {protocol} level must be a fraction, got {level!r}") from None
    if not 0.0 < value <= upper:
        raise CorruptionError(f"{label}: {protocol} level must be in (0, {upper}], got {value}")
    return value


def _choose_entries(rng: np.random.Generator, candidates: np.ndarray, fraction: float) -> np.ndarray:
    """bool mask of ``round(fraction · candidates.sum())`` entries drawn uniformly from ``candidates``."""
    flat = np.flatnonzero(candidates)
    count = round(float(fraction * flat.size))
    chosen = np.zeros(candidates.size, bool)
    chosen[rng.choice(flat, size=count, replace=False)] = True
    return chosen.reshape(candidates.shape)


def _noise(rng: np.random.Generator, positions: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = positions.copy()
    out[mask] += rng.normal(0.0, NOISE_SIGMA_M, size=(int(mask.sum()), 3)).astype(np.float32)
    return out


def _check_length(motion: Motion, protocol: str, length: int) -> None:
    if motion.num_frames < length + 2:
        raise CorruptionError(
            f"{_label(motion)}: {motion.num_frames} frames ({motion.duration:.3g} s) are too few for "
            f"{protocol} gaps of {_seconds(length, motion.fps)}; gaps keep the first and last frame, "
            f"so it needs at least {length + 2} frames"
        )


def _place_gaps(rng: np.random.Generator, frames: int, count: int, length: int) -> list[int]:
    """Starts of ``count`` gaps of ``length`` frames inside frames ``1 … frames−2``, pairwise separated by ≥ 1 frame,
    drawn uniformly over all such placements (blocks of ``length + 1`` in ``frames − 1`` slots)."""
    slots = frames - 2 + 1  # interior frames, plus one for the separator after the last gap
    leftover = slots - count * (length + 1)
    picks = np.sort(rng.choice(leftover + count, size=count, replace=False))
    return [1 + int(p - i) + i * (length + 1) for i, p in enumerate(picks)]


def _gap_capacity(frames: int, length: int) -> int:
    return max(0, (frames - 1) // (length + 1))


def _longest_runs(mask: np.ndarray) -> int:
    """Longest run of True along axis 0 of a ``[frames, joints]`` mask."""
    return max((stop - start for column in mask.T for start, stop in true_runs(column)), default=0)


# ---------------------------------------------------------------------------------------------------- protocols


def _random_entries(motion, rng, level, protocol):
    fraction = _fraction(level, protocol, _label(motion))
    removed = _choose_entries(rng, ~motion.missing, fraction)
    text = f"{int(removed.sum())} of {int((~motion.missing).sum())} observed entries ({fraction:.0%}) removed at random"
    return removed, None, None, (), text


def _rdcrypt(motion, rng, level, protocol):
    fraction = _fraction(level, protocol, _label(motion))
    perturbed = _choose_entries(rng, ~motion.missing, fraction)
    text = (
        f"Gaussian noise σ = {NOISE_SIGMA_M * 100:g} cm per coordinate on {int(perturbed.sum())} of "
        f"{int((~motion.missing).sum())} observed entries ({fraction:.0%}); nothing removed"
    )
    return None, perturbed, _noise(rng, motion.positions, perturbed), (), text


def _mxcrypt(motion, rng, level, protocol):
    fraction = _fraction(level, protocol, _label(motion))
    removed = _choose_entries(rng, ~motion.missing, fraction)
    perturbed = _choose_entries(rng, ~motion.missing & ~removed, fraction)
    text = (
        f"{int(removed.sum())} of {int((~motion.missing).sum())} observed entries ({fraction:.0%}) removed at "
        f"random, then Gaussian noise σ = {NOISE_SIGMA_M * 100:g} cm on {int(perturbed.sum())} of the "
        f"{int((~motion.missing & ~removed).sum())} remaining ({fraction:.0%})"
    )
    return removed, perturbed, _noise(rng, motion.positions, perturbed), (), text


def _random_missing(motion, rng, level, protocol):
    mr = _fraction(level, protocol, _label(motion), upper=1.0)
    joints = motion.num_joints
    per_frame = round(float(mr * joints))
    removed = np.zeros_like(motion.missing)
    for t in range(motion.num_frames):
        observed = np.flatnonzero(~motion.missing[t])
        removed[t, rng.choice(observed, size=min(per_frame, observed.size), replace=False)] = True
    text = (
        f"{per_frame} of {joints} markers (mr = {mr:g}) removed in every frame, drawn per frame among the "
        f"frame's observed markers ({int(removed.sum())} entries)"
    )
    return removed, None, None, (), text


def _fixed_gaps(motion, rng, markers: int, length: int, protocol: str):
    """``markers`` distinct markers (all if fewer), one gap of ``length`` frames each."""
    _check_length(motion, protocol, length)
    joints = rng.choice(motion.num_joints, size=min(markers, motion.num_joints), replace=False)
    gaps = tuple((int(j), _place_gaps(rng, motion.num_frames, 1, length)[0], length) for j in sorted(joints))
    removed = np.zeros_like(motion.missing)
    for j, start, n in gaps:
        removed[start : start + n, j] = True
    removed &= ~motion.missing
    names = ", ".join(motion.joint_names[j] for j, _, _ in gaps)
    text = (
        f"{len(gaps)} markers ({names}) each missing for {_seconds(length, motion.fps)} in one gap "
        f"({int(removed.sum())} entries removed)"
    )
    return removed, None, None, gaps, text


def _rgloss(motion, rng, level, protocol):
    count, length = _parse_gaps(level, protocol, motion.fps, _label(motion))
    return _fixed_gaps(motion, rng, count, length, protocol)


def _continuous_missing(motion, rng, level, protocol):
    try:
        ml = int(level)
    except (TypeError, ValueError):
        raise CorruptionError(
            f"{_label(motion)}: {protocol} level is a gap length ml in frames, got {level!r}"
        ) from None
    if ml < 1 or ml != float(level):
        raise CorruptionError(f"{_label(motion)}: {protocol} level must be a whole number of frames ≥ 1, got {level!r}")
    return _fixed_gaps(motion, rng, 10, ml, protocol)


def _long_gaps(motion, rng, level, protocol):
    count, length = _parse_gaps(level, protocol, motion.fps, _label(motion))
    _check_length(motion, protocol, length)
    capacity = _gap_capacity(motion.num_frames, length)
    if count > capacity * motion.num_joints:
        raise CorruptionError(
            f"{_label(motion)}: {count} {protocol} gaps of {_seconds(length, motion.fps)} do not fit "
            f"in {motion.num_joints} markers × {motion.num_frames} frames (at most {capacity} "
            f"separated gaps per marker)"
        )
    per_marker = np.zeros(motion.num_joints, int)
    for _ in range(count):  # markers with replacement, among those with room left
        room = np.flatnonzero(per_marker < capacity)
        per_marker[rng.choice(room)] += 1
    gaps = []
    for j in np.flatnonzero(per_marker):
        gaps += [(int(j), s, length) for s in _place_gaps(rng, motion.num_frames, int(per_marker[j]), length)]
    removed = np.zeros_like(motion.missing)
    for j, start, n in gaps:
        removed[start : start + n, j] = True
    removed &= ~motion.missing
    text = (
        f"{count} gaps of {_seconds(length, motion.fps)} on {int((per_marker > 0).sum())} markers "
        f"(at most {int(per_marker.max())} per marker, never overlapping; {int(removed.sum())} entries removed)"
    )
    return removed, None, None, tuple(gaps), text


def _swaps(motion, rng, level, protocol):
    count, length = _parse_gaps(level, protocol, motion.fps, _label(motion))
    _check_length(motion, protocol, length)
    if motion.num_joints < 2:
        raise CorruptionError(f"{_label(motion)}: {protocol} needs at least 2 markers")
    sample = np.unique(np.linspace(0, motion.num_frames - 1, min(motion.num_frames, 240)).astype(int))
    filled = motion.positions[sample].astype(np.float64)  # ≤ 240 frames suffice
    distance = np.sqrt(np.nansum((filled[:, :, None] - filled[:, None]) ** 2, axis=3))  # [t, J, J]
    both = ~motion.missing[sample][:, :, None] & ~motion.missing[sample][:, None]
    with np.errstate(invalid="ignore"):
        mean_distance = np.where(both.any(0), (distance * both).sum(0) / np.maximum(both.sum(0), 1), np.inf)
    np.fill_diagonal(mean_distance, np.inf)
    positions = motion.positions.copy()
    perturbed = np.zeros_like(motion.missing)
    events, pairs = [], []
    for _ in range(count):
        a = int(rng.integers(motion.num_joints))
        partners = np.flatnonzero((mean_distance[a] >= SWAP_MIN_DISTANCE_M) & np.isfinite(mean_distance[a]))
        if partners.size == 0:
            raise CorruptionError(
                f"{_label(motion)}: marker {motion.joint_names[a]!r} has no partner at least "
                f"{SWAP_MIN_DISTANCE_M * 100:g} cm away for {protocol}"
            )
        b = int(rng.choice(partners[np.argsort(mean_distance[a, partners], kind="stable")][:3]))  # one of 3 nearest
        start = _place_gaps(rng, motion.num_frames, 1, length)[0]
        frames = np.arange(start, start + length)
        frames = frames[~motion.missing[frames, a] & ~motion.missing[frames, b]]
        positions[frames, a], positions[frames, b] = motion.positions[frames, b], motion.positions[frames, a]
        perturbed[frames, a] = perturbed[frames, b] = True
        events.append((a, int(start), length))
        pairs.append(f"{motion.joint_names[a]}↔{motion.joint_names[b]} @ {start}")
    # a second swap over the same stretch can undo a first one: perturbed = actually changed
    perturbed &= ~all_coordinates(positions == motion.positions)
    text = (
        f"{count} marker swaps of {_seconds(length, motion.fps)} each ({'; '.join(pairs)}); "
        f"{int(perturbed.sum())} entries moved, nothing removed"
    )
    return None, perturbed, positions, tuple(events), text


def _spikes(motion, rng, level, protocol):
    fraction = _fraction(level, protocol, _label(motion), upper=0.25)
    frames, joints = motion.missing.shape
    if frames < 3:
        raise CorruptionError(f"{_label(motion)}: {protocol} needs at least 3 frames (spikes avoid the first and last)")
    candidates = ~motion.missing
    candidates[[0, -1]] = False
    target = round(float(fraction * (~motion.missing).sum()))
    perturbed = np.zeros_like(motion.missing)
    for flat in rng.permutation(np.flatnonzero(candidates)):
        if perturbed.sum() >= target:
            break
        t, j = divmod(int(flat), joints)
        if not (perturbed[t - 1, j] or perturbed[t + 1, j]):  # isolated: a spike is one frame long
            perturbed[t, j] = True
    if perturbed.sum() < target:
        raise CorruptionError(f"{_label(motion)}: only {int(perturbed.sum())} isolated {protocol} fit, {target} asked")
    direction = rng.normal(size=(target, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    magnitude = rng.uniform(*SPIKE_RANGE_M, size=(target, 1))
    positions = motion.positions.copy()
    positions[perturbed] += (direction * magnitude).astype(np.float32)
    text = (
        f"{target} isolated single-frame spikes (1 frame = {1000 / motion.fps:.3g} ms at {motion.fps:g} fps) of "
        f"{SPIKE_RANGE_M[0] * 100:g}–{SPIKE_RANGE_M[1] * 100:g} cm on {fraction:.1%} of the observed entries; "
        f"nothing removed"
    )
    return None, perturbed, positions, (), text


_IMPLEMENTATIONS = {
    "rdcrypt": _rdcrypt,
    "rdloss": _random_entries,
    "mxcrypt": _mxcrypt,
    "rgloss": _rgloss,
    "random_missing": _random_missing,
    "continuous_missing": _continuous_missing,
    "missing_ratio": _random_entries,
    "long_gaps": _long_gaps,
    "swaps": _swaps,
    "spikes": _spikes,
}


def corrupt(motion: Motion, protocol: str, level=None, seed: int = 0) -> Corruption:
    """Apply ``protocol`` (a key of :data:`PROTOCOLS`) at ``level`` to ``motion``; see the module docstring.

    Args:
        motion: the clean motion (positions float32 ``[frames, joints, 3]`` metres; already-missing entries are
            left alone and never counted).
        protocol: ``rdcrypt``, ``rdloss``, ``mxcrypt``, ``rgloss``, ``random_missing``, ``continuous_missing``,
            ``missing_ratio``, ``long_gaps``, ``swaps`` or ``spikes``.
        level: the protocol's parameter (fraction, gap length in frames, or ``"NxL"`` / ``"NxLs"``); ``None``
            takes ``PROTOCOLS[protocol].default``.
        seed: seed of ``numpy.random.default_rng``; the same seed gives the same corruption.

    Returns:
        a :class:`Corruption`; ``corruption.motion.metadata["corruption"]`` holds protocol, level, seed and the text.

    Raises:
        CorruptionError: unknown protocol, bad level, or a motion too short for the protocol's gaps
            (the message names the motion and the protocol).
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"corrupt: expected a Motion, got {type(motion).__name__}")
    if protocol not in PROTOCOLS:
        raise CorruptionError(f"{_label(motion)}: unknown corruption protocol {protocol!r}; known: {sorted(PROTOCOLS)}")
    if (~motion.missing).sum() == 0:
        raise CorruptionError(f"{_label(motion)}: every entry is already missing, nothing to corrupt ({protocol})")
    level = PROTOCOLS[protocol].default if level is None else level
    rng = np.random.default_rng(seed)
    removed, perturbed, positions, gaps, text = _IMPLEMENTATIONS[protocol](motion, rng, level, protocol)
    shape = motion.missing.shape
    removed = np.zeros(shape, bool) if removed is None else removed & ~motion.missing
    perturbed = np.zeros(shape, bool) if perturbed is None else perturbed & ~motion.missing & ~removed
    positions = (motion.positions if positions is None else positions).copy()
    positions[removed] = np.nan
    longest = _longest_runs(removed)
    if longest:
        text += f"; longest run of removed frames per marker: {_seconds(longest, motion.fps)}"
    description = (
        f"{protocol} (level {level!r}, seed {seed}) on {_label(motion)} "
        f"[{shape[0]} frames, {shape[1]} markers, {motion.fps:g} fps]: {text}"
    )
    corrupted = replace(
        motion,
        positions=positions,
        missing=motion.missing | removed,
        rotations=None,
        metadata={
            **motion.metadata,
            "corruption": {"protocol": protocol, "level": level, "seed": seed, "description": description},
        },
    )
    return Corruption(
        motion=corrupted,
        removed=removed,
        perturbed=perturbed,
        protocol=protocol,
        level=level,
        description=description,
        seed=seed,
        gaps=tuple(gaps),
    )


# ---------------------------------------------------------------------------------------------------- training

#: The corruption mixture of learned refiners' training (:func:`training_corruption`): every protocol of
#: :data:`PROTOCOLS`, with levels drawn around (and beyond) the theses' levels, gap lengths up to the window.
TRAINING_MIXTURE = (
    "rdcrypt",
    "rdloss",
    "mxcrypt",
    "random_missing",
    "continuous_missing",
    "long_gaps",
    "spikes",
    "swaps",
)


def training_corruption(
    motion: Motion, rng: np.random.Generator, whole_joint_rate: float = 0.15, weights: dict[str, float] | None = None
) -> Corruption:
    """One corruption of ``motion`` (a training window) drawn from :data:`TRAINING_MIXTURE`.

    The protocol is drawn with ``weights`` (protocol → relative weight; None: uniform over the mixture;
    a protocol left out or weighted 0 is never drawn); its level is drawn: fractions 0.05–0.6 (rdcrypt, rdloss, mxcrypt,
    random_missing), spikes 0.005–0.03, 1–10 gaps of 2 … ``frames − 2`` frames (continuous_missing draws the
    length, long_gaps the count and length), swaps of 2 … ``frames / 3`` frames. With probability
    ``whole_joint_rate`` 1–3 joints are also removed in every frame (a gap longer than the window, as the
    windows inside a 2 s gap see). Protocols a short window cannot take fall back to ``rdloss``.
    """
    frames = motion.num_frames
    if weights is None:
        protocol = TRAINING_MIXTURE[rng.integers(len(TRAINING_MIXTURE))]
    else:
        unknown = sorted(set(weights) - set(TRAINING_MIXTURE))
        if unknown or not sum(float(w) for w in weights.values()) > 0:
            raise ValueError(
                f"corruption weights {dict(weights)}: protocols must be among {list(TRAINING_MIXTURE)} "
                "with a positive total weight"
            )
        names = list(weights)
        p = np.asarray([float(weights[n]) for n in names])
        protocol = names[rng.choice(len(names), p=p / p.sum())]
    if protocol in ("rdcrypt", "rdloss", "mxcrypt", "random_missing"):
        level = float(rng.uniform(0.05, 0.6))
    elif protocol == "spikes":
        level = float(rng.uniform(0.005, 0.03))
    elif protocol == "continuous_missing":
        level = int(rng.integers(2, max(3, frames - 1)))
    elif protocol == "long_gaps":
        level = f"{int(rng.integers(1, 11))}x{int(rng.integers(2, max(3, frames - 1)))}"
    else:
        level = f"{int(rng.integers(1, 4))}x{int(rng.integers(2, max(3, frames // 3)))}"
    seed = int(rng.integers(2**31))
    try:
        result = corrupt(motion, protocol, level, seed=seed)
    except CorruptionError:
        result = corrupt(motion, "rdloss", 0.2, seed=seed)
    if rng.random() < whole_joint_rate:
        joints = rng.choice(motion.num_joints, size=min(int(rng.integers(1, 4)), motion.num_joints), replace=False)
        extra = np.zeros_like(result.removed)
        extra[:, joints] = ~result.motion.missing[:, joints]
        if (~(result.motion.missing | extra)).any():  # keep at least one observed entry
            positions = result.motion.positions.copy()
            positions[extra] = np.nan
            moved = replace(result.motion, positions=positions, missing=result.motion.missing | extra)
            result = replace(
                result,
                motion=moved,
                removed=result.removed | extra,
                perturbed=result.perturbed & ~extra,
                description=result.description + f"; joints {sorted(joints.tolist())} missing throughout",
            )
    return result
