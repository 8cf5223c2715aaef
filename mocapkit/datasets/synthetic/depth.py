"""Synthetic depth video of a performer from mocap: ``mocapkit synth depth`` (the data of Lou 2012 ch. 3, digest
``../shared/spec/thesis-lou-2012-noisy-motion.md`` §2.3, with a sensor noise model the thesis did not have).

:func:`render_depth_sequence` turns Kinect-20 landmarks (metres, y up; ``kinect_noise.kinect20_from_motion``) into
a :class:`~mocapkit.datasets.formats.depth_images.DepthSequence`:

- **camera**: placed per take as the Kinect skeleton simulator places it (``kinect_noise.place_camera``: 2–3.5 m
  away, 0.8 m above the floor, the performer turned by up to 45°), with the
  field of view of the chosen intrinsics and, where the noise model has a range limit, no farther than half a metre
  inside it (so the body is not cut away by the range).
- **body**: the 17 capsules of :data:`~mocapkit.datasets.synthetic.kinect_noise.CAPSULES` with the simulator's
  default radii, scaled by the performer's stature (:func:`stature_scale`) and by a **girth factor drawn per take**,
  uniform in :data:`GIRTH_RANGE` (0.9–1.15): the tracker's nominal body model never fits the data exactly, as a real
  performer's body never fits a hand-made model. Only the body is rendered: background (no floor, no walls) is 0.
- **depth**: the nearest capsule along each pixel's ray (``capsule_render.raycast_capsules``), then the sensor's
  errors (:class:`DepthNoiseConfig`, :func:`apply_depth_noise`), then whole
  millimetres (uint16), always.
- **parts**: the clean label of the capsule each pixel's ray hits (1-based, in ``CAPSULES`` order; 0 = none), before
  any noise: they can be non-zero where the depth is a hole.
- **colour**: every capsule a fixed colour of :data:`PALETTE`, Lambert-shaded by a light at the camera, plus noise;
  background mid-grey with noise. Registered to the depth image (the same pixels).
- **joints**: the ground-truth Kinect-20 landmarks in camera coordinates (x right, y down, z forward, metres);
  **sensor_joints** / **sensor_state**: what a Kinect SDK would report for the same take from the same camera
  (:func:`~mocapkit.datasets.synthetic.kinect_noise.simulate_kinect`, preset ``real_sensor``), also in camera
  coordinates; **camera_to_world** maps both back to the input's world frame.

The sensor noise model (:meth:`DepthNoiseConfig.preset`) is **an approximation**: published figures for one sensor,
applied per pixel to a body of capsules; what each number is and where it comes from is in
:class:`DepthNoiseConfig`. Everything random derives from one seed (fixed streams for camera and sensor skeleton,
body, depth noise and colour noise).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.depth_images import (
    CAMERA_PRESETS,
    CameraIntrinsics,
    DepthSequence,
    camera_from_argument,
    write_depth_sequence,
)
from mocapkit.datasets.synthetic.kinect_noise import (
    CAPSULES,
    KinectNoiseConfig,
    VirtualCamera,
    file_seed,
    place_camera,
    simulate_kinect,
)
from mocapkit.motion.layouts import LANDMARK_NAMES

#: Noise presets of :meth:`DepthNoiseConfig.preset`.
NOISE_PRESETS: tuple[str, ...] = ("kinect_v1", "azure_kinect", "none")
#: Range of the per-take girth factor (capsule radii times this, uniform).
GIRTH_RANGE: tuple[float, float] = (0.9, 1.15)
#: Stature of the body the default capsule radii were chosen for (m).
NOMINAL_STATURE_M = 1.75
#: Ankle → knee → hip plus pelvis → spine → neck → head, as a share of stature: 0.246 (shank) + 0.245 (thigh) +
#: 0.405 (hip joint to head centre), segment proportions of Drillis & Contini (1966) as tabulated in Winter,
#: *Biomechanics and Motor Control of Human Movement*. Approximate: a mocap head landmark above the head's centre
#: makes a performer a few per cent larger.
CHAIN_SHARE_OF_STATURE = 0.896
#: Clip of the stature scale (a skeleton in other units or a child's stays a plausible body).
STATURE_SCALE_RANGE: tuple[float, float] = (0.5, 1.5)
#: The body capsules' names: part ``k`` (1-based) of ``parts`` is ``CAPSULE_NAMES[k - 1]``.
CAPSULE_NAMES: tuple[str, ...] = tuple(CAPSULES)
#: One fixed RGB colour per capsule, in :data:`CAPSULE_NAMES` order (left and right differ).
PALETTE: np.ndarray = np.array(
    [
        (214, 39, 40),  # torso
        (255, 152, 150),  # upper_torso
        (148, 103, 189),  # chest
        (140, 86, 75),  # pelvis
        (227, 119, 194),  # head
        (31, 119, 180),  # l_upper_arm
        (174, 199, 232),  # l_forearm
        (23, 190, 207),  # l_hand
        (44, 160, 44),  # r_upper_arm
        (152, 223, 138),  # r_forearm
        (188, 189, 34),  # r_hand
        (255, 127, 14),  # l_thigh
        (255, 187, 120),  # l_shin
        (196, 156, 148),  # l_foot
        (127, 127, 127),  # r_thigh
        (219, 219, 141),  # r_shin
        (158, 218, 229),  # r_foot
    ],
    dtype=np.float32,
)
#: Background grey level, and the σ of the colour noise (8-bit levels).
BACKGROUND_GREY = 128
COLOUR_NOISE = 3.0
#: Share of a capsule's colour lit whatever its angle (the rest is Lambert, cos θ to the camera).
AMBIENT = 0.3

_INDEX = {name: k for k, name in enumerate(LANDMARK_NAMES)}
_CAP_A = np.array([_INDEX[a] for a, _ in CAPSULES.values()])
_CAP_B = np.array([_INDEX[b] for _, b in CAPSULES.values()])
#: Image convention (y down) from the skeleton simulator's camera frame (y up).
_FLIP_Y = np.diag([1.0, -1.0, 1.0])


class DepthSynthesisError(ValueError):
    """A motion file that cannot be rendered (unreadable, no body landmarks); the message names the file."""


# ------------------------------------------------------------------------------------------------ noise


@dataclass(frozen=True)
class DepthNoiseConfig:
    """The depth sensor's errors, applied per pixel by :func:`apply_depth_noise` (in this order).

    θ is the angle between the surface normal and the ray back to the camera; z the depth in metres.

    1. **lateral noise**: each pixel takes its depth (and θ) from a pixel displaced by a rounded Gaussian offset of
       σ_L = ``lateral_sigma_px + lateral_angle_px · θ / (π/2 − θ)`` pixels per axis: silhouette edges become ragged.
    2. **grazing-angle holes**: θ above ``grazing_limit_deg`` → 0 (too little light returns).
    3. **edge dropout**: a pixel next to background or to a depth jump above ``edge_jump_m`` (4-neighbours) → 0 with
       probability ``edge_dropout`` (structured-light IR shadow, time-of-flight flying pixels that the SDK drops).
    4. **axial noise**: Gaussian along z, σ_z = ``axial_sigma_m + axial_linear · z + axial_quadratic_per_m ·
       (z − axial_reference_m)² + axial_angle_m / √z · θ² / (π/2 − θ)²``.
    5. **disparity quantisation**: 1/z rounded to a multiple of ``disparity_step_per_m`` (0 = off): a structured-
       light sensor measures disparity in whole (sub-)pixel steps, so its depth steps grow with z².
    6. **random dropout** with probability ``dropout``; depth outside ``[min_range_m, max_range_m]`` → 0.
    7. whole millimetres (uint16), always.

    Presets (:meth:`preset`):

    ``kinect_v1`` (structured light, the Kinect of Lou 2012): steps 1 and 4 are Nguyen, Izadi & Lovell (2012),
    "Modeling Kinect sensor noise for improved 3D reconstruction and tracking" (3DIMPVT), fitted on planes:
    σ_z = 0.0012 + 0.0019 (z − 0.4)² m plus their angle term 0.0001/√z · θ²/(π/2 − θ)² m, σ_L = 0.8 + 0.035 θ/(π/2
    − θ) pixels (their pixels are 640×480 ones; we apply the same number to the 320×240 stream, a simplification).
    Step 5: depth resolution ≈ 2.85·10⁻³ z² m (Khoshelham & Oude Elberink 2012, "Accuracy and resolution of Kinect
    depth data for indoor mapping applications", Sensors 12), i.e. 1/z in steps of 2.85·10⁻³ m⁻¹. Range 0.8–4.0 m
    (the Kinect for Windows default range). Our choices, not measurements: holes beyond θ = 75°, edge pixels
    (jumps above 5 cm) dropped with probability 0.5, random dropout 0.5 %.

    ``azure_kinect`` (time of flight, NFOV unbinned): Microsoft's hardware specification gives a systematic error
    below 11 mm + 0.1 % of the distance and a random error σ ≤ 17 mm, and an operating range of 0.5–3.86 m;
    Tölgyessy et al. (2021), "Evaluation of the Azure Kinect and its comparison to Kinect V1 and Kinect V2"
    (Sensors 21, 413), confirm those bounds. 17 mm is a worst-case bound, not a typical σ: we use σ_z = 1 mm +
    0.001 · z (2 mm at 1 m, 4 mm at 3 m), **a choice of ours** of a few millimetres, inside the bound (not a fit to a
    published measurement), with no angle term and no lateral noise (a ToF pixel measures its own depth). The systematic
    error is not simulated. Holes beyond θ = 75°, edge pixels dropped with probability 0.3 (flying pixels the SDK
    invalidates), random dropout 0.2 %: our choices.

    ``none``: exact depth (whole millimetres), no holes, no range limit.
    """

    name: str = "custom"
    axial_sigma_m: float = 0.0  # m, constant part of σ_z
    axial_linear: float = 0.0  # m of σ_z per m of depth
    axial_quadratic_per_m: float = 0.0  # 1/m; σ_z term · (z − axial_reference_m)²
    axial_reference_m: float = 0.0  # m
    axial_angle_m: float = 0.0  # m·√m; σ_z term / √z · θ²/(π/2 − θ)²
    lateral_sigma_px: float = 0.0  # pixels
    lateral_angle_px: float = 0.0  # pixels; σ_L term · θ/(π/2 − θ)
    disparity_step_per_m: float = 0.0  # 1/m; step of 1/z, 0 = no quantisation but whole millimetres
    grazing_limit_deg: float = 90.0  # degrees; θ above it → hole (90 = never)
    edge_jump_m: float = 0.05  # m; a larger depth step between 4-neighbours is an edge
    edge_dropout: float = 0.0  # probability, edge pixels → 0
    dropout: float = 0.0  # probability, any pixel → 0
    min_range_m: float = 0.0  # m
    max_range_m: float | None = None  # m, None = no limit

    def __post_init__(self) -> None:
        for name in ("edge_dropout", "dropout"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"DepthNoiseConfig.{name} must be in [0, 1], got {getattr(self, name)}")
        for name in (
            "axial_sigma_m",
            "axial_linear",
            "axial_quadratic_per_m",
            "axial_angle_m",
            "lateral_sigma_px",
            "lateral_angle_px",
            "disparity_step_per_m",
            "edge_jump_m",
            "min_range_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"DepthNoiseConfig.{name} must be a non-negative number, got {value}")
        if not 0.0 < self.grazing_limit_deg <= 90.0:
            raise ValueError(f"DepthNoiseConfig.grazing_limit_deg must be in (0, 90], got {self.grazing_limit_deg}")
        if self.max_range_m is not None and not self.max_range_m > self.min_range_m:
            raise ValueError(
                f"DepthNoiseConfig: max_range_m ({self.max_range_m}) must exceed min_range_m ({self.min_range_m})"
            )

    @classmethod
    def preset(cls, name: str) -> DepthNoiseConfig:
        """``"kinect_v1"``, ``"azure_kinect"`` or ``"none"`` (figures and sources: the class docstring)."""
        if name == "kinect_v1":
            return cls(
                name="kinect_v1",
                axial_sigma_m=0.0012,
                axial_quadratic_per_m=0.0019,
                axial_reference_m=0.4,
                axial_angle_m=0.0001,
                lateral_sigma_px=0.8,
                lateral_angle_px=0.035,
                disparity_step_per_m=2.85e-3,
                grazing_limit_deg=75.0,
                edge_dropout=0.5,
                dropout=0.005,
                min_range_m=0.8,
                max_range_m=4.0,
            )
        if name == "azure_kinect":
            return cls(
                name="azure_kinect",
                axial_sigma_m=0.001,
                axial_linear=0.001,
                grazing_limit_deg=75.0,
                edge_dropout=0.3,
                dropout=0.002,
                min_range_m=0.5,
                max_range_m=3.86,
            )
        if name == "none":
            return cls(name="none")
        raise ValueError(f"unknown depth noise preset {name!r}; known: {', '.join(NOISE_PRESETS)}")

    def axial_sigma(self, depth_m: np.ndarray, theta: np.ndarray | float = 0.0) -> np.ndarray:
        """σ_z (m) at depth ``depth_m`` (m) and angle ``theta`` (radians, below π/2), step 4 of the class docstring."""
        z = np.asarray(depth_m, dtype=np.float64)
        theta = np.asarray(theta, dtype=np.float64)
        sigma = (
            self.axial_sigma_m + self.axial_linear * z + self.axial_quadratic_per_m * (z - self.axial_reference_m) ** 2
        )
        if self.axial_angle_m:
            sigma = sigma + self.axial_angle_m / np.sqrt(np.maximum(z, 1e-3)) * _angle_ratio(theta) ** 2
        return sigma

    def lateral_sigma(self, theta: np.ndarray | float = 0.0) -> np.ndarray:
        """σ_L (pixels) at angle ``theta`` (radians), step 1 of the class docstring."""
        return self.lateral_sigma_px + self.lateral_angle_px * _angle_ratio(np.asarray(theta, dtype=np.float64))


def _angle_ratio(theta: np.ndarray) -> np.ndarray:
    """θ / (π/2 − θ), with θ kept below 89° (steeper pixels are holes in every preset that uses it)."""
    theta = np.minimum(theta, math.radians(89.0))
    return theta / (math.pi / 2 - theta)


def noise_config(noise: str | DepthNoiseConfig | None, intrinsics: CameraIntrinsics) -> DepthNoiseConfig:
    """The noise model ``noise`` names; None: the camera's own preset (``kinect_v1`` for a custom camera)."""
    if isinstance(noise, DepthNoiseConfig):
        return noise
    if noise is None:
        noise = intrinsics.name if intrinsics.name in CAMERA_PRESETS else "kinect_v1"
    return DepthNoiseConfig.preset(str(noise))


def apply_depth_noise(
    depth_m: np.ndarray,
    cos_theta: np.ndarray,
    config: DepthNoiseConfig,
    rng: np.random.Generator | int | None = 0,
) -> np.ndarray:
    """One frame of clean depth → the sensor's depth image (steps 1–7 of :class:`DepthNoiseConfig`).

    Args:
        depth_m: ``[H, W]`` clean depth (m), 0 = nothing.
        cos_theta: ``[H, W]`` cosine of the angle between the surface normal and the ray back to the camera.
        config: the noise model.
        rng: the random stream, or its seed (the same draws whatever the config, so that switching one error off
            leaves the others' noise as it was).

    Returns:
        uint16 ``[H, W]`` depth in millimetres, 0 = no measurement.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    cos_theta = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    H, W = z.shape
    rng = np.random.default_rng(rng)
    lateral = rng.standard_normal((2, H, W))
    axial = rng.standard_normal((H, W))
    uniform = rng.random((2, H, W))
    theta = np.arccos(cos_theta)
    if config.lateral_sigma_px or config.lateral_angle_px:
        offset = np.rint(lateral * config.lateral_sigma(theta)).astype(np.int64)
        rows = np.clip(np.arange(H)[:, None] + offset[0], 0, H - 1)
        cols = np.clip(np.arange(W)[None, :] + offset[1], 0, W - 1)
        z, theta = z[rows, cols], theta[rows, cols]
    valid = z > 0
    edge = np.zeros_like(valid)
    padded = np.pad(z, 1, mode="edge")  # the image border is not an edge
    for dr, dc in ((0, 1), (2, 1), (1, 0), (1, 2)):
        neighbour = padded[dr : dr + H, dc : dc + W]
        edge |= (neighbour <= 0) | (np.abs(neighbour - z) > config.edge_jump_m)
    noisy = z + config.axial_sigma(z, theta) * axial
    if config.disparity_step_per_m:
        disparity = np.rint(1.0 / (np.maximum(noisy, 1e-3) * config.disparity_step_per_m))
        noisy = 1.0 / (np.maximum(disparity, 1.0) * config.disparity_step_per_m)
    keep = valid & (theta <= math.radians(config.grazing_limit_deg) + 1e-12)
    keep &= ~(edge & (uniform[0] < config.edge_dropout))
    keep &= uniform[1] >= config.dropout
    keep &= noisy >= config.min_range_m
    if config.max_range_m is not None:
        keep &= noisy <= config.max_range_m
    millimetres = np.clip(np.rint(noisy * 1000.0), 1, 65535)
    return np.where(keep, millimetres, 0).astype(np.uint16)


# ------------------------------------------------------------------------------------------------- body


def stature_scale(positions: np.ndarray) -> float:
    """The performer's size relative to a :data:`NOMINAL_STATURE_M` adult, from Kinect-20 landmarks ``[T, 20, 3]``
    (m): the median over frames of ankle → knee → hip (mean of both legs) plus pelvis → spine → neck → head, over
    :data:`CHAIN_SHARE_OF_STATURE` × 1.75 m, clipped to :data:`STATURE_SCALE_RANGE`. Segment lengths do not change
    with the pose, so a take of crouching gives the same scale as one of standing."""
    p = np.asarray(positions, dtype=np.float64)

    def length(a: str, b: str) -> np.ndarray:
        return np.linalg.norm(p[:, _INDEX[a]] - p[:, _INDEX[b]], axis=-1)

    legs = sum(length(f"{s}_ankle", f"{s}_knee") + length(f"{s}_knee", f"{s}_hip") for s in ("l", "r")) / 2
    chain = legs + length("pelvis", "spine") + length("spine", "neck") + length("neck", "head")
    scale = float(np.median(chain)) / (CHAIN_SHARE_OF_STATURE * NOMINAL_STATURE_M)
    return float(np.clip(scale, *STATURE_SCALE_RANGE))


def body_radii(positions: np.ndarray, girth: float) -> np.ndarray:
    """float64 ``[17]`` capsule radii (m, :data:`CAPSULE_NAMES` order): the skeleton simulator's defaults times
    :func:`stature_scale` times ``girth``."""
    default = KinectNoiseConfig().capsule_radius_m
    return np.array([default[name] for name in CAPSULE_NAMES]) * stature_scale(positions) * float(girth)


# ---------------------------------------------------------------------------------------------- render


def _seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, np.random.Generator):
        return np.random.SeedSequence(int(seed.integers(2**63)))
    return np.random.SeedSequence(seed)


def _child(sequence: np.random.SeedSequence, k: int) -> np.random.SeedSequence:
    """Child ``k`` of ``sequence``, a fresh object each call (``spawn`` would count calls and change the streams)."""
    return np.random.SeedSequence(sequence.entropy, spawn_key=(*sequence.spawn_key, k))


def _seed_metadata(sequence: np.random.SeedSequence) -> dict:
    return {"entropy": sequence.entropy, "spawn_key": list(sequence.spawn_key)}


def camera_rotation(camera: VirtualCamera) -> np.ndarray:
    """``[3, 3]`` world → camera rotation of ``camera`` in the image convention (rows: x right, y down, z forward)."""
    return _FLIP_Y @ camera.axes


def _placement_config(config: KinectNoiseConfig, noise: DepthNoiseConfig) -> KinectNoiseConfig:
    """The camera placement of ``config`` kept half a metre inside the noise model's range (the body stays seen)."""
    if noise.max_range_m is None:
        return config
    far = max(noise.max_range_m - 0.5, config.min_subject_distance_m)
    low, high = config.camera_distance_m
    return replace(
        config,
        camera_distance_m=(min(low, far), min(high, far)),
        max_camera_distance_m=min(config.max_camera_distance_m, far),
    )


def render_depth_sequence(
    positions: np.ndarray,
    fps: float,
    camera: str | CameraIntrinsics = "kinect_v1",
    noise: str | DepthNoiseConfig | None = None,
    seed: int | np.random.SeedSequence | np.random.Generator | None = 0,
    source: str = "",
    device: str = "cpu",
    sensor_config: KinectNoiseConfig | None = None,
) -> DepthSequence:
    """Render the depth video of a performer (module docstring).

    Args:
        positions: ``[T, 20, 3]`` Kinect-20 world landmarks (metres, y up, in ``LANDMARK_NAMES`` order), e.g. from
            :func:`~mocapkit.datasets.synthetic.kinect_noise.kinect20_from_motion`.
        fps: their frame rate.
        camera: intrinsics, a preset name or a ``camera.yaml`` path.
        noise: a :class:`DepthNoiseConfig` or preset name; None: the camera's preset (``kinect_v1`` for a custom one).
        seed: everything random derives from it.
        source: where the positions came from, for messages and ``metadata["source"]``.
        device: torch device of the ray casting.
        sensor_config: the skeleton simulator's config for ``sensor_joints`` (default ``real_sensor``); its field of
            view is replaced by the camera's.

    Returns:
        the :class:`~mocapkit.datasets.formats.depth_images.DepthSequence`, every field filled.
    """
    import torch

    from mocapkit.datasets.synthetic.capsule_render import raycast_capsules

    intrinsics = camera_from_argument(camera)
    noise_cfg = noise_config(noise, intrinsics)
    clean = np.asarray(positions, dtype=np.float64)
    if clean.ndim != 3 or clean.shape[1:] != (len(LANDMARK_NAMES), 3) or len(clean) == 0:
        raise ValueError(
            f"{source or 'positions'}: must be [frames ≥ 1, 20, 3] Kinect-20 landmarks, got {list(clean.shape)}"
        )
    if not np.isfinite(clean).all():
        raise ValueError(f"{source or 'positions'}: positions must be finite")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps}")
    root = _seed_sequence(seed)
    sensor_seed, body_rng, depth_rng, colour_rng = (
        _child(root, 0),
        *(np.random.default_rng(_child(root, k)) for k in (1, 2, 3)),
    )
    sensor_cfg = replace(
        sensor_config or KinectNoiseConfig.preset("real_sensor"), field_of_view_deg=intrinsics.field_of_view_deg
    )
    # the same child seed places the camera and drives the skeleton simulator: simulate_kinect(positions, cfg,
    # sensor_seed) alone would place this camera too (given the same placement limits)
    virtual = place_camera(clean, _placement_config(sensor_cfg, noise_cfg), sensor_seed)
    sensor, state = simulate_kinect(clean, sensor_cfg, _child(root, 0), fps, camera=virtual)
    rotation = camera_rotation(virtual)
    origin = np.asarray(virtual.position, dtype=np.float64)
    joints = (clean - origin) @ rotation.T
    sensor_joints = (np.asarray(sensor, dtype=np.float64) - origin) @ rotation.T
    camera_to_world = np.eye(4)
    camera_to_world[:3, :3] = rotation.T
    camera_to_world[:3, 3] = origin

    girth = float(body_rng.uniform(*GIRTH_RANGE))
    radii = body_radii(clean, girth)
    T, (H, W) = len(clean), intrinsics.shape
    depth_mm = np.zeros((T, H, W), dtype=np.uint16)
    parts = np.zeros((T, H, W), dtype=np.uint8)
    colour = np.zeros((T, H, W, 3), dtype=np.uint8)
    dtype = torch.float32
    ends_a = torch.as_tensor(joints[:, _CAP_A], dtype=dtype, device=device)
    ends_b = torch.as_tensor(joints[:, _CAP_B], dtype=dtype, device=device)
    radius = torch.as_tensor(radii, dtype=dtype, device=device)
    with torch.no_grad():
        for t in range(T):
            hits = raycast_capsules(ends_a[t], ends_b[t], radius, intrinsics)
            # cos θ between the outward normal and the ray back to the camera (the light is at the camera too)
            cos = -(hits.normals * hits.points).sum(-1) / hits.points.norm(dim=-1).clamp_min(1e-9)
            depth = hits.full_image(intrinsics).cpu().numpy()
            capsule = hits.full_image(intrinsics, hits.capsule, fill=-1).cpu().numpy()
            cos = hits.full_image(intrinsics, cos).cpu().numpy()
            depth_mm[t] = apply_depth_noise(depth, cos, noise_cfg, depth_rng)
            parts[t] = capsule + 1
            colour[t] = _shade(capsule, cos, colour_rng)
    empty = int((~depth_mm.reshape(T, -1).any(axis=1)).sum())
    metadata = {
        "renderer": "mocapkit.datasets.synthetic.depth",
        "source": str(source),
        "noise": noise_cfg.name,
        "noise_config": asdict(noise_cfg),
        "sensor_skeleton": "real_sensor" if sensor_config is None else "custom",
        "girth_factor": girth,
        "stature_scale": stature_scale(clean),
        "capsule_radius_m": dict(zip(CAPSULE_NAMES, radii.tolist())),
        "seed": _seed_metadata(root),
        "camera_position": origin.tolist(),
        "camera_look_at": np.asarray(virtual.look_at, dtype=np.float64).tolist(),
        "empty_frames": empty,
    }
    return DepthSequence(
        depth_mm=depth_mm,
        intrinsics=intrinsics,
        fps=float(fps),
        colour=colour,
        parts=parts,
        part_names=CAPSULE_NAMES,
        joints=joints.astype(np.float32),
        joint_names=tuple(LANDMARK_NAMES),
        sensor_joints=sensor_joints.astype(np.float32),
        sensor_state=np.asarray(state, dtype=np.int8),
        camera_to_world=camera_to_world,
        source=str(source),
        metadata=metadata,
    )


def _shade(capsule: np.ndarray, cos: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """uint8 ``[H, W, 3]``: capsule colours, Lambert-shaded (light at the camera), on a grey background, noisy."""
    hit = capsule >= 0
    albedo = np.where(hit[..., None], PALETTE[np.maximum(capsule, 0)], np.float32(BACKGROUND_GREY))
    light = np.where(hit, AMBIENT + (1.0 - AMBIENT) * np.clip(cos, 0.0, 1.0), 1.0)[..., None]
    noise = COLOUR_NOISE * rng.standard_normal(albedo.shape)
    return np.clip(np.rint(albedo * light + noise), 0, 255).astype(np.uint8)


# ---------------------------------------------------------------------------------------------- batches


def synthesise_depth(
    paths: Iterable[str | os.PathLike],
    out: str | os.PathLike,
    camera: str | CameraIntrinsics = "kinect_v1",
    noise: str | DepthNoiseConfig | None = None,
    seed: int = 0,
    fps: float = 30.0,
    format: str = "npz",
    max_frames: int | None = None,
    skip_bad: bool = False,
    progress: bool | None = None,
    device: str = "cpu",
) -> tuple[list[Path], list[tuple[Path, str]]]:
    """Render mocap files as depth sequences: one ``out/<stem>.npz`` (``format="npz"``) or ``out/<stem>/`` folder
    (``format="png"``) per motion file.

    Args:
        paths: motion files :func:`~mocapkit.datasets.formats.motion_io.read_motion` reads, and folders (searched
            recursively for them).
        out: output folder (created).
        camera, noise: as :func:`render_depth_sequence`.
        seed: base seed; each file's is :func:`~mocapkit.datasets.synthetic.kinect_noise.file_seed` of it and the
            file name, so a file's output does not depend on the others.
        fps: frame rate the motions are resampled to.
        format: ``"npz"`` or ``"png"``.
        max_frames: render at most the first this many frames of each motion.
        skip_bad: skip unreadable or unusable files (each reported: returned and warned) instead of raising.
        progress: tqdm bar (default: when more than 20 files).
        device: torch device of the ray casting.

    Returns:
        ``(written, skipped)``: the paths written, in input order; ``(path, reason)`` per skipped file.

    Raises:
        DepthSynthesisError: a file that cannot be read or used, naming it (unless ``skip_bad``); two inputs with the
            same file name (their outputs would collide).
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths, read_motion
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion

    if format not in ("npz", "png"):
        raise ValueError(f"format must be 'npz' or 'png', got {format!r}")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be at least 1, got {max_frames}")
    intrinsics = camera_from_argument(camera)
    noise_cfg = noise_config(noise, intrinsics)
    files = expand_motion_paths(list(paths), "input", empty_error=DepthSynthesisError)
    seen: dict[str, Path] = {}
    for path in files:
        if path.stem in seen:
            raise DepthSynthesisError(f"{path} and {seen[path.stem]}: same name, their outputs would collide in {out}")
        seen[path.stem] = path
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    iterator: Sequence[Path] = files
    if progress if progress is not None else len(files) > 20:
        from tqdm import tqdm

        iterator = tqdm(files, desc="synth depth", unit="file")
    written: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    for path in iterator:
        try:
            positions = kinect20_from_motion(read_motion(path), fps=fps)
        except (OSError, ValueError) as exc:
            reason = str(exc) if str(path) in str(exc) else f"{path}: {exc}"
            if not skip_bad:
                raise DepthSynthesisError(reason) from exc
            warnings.warn(f"synthesise_depth skipped {reason}", stacklevel=2)
            skipped.append((path, reason))
            continue
        if max_frames is not None:
            positions = positions[:max_frames]
        sequence = render_depth_sequence(
            positions, fps, intrinsics, noise_cfg, seed=file_seed(seed, path), source=str(path), device=device
        )
        sequence.metadata["base_seed"] = int(seed)
        target = out / (f"{path.stem}.npz" if format == "npz" else path.stem)
        written.append(write_depth_sequence(sequence, target))
    return written, skipped


__all__ = [
    "CAPSULE_NAMES",
    "GIRTH_RANGE",
    "NOISE_PRESETS",
    "PALETTE",
    "DepthNoiseConfig",
    "DepthSynthesisError",
    "apply_depth_noise",
    "body_radii",
    "camera_rotation",
    "noise_config",
    "render_depth_sequence",
    "stature_scale",
    "synthesise_depth",
]
