"""Kinect posture reconstruction (Zhou 2014, chapter 5): a per-joint sparse-GP prior on the offset
mocap − Kinect, a constant-velocity temporal term and a per-joint reliability term, minimised frame by frame in
closed form; and the Shen et al. 2012-style random-forest baseline.

Everything works on 20-joint Kinect v1 skeletons ``[T, 20, 3]`` in
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order (HipCenter 0, Spine 1, ShoulderCenter 2, Head 3,
left arm 4–7, right arm 8–11, left leg 12–15, right leg 16–19), metres, y up. Design choices where the thesis is
silent (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §4 and §7 items 23–32):

**Frames (§7 item 23).** :func:`normalise_posture` is the thesis's F (§4.1, §1.7), per posture: retarget to the
template skeleton of :mod:`mocapkit.motion.geometry` (every bone keeps its direction, takes the template
length), HipCenter moved to the origin, yaw about y removed so that the hip line (left → right) points along −x
(the body faces +z; the angle is taken on the retargeted hips, exactly as
:func:`~mocapkit.motion.geometry.normalised_landmarks` does). The GP *inputs* are these normalised positions;
the GP *outputs* are the offsets ``mocap − kinect`` expressed in the normalised frame, i.e. turned by the frame's
yaw and divided by the clip's size factor ``s`` (sum of the clip's median Kinect bone lengths / sum of the
template's). At run time the predicted offset mean is turned back by the inverse yaw and multiplied by ``s``,
its variance multiplied by ``s²``; the temporal term, the reliability term and the output are in **world**
coordinates (the raw Kinect frame), so errors are measured against world mocap.
:class:`PostureTransform` holds the per-frame translation, yaw and input bone lengths (its :meth:`to_world` is an
exact inverse of F) and the per-clip ``s``.

**Spatial term (§4.2, §7 item 28).** One sparse GP per joint ``i``: input = normalised positions of ``i`` and its
neighbours ``N(i)`` (the joints sharing a bone with ``i``), flattened (6–15 numbers; ``gp_input="posture"``
instead gives every joint's GP the whole normalised posture, 60 numbers, as the random forest sees it: not the
thesis's model); output = its 3-D normalised offset. The 3 coordinates share one kernel and one noise (as Lawrence's GP toolbox, which the thesis used, does
for multi-dimensional outputs), so the predictive variance is one number per joint and frame, isotropic, and
unchanged by the yaw rotation; offsets are centred per coordinate and divided by one scalar per joint.
Kernel = RBF + bias + noise (thesis eq. 4.3, isotropic): ``gpytorch.kernels.InducingPointKernel`` over
``ScaleKernel(RBFKernel) + ConstantKernel`` with a ``GaussianLikelihood``, i.e. SGPR (Titsias 2009 collapsed
bound; the thesis names the Quiñonero-Candela & Rasmussen 2005 family, of which this is the DTC/VFE member).
All 20 joints are one batch of independent models (inputs zero-padded to 15 dimensions, the padding frozen):
the objective is the sum over joints and coordinates of the exact SGPR bound, optimised by Adam for
``gp_iterations`` steps (hyper-parameters and inducing points; inducing points start at k-means centres of the
joint's training inputs, seeded). Prediction uses the SGPR (DTC) predictive in closed form, float64, from the
trained hyper-parameters: mean and variance of the *observation* (noise included).

**Reliability (§4.4, §7 item 26)** — an *approximation* of Shum et al. 2013, whose formulas the thesis does not
give; see :func:`joint_reliability`.

**Energy (§4.5, §7 item 31).** Per frame ``t`` and joint ``j`` the energy
``w_S‖y − μ‖²/(2σ²) + w_T‖y − c‖² + w_R r²‖y‖²`` with ``c = 2m_{t−1} − m_{t−2} − x_t`` (previous *reconstructed*
frames) is minimised in closed form: ``y* = (w_S/σ²·μ + 2w_T·c) / (w_S/σ² + 2w_T + 2w_R·r²)``, ``m_t = x_t + y*``.
E_T is dropped for the first two frames. When the denominator is 0 (e.g. only ``w_R`` with ``r = 0``, or only
``w_T`` in the first two frames) every offset has the same energy and the input is kept (``y* = 0``): with only
E_R the output is the raw input, with only E_T it is constant-velocity extrapolation from the first two input
frames (Table 5.3 (b) and (a)). The energy's length unit matters (``σ²`` against the unit-free weights): it is
``energy_unit`` metres, centimetres by default — the thesis's error unit; in metres the GP term would outweigh
the others ~10⁴ times and the weights 0.6/0.2/0.2 would have no effect.

**Rigid output (ours, off by default).** The minimiser moves each joint on its own, so the output's bone lengths
vary from frame to frame even on a steady input; ``rigid_bones=True`` then gives every bone the clip's median
reconstructed length along its reconstructed direction (from HipCenter outwards).

Errors are :func:`mocapkit.kinect.metrics.joint_error_cm` (eqs. 5.7–5.9 with the per-frame mean, §7 item 29).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from mocapkit.datasets.cache_files import save_npz_atomic
from mocapkit.kinect.steady import check_steady_params, steady_output
from mocapkit.motion.container import all_coordinates
from mocapkit.motion.geometry import TEMPLATE_BONES, hip_line_heading, retarget, turn_about_up
from mocapkit.motion.layouts import LANDMARK_NAMES, LANDMARK_PARENTS

N_JOINTS = 20
MODEL_FORMAT = "mocapkit-kinect-reconstruction-1"
PELVIS, L_HIP, R_HIP = 0, LANDMARK_NAMES.index("l_hip"), LANDMARK_NAMES.index("r_hip")
#: Kinect SDK v1 tracking states.
NOT_TRACKED, INFERRED, TRACKED = 0, 1, 2
#: Reliability of each tracking state (indexed by the state value).
STATE_RELIABILITY = np.array([0.0, 0.5, 1.0])
#: Template bone length (m) of each joint's bone to its parent, 0 for the root.
TEMPLATE_LENGTHS = np.array([0.0] + [TEMPLATE_BONES[name] for name in LANDMARK_NAMES[1:]])
#: Joints sharing a bone with each joint (sorted), e.g. the right hand → (right wrist,).
NEIGHBOURS: tuple[tuple[int, ...], ...] = tuple(
    tuple(sorted({LANDMARK_PARENTS[i]} - {-1} | {k for k, p in enumerate(LANDMARK_PARENTS) if p == i}))
    for i in range(N_JOINTS)
)
#: The joints of each joint's GP input: itself, then its neighbours.
GP_INPUT_JOINTS: tuple[tuple[int, ...], ...] = tuple((i, *NEIGHBOURS[i]) for i in range(N_JOINTS))
_MAX_INPUT_DIM = 3 * max(len(j) for j in GP_INPUT_JOINTS)
#: What a joint's GP sees: its own and its neighbours' positions (the thesis), or the whole posture.
GP_INPUTS = ("neighbours", "posture")
COMBINATIONS = ("product", "min")


# ----------------------------------------------------------------------------------------------------- validation


def _check_clip(clip, name: str) -> np.ndarray:
    """float64 ``[T, 20, 3]`` with T ≥ 1 and finite values, or a ValueError naming ``name``."""
    try:
        arr = np.asarray(clip, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name}: not a numeric [T, 20, 3] array ({err})") from None
    if arr.ndim != 3 or arr.shape[1:] != (N_JOINTS, 3) or arr.shape[0] < 1:
        raise ValueError(
            f"{name}: expected a [T, 20, 3] array (T ≥ 1 frames of the 20 Kinect v1 joints), got shape {arr.shape}"
        )
    bad = ~all_coordinates(np.isfinite(arr))
    if bad.any():
        t, j = np.argwhere(bad)[0]
        raise ValueError(
            f"{name}: {int(bad.sum())} non-finite joint position(s), the first at frame {t}, joint "
            f"{j} ({LANDMARK_NAMES[j]})"
        )
    return arr


def _check_clips(clips, name: str) -> list[np.ndarray]:
    if isinstance(clips, np.ndarray) and clips.ndim == 3:
        clips = [clips]
    if isinstance(clips, (str, bytes)) or not hasattr(clips, "__len__"):
        raise ValueError(f"{name}: expected a list of [T, 20, 3] arrays, got {type(clips).__name__}")
    if len(clips) == 0:
        raise ValueError(f"{name}: no clips")
    return [_check_clip(c, f"{name}[{k}]") for k, c in enumerate(clips)]


def _check_state(state, frames: int, name: str) -> np.ndarray | None:
    if state is None:
        return None
    arr = np.asarray(state)
    if arr.shape != (frames, N_JOINTS):
        raise ValueError(f"{name}: expected a [T, 20] tracking-state array with T = {frames}, got shape {arr.shape}")
    if not np.isin(arr, (NOT_TRACKED, INFERRED, TRACKED)).all():
        raise ValueError(
            f"{name}: tracking states must be 0 (not tracked), 1 (inferred) or 2 (tracked), got "
            f"values {np.unique(arr[~np.isin(arr, (0, 1, 2))])[:5].tolist()}"
        )
    return arr.astype(np.int64)


def _check_states(states, lengths: list[int], name: str) -> list[np.ndarray | None]:
    if states is None:
        return [None] * len(lengths)
    if isinstance(states, np.ndarray) and states.ndim == 2:
        states = [states]
    if len(states) != len(lengths):
        raise ValueError(f"{name}: {len(states)} state arrays for {len(lengths)} clips")
    return [_check_state(s, n, f"{name}[{k}]") for k, (s, n) in enumerate(zip(states, lengths))]


def _check_pairs(kinect_clips, mocap_clips) -> tuple[list[np.ndarray], list[np.ndarray]]:
    kinect = _check_clips(kinect_clips, "kinect_clips")
    mocap = _check_clips(mocap_clips, "mocap_clips")
    if len(kinect) != len(mocap):
        raise ValueError(f"{len(kinect)} kinect clips but {len(mocap)} mocap clips; they must be paired")
    for k, (a, b) in enumerate(zip(kinect, mocap)):
        if len(a) != len(b):
            raise ValueError(f"clip {k}: kinect_clips[{k}] has {len(a)} frames but mocap_clips[{k}] has {len(b)}")
    return kinect, mocap


def _check_nonneg(name: str, value, integer: bool = False, minimum: float = 0.0):
    ok = isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.number))
    if isinstance(value, bool) or not ok or not math.isfinite(float(value)) or value < minimum:
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{name}={value!r}: must be {kind} ≥ {minimum:g}")


# --------------------------------------------------------------------------------------------------- normalisation


def bone_lengths(positions: np.ndarray) -> np.ndarray:
    """``[T, 20]``: the length of each joint's bone to its parent (0 for HipCenter)."""
    parents = np.array(LANDMARK_PARENTS)
    lengths = np.linalg.norm(positions - positions[:, np.maximum(parents, 0)], axis=-1)
    lengths[:, PELVIS] = 0.0
    return lengths


@dataclass
class PostureTransform:
    """What :func:`normalise_posture` removed from a clip, to map back to the world frame.

    Attributes:
        translation: ``[T, 3]`` HipCenter position of each input frame (m).
        yaw: ``[T]`` heading (rad) each frame was turned by: its hip line's yaw from −x
            (:func:`~mocapkit.motion.geometry.hip_line_heading` with ``along="-x"``: the body then faces +z).
        lengths: ``[T, 20]`` the input's bone lengths (each joint to its parent; 0 for HipCenter).
        scale: the clip's size factor: sum of its median bone lengths / sum of the template's.
    """

    translation: np.ndarray
    yaw: np.ndarray
    lengths: np.ndarray
    scale: float

    def to_world(self, normalised: np.ndarray) -> np.ndarray:
        """Exact inverse of F: positions ``[T, 20, 3]`` in the normalised frame → world (each bone keeps its
        normalised direction and takes back the input's length; then inverse yaw, then the translation)."""
        out = retarget(np.asarray(normalised, dtype=np.float64), lengths=self.lengths)
        return turn_about_up(out, -self.yaw, along="-x") + self.translation[:, None]

    def offsets_to_world(self, offsets: np.ndarray) -> np.ndarray:
        """Offsets ``[T, 20, 3]`` in the normalised frame → world: inverse yaw, times ``scale``."""
        return turn_about_up(np.asarray(offsets, dtype=np.float64), -self.yaw, along="-x") * self.scale

    def offsets_to_normalised(self, offsets: np.ndarray) -> np.ndarray:
        """World offsets ``[T, 20, 3]`` (e.g. mocap − kinect) → the normalised frame: yaw, divided by ``scale``."""
        return turn_about_up(np.asarray(offsets, dtype=np.float64), self.yaw, along="-x") / self.scale

    def variance_to_world(self, variance: np.ndarray) -> np.ndarray:
        """Isotropic offset variances (any shape) in the normalised frame → world (times ``scale²``)."""
        return np.asarray(variance, dtype=np.float64) * self.scale**2


def normalise_posture(kinect: np.ndarray) -> tuple[np.ndarray, PostureTransform]:
    """Zhou's F (§4.1 / §1.7), per posture: ``(normalised [T, 20, 3], transform)``.

    Each frame is retargeted to the template skeleton (:func:`~mocapkit.motion.geometry.retarget`: bones keep
    their direction and take :data:`~mocapkit.motion.geometry.TEMPLATE_BONES` lengths), HipCenter moved to the
    origin, and turned about y so that its (retargeted) hip line, left → right, points along −x (facing +z), as in
    :func:`~mocapkit.motion.geometry.normalised_landmarks` with ``heading="frame"``. The result is invariant to
    the subject's position, facing direction and size; ``transform`` (:class:`PostureTransform`) maps back.

    Raises:
        ValueError: ``kinect`` is not a finite ``[T, 20, 3]`` array.
    """
    x = _check_clip(kinect, "kinect")
    lengths = bone_lengths(x)
    translation = x[:, PELVIS].copy()
    p = retarget(x - translation[:, None])
    yaw = hip_line_heading(p, L_HIP, R_HIP, along="-x")  # the body's yaw: it then faces +z
    reference = TEMPLATE_LENGTHS.sum()
    scale = float(np.median(lengths, axis=0).sum() / reference)
    if not scale > 1e-6:
        scale = 1.0
    return turn_about_up(p, yaw, along="-x"), PostureTransform(translation, yaw, lengths, scale)


# ----------------------------------------------------------------------------------------------------- reliability


def _attachment_matrix() -> np.ndarray:
    """``[20 joints, 20 bones]`` (bone = its child joint): row j averages the bones attached to joint j."""
    A = np.zeros((N_JOINTS, N_JOINTS))
    for child, parent in enumerate(LANDMARK_PARENTS):
        if parent >= 0:
            A[child, child] = A[parent, child] = 1.0
    return A / A.sum(axis=1, keepdims=True)


_ATTACHED = _attachment_matrix()


def behaviour_reliability(
    kinect: np.ndarray, jump_threshold: float = 0.15, still_threshold: float = 0.01
) -> np.ndarray:
    """``[T, 20]`` in [0, 1] from each joint's own trajectory (causal: frame t uses t−2, t−1, t).

    - direction: ``clip(1 + cos θ, 0, 1)`` with θ the angle between the displacements into t−1 and into t, so
      turns up to 90° keep 1 and a reversal gives 0; it counts only when both displacements exceed
      ``still_threshold`` (m/frame; weight ramping 0 → 1 from 1× to 2× the threshold), since the direction of a
      near-still joint is noise;
    - jumps: ``exp(−max(0, d − τ)/τ)`` with ``d`` the displacement into t and ``τ = jump_threshold`` (m/frame,
      0.15 = 4.5 m/s at 30 fps).

    Frames 0 (and 1 for the direction) have no history and keep 1 for that part.
    """
    x = _check_clip(kinect, "kinect")
    rel = np.ones(x.shape[:2])
    if len(x) < 2:
        return rel
    d = np.diff(x, axis=0)  # d[t-1] = x_t − x_{t−1}
    speed = np.linalg.norm(d, axis=-1)
    tau = float(jump_threshold)
    rel[1:] *= np.exp(-np.maximum(speed - tau, 0.0) / tau) if tau > 0 else 1.0
    if len(x) >= 3:
        prod = speed[1:] * speed[:-1]
        cos = np.where(prod > 0, (d[1:] * d[:-1]).sum(-1) / np.maximum(prod, 1e-300), 1.0)
        direction = np.clip(1.0 + cos, 0.0, 1.0)
        slow = np.minimum(speed[1:], speed[:-1])
        weight = np.clip(slow / still_threshold - 1.0, 0.0, 1.0) if still_threshold > 0 else (slow > 0) * 1.0
        rel[2:] *= 1.0 - weight * (1.0 - direction)
    return rel


def kinematic_reliability(kinect: np.ndarray, kappa: float = 5.0, reference: np.ndarray | None = None) -> np.ndarray:
    """``[T, 20]`` in [0, 1]: ``exp(−κ · mean over the joint's attached bones of |ℓ − ℓ_ref| / ℓ_ref)``.

    ``ℓ_ref`` = ``reference`` (``[20]``, each joint's bone to its parent) or the clip's median bone lengths.
    Averaging (rather than taking the worst bone) singles out the joint between two stretched bones: a wrong
    wrist stretches both the forearm and the hand bone, its elbow and hand only one of them.
    """
    x = _check_clip(kinect, "kinect")
    lengths = bone_lengths(x)
    ref = np.median(lengths, axis=0) if reference is None else np.asarray(reference, dtype=np.float64)
    valid = ref > 1e-6
    dev = np.where(valid, np.abs(lengths - ref) / np.where(valid, ref, 1.0), 0.0)
    dev[:, PELVIS] = 0.0
    return np.exp(-float(kappa) * dev @ _ATTACHED.T)


def state_reliability(state: np.ndarray | None, frames: int) -> np.ndarray:
    """``[T, 20]``: TRACKED 1, INFERRED 0.5, NOT_TRACKED 0; all 1 when ``state`` is None."""
    state = _check_state(state, frames, "state")
    return np.ones((frames, N_JOINTS)) if state is None else STATE_RELIABILITY[state]


def joint_reliability(
    kinect: np.ndarray,
    state: np.ndarray | None = None,
    kappa: float = 5.0,
    combine: str = "product",
    jump_threshold: float = 0.15,
    still_threshold: float = 0.01,
) -> np.ndarray:
    """Per-joint reliability ``r ∈ [0, 1]``, ``[T, 20]``, of a Kinect clip (world coordinates, metres).

    An **approximation of Shum et al. 2013** (the thesis's [85]; its formulas are not reproduced in the thesis,
    digest §7 item 26): the product (``combine="product"``) or minimum (``"min"``) of
    :func:`behaviour_reliability`, :func:`kinematic_reliability` (``ℓ_ref`` = the clip's median bone lengths)
    and :func:`state_reliability`. A clean, smooth clip with constant bone lengths and no state has reliability
    1 everywhere.
    """
    if combine not in COMBINATIONS:
        raise ValueError(f"combine={combine!r}: expected one of {COMBINATIONS}")
    x = _check_clip(kinect, "kinect")
    cues = np.stack(
        [
            behaviour_reliability(x, jump_threshold, still_threshold),
            kinematic_reliability(x, kappa),
            state_reliability(state, len(x)),
        ]
    )
    return np.clip(cues.prod(0) if combine == "product" else cues.min(0), 0.0, 1.0)


# ----------------------------------------------------------------------------------------------------- shared data


def _training_pairs(kinect: list[np.ndarray], mocap: list[np.ndarray], max_frames, random_state):
    """Stacked normalised Kinect postures and normalised offsets ``([N, 20, 3], [N, 20, 3])``, subsampled."""
    inputs, offsets = [], []
    for x, m in zip(kinect, mocap):
        norm, tf = normalise_posture(x)
        inputs.append(norm)
        offsets.append(tf.offsets_to_normalised(m - x))
    X, Y = np.concatenate(inputs), np.concatenate(offsets)
    if max_frames is not None and len(X) > max_frames:
        keep = np.sort(check_random_state(random_state).choice(len(X), size=int(max_frames), replace=False))
        X, Y = X[keep], Y[keep]
    return X, Y


def _input_joints(gp_input: str) -> tuple[tuple[int, ...], ...]:
    """The joints of each joint's GP input: :data:`GP_INPUT_JOINTS` (``"neighbours"``) or all 20 (``"posture"``)."""
    if gp_input == "neighbours":
        return GP_INPUT_JOINTS
    if gp_input == "posture":
        return (tuple(range(N_JOINTS)),) * N_JOINTS
    raise ValueError(f"gp_input={gp_input!r}: expected one of {GP_INPUTS}")


def _gp_inputs(normalised: np.ndarray, gp_input: str = "neighbours") -> np.ndarray:
    """Normalised postures ``[N, 20, 3]`` → per-joint GP inputs ``[20, N, D]`` (D = 15 for the neighbours,
    zero-padded; 60 for the whole posture)."""
    joints_of = _input_joints(gp_input)
    out = np.zeros((N_JOINTS, len(normalised), 3 * max(len(j) for j in joints_of)))
    for j, joints in enumerate(joints_of):
        out[j, :, : 3 * len(joints)] = normalised[:, joints].reshape(len(normalised), -1)
    return out


def _input_mask(gp_input: str = "neighbours") -> np.ndarray:
    """``[20, D]``: 1 on the input dimensions each joint's GP uses, 0 on the padding."""
    joints_of = _input_joints(gp_input)
    mask = np.zeros((N_JOINTS, 3 * max(len(j) for j in joints_of)))
    for j, joints in enumerate(joints_of):
        mask[j, : 3 * len(joints)] = 1.0
    return mask


# --------------------------------------------------------------------------------------------------------- the GPs


def _rbf_bias(a: np.ndarray, b: np.ndarray, lengthscale, outputscale, constant) -> np.ndarray:
    """Batched eq. 4.3 kernel without noise: ``os·exp(−|a−b|²/(2ℓ²)) + c``, ``a [J, n, D]``, ``b [J, m, D]``."""
    sq = (a**2).sum(-1)[:, :, None] + (b**2).sum(-1)[:, None, :] - 2.0 * a @ b.transpose(0, 2, 1)
    sq = np.maximum(sq, 0.0)
    return outputscale[:, None, None] * np.exp(-0.5 * sq / lengthscale[:, None, None] ** 2) + constant[:, None, None]


@dataclass
class JointSGPRs:
    """The trained per-joint sparse GPs, stored as the arrays of their closed-form SGPR (DTC) predictive.

    For joint ``j`` and input ``x``: ``k = k(x, Z_j)``, mean ``= y_mean_j + y_scale_j · k·W_j``, variance
    ``= y_scale_j² · (os_j + c_j − k V_j kᵀ + noise_j)`` (the observation's variance, noise included).
    """

    inducing: np.ndarray  # [J, M, D] (padded dimensions zero)
    lengthscale: np.ndarray  # [J]
    outputscale: np.ndarray  # [J]
    constant: np.ndarray  # [J]
    noise: np.ndarray  # [J], standardised units
    weights: np.ndarray  # [J, M, 3]
    var_matrix: np.ndarray  # [J, M, M]
    y_mean: np.ndarray  # [J, 3]
    y_scale: np.ndarray  # [J]

    def predict(self, inputs: np.ndarray, chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint inputs ``[J, N, D]`` → (offset mean ``[N, J, 3]``, variance ``[N, J]``), normalised frame."""
        n = inputs.shape[1]
        mean, var = np.empty((n, N_JOINTS, 3)), np.empty((n, N_JOINTS))
        for s in range(0, n, chunk):
            K = _rbf_bias(inputs[:, s : s + chunk], self.inducing, self.lengthscale, self.outputscale, self.constant)
            mu = K @ self.weights  # [J, n, 3]
            quad = ((K @ self.var_matrix) * K).sum(-1)  # [J, n]: k V kᵀ
            v = np.maximum(self.outputscale + self.constant - quad.T, 0.0) + self.noise  # [n, J]
            mean[s : s + chunk] = (mu * self.y_scale[:, None, None] + self.y_mean[:, None]).transpose(1, 0, 2)
            var[s : s + chunk] = v * self.y_scale**2
        return mean, var


def _kmeans_inducing(inputs: np.ndarray, mask: np.ndarray, m: int, seed: int) -> np.ndarray:
    from sklearn.cluster import KMeans

    Z = np.zeros((inputs.shape[0], m, inputs.shape[2]))
    for j in range(inputs.shape[0]):
        dims = mask[j] > 0
        data = inputs[j][:, dims]
        if m >= len(data):
            Z[j][:, dims] = data[:m]
            continue
        with warnings.catch_warnings():  # duplicate postures → fewer distinct clusters than m: harmless
            warnings.simplefilter("ignore")
            km = KMeans(n_clusters=m, n_init=1, max_iter=50, random_state=seed + j).fit(data)
        Z[j][:, dims] = km.cluster_centers_
    return Z


def _train_sgpr(
    inputs: np.ndarray, targets: np.ndarray, mask: np.ndarray, Z0: np.ndarray, iterations: int, lr: float, device: str
) -> tuple[dict, list[float]]:
    """Adam on the summed exact SGPR bound of ``J`` independent shared-kernel 3-output GPs.

    ``inputs [J, N, D]``, ``targets [J, N, 3]`` (standardised), ``Z0 [J, M, D]``. Returns the hyper-parameters
    and the loss history (negative bound per datum and output, summed over joints).
    """
    import gpytorch
    import torch

    dev = torch.device(device)
    dtype = torch.float64
    J, N, _ = inputs.shape
    x = torch.as_tensor(inputs, dtype=dtype, device=dev)
    y = torch.as_tensor(targets, dtype=dtype, device=dev)
    batch = torch.Size([J])

    # starting values: length-scale = median pairwise input distance of each joint (on ≤ 500 points)
    sub = x[:, :: max(1, N // 500)]
    i, k = torch.triu_indices(sub.shape[1], sub.shape[1], offset=1, device=dev)
    pairs = torch.cdist(sub, sub, compute_mode="donot_use_mm_for_euclid_dist")[:, i, k]  # [J, n(n−1)/2]
    ls0 = torch.stack(
        [torch.quantile(d[d > 0], 0.5) if (d > 0).any() else torch.ones((), dtype=dtype, device=dev) for d in pairs]
    )

    likelihood = gpytorch.likelihoods.GaussianLikelihood(batch_shape=batch).to(device=dev, dtype=dtype)
    likelihood.noise = torch.full((J, 1), 0.1, dtype=dtype, device=dev)
    rbf = gpytorch.kernels.RBFKernel(batch_shape=batch)
    scaled = gpytorch.kernels.ScaleKernel(rbf, batch_shape=batch)
    bias = gpytorch.kernels.ConstantKernel(batch_shape=batch)
    kernel = gpytorch.kernels.InducingPointKernel(scaled + bias, torch.tensor(Z0, dtype=dtype), likelihood)
    kernel = kernel.to(device=dev, dtype=dtype)
    rbf.lengthscale = ls0.view(J, 1, 1)
    scaled.outputscale = torch.ones(J, dtype=dtype, device=dev)
    bias.constant = torch.full((J, 1), 0.1, dtype=dtype, device=dev)
    zmask = torch.as_tensor(mask[:, None, :], dtype=dtype, device=dev)
    kernel.inducing_points.register_hook(lambda g: g * zmask)  # padded input dimensions stay 0

    # (the likelihood is a sub-module of the kernel too: take each parameter once)
    hyper = list(
        {
            id(p): p
            for n, p in [*kernel.named_parameters(), *likelihood.named_parameters()]
            if p is not kernel.inducing_points
        }.values()
    )
    optimiser = torch.optim.Adam([{"params": hyper, "lr": lr}, {"params": [kernel.inducing_points], "lr": lr * 0.2}])
    log2pi = math.log(2.0 * math.pi)
    history = []
    kernel.train()
    likelihood.train()
    with gpytorch.settings.lazily_evaluate_kernels(False):
        for _ in range(int(iterations)):
            optimiser.zero_grad()
            prior = gpytorch.distributions.MultivariateNormal(torch.zeros(J, N, dtype=dtype, device=dev), kernel(x))
            covar = likelihood(prior).lazy_covariance_matrix  # Q + σ²I (low rank + diagonal)
            inv_quad, logdet = covar.inv_quad_logdet(inv_quad_rhs=y, logdet=True)  # Σ over the 3 outputs
            bound = -0.5 * (inv_quad + 3.0 * logdet + 3.0 * N * log2pi)
            for term in kernel.added_loss_terms():  # −tr(K − Q)/(2σ²), per output
                bound = bound + 3.0 * term.loss()
            loss = -(bound / (3.0 * N)).sum()
            loss.backward()
            optimiser.step()
            history.append(float(loss.detach()))
    with torch.no_grad():
        params = {
            "inducing": (kernel.inducing_points * zmask).cpu().numpy().astype(np.float64),
            "lengthscale": rbf.lengthscale.reshape(J).cpu().numpy().astype(np.float64),
            "outputscale": scaled.outputscale.reshape(J).cpu().numpy().astype(np.float64),
            "constant": bias.constant.reshape(J).cpu().numpy().astype(np.float64),
            "noise": likelihood.noise.reshape(J).cpu().numpy().astype(np.float64),
        }
    return params, history


def _sgpr_predictive(inputs: np.ndarray, targets: np.ndarray, params: dict) -> tuple[np.ndarray, np.ndarray]:
    """The SGPR (Titsias 2009) / DTC predictive arrays ``W [J, M, 3]`` and ``V [J, M, M]`` (float64, Cholesky)."""
    Z, ls, os_, c, noise = (params[k] for k in ("inducing", "lengthscale", "outputscale", "constant", "noise"))
    J, M, _ = Z.shape
    eye = np.eye(M)
    Kzz = _rbf_bias(Z, Z, ls, os_, c) + 1e-6 * (os_ + c)[:, None, None] * eye
    Kzx = _rbf_bias(Z, inputs, ls, os_, c)  # [J, M, N]
    sigma = np.sqrt(noise)[:, None, None]
    W, V = np.empty((J, M, 3)), np.empty((J, M, M))
    for j in range(J):
        L = np.linalg.cholesky(Kzz[j])
        A = np.linalg.solve(L, Kzx[j]) / sigma[j]  # L⁻¹K_zx/σ
        LB = np.linalg.cholesky(eye + A @ A.T)
        cvec = np.linalg.solve(LB, A @ targets[j]) / sigma[j]  # L_B⁻¹ A y / σ
        Linv = np.linalg.solve(L, eye)
        LBinv = np.linalg.solve(LB, eye)
        W[j] = Linv.T @ (LBinv.T @ cvec)  # mean = k·W
        V[j] = Linv.T @ (eye - LBinv.T @ LBinv) @ Linv  # var_f = k** − k V kᵀ
    return W, V


# -------------------------------------------------------------------------------------------------- the estimators


class KinectPostureReconstructor(BaseEstimator):
    """Zhou 2014 ch. 5: per-joint sparse-GP offset prior + temporal + reliability energy, solved per frame.

    See the module docstring for the frames, the GP structure and the energy.

    Args:
        w_spatial, w_temporal, w_reliability: the energy weights (thesis 0.6 / 0.2 / 0.2); each ≥ 0, not all 0.
            They are used only by :meth:`predict`, so ``set_params`` after ``fit`` runs the Table 5.3 ablation
            without retraining.
        gp_input: ``"neighbours"`` (the thesis: each joint's GP sees the joint and its neighbours) or ``"posture"``
            (every joint's GP sees the whole normalised posture, 60 numbers, as the random-forest baseline does).
        n_inducing: inducing points per joint GP (capped at the training frames).
        max_train_frames: training frames kept (a seeded random subset of all clips' frames); None = all.
        gp_iterations: Adam steps on the SGPR bound (0 keeps the starting hyper-parameters).
        learning_rate: Adam step of the hyper-parameters (inducing points: a fifth of it).
        reliability: ``"product"`` or ``"min"``: how the three reliability cues combine.
        kappa: the kinematic cue's rate κ (:func:`kinematic_reliability`).
        jump_threshold, still_threshold: the behaviour cue's thresholds, m/frame (:func:`behaviour_reliability`).
        energy_unit: the energy's length unit in metres (0.01: centimetres, see the module docstring).
        rigid_bones: give every output bone the clip's median reconstructed length, keeping the bone directions
            (:func:`~mocapkit.motion.geometry.retarget`; not in the thesis). The energy corrects each joint on
            its own, so its output's bone lengths wobble from frame to frame even on a steady input; this makes the
            skeleton rigid, as a real body is. Applied after ``smooth_window``.
        tracked_correction, smooth_window: the output options of :mod:`mocapkit.kinect.steady` (the share of the
            correction a TRACKED joint gets; a zero-lag Savitzky–Golay filter of that many frames, 0 off).
        device: torch device of the GP training (``"cpu"``, ``"cuda"``); prediction runs in numpy.
        random_state: seeds the frame subset and the k-means initialisation of the inducing points.

    Attributes (after ``fit``): ``gp_`` (:class:`JointSGPRs`), ``n_train_frames_``, ``n_inducing_``,
    ``training_loss_`` (the loss per Adam step). Before ``fit``, :meth:`predict` raises ``NotFittedError``.
    """

    #: Parameters used only by :meth:`predict`: changing them after ``fit`` needs no refit (the comparison
    #: benchmark reuses one fit across them).
    predict_params = (
        "w_spatial",
        "w_temporal",
        "w_reliability",
        "reliability",
        "kappa",
        "jump_threshold",
        "still_threshold",
        "energy_unit",
        "rigid_bones",
        "tracked_correction",
        "smooth_window",
    )

    def __init__(
        self,
        w_spatial: float = 0.6,
        w_temporal: float = 0.2,
        w_reliability: float = 0.2,
        gp_input: str = "neighbours",
        n_inducing: int = 200,
        max_train_frames: int | None = 3000,
        gp_iterations: int = 100,
        learning_rate: float = 0.05,
        reliability: str = "product",
        kappa: float = 5.0,
        jump_threshold: float = 0.15,
        still_threshold: float = 0.01,
        energy_unit: float = 0.01,
        rigid_bones: bool = False,
        tracked_correction: float = 1.0,
        smooth_window: int = 0,
        device: str = "cpu",
        random_state: int | None = 0,
    ):
        self.w_spatial = w_spatial
        self.w_temporal = w_temporal
        self.w_reliability = w_reliability
        self.gp_input = gp_input
        self.n_inducing = n_inducing
        self.max_train_frames = max_train_frames
        self.gp_iterations = gp_iterations
        self.learning_rate = learning_rate
        self.reliability = reliability
        self.kappa = kappa
        self.jump_threshold = jump_threshold
        self.still_threshold = still_threshold
        self.energy_unit = energy_unit
        self.rigid_bones = rigid_bones
        self.tracked_correction = tracked_correction
        self.smooth_window = smooth_window
        self.device = device
        self.random_state = random_state

    # -- checks
    def _check_energy_params(self):
        for name in ("w_spatial", "w_temporal", "w_reliability", "kappa", "jump_threshold", "still_threshold"):
            _check_nonneg(name, getattr(self, name))
        if self.w_spatial + self.w_temporal + self.w_reliability <= 0:
            raise ValueError("at least one of w_spatial, w_temporal, w_reliability must be positive")
        if self.reliability not in COMBINATIONS:
            raise ValueError(f"reliability={self.reliability!r}: expected one of {COMBINATIONS}")
        check_steady_params(self.tracked_correction, self.smooth_window, self.rigid_bones, "KinectPostureReconstructor")
        _check_nonneg("energy_unit", self.energy_unit)
        if self.energy_unit <= 0:
            raise ValueError(f"energy_unit={self.energy_unit!r}: must be positive (metres per unit)")

    def _check_fit_params(self):
        self._check_energy_params()
        _input_joints(self.gp_input)
        _check_nonneg("n_inducing", self.n_inducing, integer=True, minimum=1)
        _check_nonneg("gp_iterations", self.gp_iterations, integer=True)
        if self.max_train_frames is not None:
            _check_nonneg("max_train_frames", self.max_train_frames, integer=True, minimum=1)
        _check_nonneg("learning_rate", self.learning_rate)
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate={self.learning_rate!r}: must be positive")

    # -- training
    def fit(self, kinect_clips, mocap_clips, states=None) -> KinectPostureReconstructor:
        """Train the 20 joint GPs on paired clips (lists of ``[T, 20, 3]`` arrays in metres, same T per pair).

        ``states`` (optional list of ``[T, 20]`` tracking states) is validated but not used: the GP is trained on
        every frame, as the thesis's is (reliability enters only at reconstruction).
        """
        self._check_fit_params()
        kinect, mocap = _check_pairs(kinect_clips, mocap_clips)
        _check_states(states, [len(c) for c in kinect], "states")
        seed = int(check_random_state(self.random_state).randint(2**31 - N_JOINTS))  # k-means seeds
        X, Y = _training_pairs(kinect, mocap, self.max_train_frames, self.random_state)
        inputs = _gp_inputs(X, self.gp_input)  # [J, N, D]
        offsets = Y.transpose(1, 0, 2)  # [J, N, 3]
        y_mean = offsets.mean(1)
        y_scale = np.maximum(np.sqrt(((offsets - y_mean[:, None]) ** 2).mean((1, 2))), 1e-4)
        targets = (offsets - y_mean[:, None]) / y_scale[:, None, None]
        mask = _input_mask(self.gp_input)
        m = min(int(self.n_inducing), len(X))
        Z0 = _kmeans_inducing(inputs, mask, m, seed)
        params, history = _train_sgpr(
            inputs, targets, mask, Z0, self.gp_iterations, float(self.learning_rate), self.device
        )
        W, V = _sgpr_predictive(inputs, targets, params)
        self.gp_ = JointSGPRs(weights=W, var_matrix=V, y_mean=y_mean, y_scale=y_scale, **params)
        self.n_train_frames_ = len(X)
        self.n_inducing_ = m
        self.training_loss_ = history
        return self

    # -- persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted model as one ``.npz`` (plain arrays and the parameters as JSON; no pickles); parent
        folders are created."""
        check_is_fitted(self, "gp_")
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        arrays = {f"gp_{name}": getattr(self.gp_, name) for name in JointSGPRs.__dataclass_fields__}
        meta = {
            "format": MODEL_FORMAT,
            "params": self.get_params(deep=False),
            "n_train_frames": self.n_train_frames_,
            "n_inducing": self.n_inducing_,
        }
        return save_npz_atomic(path, meta=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> KinectPostureReconstructor:
        """A model written by :meth:`save`; a ValueError names the file when it is not one."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {name: data[f"gp_{name}"] for name in JointSGPRs.__dataclass_fields__}
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(
                f"{path}: not a Kinect reconstruction model written by "
                f"KinectPostureReconstructor.save / mocapkit kinect-fix train ({exc})"
            ) from exc
        if meta.get("format") != MODEL_FORMAT:
            raise ValueError(f"{path}: format {meta.get('format')!r}, expected {MODEL_FORMAT!r}")
        model = cls(**meta["params"])
        model.gp_ = JointSGPRs(**arrays)
        model.n_train_frames_, model.n_inducing_ = meta["n_train_frames"], meta["n_inducing"]
        model.training_loss_ = []
        return model

    # -- reconstruction
    def predict_offsets(self, kinect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The GP prior in world coordinates: offset means ``[T, 20, 3]`` (m) and variances ``[T, 20]`` (m²)."""
        check_is_fitted(self, "gp_")
        x = _check_clip(kinect, "kinect")
        norm, tf = normalise_posture(x)
        mean, var = self.gp_.predict(_gp_inputs(norm, self.gp_input))
        return tf.offsets_to_world(mean), tf.variance_to_world(var)

    def reliability_of(self, kinect: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        """:func:`joint_reliability` with this estimator's settings, ``[T, 20]``."""
        return joint_reliability(kinect, state, self.kappa, self.reliability, self.jump_threshold, self.still_threshold)

    def predict(self, kinect, state=None, reliability: np.ndarray | None = None):
        """Reconstruct a Kinect clip ``[T, 20, 3]`` (world, m) → ``[T, 20, 3]`` (world, m).

        ``state``: optional ``[T, 20]`` tracking states; ``reliability``: optional ``[T, 20]`` values in [0, 1]
        replacing :meth:`reliability_of`. A list of clips (and of states) gives a list of reconstructions.
        """
        check_is_fitted(self, "gp_")
        self._check_energy_params()
        if isinstance(kinect, (list, tuple)):
            clips = _check_clips(kinect, "kinect")
            states = _check_states(state, [len(c) for c in clips], "state")
            if reliability is not None:
                raise ValueError("reliability= is for a single clip")
            return [self._reconstruct(c, s, None, f"kinect[{k}]") for k, (c, s) in enumerate(zip(clips, states))]
        return self._reconstruct(kinect, state, reliability, "kinect")

    transform = predict

    def _reconstruct(self, kinect, state, reliability, name: str) -> np.ndarray:
        x = _check_clip(kinect, name)
        T = len(x)
        state = _check_state(state, T, f"state of {name}")
        if reliability is None:
            r = self.reliability_of(x, state) if self.w_reliability > 0 else np.ones((T, N_JOINTS))
        else:
            r = np.asarray(reliability, dtype=np.float64)
            if r.shape != (T, N_JOINTS) or not np.isfinite(r).all() or (r < 0).any() or (r > 1).any():
                raise ValueError(f"reliability for {name}: expected [T, 20] values in [0, 1] with T = {T}")
        if self.w_spatial > 0:
            mu, var = self.predict_offsets(x)
            a = self.w_spatial * self.energy_unit**2 / np.maximum(var, 1e-300)  # w_S/σ² in energy units
        else:
            mu, a = np.zeros_like(x), np.zeros((T, N_JOINTS))
        base_num = a[..., None] * mu  # [T, J, 3]
        base_den = a + 2.0 * self.w_reliability * r**2  # [T, J]
        out = np.empty_like(x)
        head = min(T, 2) if self.w_temporal > 0 else T  # no E_T before frame 2
        out[:head] = x[:head] + _safe_ratio(base_num[:head], base_den[:head])
        two_wt = 2.0 * self.w_temporal
        for t in range(head, T):  # sequential over frames
            c = 2.0 * out[t - 1] - out[t - 2] - x[t]
            out[t] = x[t] + _safe_ratio(base_num[t] + two_wt * c, base_den[t] + two_wt)
        return steady_output(x, out, state, self.tracked_correction, self.smooth_window, self.rigid_bones)


def _safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den[..., None]``, 0 where ``den`` is 0 (a flat energy: keep the input)."""
    ok = den > 0
    return np.where(ok[..., None], num / np.where(ok, den, 1.0)[..., None], 0.0)


class RandomForestPoseCorrector(BaseEstimator):
    """The Shen et al. 2012-style baseline (thesis §5.3, digest §4.6): a random forest regressing all 20
    normalised offsets (60-D) from the whole normalised Kinect posture (60-D), frame by frame, with no
    reliability and no temporal term. Frames and mapping back as in :class:`KinectPostureReconstructor`.

    Args:
        n_estimators, max_depth, min_samples_leaf, n_jobs: of ``sklearn.ensemble.RandomForestRegressor``.
        max_train_frames: training frames kept (seeded random subset); None = all.
        random_state: seeds the subset and the forest.

    Attributes (after ``fit``): ``forest_``, ``n_train_frames_``.
    """

    def __init__(
        self,
        n_estimators: int = 100,
        max_depth: int | None = None,
        min_samples_leaf: int = 5,
        max_train_frames: int | None = None,
        n_jobs: int | None = None,
        random_state: int | None = 0,
    ):
        self.n_estimators = n_estimators
        self.max_depth = max_depth
        self.min_samples_leaf = min_samples_leaf
        self.max_train_frames = max_train_frames
        self.n_jobs = n_jobs
        self.random_state = random_state

    def fit(self, kinect_clips, mocap_clips, states=None) -> RandomForestPoseCorrector:
        """Fit on paired clips (lists of ``[T, 20, 3]``); ``states`` is validated and not used."""
        from sklearn.ensemble import RandomForestRegressor

        _check_nonneg("n_estimators", self.n_estimators, integer=True, minimum=1)
        _check_nonneg("min_samples_leaf", self.min_samples_leaf, integer=True, minimum=1)
        if self.max_depth is not None:
            _check_nonneg("max_depth", self.max_depth, integer=True, minimum=1)
        if self.max_train_frames is not None:
            _check_nonneg("max_train_frames", self.max_train_frames, integer=True, minimum=1)
        kinect, mocap = _check_pairs(kinect_clips, mocap_clips)
        _check_states(states, [len(c) for c in kinect], "states")
        X, Y = _training_pairs(kinect, mocap, self.max_train_frames, self.random_state)
        self.forest_ = RandomForestRegressor(
            n_estimators=self.n_estimators,
            max_depth=self.max_depth,
            min_samples_leaf=self.min_samples_leaf,
            n_jobs=self.n_jobs,
            random_state=self.random_state,
        )
        self.forest_.fit(X.reshape(len(X), -1), Y.reshape(len(Y), -1))
        self.n_train_frames_ = len(X)
        return self

    def predict(self, kinect, state=None):
        """Correct a clip ``[T, 20, 3]`` (or a list of clips) → world ``[T, 20, 3]``; ``state`` is ignored."""
        check_is_fitted(self, "forest_")
        if isinstance(kinect, (list, tuple)):
            return [self._correct(c, f"kinect[{k}]") for k, c in enumerate(_check_clips(kinect, "kinect"))]
        return self._correct(kinect, "kinect")

    transform = predict

    def _correct(self, kinect, name: str) -> np.ndarray:
        x = _check_clip(kinect, name)
        norm, tf = normalise_posture(x)
        offsets = self.forest_.predict(norm.reshape(len(x), -1)).reshape(x.shape)
        return x + tf.offsets_to_world(offsets)


class DoubleExponentialSmoother(BaseEstimator):
    """The smoothing a Kinect v1 user already has: the SDK's joint filter (``NuiTransformSmooth``), a Holt double
    exponential filter with a jitter radius and a maximum deviation, run causally per joint. Nothing is learned
    (``fit`` only checks its input); the comparison runner chooses the parameters by cross-validation on the
    training performers.

    Per joint, with raw position ``x_t``, filtered ``f_t`` and trend ``b_t`` (the SDK's order of steps):

    - ``t = 0``: ``f = x``, ``b = 0``;
    - ``t = 1``: ``f = (x_t + x_{t−1})/2``, ``b = c·(f_t − f_{t−1}) + (1 − c)·b_{t−1}``;
    - later: jitter first — when ``d = |x_t − f_{t−1}| ≤ jitter_radius`` the input becomes
      ``x·d/J + f_{t−1}·(1 − d/J)``; then ``f_t = (1 − s)·x + s·(f_{t−1} + b_{t−1})`` and
      ``b_t = c·(f_t − f_{t−1}) + (1 − c)·b_{t−1}``;
    - output ``f_t + p·b_t``, pulled back to within ``max_deviation`` of the raw ``x_t``.

    Args:
        smoothing (s), correction (c), prediction (p): in [0, 1] (0.5, 0.5, 0.5 are the SDK's defaults).
        jitter_radius, max_deviation: metres (the SDK: 0.05 and 0.04); 0 turns the step off.
    """

    def __init__(
        self,
        smoothing: float = 0.5,
        correction: float = 0.5,
        prediction: float = 0.5,
        jitter_radius: float = 0.05,
        max_deviation: float = 0.04,
    ):
        self.smoothing = smoothing
        self.correction = correction
        self.prediction = prediction
        self.jitter_radius = jitter_radius
        self.max_deviation = max_deviation

    def _check_params(self):
        for name in ("smoothing", "correction", "prediction"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}={value!r}: must be in [0, 1]")
        _check_nonneg("jitter_radius", self.jitter_radius)
        _check_nonneg("max_deviation", self.max_deviation)

    def fit(self, kinect_clips, mocap_clips=None, states=None) -> DoubleExponentialSmoother:
        """Check the parameters and the clips; nothing is learned."""
        self._check_params()
        if mocap_clips is None:
            _check_clips(kinect_clips, "kinect")
        else:
            _check_pairs(kinect_clips, mocap_clips)
        self.fitted_ = True
        return self

    def predict(self, kinect, state=None):
        """Smooth a clip ``[T, 20, 3]`` (or a list of clips) → ``[T, 20, 3]``; ``state`` is ignored."""
        self._check_params()
        if isinstance(kinect, (list, tuple)):
            return [self._smooth(c) for c in _check_clips(kinect, "kinect")]
        return self._smooth(_check_clip(kinect, "kinect"))

    transform = predict

    def _smooth(self, x: np.ndarray) -> np.ndarray:
        s, c, p = float(self.smoothing), float(self.correction), float(self.prediction)
        jitter, deviation = float(self.jitter_radius), float(self.max_deviation)
        out = np.empty_like(x)
        filtered, trend = x[0].copy(), np.zeros_like(x[0])
        for t in range(len(x)):
            raw = x[t]
            if t == 0:
                new_filtered, new_trend = raw.copy(), trend
            elif t == 1:
                new_filtered = 0.5 * (raw + x[0])
                new_trend = c * (new_filtered - filtered) + (1.0 - c) * trend
            else:
                smoothed_raw = raw
                if jitter > 0:
                    d = np.linalg.norm(raw - filtered, axis=-1, keepdims=True)
                    w = np.minimum(d / jitter, 1.0)
                    smoothed_raw = w * raw + (1.0 - w) * filtered
                new_filtered = (1.0 - s) * smoothed_raw + s * (filtered + trend)
                new_trend = c * (new_filtered - filtered) + (1.0 - c) * trend
            predicted = new_filtered + p * new_trend
            if deviation > 0:
                diff = predicted - raw
                d = np.linalg.norm(diff, axis=-1, keepdims=True)
                predicted = raw + diff * np.minimum(1.0, deviation / np.maximum(d, 1e-300))
            out[t] = predicted
            filtered, trend = new_filtered, new_trend
        return out
