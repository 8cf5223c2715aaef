"""Lou 2012 ch. 3: model-based full-body tracking from one depth (+ colour) camera in a MAP framework.

Per frame ``t+1``, starting from the previous estimate ``q_t``, Gauss–Newton minimises (eq. 3.14, digest §2.8)

    E_surf + λ1 E_edge + λ2 E_prior + λ3 ‖q − q_t‖²

over the 34 DOF of :mod:`mocapkit.depth_tracking.body_model`:

- **surface** (§2.5): the body model is rendered at the current estimate (:func:`~mocapkit.datasets.synthetic.
  capsule_render.raycast_capsules`, every ``subsample``-th pixel in each direction); each rendered point, fixed to
  its bone, is matched to the observed pixel of a ``surface_window``² window around it with the least
  ``|Δdepth| + colour_weight · |Δcolour|`` (depth in metres, colour the sum of absolute RGB differences on the 0–255
  scale; the rendered point's colour is the frame-t image sampled where the point was at ``q_t``), and pulled to
  that pixel's 3-D point;
- **depth edges** (§2.6): Canny (kornia) on the observed and the rendered depth (background far away), an edge pixel
  on the background replaced by its nearest foreground neighbour; each *observed* edge point is matched to the
  nearest *rendered* edge point in 3-D within an ``edge_window``² window;
- **prior** (§2.7): :class:`~mocapkit.depth_tracking.lpca.LocalPCAPrior` around ``q_t``;
- **smoothness**: ``λ3 ‖q − q_t‖²`` (also Levenberg damping of DOF no data constrains).

Jacobians ``∂f(a_i; q)/∂q`` are exact and analytic (:func:`~mocapkit.depth_tracking.body_model.
body_points_jacobian`, the chain rule down the bone tree; 8× faster than ``torch.func.jacfwd``, which the tests
compare them with), and everything is PyTorch, so it runs on the tensors' device. Iterations stop when
``‖Δq‖ < tolerance`` or after ``iterations``.

Where the thesis is silent (digest §4 item 14), ours: correspondences farther than ``max_surface_distance``
(depth) or ``max_edge_distance`` (3-D) are dropped as outliers; the Canny thresholds are on the depth gradient in
metres after Gaussian smoothing; colour weights as above. **Start** (§2.4): ``"sensor"`` (what a user has): the
rest pose placed on the sensor skeleton's HipCenter, turned by its hips and spine, inverse kinematics on the sensor
joints (``init_joints``: all 16 by default, the thesis's 5 — head, wrists, ankles — in ``lou_thesis``), then a
depth step on frame 0 without colour; ``"ground_truth"``: the first ground-truth frame (the thesis's synthetic
protocol); ``"standing"``: the rest pose facing the camera. **Skeleton** (the thesis assumes the performer's is
known): bone lengths from the sensor skeleton, the ground truth or a template, or a mocap take of the performer
(:meth:`DepthTracker.predict`'s ``performer``).

**Beyond the thesis** (the registry's ``tracker``; docs/decisions.md#depth-tracker-defaults): Levenberg–Marquardt
damping, 5 cm outlier distances, a wider first step, and the sensor's skeleton (optionally corrected by the Kinect
GP, ``anchor``) as a soft target of weight ``sensor_weight``. Without them the printed method loses the body on
rendered noisy depth; its settings are the registry's ``lou_thesis``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from mocapkit.datasets.formats.depth_images import CameraIntrinsics, DepthSequence
from mocapkit.datasets.synthetic.capsule_render import capsule_box, raycast_capsules
from mocapkit.depth_tracking import body_model as bm
from mocapkit.depth_tracking.base import DepthInputError, check_sequence, tracked_joints
from mocapkit.depth_tracking.lpca import LocalPCAPrior, LocalSubspace

#: Depth given to background pixels before edge detection, metres (the thesis uses a large constant, 100).
FAR = 10.0
PRIORS = ("lpca", "none")
SURFACE_COSTS = ("depth", "point")
#: What the start and the sensor term use: the sensor's skeleton, or that skeleton corrected by the Kinect GP.
ANCHORS = ("sensor", "sensor_gp")
#: The sensor joints the start's inverse kinematics fits: the thesis's five (head, wrists, ankles), or all 16.
INIT_JOINT_SETS = ("five", "all")
#: Metres of cost per pixel of offset added to the depth-only surface cost, so ties go to the nearest pixel.
TIE_BREAK = 1e-4
SKELETONS = ("sensor", "ground_truth", "template")
STARTS = ("sensor", "ground_truth", "standing")


@dataclass
class _Frame:
    """One observed frame on the device: depth (m, 0 = none), 3-D points, colour, edge points."""

    depth: torch.Tensor  # [H, W]
    points: torch.Tensor  # [H, W, 3]
    colour: torch.Tensor | None  # [H, W, 3] float 0–255
    edge_pixels: torch.Tensor  # long [M, 2] (v, u)
    edge_points: torch.Tensor  # [M, 3]
    sensor: torch.Tensor | None = None  # [16, 3] the sensor's joints, when the sequence has them
    sensor_weight: torch.Tensor | None = None  # [16] their weights (by tracking state)


def _unproject(depth: torch.Tensor, k: CameraIntrinsics) -> torch.Tensor:
    v, u = torch.meshgrid(
        torch.arange(depth.shape[0], device=depth.device, dtype=depth.dtype),
        torch.arange(depth.shape[1], device=depth.device, dtype=depth.dtype),
        indexing="ij",
    )
    return torch.stack([(u - k.cx) * depth / k.fx, (v - k.cy) * depth / k.fy, depth], dim=-1)


def _edges(depth: torch.Tensor, points: torch.Tensor, low: float, high: float):
    """Canny edges of a depth image ``[H, W]`` (0 = background): ``(pixels long [M, 2], points [M, 3], source
    long [M, 2])``; an edge pixel on the background takes the 3-D point of its nearest 3×3 foreground neighbour
    (§2.6), pixels without one are dropped; ``source`` is the pixel whose point was taken. Only the box around the
    foreground is searched (edges need a foreground pixel next to them)."""
    import kornia

    foreground = torch.nonzero(depth > 0)
    empty = torch.zeros((0, 2), dtype=torch.long, device=depth.device)
    if len(foreground) == 0:
        return empty, points.new_zeros((0, 3)), empty
    margin = 4
    v0, u0 = (foreground.min(dim=0).values - margin).clamp_min(0).tolist()
    v1, u1 = (foreground.max(dim=0).values + margin + 1).tolist()
    crop = depth[v0:v1, u0:u1]
    far = torch.where(crop > 0, crop, torch.full_like(crop, FAR))
    _, edges = kornia.filters.canny(far[None, None].float(), low_threshold=low, high_threshold=high)
    edges = edges[0, 0] > 0
    # the nearest (smallest-depth) pixel of each 3×3 neighbourhood
    h, w = crop.shape
    padded = torch.nn.functional.pad(far[None, None], (1, 1, 1, 1), value=FAR * 2)[0, 0]
    best = padded.unfold(0, 3, 1).unfold(1, 3, 1).reshape(h, w, 9).argmin(dim=-1)
    rows = torch.arange(h, device=depth.device)[:, None].expand(h, w)
    cols = torch.arange(w, device=depth.device)[None, :].expand(h, w)
    background = crop <= 0
    src_v = torch.where(background, rows + best // 3 - 1, rows).clamp(0, h - 1)
    src_u = torch.where(background, cols + best % 3 - 1, cols).clamp(0, w - 1)
    keep = edges & (crop[src_v, src_u] > 0)
    offset = torch.tensor([v0, u0], device=depth.device)
    pixels = torch.nonzero(keep) + offset
    source = torch.stack([src_v[keep], src_u[keep]], dim=-1) + offset
    return pixels, points[source[:, 0], source[:, 1]], source


def fill_holes(depth: torch.Tensor, passes: int = 2, min_neighbours: int = 5) -> torch.Tensor:
    """Depth ``[H, W]`` (0 = none) with small holes closed: a pixel without depth that has at least
    ``min_neighbours`` of its 8 neighbours measured takes their median, ``passes`` times. Sensor dropouts inside
    the body would otherwise be depth edges (ours; the thesis's synthetic depth had no holes)."""
    h, w = depth.shape
    for _ in range(passes):
        padded = torch.nn.functional.pad(depth[None, None], (1, 1, 1, 1))[0, 0]
        windows = padded.unfold(0, 3, 1).unfold(1, 3, 1).reshape(h, w, 9)[..., [0, 1, 2, 3, 5, 6, 7, 8]]
        valid = windows > 0
        count = valid.sum(-1)
        # median of the valid neighbours: sort with the invalid ones pushed to the end
        ordered = torch.where(valid, windows, torch.full_like(windows, float("inf"))).sort(dim=-1).values
        median = ordered.gather(-1, ((count - 1).clamp_min(0) // 2)[..., None])[..., 0]
        fill = (depth <= 0) & (count >= min_neighbours)
        if not bool(fill.any()):
            break
        depth = torch.where(fill, median, depth)
    return depth


def _window_offsets(size: int, device) -> tuple[torch.Tensor, torch.Tensor]:
    half = size // 2
    r = torch.arange(-half, half + 1, device=device)
    dv, du = torch.meshgrid(r, r, indexing="ij")
    return dv.reshape(-1), du.reshape(-1)


class DepthTracker(BaseEstimator):
    """Lou 2012's MAP tracker (module docstring), a depth-tracking estimator (:mod:`mocapkit.depth_tracking.base`).

    Args:
        surface_window, edge_window: correspondence search windows in pixels (15, 21).
        subsample: rendered points kept every ``subsample`` pixels in each direction (4).
        colour_weight: weight of the colour difference in the surface search (1e-4; 0 or ``use_colour=False``: depth
            only).
        surface_cost: ``"depth"`` (the thesis: the least ``|Δdepth|``, ties to the nearest pixel) or ``"point"``
            (the least 3-D distance).
        use_colour, use_edges: the thesis's ablations (Fig. 3.6a).
        prior: ``"lpca"`` (the database of ``fit``) or ``"none"``.
        neighbours, successors, energy: LPCA's K, w and kept energy (50, 3, 0.95).
        edge_weight, prior_weight, smooth_weight: λ1, λ2, λ3 (10, 0.001, 1e-5).
        constant_velocity: start each frame's iterations at ``q_t + (q_t − q_{t−1})`` instead of ``q_t`` (ours).
        damping: Levenberg–Marquardt damping, ``A + damping · diag(A)`` (ours; 0: the thesis's plain Gauss–Newton,
            which overshoots along directions the data barely constrain).
        sensor_weight: weight of the sensor skeleton's joints as a soft target (ours; per joint × 1 tracked, 0.5
            inferred, 0 not tracked; 0: not used, the thesis).
        anchor: the skeleton the start and the sensor term use: ``"sensor"`` (as the sequence has it) or
            ``"sensor_gp"`` (corrected by the Kinect GP of Zhou ch. 5, fitted in :meth:`fit` on the training
            sequences' sensor and ground-truth joints; ours).
        anchor_corrector: the GP's parameters over the registry's ``kinect/gp`` (None: as registered).
        iterations, tolerance: Gauss–Newton iterations per frame at most (10) and the ``‖Δq‖`` that stops them.
        init_iterations, init_reach: the first frame's depth step: its iterations, and how many times wider its
            outlier distances start (shrinking to the normal ones over its first half).
        init_joints: the sensor joints the start's inverse kinematics fits: ``"five"`` (head, wrists, ankles: the
            thesis) or ``"all"`` 16.
        max_surface_distance, max_edge_distance: outlier rejection of correspondences (metres).
        canny_low, canny_high: Canny hysteresis thresholds on the smoothed depth gradient (metres).
        skeleton: where bone lengths come from: ``"sensor"`` (the anchor's, median over the take),
            ``"ground_truth"`` (the thesis's known performer) or
            ``"template"`` (a 1.7 m body); :meth:`predict`'s ``performer`` overrides it.
        start: the first frame's pose: ``"sensor"`` (IK on sensor joints, then a depth step), ``"ground_truth"``
            (the thesis's synthetic protocol) or ``"standing"`` (the rest pose facing the camera at the depth's
            median point, then a depth step).
        device: ``"cpu"``, ``"cuda"``...; ``"auto"``: CUDA where there is one.
        progress: a tqdm bar per sequence.

    Attributes (after ``fit``): ``prior_`` (:class:`LocalPCAPrior` or None), ``database_frames_``,
    ``anchor_model_`` (the fitted GP anchor or None).
    """

    def __init__(
        self,
        surface_window: int = 15,
        edge_window: int = 21,
        subsample: int = 4,
        colour_weight: float = 1e-4,
        surface_cost: str = "depth",
        use_colour: bool = True,
        use_edges: bool = True,
        prior: str = "none",
        neighbours: int = 50,
        successors: int = 3,
        energy: float = 0.95,
        edge_weight: float = 10.0,
        prior_weight: float = 1e-3,
        smooth_weight: float = 1e-5,
        constant_velocity: bool = False,
        damping: float = 0.1,
        sensor_weight: float = 10.0,
        anchor: str = "sensor",
        anchor_corrector: dict | None = None,
        iterations: int = 10,
        init_iterations: int = 30,
        init_reach: float = 3.0,
        init_joints: str = "all",
        tolerance: float = 1e-3,
        max_surface_distance: float = 0.05,
        max_edge_distance: float = 0.05,
        canny_low: float = 0.08,
        canny_high: float = 0.16,
        skeleton: str = "sensor",
        start: str = "sensor",
        device: str = "cpu",
        progress: bool = False,
    ):
        self.surface_window = surface_window
        self.edge_window = edge_window
        self.subsample = subsample
        self.colour_weight = colour_weight
        self.surface_cost = surface_cost
        self.use_colour = use_colour
        self.use_edges = use_edges
        self.prior = prior
        self.neighbours = neighbours
        self.successors = successors
        self.energy = energy
        self.edge_weight = edge_weight
        self.prior_weight = prior_weight
        self.smooth_weight = smooth_weight
        self.constant_velocity = constant_velocity
        self.damping = damping
        self.sensor_weight = sensor_weight
        self.anchor = anchor
        self.anchor_corrector = anchor_corrector
        self.iterations = iterations
        self.init_iterations = init_iterations
        self.init_reach = init_reach
        self.init_joints = init_joints
        self.tolerance = tolerance
        self.max_surface_distance = max_surface_distance
        self.max_edge_distance = max_edge_distance
        self.canny_low = canny_low
        self.canny_high = canny_high
        self.skeleton = skeleton
        self.start = start
        self.device = device
        self.progress = progress

    # ------------------------------------------------------------------------------------------------ fit
    def _check_params(self) -> None:
        for name, choices in (
            ("surface_cost", SURFACE_COSTS),
            ("prior", PRIORS),
            ("skeleton", SKELETONS),
            ("start", STARTS),
            ("init_joints", INIT_JOINT_SETS),
            ("anchor", ANCHORS),
        ):
            if getattr(self, name) not in choices:
                raise ValueError(f"DepthTracker: {name} must be one of {list(choices)}, got {getattr(self, name)!r}")
        for name in ("surface_window", "edge_window"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1 or value % 2 == 0:
                raise ValueError(f"DepthTracker: {name} must be an odd number of pixels ≥ 1, got {value!r}")
        for name in ("subsample", "iterations", "init_iterations", "neighbours", "successors"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"DepthTracker: {name} must be an integer ≥ 1, got {value!r}")
        for name in (
            "colour_weight",
            "damping",
            "sensor_weight",
            "edge_weight",
            "prior_weight",
            "smooth_weight",
            "tolerance",
            "max_surface_distance",
            "max_edge_distance",
            "init_reach",
            "canny_low",
            "canny_high",
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating)) or not np.isfinite(value) or value < 0:
                raise ValueError(f"DepthTracker: {name} must be a finite number ≥ 0, got {value!r}")
        if not 0 < float(self.energy) <= 1:
            raise ValueError(f"DepthTracker: energy must be in (0, 1], got {self.energy!r}")

    def _device(self) -> torch.device:
        if self.device == "auto":
            return torch.device("cuda" if torch.cuda.is_available() else "cpu")
        return torch.device(self.device)

    def fit(self, sequences: list[DepthSequence]) -> DepthTracker:
        """Build the motion-prior database from the ground-truth ``joints`` of training sequences and, with
        ``anchor="sensor_gp"``, fit the GP correction of their sensor skeletons."""
        clips = []
        for seq in sequences:
            if seq.joints is None:
                raise DepthInputError(f"{seq.source or 'depth sequence'}: fit needs the sequence's joints")
            clips.append(tracked_joints(seq.joints))
        self._fit_database(clips)
        if self.anchor == "sensor_gp":
            from mocapkit.depth_tracking.baselines import SensorSkeletonGP

            self.anchor_model_ = SensorSkeletonGP(self.anchor_corrector).fit(sequences)
        return self

    def fit_mocap(self, clips: list[np.ndarray]) -> DepthTracker:
        """Build the prior database from mocap takes: each ``[T, 16, 3]`` (metres, any frame; 30 fps, the
        camera's rate, is what the successors assume) of :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS`.
        The GP anchor needs depth sequences (:meth:`fit`)."""
        self._check_params()
        if self.anchor == "sensor_gp":
            raise ValueError(
                "DepthTracker: anchor=sensor_gp learns from depth sequences with sensor and ground-truth joints "
                "(fit), not from mocap alone; use anchor=sensor"
            )
        return self._fit_database(clips)

    def _fit_database(self, clips: list[np.ndarray]) -> DepthTracker:
        self._check_params()
        self.anchor_model_ = None
        poses, takes = [], []
        if self.prior == "lpca":
            if len(clips) == 0:
                raise ValueError("DepthTracker: the LPCA prior needs at least one mocap take")
            for k, clip in enumerate(clips):
                poses.append(database_poses(clip))
                takes.append(np.full(len(clip), k))
            self.prior_ = LocalPCAPrior(
                np.concatenate(poses), np.concatenate(takes), self.neighbours, self.successors, self.energy
            )
            self.database_frames_ = len(self.prior_)
        else:
            self.prior_ = None
            self.database_frames_ = 0
        return self

    # ------------------------------------------------------------------------------------------------ predict
    def predict(self, sequence: DepthSequence, performer: np.ndarray | None = None) -> np.ndarray:
        """float32 ``[T, 16, 3]`` camera coordinates of the 16 joints in every frame.

        ``performer``: the 16 joints ``[T', 16, 3]`` (metres, any frame) of a mocap take of this performer, whose
        median bone lengths are the body's (instead of the ``skeleton`` parameter's source)."""
        check_is_fitted(self, "database_frames_")
        self._check_params()
        needs = ["sensor_joints"] if self.start == "sensor" or (self.skeleton == "sensor" and performer is None) else []
        if self.start == "ground_truth" or (self.skeleton == "ground_truth" and performer is None):
            needs.append("joints")
        check_sequence(sequence, tuple(needs))
        device = self._device()
        dtype = torch.float32
        anchor = None  # the sensor's joints, GP-corrected with anchor=sensor_gp
        if self.anchor_model_ is not None:
            anchor = self.anchor_model_.predict(sequence)
        elif sequence.sensor_joints is not None:
            anchor = tracked_joints(sequence.sensor_joints)
        if performer is not None:
            skeleton = bm.skeleton_from_joints(performer)
        elif self.skeleton == "template":
            skeleton = bm.template_skeleton()
        elif self.skeleton == "ground_truth":
            skeleton = bm.skeleton_from_joints(tracked_joints(sequence.joints))
        else:
            skeleton = bm.skeleton_from_joints(anchor)
        offsets, radii = skeleton.tensors(device, dtype)
        state = _TrackState(self, sequence.intrinsics, offsets, radii, device, dtype, anchor)
        out = np.zeros((sequence.num_frames, len(bm.TRACKED_JOINTS), 3), dtype=np.float32)
        frames = range(sequence.num_frames)
        if self.progress:
            from tqdm import tqdm

            frames = tqdm(frames, desc=f"tracking {sequence.source or ''}".strip(), unit="frame")
        q = q_before = None
        previous: _Frame | None = None
        started = time.perf_counter()
        for t in frames:
            frame = state.observe(sequence, t)
            if q is None:
                q = state.initial_pose(sequence)
                q = state.track(frame, q, None, previous_frame=None, use_colour=False, use_prior=False, first=True)
            else:
                subspace = self.prior_.subspace(q.double()) if self.prior_ is not None else None
                start = q + (q - q_before) if self.constant_velocity and q_before is not None else q
                q_before = q
                q = state.track(frame, q, subspace, previous_frame=previous, use_colour=self.use_colour, q_start=start)
            joints, _ = bm.forward_kinematics(q, offsets)
            out[t] = joints.detach().cpu().numpy()
            previous = frame
        self.last_seconds_per_frame_ = (time.perf_counter() - started) / max(sequence.num_frames, 1)
        return out


def database_poses(clip: np.ndarray, iterations: int = 40) -> np.ndarray:
    """Poses ``[T, 34]`` of a mocap take's 16 joints ``[T, 16, 3]`` by inverse kinematics (root from the hips and
    spine, joint DOF from the rest pose)."""
    clip = np.asarray(clip, dtype=np.float64)
    skeleton = bm.skeleton_from_joints(clip)
    offsets, _ = skeleton.tensors(dtype=torch.float64)
    q0 = torch.zeros(len(clip), bm.NUM_DOF, dtype=torch.float64)
    q0[:, :6] = torch.as_tensor(bm.root_pose(clip))
    return bm.fit_pose(torch.as_tensor(clip), offsets, q0, iterations=iterations).numpy()


class _TrackState:
    """What tracking one sequence needs on the device: the camera, the body, the window offsets."""

    def __init__(self, tracker: DepthTracker, intrinsics: CameraIntrinsics, offsets, radii, device, dtype, anchor=None):
        self.p = tracker
        self.anchor = anchor  # [T, 16, 3] the sensor's joints (GP-corrected with anchor=sensor_gp), or None
        self.k = intrinsics
        self.offsets, self.radii = offsets, radii
        self.device, self.dtype = device, dtype
        self.surface_dv, self.surface_du = _window_offsets(tracker.surface_window, device)
        self.edge_dv, self.edge_du = _window_offsets(tracker.edge_window, device)
        self.surface_offset = torch.hypot(self.surface_dv.to(dtype), self.surface_du.to(dtype))  # pixels

        def points_of(q, bone, local):
            return bm.body_points(q, offsets, bone, local)

        self.points_of = points_of

    def observe(self, sequence: DepthSequence, t: int) -> _Frame:
        depth = torch.as_tensor(sequence.depth_mm[t].astype(np.float32) / 1000.0, device=self.device)
        points = _unproject(depth, self.k)
        colour = None
        if sequence.colour is not None:
            colour = torch.as_tensor(sequence.colour[t], device=self.device, dtype=self.dtype)
        if self.p.use_edges:
            filled = fill_holes(depth)
            pixels, edge_points, _ = _edges(filled, _unproject(filled, self.k), self.p.canny_low, self.p.canny_high)
        else:
            pixels, edge_points = torch.zeros((0, 2), dtype=torch.long), torch.zeros((0, 3))
        sensor = weights = None
        if self.p.sensor_weight > 0 and self.anchor is not None:
            sensor = torch.as_tensor(self.anchor[t], device=self.device, dtype=self.dtype)
            weights = torch.ones(len(bm.TRACKED_JOINTS), device=self.device, dtype=self.dtype)
            if sequence.sensor_state is not None:  # tracked 1, inferred 0.5, not tracked 0
                state = tracked_joints(sequence.sensor_state[t][:, None])[:, 0].astype(np.float32)
                weights = torch.as_tensor(state / 2.0, device=self.device, dtype=self.dtype)
        return _Frame(
            depth, points, colour, pixels.to(self.device), edge_points.to(self.device, self.dtype), sensor, weights
        )

    # --------------------------------------------------------------------------------------- initialisation
    def initial_pose(self, sequence: DepthSequence) -> torch.Tensor:
        if self.p.start == "standing":  # the rest pose facing the camera, HipCenter 10 cm behind the median point
            depth = sequence.depth_m(0)
            points = self.k.unproject(depth)[depth > 0]
            centre = np.median(points, axis=0) + np.array([0.0, 0.0, 0.1])
            q = torch.zeros(bm.NUM_DOF, dtype=self.dtype, device=self.device)
            q[:3] = torch.as_tensor(centre, dtype=self.dtype)
            q[3] = np.pi  # body up = −y, forward = −z of the camera: a half turn about x
            return q
        if self.p.start == "ground_truth":
            target = torch.as_tensor(tracked_joints(sequence.joints[:1]), device=self.device, dtype=torch.float64)
            weights = None
            prior_weight = 0.0
        else:
            target = torch.as_tensor(self.anchor[:1], device=self.device, dtype=torch.float64)
            if self.p.init_joints == "five":
                weights = torch.zeros(len(bm.TRACKED_JOINTS), dtype=torch.float64, device=self.device)
                weights[list(bm.INIT_JOINTS)] = 1.0
                prior_weight = 1e-3
            else:
                weights, prior_weight = None, 1e-4
        q0 = torch.zeros(1, bm.NUM_DOF, dtype=torch.float64, device=self.device)
        q0[:, :6] = torch.as_tensor(bm.root_pose(target.cpu().numpy()), device=self.device)
        q = bm.fit_pose(
            target, self.offsets.double(), q0, joint_weights=weights, iterations=30, prior_weight=prior_weight
        )
        return q[0].to(self.dtype)

    # --------------------------------------------------------------------------------------- one frame
    def track(
        self,
        frame: _Frame,
        q_prev: torch.Tensor,
        subspace: LocalSubspace | None,
        previous_frame,
        use_colour: bool,
        use_prior: bool = True,
        q_start: torch.Tensor | None = None,
        first: bool = False,
    ) -> torch.Tensor:
        """Gauss–Newton on one frame from ``q_start`` (default ``q_prev``). ``first``: the initialisation step, which
        starts farther from the truth: ``init_iterations`` iterations whose outlier distances shrink from
        ``init_reach`` times the normal ones to the normal ones over the first half."""
        p = self.p
        q = (q_prev if q_start is None else q_start).clone()
        colour_ref = None
        if (
            use_colour
            and p.colour_weight > 0
            and frame.colour is not None
            and previous_frame is not None
            and previous_frame.colour is not None
        ):
            colour_ref = (previous_frame.colour, q_prev)
        iterations = p.init_iterations if first else p.iterations
        for i in range(iterations):
            reach = 1.0
            if first:
                reach = max(1.0, p.init_reach ** (1 - 2 * i / max(iterations, 1)))
            bone_s, local_s, target_s, bone_e, local_e, target_e = self.correspondences(frame, q, colour_ref, reach)
            bone = torch.cat([bone_s, bone_e])
            local = torch.cat([local_s, local_e])
            target = torch.cat([target_s, target_e])
            weight = torch.cat(
                [
                    torch.ones(len(bone_s), device=self.device, dtype=self.dtype),
                    torch.full((len(bone_e),), float(p.edge_weight), device=self.device, dtype=self.dtype),
                ]
            )
            a = torch.zeros(bm.NUM_DOF, bm.NUM_DOF, dtype=torch.float64, device=self.device)
            b = torch.zeros(bm.NUM_DOF, dtype=torch.float64, device=self.device)
            if len(bone):
                points, jac = bm.body_points_jacobian(q, self.offsets, bone, local)  # [N, 3], [N, 3, 34]
                residual = target - points
                jw = (jac * weight[:, None, None]).reshape(-1, bm.NUM_DOF).double()
                a += jw.T @ jac.reshape(-1, bm.NUM_DOF).double()
                b += jw.T @ residual.reshape(-1).double()
            if frame.sensor is not None:  # the sensor-skeleton anchor (ours): keeps the fit from drifting away
                joints, _, d_joints, _ = bm.forward_kinematics_jacobian(q[None], self.offsets)
                jac_s = d_joints[0].permute(1, 2, 0).reshape(-1, bm.NUM_DOF).double()  # [48, 34]
                w_s = (p.sensor_weight * frame.sensor_weight).repeat_interleave(3).double()
                a += jac_s.T @ (w_s[:, None] * jac_s)
                b += jac_s.T @ (w_s * (frame.sensor - joints[0]).reshape(-1).double())
            if subspace is not None and use_prior:
                a_prior, b_prior = subspace.normal_equations(q.double())
                a += p.prior_weight * a_prior
                b += p.prior_weight * b_prior
            a += p.smooth_weight * torch.eye(bm.NUM_DOF, dtype=torch.float64, device=self.device)
            a += p.damping * torch.diag(torch.diagonal(a).clamp_min(1e-9))  # Levenberg–Marquardt (ours)
            b += p.smooth_weight * (q_prev - q).double()
            step = torch.linalg.solve(a, b).to(self.dtype)
            q = q + step
            if float(step.norm()) < p.tolerance:
                break
        return q

    def render(self, q: torch.Tensor, stride: int):
        joints, rotations = bm.forward_kinematics(q, self.offsets)
        a, b, r = bm.capsules(joints, self.radii)
        box = capsule_box(a, b, r, self.k)
        return raycast_capsules(a, b, r, self.k, stride=stride, box=box), joints, rotations

    def correspondences(self, frame: _Frame, q: torch.Tensor, colour_ref, reach: float = 1.0):
        p, k = self.p, self.k
        h, w = k.height, k.width
        hits, joints, rotations = self.render(q, p.subsample)
        mask = hits.hit
        v = hits.v[:, None].expand_as(mask)[mask]
        u = hits.u[None, :].expand_as(mask)[mask]
        rendered = hits.points[mask]
        bone = hits.capsule[mask]
        local = bm.local_coordinates(rendered, bone, joints, rotations)
        # surface: the observed pixel of the window with the least |Δz| (+ colour), pulled to its 3-D point
        wv = (v[:, None] + self.surface_dv[None]).clamp(0, h - 1)
        wu = (u[:, None] + self.surface_du[None]).clamp(0, w - 1)
        z = frame.depth[wv, wu]  # [N, S]
        if p.surface_cost == "depth":  # the thesis's; ties (quantised depth) go to the nearest pixel, not the first
            cost = (z - rendered[:, 2:3]).abs() + TIE_BREAK * self.surface_offset[None]
        else:
            cost = (frame.points[wv, wu] - rendered[:, None]).norm(dim=-1)
        if colour_ref is not None:
            image, q_ref = colour_ref
            at_ref = self.points_of(q_ref, bone, local)
            ref_uv = _project(at_ref, k).round().long()
            ref_colour = image[ref_uv[:, 1].clamp(0, h - 1), ref_uv[:, 0].clamp(0, w - 1)]  # [N, 3]
            cost = cost + p.colour_weight * (frame.colour[wv, wu] - ref_colour[:, None]).abs().sum(-1)
        cost = torch.where(z > 0, cost, torch.full_like(cost, float("inf")))
        best = cost.argmin(dim=1)
        rows = torch.arange(len(best), device=self.device)
        bv, bu = wv[rows, best], wu[rows, best]
        keep = (frame.depth[bv, bu] > 0) & (
            (frame.depth[bv, bu] - rendered[:, 2]).abs() <= reach * p.max_surface_distance
        )
        surface = (bone[keep], local[keep], frame.points[bv[keep], bu[keep]])
        if not p.use_edges or len(frame.edge_pixels) == 0:
            empty_l = torch.zeros((0, 3), device=self.device, dtype=self.dtype)
            return (*surface, torch.zeros(0, dtype=torch.long, device=self.device), empty_l, empty_l)
        # edges: each observed edge point → the nearest rendered edge point in its window
        full, joints, rotations = self.render(q, 1)
        depth = full.full_image(k)
        pts = full.full_image(k, full.points)
        capsule = full.full_image(k, full.capsule, fill=-1)
        r_pixels, r_points, r_source = _edges(depth, pts, p.canny_low, p.canny_high)
        if len(r_pixels) == 0:
            empty_l = torch.zeros((0, 3), device=self.device, dtype=self.dtype)
            return (*surface, torch.zeros(0, dtype=torch.long, device=self.device), empty_l, empty_l)
        edge_index = torch.full((h, w), -1, dtype=torch.long, device=self.device)
        edge_index[r_pixels[:, 0], r_pixels[:, 1]] = torch.arange(len(r_pixels), device=self.device)
        ov, ou = frame.edge_pixels[:, 0], frame.edge_pixels[:, 1]
        wv = ov[:, None] + self.edge_dv[None]
        wu = ou[:, None] + self.edge_du[None]
        inside = (wv >= 0) & (wv < h) & (wu >= 0) & (wu < w)
        candidate = torch.where(inside, edge_index[wv.clamp(0, h - 1), wu.clamp(0, w - 1)], -1)  # [M, S]
        distance = (r_points[candidate.clamp_min(0)] - frame.edge_points[:, None]).norm(dim=-1)
        distance = torch.where(candidate >= 0, distance, torch.full_like(distance, float("inf")))
        nearest, which = distance.min(dim=1)
        keep = nearest <= reach * p.max_edge_distance
        chosen = candidate[torch.arange(len(which), device=self.device), which][keep]
        src = r_source[chosen]
        e_bone = capsule[src[:, 0], src[:, 1]]
        e_local = bm.local_coordinates(r_points[chosen], e_bone, joints, rotations)
        return (*surface, e_bone, e_local, frame.edge_points[keep])


def _project(points: torch.Tensor, k: CameraIntrinsics) -> torch.Tensor:
    z = points[:, 2].clamp_min(1e-6)
    return torch.stack([k.fx * points[:, 0] / z + k.cx, k.fy * points[:, 1] / z + k.cy], dim=-1)


__all__ = ["PRIORS", "SKELETONS", "STARTS", "SURFACE_COSTS", "DepthTracker", "database_poses"]
