"""Metrics of motion-variation synthesis (Zhou 2014 ch. 4): how varied a set of variants is, and proxies of how
natural each one is that need no user study.

Everything is computed on **joint positions from forward kinematics** (``Motion.positions``: metres, y up,
``[frames, joints, 3]``) at the motions' own frame rate; the variants of a synthesiser
(:mod:`mocapkit.synthesis.base`) are AMC motions, so their positions are the skeleton's FK.

**Variation** (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §3.7, eq. 4.5):
``V = 2 / (N (N − 1)) Σ_{i<j} DTW(M_i, M_j)``, the mean pairwise DTW distance of ``N`` motions. The thesis does
not say in which space (§7 gap 20); here, as that gap proposes:

- **features**: :func:`root_normalised_positions` per frame, i.e. every joint position after moving the root
  joint to ``x = z = 0`` (its height above the floor is kept) and turning the frame about the vertical so that
  the hip line (left hip → right hip) points along ``+x``; flattened to ``[T, 3J]`` metres;
- **local cost**: the Euclidean distance between two such frames (metres, all ``3J`` coordinates together);
- **accumulated cost**: the plain sum of local costs along the optimal warping path (no window, no slope
  constraint; dtaidistance's ``dtw_ndim`` with ``inner_dist="euclidean"``, the DTW library of
  :mod:`mocapkit.retrieval.dtw`), unnormalised (metres × path steps): :attr:`Variation.v`. It grows with the
  clip length and the frame rate, so absolute values are comparable only at one length and rate (the thesis's
  435 / 558.7 are not comparable to these); :attr:`Variation.v_per_step` divides each pair's cost by the
  number of steps of its warping path (metres: the mean per-frame distance along the alignment).

**Naturalness proxies** (one number per motion; the benchmark averages them over clips):

- :func:`foot_skating`: mean horizontal speed of the foot joints while in contact, **cm/s** (a foot is in
  contact in a frame when its height is within ``height_threshold`` of its lowest height in the clip and its
  vertical speed is below ``vertical_speed``; :func:`foot_contacts`);
- :func:`bone_length_drift`: the sd over time of each bone's length, averaged over the bones, **mm** (0 for
  any method that poses a fixed skeleton by joint angles; a check for position-based generators);
- :func:`mean_jerk`: the mean norm of the third time derivative of the joint positions (third finite
  difference × fps³), **m/s³**;
- :func:`feature_distance`: a standardised mean/sd distance between the per-frame :func:`pose_features`
  (root-normalised positions and heading-frame velocities) of one clip and those of a set of real clips,
  **dimensionless** (units of the real set's per-feature sd); :func:`feature_distances` scores every variant
  against held-out real clips of the same type and gives the **reference spread**: each held-out clip scored
  against the other held-out clips, the same one-clip-against-a-set distance, so a variant "within the spread
  of real clips" has a distance no larger than theirs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import hip_line_heading, turn_about_up
from mocapkit.motion.layouts import find_landmarks, hip_joints

#: Landmarks whose joints are checked for foot skating (ankle and ball of each foot).
FOOT_LANDMARKS = ("l_ankle", "l_foot", "r_ankle", "r_foot")


def _label(motion: Motion) -> str:
    return str(motion.source or motion.name or "motion")


def _checked(motion: Motion, min_frames: int = 1) -> np.ndarray:
    """float64 positions ``[T, J, 3]`` of a y-up motion with no missing entry and at least ``min_frames`` frames."""
    if motion.up_axis != "y":
        raise ValueError(f"{_label(motion)}: synthesis metrics need y-up positions, got up_axis={motion.up_axis!r}")
    if motion.num_frames < min_frames:
        raise ValueError(f"{_label(motion)}: {motion.num_frames} frames; this metric needs at least {min_frames}")
    if motion.missing.any():
        raise ValueError(f"{_label(motion)}: has missing entries; synthesis metrics need complete FK positions")
    return motion.positions.astype(np.float64)


def _root_index(motion: Motion) -> int:
    return motion.parents.index(-1) if motion.parents else 0


def heading_angles(motion: Motion) -> np.ndarray:
    """float64 ``[T]`` radians: the angle about +y that turns each frame's hip line (left → right) onto ``+x``.

    Raises:
        ValueError: the skeleton's hips cannot be told (:func:`~mocapkit.motion.layouts.hip_joints`).
    """
    hips = hip_joints(motion.joint_names, motion.layout_name)
    if hips is None:
        raise ValueError(f"{_label(motion)}: cannot find the left and right hip joints for the heading")
    # hip line onto +x, as the variation feature was defined (the landmarks' "-x" is a turn by π: same distances,
    # other rounding)
    return hip_line_heading(_checked(motion), hips[0], hips[1], up="y", along="+x")


def root_normalised_positions(motion: Motion) -> np.ndarray:
    """float64 ``[T, J, 3]`` metres: each frame with the root joint moved to ``x = z = 0`` (height kept) and turned
    about +y so that its hip line (left → right) lies along +x (the DTW feature of :func:`variation`)."""
    p = _checked(motion)
    root = p[:, _root_index(motion)]
    centred = p - np.stack([root[:, 0], np.zeros(len(p)), root[:, 2]], axis=1)[:, None]
    return turn_about_up(centred, heading_angles(motion), up="y", along="+x")


def pose_features(motion: Motion) -> np.ndarray:
    """float64 ``[T − 1, 6J]`` per-frame features of :func:`feature_distance`: the root-normalised positions of
    frames 1.. (metres) and the world velocities ``(p_t − p_{t−1}) · fps`` turned into frame t's heading (m/s)."""
    p = _checked(motion, min_frames=2)
    velocity = turn_about_up((p[1:] - p[:-1]) * float(motion.fps), heading_angles(motion)[1:], up="y", along="+x")
    positions = root_normalised_positions(motion)[1:]
    return np.concatenate([positions.reshape(len(positions), -1), velocity.reshape(len(velocity), -1)], axis=1)


# ------------------------------------------------------------------------------------------ variation (eq. 4.5)
@dataclass
class Variation:
    """Zhou eq. 4.5 on a set of motions (module docstring for the feature space and the cost).

    Attributes:
        v: the mean pairwise DTW cost, unnormalised (metres × path steps).
        v_per_step: the mean pairwise DTW cost divided by each pair's warping-path length (metres).
        distances: float64 ``[N, N]`` pairwise DTW costs (symmetric, zero diagonal).
        path_lengths: int64 ``[N, N]`` steps of each pair's warping path (diagonal: the clip's length).
    """

    v: float
    v_per_step: float
    distances: np.ndarray
    path_lengths: np.ndarray


def dtw_cost(a: np.ndarray, b: np.ndarray) -> tuple[float, int]:
    """``(accumulated cost, path steps)`` of the DTW alignment of two ``[T, d]`` sequences: Euclidean local cost,
    the plain sum along the optimal path, no window (dtaidistance)."""
    from dtaidistance import dtw, dtw_ndim

    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    cost, paths = dtw_ndim.warping_paths_fast(a, b, inner_dist="euclidean")
    return float(cost), len(dtw.best_path(paths))


def variation(motions: Sequence[Motion]) -> Variation:
    """Zhou eq. 4.5, ``V = 2/(N(N−1)) Σ_{i<j} DTW(M_i, M_j)``, over ``N ≥ 2`` motions of one skeleton.

    Raises:
        ValueError: fewer than two motions, or motions with different joints.
    """
    motions = list(motions)
    if len(motions) < 2:
        raise ValueError(f"variation needs at least two motions, got {len(motions)}")
    for m in motions[1:]:
        if m.joint_names != motions[0].joint_names:
            raise ValueError(f"variation: {_label(m)} has other joints than {_label(motions[0])}")
    features = [root_normalised_positions(m).reshape(m.num_frames, -1) for m in motions]
    n = len(features)
    distances = np.zeros((n, n))
    steps = np.diag([len(f) for f in features]).astype(np.int64)
    for i in range(n):
        for j in range(i + 1, n):
            distances[i, j], steps[i, j] = dtw_cost(features[i], features[j])
            distances[j, i], steps[j, i] = distances[i, j], steps[i, j]
    upper = np.triu_indices(n, 1)
    return Variation(
        v=float(distances[upper].mean()),
        v_per_step=float((distances[upper] / steps[upper]).mean()),
        distances=distances,
        path_lengths=steps,
    )


# ------------------------------------------------------------------------------------------ naturalness proxies
def foot_joints(motion: Motion) -> list[int]:
    """Indices of the ankle and ball joints of both feet (:data:`FOOT_LANDMARKS`; a rig whose foot joint is both
    is listed once)."""
    found = find_landmarks(motion.joint_names, motion.layout_name)
    joints = list(dict.fromkeys(found[name] for name in FOOT_LANDMARKS if name in found))
    if not joints:
        raise ValueError(f"{_label(motion)}: no foot joints found ({', '.join(FOOT_LANDMARKS)})")
    return joints


def foot_contacts(motion: Motion, height_threshold: float = 0.03, vertical_speed: float = 0.15) -> np.ndarray:
    """bool ``[T − 1, F]``: whether each foot joint (:func:`foot_joints`) is in contact between frames t and t+1.

    In contact: at both frames within ``height_threshold`` metres of the joint's lowest height in the clip, and
    moving vertically slower than ``vertical_speed`` m/s between them.
    """
    p = _checked(motion, min_frames=2)[:, foot_joints(motion)]
    height = p[..., 1]
    low = height - height.min(axis=0, keepdims=True) <= float(height_threshold)
    slow = np.abs(np.diff(height, axis=0)) * float(motion.fps) < float(vertical_speed)
    return low[1:] & low[:-1] & slow


def foot_skating(motion: Motion, height_threshold: float = 0.03, vertical_speed: float = 0.15) -> float:
    """Mean horizontal speed (cm/s) of the foot joints over their contacts (:func:`foot_contacts`); NaN when no
    foot joint is ever in contact."""
    p = _checked(motion, min_frames=2)[:, foot_joints(motion)]
    contact = foot_contacts(motion, height_threshold, vertical_speed)
    if not contact.any():
        return float("nan")
    step = p[1:] - p[:-1]
    speed = np.hypot(step[..., 0], step[..., 2]) * float(motion.fps) * 100.0
    return float(speed[contact].mean())


def bone_length_drift(motion: Motion) -> float:
    """Mean over the bones (joint–parent pairs) of the sd over time of the bone's length, mm."""
    if not motion.parents:
        raise ValueError(f"{_label(motion)}: bone-length drift needs a joint hierarchy")
    p = _checked(motion)
    child = [j for j, parent in enumerate(motion.parents) if parent >= 0]
    parent = [motion.parents[j] for j in child]
    lengths = np.linalg.norm(p[:, child] - p[:, parent], axis=-1)
    return float(lengths.std(axis=0).mean() * 1000.0)


def mean_jerk(motion: Motion) -> float:
    """Mean over joints and frames of ‖d³p/dt³‖ from the third finite difference of the positions, m/s³."""
    p = _checked(motion, min_frames=4)
    jerk = np.diff(p, n=3, axis=0) * float(motion.fps) ** 3
    return float(np.linalg.norm(jerk, axis=-1).mean())


def clip_naturalness(
    motions: Sequence[Motion], height_threshold: float = 0.03, vertical_speed: float = 0.15
) -> dict[str, np.ndarray]:
    """The proxies of every clip: ``{"foot_skating_cms", "bone_drift_mm", "jerk"}``, each ``[len(motions)]``
    (cm/s, mm, m/s³; the foot skating is NaN for a clip without contacts)."""
    return {
        "foot_skating_cms": np.array([foot_skating(m, height_threshold, vertical_speed) for m in motions]),
        "bone_drift_mm": np.array([bone_length_drift(m) for m in motions]),
        "jerk": np.array([mean_jerk(m) for m in motions]),
    }


def proxy_means(table: dict[str, np.ndarray]) -> dict[str, float]:
    """The means over clips of a :func:`clip_naturalness` table (a clip without contacts does not count towards the
    foot skating; NaN when none has contacts)."""
    skating = table["foot_skating_cms"][np.isfinite(table["foot_skating_cms"])]
    return {
        "foot_skating_cms": float(skating.mean()) if skating.size else float("nan"),
        "bone_drift_mm": float(table["bone_drift_mm"].mean()),
        "jerk": float(table["jerk"].mean()),
    }


def naturalness(motions: Sequence[Motion], height_threshold: float = 0.03, vertical_speed: float = 0.15) -> dict:
    """The proxies averaged over ``motions``: ``{"foot_skating_cms", "bone_drift_mm", "jerk"}`` (cm/s, mm,
    m/s³; a clip without contacts does not count towards the foot skating)."""
    return proxy_means(clip_naturalness(motions, height_threshold, vertical_speed))


#: Bone-length drift below this (mm) is numerical noise, not drift: forward kinematics of float32 positions gives
#: rigid bones a drift of about 1e-4 mm (the proxies' resolution, :data:`PROXY_RESOLUTION`).
BONE_DRIFT_RESOLUTION_MM = 0.01
#: Per proxy, the difference below which two values are the same for :func:`within_spread`.
PROXY_RESOLUTION = {"bone_drift_mm": BONE_DRIFT_RESOLUTION_MM}


def within_spread(values: np.ndarray, real: np.ndarray, resolution: float = 0.0) -> np.ndarray:
    """bool ``[n]``: whether each value of a proxy that is worse when larger (foot skating, jerk, bone drift, a
    feature distance) is within the spread of the real clips' values ``[m]``, i.e. no larger than the largest
    (plus ``resolution``: the proxy's numerical resolution, :data:`PROXY_RESOLUTION`).

    NaN (a clip without foot contacts) is within only if some real clip has NaN too; a NaN among the real
    values does not widen the spread of the finite ones.
    """
    values, real = np.asarray(values, dtype=np.float64), np.asarray(real, dtype=np.float64)
    finite = real[np.isfinite(real)]
    bound = finite.max() + float(resolution) if finite.size else -np.inf
    return np.where(np.isnan(values), bool(np.isnan(real).any()), values <= bound)


# ------------------------------------------------------------------------------------------ feature statistics
def _moments(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return frames.mean(axis=0), frames.std(axis=0)


def feature_distance(features: np.ndarray, reference: np.ndarray, scale: np.ndarray) -> float:
    """Standardised mean/sd distance of one clip's per-frame features ``[T, F]`` to a reference set's pooled
    frames ``[N, F]``: ``sqrt(mean_k ((μ_k − μ'_k)² + (s_k − s'_k)²) / scale_k²)`` (dimensionless)."""
    mean, sd = _moments(features)
    ref_mean, ref_sd = _moments(reference)
    return float(np.sqrt(np.mean(((mean - ref_mean) ** 2 + (sd - ref_sd) ** 2) / scale**2)))


@dataclass
class FeatureDistances:
    """:func:`feature_distances`: every variant against the real clips, and the real clips' own spread.

    Attributes:
        variants: ``[n_variants]`` distance of each variant to all real clips pooled.
        real: ``[n_real]`` distance of each real clip to the other real clips pooled (the reference spread).
    """

    variants: np.ndarray
    real: np.ndarray

    def summary(self) -> dict:
        """``{"feature_distance", "feature_distance_real", "feature_distance_real_sd", "within_real"}``: the mean
        distance of the variants, the mean and sd of the real clips', and the fraction of variants whose distance
        is at most the largest real clip's."""
        return {
            "feature_distance": float(self.variants.mean()),
            "feature_distance_real": float(self.real.mean()),
            "feature_distance_real_sd": float(self.real.std(ddof=1)) if len(self.real) > 1 else 0.0,
            "within_real": float(within_spread(self.variants, self.real).mean()),
        }


def feature_distances(variants: Sequence[Motion], real: Sequence[Motion]) -> FeatureDistances:
    """:func:`feature_distance` of each variant to the pooled :func:`pose_features` of the ``real`` clips, and of
    each real clip to the other real clips (leave one out). The scale of every feature is its sd over all the real
    clips' frames (floored at 1e-6 of the largest, so that constant features do not explode).

    Raises:
        ValueError: fewer than two real clips (the reference spread needs one to leave out).
    """
    real = list(real)
    if len(real) < 2:
        raise ValueError(f"feature_distances needs at least two real clips, got {len(real)}")
    real_features = [pose_features(m) for m in real]
    pooled = np.concatenate(real_features)
    scale = pooled.std(axis=0)
    scale = np.maximum(scale, 1e-6 * scale.max())
    ours = np.array([feature_distance(pose_features(m), pooled, scale) for m in variants])
    own = np.array(
        [
            feature_distance(f, np.concatenate(real_features[:i] + real_features[i + 1 :]), scale)
            for i, f in enumerate(real_features)
        ]
    )
    return FeatureDistances(variants=ours, real=own)


def proxies_within(
    variant_proxies: dict[str, np.ndarray], real_proxies: dict[str, np.ndarray], distances: FeatureDistances
) -> dict[str, np.ndarray]:
    """Per variant, whether it lies within the real clips' spread (:func:`within_spread`, each proxy at its
    :data:`PROXY_RESOLUTION`): bool ``[n_variants]`` per :func:`clip_naturalness` proxy, ``"feature_distance"``
    (:func:`feature_distances` of the variants against the real clips) and ``"every_proxy"`` (all of them)."""
    within = {
        name: within_spread(values, real_proxies[name], PROXY_RESOLUTION.get(name, 0.0))
        for name, values in variant_proxies.items()
    }
    within["feature_distance"] = within_spread(distances.variants, distances.real)
    within["every_proxy"] = np.logical_and.reduce(list(within.values()))
    return within


__all__ = [
    "FOOT_LANDMARKS",
    "FeatureDistances",
    "Variation",
    "bone_length_drift",
    "clip_naturalness",
    "dtw_cost",
    "feature_distance",
    "feature_distances",
    "foot_contacts",
    "foot_joints",
    "foot_skating",
    "heading_angles",
    "mean_jerk",
    "naturalness",
    "pose_features",
    "proxies_within",
    "proxy_means",
    "root_normalised_positions",
    "variation",
    "within_spread",
    "BONE_DRIFT_RESOLUTION_MM",
    "PROXY_RESOLUTION",
]
