"""The tracker's parts: ray casting, forward kinematics and its analytic Jacobian, inverse kinematics, the LPCA prior,
and tracking on depth rendered from the tracker's own body (where the answer is known exactly)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.exceptions import NotFittedError

from mocapkit.datasets.formats.depth_images import CameraIntrinsics, DepthSequence
from mocapkit.datasets.synthetic.capsule_render import raycast_capsules
from mocapkit.depth_tracking import body_model as bm
from mocapkit.depth_tracking.base import DepthInputError, joint_error_mm
from mocapkit.depth_tracking.lpca import LocalPCAPrior
from mocapkit.depth_tracking.tracker import DepthTracker, database_poses, fill_holes

K = CameraIntrinsics.preset("kinect_v1")


def _standing(distance: float = 2.5) -> torch.Tensor:
    """The rest pose facing the camera, HipCenter ``distance`` metres in front of it."""
    q = torch.zeros(bm.NUM_DOF, dtype=torch.float64)
    q[:3] = torch.tensor([0.0, 0.1, distance])
    q[3] = np.pi
    return q


def _clip(frames: int = 12) -> torch.Tensor:
    """A slow made-up motion: arms raising, a knee bending, the body turning a little. ``[T, 34]``."""
    t = torch.linspace(0, 1, frames, dtype=torch.float64)
    q = _standing().repeat(frames, 1)
    q[:, 4] = 0.3 * t  # turn about the vertical
    q[:, 16] = -0.8 * t  # left shoulder forward
    q[:, 19] = -0.6 * t  # left elbow
    q[:, 24] = 0.5 * t  # right shoulder sideways
    q[:, 29] = 0.7 * t  # left knee
    return q


def _skeleton() -> bm.Skeleton:
    return bm.template_skeleton()


def _render(q: torch.Tensor, skeleton: bm.Skeleton) -> np.ndarray:
    offsets, radii = skeleton.tensors(dtype=torch.float64)
    depth = []
    for pose in q:
        joints, _ = bm.forward_kinematics(pose, offsets)
        hits = raycast_capsules(*bm.capsules(joints, radii), K)
        depth.append(np.round(hits.full_image(K).numpy() * 1000).astype(np.uint16))
    return np.stack(depth)


def _sequence(q: torch.Tensor, skeleton: bm.Skeleton, noise_m: float = 0.0) -> DepthSequence:
    offsets, _ = skeleton.tensors(dtype=torch.float64)
    joints16, _ = bm.forward_kinematics(q, offsets)
    joints20 = np.zeros((len(q), 20, 3), np.float32)
    from mocapkit.depth_tracking.base import KINECT20_INDEX

    joints20[:, KINECT20_INDEX] = joints16.numpy()
    rng = np.random.default_rng(0)
    sensor = joints20 + rng.normal(0, noise_m, joints20.shape).astype(np.float32)
    return DepthSequence(_render(q, skeleton), K, 30.0, joints=joints20, sensor_joints=sensor, source="made-up.npz")


def test_raycast_depth_of_a_capsule_facing_the_camera():
    a = torch.tensor([[0.0, -0.3, 2.0]], dtype=torch.float64)
    b = torch.tensor([[0.0, 0.3, 2.0]], dtype=torch.float64)
    hits = raycast_capsules(a, b, torch.tensor([0.1], dtype=torch.float64), K)
    depth = hits.full_image(K)
    centre = depth[int(round(K.cy)), int(round(K.cx))]
    assert abs(float(centre) - 1.9) < 2e-3  # the front of the cylinder
    assert float(depth[depth > 0].max()) < 2.0 + 1e-9  # nothing behind the axis is visible
    width = int((depth[int(round(K.cy))] > 0).sum())
    assert abs(width - 2 * 0.1 / 2.0 * K.fx) <= 3  # 20 cm wide at 2 m


def test_analytic_jacobian_equals_autodiff():
    torch.manual_seed(0)
    q = torch.randn(bm.NUM_DOF, dtype=torch.float64) * 0.8
    offsets, _ = _skeleton().tensors(dtype=torch.float64)
    bone = torch.randint(0, bm.NUM_BONES, (40,))
    local = torch.randn(40, 3, dtype=torch.float64) * 0.1
    points, jac = bm.body_points_jacobian(q, offsets, bone, local)
    expected = torch.func.jacfwd(lambda x: bm.body_points(x, offsets, bone, local))(q)
    assert torch.allclose(points, bm.body_points(q, offsets, bone, local))
    assert torch.allclose(jac, expected, atol=1e-10)
    q[6:] = 0  # at the rest pose the rotation derivatives take their small-angle branch
    _, jac = bm.body_points_jacobian(q, offsets, bone, local)
    expected = torch.func.jacfwd(lambda x: bm.body_points(x, offsets, bone, local))(q)
    assert torch.allclose(jac, expected, atol=1e-8)


def test_inverse_kinematics_recovers_joint_positions():
    skeleton = _skeleton()
    offsets, _ = skeleton.tensors(dtype=torch.float64)
    q = _clip(6)
    joints, _ = bm.forward_kinematics(q, offsets)
    poses = database_poses(joints.numpy())
    fitted, _ = bm.forward_kinematics(torch.as_tensor(poses), offsets)
    assert float((fitted - joints).norm(dim=-1).max()) < 2e-3


def test_skeleton_from_joints_measures_the_bones():
    skeleton = _skeleton()
    offsets, _ = skeleton.tensors(dtype=torch.float64)
    joints, _ = bm.forward_kinematics(_clip(5), offsets)
    measured = bm.skeleton_from_joints(joints.numpy())
    assert np.allclose(measured.lengths, skeleton.lengths, atol=1e-9)
    assert 1.6 < measured.stature < 1.9
    with pytest.raises(ValueError, match=r"\[T, 16, 3\]"):
        bm.skeleton_from_joints(np.zeros((4, 20, 3)))


def test_lpca_prior_is_zero_on_the_local_subspace_and_grows_off_it():
    # database poses on a line in joint space, successors along it
    steps = np.linspace(0, 1, 200)
    poses = np.zeros((200, bm.NUM_DOF))
    direction = np.zeros(bm.NUM_DOF - bm.ROOT_DOF)
    direction[[2, 10]] = 1 / np.sqrt(2)
    poses[:, bm.ROOT_DOF :] = steps[:, None] * direction
    prior = LocalPCAPrior(poses, np.zeros(200, int), neighbours=20, successors=3)
    q = torch.as_tensor(poses[100])
    sub = prior.subspace(q)
    assert sub.dims == 1 and sub.neighbours == 60
    on_line = torch.as_tensor(poses[120])
    off_line = on_line.clone()
    off_line[bm.ROOT_DOF + 5] += 0.2
    energy = lambda x: float((sub.projector @ (x - sub.mean)).norm() ** 2)  # noqa: E731
    assert energy(on_line) < 1e-12
    assert abs(energy(off_line) - 0.04) < 1e-9
    moved_root = on_line.clone()
    moved_root[:6] += 1.0  # the root is not part of the prior
    assert energy(moved_root) < 1e-12


def test_fill_holes_closes_dropouts_inside_but_not_the_background():
    depth = torch.full((20, 20), 2.0)
    depth[:, :5] = 0  # background
    depth[10, 12] = 0  # a dropout inside
    filled = fill_holes(depth)
    assert float(filled[10, 12]) == 2.0
    assert float(filled[10, 0]) == 0.0


@pytest.fixture(scope="module")
def made_up():
    skeleton = _skeleton()
    return _clip(10), skeleton


def test_tracks_depth_of_its_own_body(made_up):
    q, skeleton = made_up
    seq = _sequence(q, skeleton)
    truth = seq.joints[:, [i for i in range(20) if i not in (7, 11, 15, 19)]]
    tracker = DepthTracker(prior="none", skeleton="ground_truth", start="ground_truth", use_colour=False).fit([])
    error = joint_error_mm(tracker.predict(seq), truth)
    assert error.max() < 25, error  # the motion is followed (the left arm moves ~40 cm)
    frozen = joint_error_mm(np.repeat(truth[:1], len(truth), axis=0), truth)
    assert error[-1] < 0.5 * frozen[-1]


def test_start_from_five_noisy_sensor_joints_converges(made_up):
    q, skeleton = made_up
    seq = _sequence(q[:4], skeleton, noise_m=0.03)
    truth = seq.joints[:, [i for i in range(20) if i not in (7, 11, 15, 19)]]
    sensor_error = joint_error_mm(seq.sensor_joints[:, [i for i in range(20) if i not in (7, 11, 15, 19)]], truth)
    tracker = DepthTracker(prior="none", skeleton="ground_truth", start="sensor", use_colour=False).fit([])
    error = joint_error_mm(tracker.predict(seq), truth)
    assert error.mean() < sensor_error.mean(), (error, sensor_error)


def test_errors_name_the_problem(made_up):
    q, skeleton = made_up
    seq = _sequence(q[:2], skeleton)
    with pytest.raises(NotFittedError):
        DepthTracker().predict(seq)
    with pytest.raises(ValueError, match="surface_window"):
        DepthTracker(surface_window=14).fit([])
    with pytest.raises(ValueError, match="prior"):
        DepthTracker(prior="global").fit([])
    with pytest.raises(ValueError, match="at least one mocap take"):
        DepthTracker(prior="lpca").fit_mocap([])
    empty = _sequence(q[:2], skeleton)
    empty.depth_mm[1] = 0
    with pytest.raises(DepthInputError, match=r"made-up.npz: frame 1 has no depth"):
        DepthTracker(prior="none").fit([]).predict(empty)
    no_sensor = _sequence(q[:2], skeleton)
    no_sensor.sensor_joints = None
    with pytest.raises(DepthInputError, match="sensor_joints"):
        DepthTracker(prior="none").fit([]).predict(no_sensor)


def test_benchmark_cuts_a_take_to_its_frames_in_view(made_up):
    from mocapkit.depth_tracking.benchmark import in_view, motion_class

    q, skeleton = made_up
    seq = _sequence(q[:6], skeleton)
    seq.depth_mm[[0, 3]] = 0  # out of view at the start and in the middle: runs 1–2 and 4–5, the first kept
    cut = in_view(seq)
    assert cut.num_frames == 2 and cut.metadata["in_view"] == [1, 3]
    assert np.array_equal(cut.joints, seq.joints[1:3]) and np.array_equal(cut.sensor_joints, seq.sensor_joints[1:3])
    assert in_view(_sequence(q[:3], skeleton)).num_frames == 3
    assert motion_class("HDM_bd_grabHighR_001_120.amc") == "grabHighR" and motion_class("02_05.amc") == "02"
