"""Motion features on the normalised landmark skeleton: relational pose features, HOD, geometric pose
descriptors and their LLC bag of words (the two views of AMFS, ``../shared/spec/thesis-wang-2017-mocap-processing.md``
§4.5).

Every function takes one sequence ``seq`` of :func:`~mocapkit.motion.geometry.normalised_landmarks`:
float ``[T, 20, 3]`` in metres of the ~1.7 m template body, landmarks in
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order, y up, pelvis at the origin. The body need not
face +z: every direction used below (forward, left, spine) is measured on the body itself, so the features do not
depend on ``heading``. Because the template is fixed, thresholds are in metres, radians and metres per second.

* :func:`relational_features` ``[T, 39]``: boolean relations between body parts (hand in front of the body,
  foot raised, knee bent, ...) in the style of Müller & Röder's relational features, 0/1 or soft (a sigmoid of
  the signed margin, for DTW).
* :func:`hod` ``[19 * 3 * bins * (2**levels - 1)]``: the Histogram of Oriented Displacements (Gowayyed et al.
  2013), the sequence-level view of AMFS.
* :func:`pose_descriptors` ``[T, 104]``: geometric pose features per frame (distances, distances to body planes,
  joint angles, velocities), the frame descriptor of the GPF view.
* :class:`GPFBagOfWords`: pose descriptors → k-means codebook → LLC codes → pooled bag of words, the
  clip-level GPF-BoVW view (spec §4.5 [rec]: LLC k = 5, max pooling, ℓ2 normalisation).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.cluster import KMeans, MiniBatchKMeans
from sklearn.exceptions import NotFittedError
from sklearn.utils import check_random_state

from mocapkit.motion.geometry import L_HIP, R_HIP, facing_direction
from mocapkit.motion.layouts import LANDMARK_NAMES

_I = {name: k for k, name in enumerate(LANDMARK_NAMES)}
PELVIS, NECK, HEAD = _I["pelvis"], _I["neck"], _I["head"]
_SIDES = ("l", "r")
_UP = np.array([0.0, 1.0, 0.0])
#: Soft-margin scales of :func:`relational_features` by unit: metres, radians, metres per second.
_SCALES = {"m": 0.05, "rad": 0.1, "m/s": 0.25}


def _as_sequence(seq) -> np.ndarray:
    P = np.asarray(seq, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (len(LANDMARK_NAMES), 3):
        raise ValueError(f"expected landmarks [T, {len(LANDMARK_NAMES)}, 3], got shape {P.shape}")
    if P.shape[0] < 1:
        raise ValueError("empty sequence (0 frames)")
    return P


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad, [0, π]) between vectors ``a`` and ``b`` [..., 3]."""
    return np.arccos(np.clip(_dot(_unit(a), _unit(b)), -1.0, 1.0))


def _velocity(P: np.ndarray, fps: float) -> np.ndarray:
    """Central finite differences × fps (m/s) along the first axis; zeros for a single frame."""
    if P.shape[0] < 2:
        return np.zeros_like(P)
    return np.gradient(P, axis=0) * float(fps)


def _body_frame(P: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame body directions [T, 3] (unit) and the floor height [T] (the lowest ankle or foot, metres)."""
    pelvis = P[:, PELVIS]
    l_sh, r_sh = P[:, _I["l_shoulder"]], P[:, _I["r_shoulder"]]
    l_hip, r_hip = P[:, _I["l_hip"]], P[:, _I["r_hip"]]
    return {
        # normal of the torso plane (pelvis, left shoulder, right shoulder): forward for an upright body
        "torso_forward": _unit(np.cross(l_sh - pelvis, r_sh - pelvis)),
        # horizontal forward of the hips ((left − right) × up), independent of trunk bending
        "hip_forward": facing_direction(P, L_HIP, R_HIP, up="y", eps=1e-9),
        "torso_left": _unit(l_sh - r_sh),
        "hip_left": _unit(l_hip - r_hip),
        "spine": _unit(P[:, NECK] - pelvis),
        "floor": P[:, [_I["l_ankle"], _I["l_foot"], _I["r_ankle"], _I["r_foot"]], 1].min(axis=1),
    }


# --------------------------------------------------------------------------- relational features


def _relational_values(P: np.ndarray, fps: float) -> dict[str, np.ndarray]:
    """The signed quantity [T] behind each relational feature (compared with its threshold)."""
    f = _body_frame(P)
    V = _velocity(P, fps)
    speed = np.linalg.norm(V, axis=-1)  # [T, 20] m/s, relative to the pelvis
    pelvis = P[:, PELVIS]
    height = P[..., 1] - f["floor"][:, None]  # [T, 20] above the lowest foot

    def j(name):
        return P[:, _I[name]]

    out: dict[str, np.ndarray] = {}
    for s, o in (("l", "r"), ("r", "l")):
        outward = 1.0 if s == "l" else -1.0  # the left side is at +left
        hand, elbow, shoulder, wrist = j(f"{s}_hand"), j(f"{s}_elbow"), j(f"{s}_shoulder"), j(f"{s}_wrist")
        out[f"{s}_hand_front"] = _dot(hand - pelvis, f["torso_forward"])
        out[f"{s}_hand_above_neck"] = _dot(hand - j("neck"), f["spine"])
        out[f"{s}_hand_above_head"] = hand[:, 1] - j("head")[:, 1]
        out[f"{s}_hand_sideways"] = outward * _dot(hand - shoulder, f["torso_left"])
        out[f"{s}_elbow_bent"] = _angle(elbow - shoulder, wrist - elbow)
        out[f"{s}_elbow_raised"] = _dot(elbow - shoulder, f["spine"])
        out[f"{s}_hand_fast"] = speed[:, _I[f"{s}_hand"]]
        out[f"{s}_hand_near_head"] = -np.linalg.norm(hand - j("head"), axis=-1)
        out[f"{s}_hand_low"] = -height[:, _I[f"{s}_hand"]]
        out[f"{s}_elbow_near_{o}_knee"] = -np.linalg.norm(elbow - j(f"{o}_knee"), axis=-1)
    for s, o in (("l", "r"), ("r", "l")):
        outward = 1.0 if s == "l" else -1.0
        hip, knee, ankle = j(f"{s}_hip"), j(f"{s}_knee"), j(f"{s}_ankle")
        out[f"{s}_foot_raised"] = ankle[:, 1] - j(f"{o}_ankle")[:, 1]
        out[f"{s}_foot_front"] = _dot(ankle - pelvis, f["hip_forward"])
        out[f"{s}_foot_behind"] = -_dot(ankle - pelvis, f["hip_forward"])
        out[f"{s}_knee_bent"] = _angle(knee - hip, ankle - knee)
        out[f"{s}_thigh_raised"] = _angle(knee - hip, -_UP)
        out[f"{s}_leg_sideways"] = outward * _dot(ankle - hip, f["hip_left"])
        out[f"{s}_foot_fast"] = speed[:, _I[f"{s}_ankle"]]
    hands = np.linalg.norm(j("l_hand") - j("r_hand"), axis=-1)
    out["hands_apart"] = hands
    out["hands_near"] = -hands
    out["feet_apart"] = np.linalg.norm(j("l_ankle") - j("r_ankle"), axis=-1)
    out["spine_bent_forward"] = np.arcsin(np.clip(_dot(f["spine"], f["hip_forward"]), -1.0, 1.0))
    out["lying"] = _angle(f["spine"], np.broadcast_to(_UP, f["spine"].shape))
    out["pelvis_low"] = -height[:, PELVIS]
    out["head_low"] = -height[:, HEAD]
    return out


def _relational_table() -> tuple[tuple[str, float, str], ...]:
    rows = []
    for s, o in (("l", "r"), ("r", "l")):
        rows += [
            (f"{s}_hand_front", 0.25, "m"),
            (f"{s}_hand_above_neck", 0.0, "m"),
            (f"{s}_hand_above_head", 0.0, "m"),
            (f"{s}_hand_sideways", 0.3, "m"),
            (f"{s}_elbow_bent", np.deg2rad(60.0), "rad"),
            (f"{s}_elbow_raised", 0.0, "m"),
            (f"{s}_hand_fast", 1.2, "m/s"),
            (f"{s}_hand_near_head", -0.25, "m"),
            (f"{s}_hand_low", -0.5, "m"),
            (f"{s}_elbow_near_{o}_knee", -0.3, "m"),
        ]
    for s in _SIDES:
        rows += [
            (f"{s}_foot_raised", 0.15, "m"),
            (f"{s}_foot_front", 0.3, "m"),
            (f"{s}_foot_behind", 0.3, "m"),
            (f"{s}_knee_bent", np.deg2rad(50.0), "rad"),
            (f"{s}_thigh_raised", np.deg2rad(45.0), "rad"),
            (f"{s}_leg_sideways", 0.25, "m"),
            (f"{s}_foot_fast", 1.2, "m/s"),
        ]
    rows += [
        ("hands_apart", 0.75, "m"),
        ("hands_near", -0.15, "m"),
        ("feet_apart", 0.5, "m"),
        ("spine_bent_forward", np.deg2rad(30.0), "rad"),
        ("lying", np.deg2rad(65.0), "rad"),
        ("pelvis_low", -0.6, "m"),
        ("head_low", -1.2, "m"),
    ]
    return tuple((name, float(thr), unit) for name, thr, unit in rows)


#: ``(name, threshold, unit)`` of every relational feature, in output order; feature = ``value > threshold``.
#: Values (see :func:`relational_features`): ``*_front`` / ``*_behind`` signed distance to the torso plane (or
#: the pelvis along the hips' forward), ``*_above_*`` height over the neck (along the spine) or head, ``*_sideways``
#: outward offset from the shoulder / hip, ``*_bent`` angle between consecutive bones, ``*_raised`` (elbow) height
#: over the shoulder along the spine, ``thigh_raised`` thigh angle from straight down, ``*_fast`` speed relative to
#: the pelvis, ``near``/``low`` negated distances / heights over the lowest foot, ``foot_raised`` ankle height over
#: the other ankle, ``spine_bent_forward`` forward lean of pelvis → neck, ``lying`` its angle from vertical.
RELATIONAL_FEATURES: tuple[tuple[str, float, str], ...] = _relational_table()
RELATIONAL_FEATURE_NAMES: tuple[str, ...] = tuple(name for name, _, _ in RELATIONAL_FEATURES)


def relational_features(seq, fps: float = 30.0, soft: bool = False) -> np.ndarray:
    """Boolean relational pose features (Müller & Röder style) per frame: float32 ``[T, 39]``.

    Args:
        seq: landmarks ``[T, 20, 3]`` (metres, y up, :func:`~mocapkit.motion.geometry.normalised_landmarks`).
        fps: frame rate of ``seq`` (Hz), for the velocity features (``*_fast``, m/s).
        soft: ``False``: 1.0 where the relation holds (``value > threshold``), else 0.0. ``True``: the sigmoid of
            the signed margin ``(value − threshold) / scale`` with ``scale`` 5 cm, 0.1 rad or 0.25 m/s, in (0, 1)
            (a smooth version for DTW).

    Returns:
        float32 ``[T, len(RELATIONAL_FEATURES)]``, columns in :data:`RELATIONAL_FEATURE_NAMES` order.
    """
    P = _as_sequence(seq)
    values = _relational_values(P, fps)
    V = np.stack([values[name] for name in RELATIONAL_FEATURE_NAMES], axis=1)  # [T, F]
    thr = np.array([t for _, t, _ in RELATIONAL_FEATURES])
    if not soft:
        return (V > thr).astype(np.float32)
    scale = np.array([_SCALES[u] for _, _, u in RELATIONAL_FEATURES])
    margin = np.clip((V - thr) / scale, -60.0, 60.0)
    return (1.0 / (1.0 + np.exp(-margin))).astype(np.float32)


# --------------------------------------------------------------------------- HOD

HOD_PLANES: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (1, 2))  # xy, xz, yz


def hod(seq, bins: int = 8, levels: int = 3) -> np.ndarray:
    """Histogram of Oriented Displacements (Gowayyed et al. 2013) of one sequence.

    Each non-pelvis landmark's trajectory (19 of them; the pelvis sits at the origin) is projected on the xy, xz
    and yz planes; every displacement between consecutive frames votes for the bin of its angle
    (``atan2(second, first axis)``, ``bins`` equal bins over [−π, π)) with its length as weight, within each
    segment of a temporal pyramid: level ``l`` splits the displacements into ``2**l`` equal parts (whole, halves,
    quarters for ``levels=3``). Each histogram is divided by its sum (ℓ1; an empty or motionless one stays zeros).
    Translation-invariant (displacements only); scale enters only through the relative weights.

    Args:
        seq: landmarks ``[T, 20, 3]``; ``T >= 2`` for a non-zero result.
        bins: orientation bins per histogram.
        levels: pyramid levels (``2**levels − 1`` segments).

    Returns:
        float32 ``[19 * 3 * (2**levels − 1) * bins]``, laid out as ``[landmark, plane, segment, bin]`` (C order):
        landmarks in :data:`LANDMARK_NAMES` order without the pelvis, planes xy, xz, yz, segments level by level
        (whole sequence, first half, second half, first quarter, ...), bins from angle −π upwards.
    """
    P = _as_sequence(seq)
    bins, levels = int(bins), int(levels)
    if bins < 1 or levels < 1:
        raise ValueError(f"bins and levels must be >= 1, got bins={bins}, levels={levels}")
    n_joints, n_planes, n_seg = P.shape[1] - 1, len(HOD_PLANES), 2**levels - 1
    hist = np.zeros((n_joints, n_planes, n_seg, bins))
    n = P.shape[0] - 1  # displacements
    if n >= 1:
        D = np.diff(np.delete(P, PELVIS, axis=1), axis=0)  # [n, 19, 3]
        a = np.array([p[0] for p in HOD_PLANES])
        b = np.array([p[1] for p in HOD_PLANES])
        u, v = D[..., a], D[..., b]  # [n, 19, 3 planes]
        weight = np.hypot(u, v)
        angle_bin = np.floor((np.arctan2(v, u) + np.pi) / (2 * np.pi) * bins).astype(np.int64)
        angle_bin = np.clip(angle_bin, 0, bins - 1)
        t = np.arange(n)
        segments = np.stack([2**lev - 1 + (t * 2**lev) // n for lev in range(levels)], axis=1)  # [n, levels]
        joint = np.arange(n_joints)[None, :, None, None]
        plane = np.arange(n_planes)[None, None, :, None]
        seg = segments[:, None, None, :]
        index = ((joint * n_planes + plane) * n_seg + seg) * bins + angle_bin[..., None]  # [n, 19, 3, levels]
        w = np.broadcast_to(weight[..., None], index.shape)
        hist = np.bincount(index.ravel(), weights=w.ravel(), minlength=hist.size).reshape(hist.shape)
        total = hist.sum(axis=-1, keepdims=True)
        hist = np.divide(hist, total, out=np.zeros_like(hist), where=total > 1e-12)
    return hist.astype(np.float32).ravel()


# --------------------------------------------------------------------------- geometric pose descriptors

#: Landmarks of the pairwise distances of :func:`pose_descriptors` (the pelvis, head and the limb ends).
POSE_DISTANCE_LANDMARKS = (
    "pelvis",
    "head",
    "l_elbow",
    "l_hand",
    "r_elbow",
    "r_hand",
    "l_knee",
    "l_foot",
    "r_knee",
    "r_foot",
)
#: Landmarks whose signed distance to the torso plane (9) / the sagittal plane (8, all but the head) is taken.
POSE_PLANE_LANDMARKS = ("head", "l_elbow", "l_hand", "r_elbow", "r_hand", "l_knee", "l_foot", "r_knee", "r_foot")
#: Landmarks whose height over the lowest foot is taken.
POSE_HEIGHT_LANDMARKS = ("pelvis", "head", "l_hand", "r_hand", "l_foot", "r_foot")
#: Landmarks whose velocity (3 components, m/s) is taken.
POSE_VELOCITY_LANDMARKS = POSE_PLANE_LANDMARKS


def pose_descriptors(seq, fps: float = 30.0) -> np.ndarray:
    """Geometric pose features per frame (Chen et al. 2011 style), continuous: float32 ``[T, 104]``.

    Columns, in order:

    * 45 pairwise distances (m) among :data:`POSE_DISTANCE_LANDMARKS` (upper-triangle order);
    * 9 signed distances (m) of :data:`POSE_PLANE_LANDMARKS` to the torso plane (pelvis, shoulders; + = front);
    * 8 signed distances (m) of the same landmarks but the head to the sagittal plane through the neck with the
      shoulder line as normal (+ = left);
    * 6 heights (m) of :data:`POSE_HEIGHT_LANDMARKS` over the lowest ankle or foot;
    * 9 joint angles (rad): elbows and knees (between consecutive bones), shoulders (spine vs upper arm), hips
      (spine vs thigh), each left then right, and the trunk inclination (spine vs vertical);
    * 27 velocities (m/s, x, y, z) of :data:`POSE_VELOCITY_LANDMARKS` relative to the pelvis (central
      differences × ``fps``; zeros for a single frame).

    Args:
        seq: landmarks ``[T, 20, 3]`` (metres, y up).
        fps: frame rate of ``seq`` (Hz).
    """
    P = _as_sequence(seq)
    f = _body_frame(P)
    T = P.shape[0]
    pelvis, neck = P[:, PELVIS], P[:, NECK]

    def j(name):
        return P[:, _I[name]]

    idx = [_I[n] for n in POSE_DISTANCE_LANDMARKS]
    iu, ju = np.triu_indices(len(idx), k=1)
    L = P[:, idx]
    dist = np.linalg.norm(L[:, iu] - L[:, ju], axis=-1)  # [T, 45]
    plane_pts = P[:, [_I[n] for n in POSE_PLANE_LANDMARKS]]
    front = _dot(plane_pts - pelvis[:, None], f["torso_forward"][:, None])  # [T, 9]
    side = _dot(plane_pts[:, 1:] - neck[:, None], f["torso_left"][:, None])  # [T, 8]
    heights = P[:, [_I[n] for n in POSE_HEIGHT_LANDMARKS], 1] - f["floor"][:, None]  # [T, 6]
    spine = neck - pelvis
    angles = []
    for s in _SIDES:
        angles.append(_angle(j(f"{s}_elbow") - j(f"{s}_shoulder"), j(f"{s}_wrist") - j(f"{s}_elbow")))
    for s in _SIDES:
        angles.append(_angle(j(f"{s}_knee") - j(f"{s}_hip"), j(f"{s}_ankle") - j(f"{s}_knee")))
    for s in _SIDES:
        angles.append(_angle(spine, j(f"{s}_elbow") - j(f"{s}_shoulder")))
    for s in _SIDES:
        angles.append(_angle(spine, j(f"{s}_knee") - j(f"{s}_hip")))
    angles.append(_angle(spine, np.broadcast_to(_UP, spine.shape)))
    vel = _velocity(P[:, [_I[n] for n in POSE_VELOCITY_LANDMARKS]] - pelvis[:, None], fps).reshape(T, -1)
    return np.concatenate([dist, front, side, heights, np.stack(angles, axis=1), vel], axis=1).astype(np.float32)


# --------------------------------------------------------------------------- GPF bag of words with LLC

POOLINGS = ("max", "mean")


def llc_codes(X: np.ndarray, codebook: np.ndarray, k: int = 5, beta: float = 1e-4, chunk: int = 4096) -> np.ndarray:
    """Approximated LLC codes (Wang et al. 2010) of the rows of ``X`` [n, F] on ``codebook`` [K, F]: float64 [n, K].

    For each row ``x``: its ``k`` nearest codewords ``B`` [k, F] (Euclidean), ``C = (B − 1xᵀ)(B − 1xᵀ)ᵀ``,
    ``C += beta · tr(C) · I``, ``w = C⁻¹1 / 1ᵀC⁻¹1`` (sum to one); the other ``K − k`` entries are zero.
    """
    X = np.asarray(X, dtype=np.float64)
    B = np.asarray(codebook, dtype=np.float64)
    n, K = X.shape[0], B.shape[0]
    k = int(min(max(int(k), 1), K))
    codes = np.zeros((n, K))
    b2 = (B * B).sum(1)
    eye = np.eye(k)
    for a in range(0, n, chunk):
        x = X[a : a + chunk]
        d2 = (x * x).sum(1, keepdims=True) - 2.0 * x @ B.T + b2
        nn = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < K else np.broadcast_to(np.arange(K), (len(x), K))
        Z = B[nn] - x[:, None, :]  # [c, k, F]
        C = Z @ Z.transpose(0, 2, 1)
        tr = np.trace(C, axis1=1, axis2=2)[:, None, None]
        C = C + (beta * tr + 1e-12) * eye
        w = np.linalg.solve(C, np.ones((len(x), k, 1)))[..., 0]
        w = w / w.sum(1, keepdims=True)
        np.put_along_axis(codes[a : a + chunk], nn, w, axis=1)
    return codes


class GPFBagOfWords(TransformerMixin, BaseEstimator):
    """GPF-BoVW: per-frame :func:`pose_descriptors`, standardised, LLC-coded on a k-means codebook, pooled over
    the frames of each sequence and ℓ2-normalised (spec §4.5; Wang et al. 2010 for LLC).

    Args:
        n_words: codebook size ``K`` (the output dimension).
        llc_k: nearest codewords per frame in LLC.
        llc_beta: LLC regulariser, relative to ``tr C``.
        pooling: ``"max"`` (the LLC paper's) or ``"mean"`` over the frames of a sequence.
        fps: frame rate of the sequences (Hz), for the velocity descriptors.
        random_state: seed of the frame sample and of k-means.

    Fitted attributes: ``mean_``, ``scale_`` (``[F]``, the descriptors' z-score), ``codebook_`` ``[n_words, F]``
    (in standardised units), ``n_frames_fit_``.
    """

    #: at most this many frames (sampled uniformly without replacement) train the codebook
    max_fit_frames = 50_000

    def __init__(
        self,
        n_words: int = 256,
        llc_k: int = 5,
        llc_beta: float = 1e-4,
        pooling: str = "max",
        fps: float = 30.0,
        random_state=0,
    ):
        self.n_words = n_words
        self.llc_k = llc_k
        self.llc_beta = llc_beta
        self.pooling = pooling
        self.fps = fps
        self.random_state = random_state

    def _descriptors(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        if isinstance(sequences, np.ndarray) and sequences.ndim == 3:
            sequences = [sequences]
        out = [pose_descriptors(s, fps=self.fps).astype(np.float64) for s in sequences]
        if not out:
            raise ValueError("no sequences")
        return out

    def fit(self, sequences: Sequence[np.ndarray], y=None) -> GPFBagOfWords:
        """Learn the descriptor z-score and the k-means codebook from the frames of ``sequences`` ([T_i, 20, 3])."""
        if self.pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {POOLINGS}, got {self.pooling!r}")
        if int(self.n_words) < 1 or int(self.llc_k) < 1:
            raise ValueError(f"n_words and llc_k must be >= 1, got {self.n_words}, {self.llc_k}")
        frames = np.concatenate(self._descriptors(sequences), axis=0)
        if len(frames) < int(self.n_words):
            raise ValueError(f"{len(frames)} frames cannot train a codebook of n_words={self.n_words}")
        rng = check_random_state(self.random_state)
        if len(frames) > self.max_fit_frames:
            frames = frames[np.sort(rng.choice(len(frames), self.max_fit_frames, replace=False))]
        self.mean_ = frames.mean(0)
        std = frames.std(0)
        self.scale_ = np.where(std > 1e-8, std, 1.0)
        Z = (frames - self.mean_) / self.scale_
        if len(Z) <= 20_000:
            km = KMeans(n_clusters=int(self.n_words), n_init=1, max_iter=100, random_state=rng)
        else:
            km = MiniBatchKMeans(n_clusters=int(self.n_words), n_init=3, batch_size=4096, random_state=rng)
        self.codebook_ = km.fit(Z).cluster_centers_.astype(np.float64)
        self.n_frames_fit_ = len(Z)
        return self

    def transform(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """float32 ``[n_sequences, n_words]``: pooled LLC codes, each row of unit ℓ2 norm."""
        if not hasattr(self, "codebook_"):
            raise NotFittedError("GPFBagOfWords is not fitted: call fit(sequences) first")
        if self.pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {POOLINGS}, got {self.pooling!r}")
        descs = self._descriptors(sequences)
        out = np.zeros((len(descs), self.codebook_.shape[0]))
        for i, d in enumerate(descs):
            codes = llc_codes((d - self.mean_) / self.scale_, self.codebook_, self.llc_k, self.llc_beta)
            out[i] = codes.max(0) if self.pooling == "max" else codes.mean(0)
        norm = np.linalg.norm(out, axis=1, keepdims=True)
        return np.divide(out, norm, out=np.zeros_like(out), where=norm > 1e-12).astype(np.float32)
