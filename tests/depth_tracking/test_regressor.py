"""DepthJointRegressor: a tiny CNN trained for a few dozen steps on tiny capsule renders of two pose families."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.exceptions import NotFittedError

from mocapkit.datasets.formats.depth_images import CameraIntrinsics, DepthSequence
from mocapkit.datasets.synthetic.capsule_render import raycast_capsules
from mocapkit.depth_tracking.base import DepthInputError, joint_error_mm, tracked_joints
from mocapkit.depth_tracking.regressor import (
    BACKGROUND,
    DepthJointRegressor,
    OnnxDepthJointRegressor,
    depth_crops,
)
from mocapkit.motion.layouts import LANDMARK_NAMES, LANDMARK_PARENTS

J = {name: i for i, name in enumerate(LANDMARK_NAMES)}
#: capsule radius (metres) of the bone ending at each landmark
RADIUS = {
    "spine": 0.13,
    "neck": 0.12,
    "head": 0.09,
    "shoulder": 0.05,
    "elbow": 0.05,
    "wrist": 0.04,
    "hand": 0.04,
    "hip": 0.09,
    "knee": 0.07,
    "ankle": 0.05,
    "foot": 0.045,
}


def kinect20(arm_l, arm_r, elbow_l, elbow_r, hip_l, hip_r, root) -> np.ndarray:
    """A Kinect-20 skeleton ``[20, 3]`` in camera coordinates (metres, y down, z forward), the person facing the
    camera with the pelvis at ``root``; angles in radians (shoulder abduction, elbow flexion towards the camera,
    hip flexion forward with the knee bending half as much)."""
    p = np.zeros((20, 3))
    p[J["pelvis"]], p[J["spine"]], p[J["neck"]], p[J["head"]] = [0, 1.0, 0], [0, 1.2, 0], [0, 1.45, 0], [0, 1.65, 0]
    for side, s, arm, elbow, hip in (("l", 1, arm_l, elbow_l, hip_l), ("r", -1, arm_r, elbow_r, hip_r)):
        shoulder = p[J[f"{side}_shoulder"]] = [0.18 * s, 1.42, 0]
        upper = np.array([s * np.sin(arm), -np.cos(arm), 0.0])
        fore = np.cos(elbow) * upper + np.sin(elbow) * np.array([0.0, 0.0, -1.0])
        p[J[f"{side}_elbow"]] = shoulder + 0.28 * upper
        p[J[f"{side}_wrist"]] = p[J[f"{side}_elbow"]] + 0.25 * fore
        p[J[f"{side}_hand"]] = p[J[f"{side}_wrist"]] + 0.08 * fore
        p[J[f"{side}_hip"]] = [0.1 * s, 0.95, 0]
        thigh = np.array([0.0, -np.cos(hip), -np.sin(hip)])
        shin = np.array([0.0, -np.cos(hip / 2), -np.sin(hip / 2)])
        p[J[f"{side}_knee"]] = p[J[f"{side}_hip"]] + 0.42 * thigh
        p[J[f"{side}_ankle"]] = p[J[f"{side}_knee"]] + 0.40 * shin
        p[J[f"{side}_foot"]] = p[J[f"{side}_ankle"]] + [0, -0.03, -0.12]
    p[:, 1] = 0.85 - p[:, 1]  # y up → y down, the camera 0.85 m above the floor: the whole body in view
    return p + np.asarray(root)


def family(kind: str, frames: int, offset: float) -> np.ndarray:
    """``[frames, 20, 3]``: arm raises or front kicks, the person walking across; ``offset`` shifts the phase."""
    phase = 2 * np.pi * (np.arange(frames) + offset) / frames * 2
    swing = 0.5 - 0.5 * np.cos(phase)
    root = np.stack([0.3 * np.sin(phase / 2 + offset), 0.05 * np.cos(phase), 3.2 + 0.3 * np.cos(phase / 2)], -1)
    out = []
    for t in range(frames):
        if kind == "arms":
            angles = (0.3 + 2.2 * swing[t], 0.3 + 2.2 * (1 - swing[t]), 1.4 * swing[t], 1.4 * (1 - swing[t]), 0, 0)
        else:
            angles = (0.5, 0.5, 0.2, 0.2, 0.1, 1.4 * swing[t])
        out.append(kinect20(*angles, root[t]))
    return np.asarray(out)


def render(joints: np.ndarray, camera: str = "kinect_v1", source: str = "synthetic.npz") -> DepthSequence:
    """Capsules along the bones of ``joints`` ``[T, 20, 3]`` (camera coordinates) ray-cast into ``camera``."""
    intrinsics = CameraIntrinsics.preset(camera)
    child = [j for j, p in enumerate(LANDMARK_PARENTS) if p >= 0]
    radius = torch.tensor([RADIUS[LANDMARK_NAMES[j].removeprefix("l_").removeprefix("r_")] for j in child])
    depth = np.zeros((len(joints), *intrinsics.shape), dtype=np.uint16)
    for t, pose in enumerate(torch.from_numpy(joints).float()):
        a, b = pose[[LANDMARK_PARENTS[j] for j in child]], pose[child]
        hits = raycast_capsules(a, b, radius, intrinsics)
        depth[t] = np.rint(hits.full_image(intrinsics).numpy() * 1000).astype(np.uint16)
    return DepthSequence(
        depth, intrinsics, 30.0, joints=joints.astype(np.float32), joint_names=LANDMARK_NAMES, source=source
    )


TINY = {"crop_size": 48, "network": {"width": 8, "blocks": 4, "hidden": 64}, "batch_size": 16, "lr": 3e-3}


@pytest.fixture(scope="module")
def data():
    train = [render(family(kind, 40, 0.0), source=f"{kind}.npz") for kind in ("arms", "kick")]
    test = [render(family(kind, 12, 0.37), source=f"{kind}-test.npz") for kind in ("arms", "kick")]
    return train, test


@pytest.fixture(scope="module")
def fitted(data):
    return DepthJointRegressor(steps=100, **TINY).fit(data[0])


def test_training_lowers_the_loss_and_beats_the_mean_pose(data, fitted):
    train, test = data
    curve = fitted.loss_curve_
    assert len(curve) == 100 and curve[-10:].mean() < 0.7 * curve[:5].mean()
    relative = np.concatenate(
        [tracked_joints(s.joints) - depth_crops(s, 48, 2.2, 1.0)[1][:, None] for s in train]
    ).mean(axis=0)  # the mean pose relative to the crop centre: what a network that learned nothing predicts
    for seq in test:
        truth = tracked_joints(seq.joints)
        centres = depth_crops(seq, 48, 2.2, 1.0)[1]
        baseline = joint_error_mm(relative + centres[:, None], truth).mean()
        error = joint_error_mm(fitted.predict(seq), truth).mean()
        assert error < 0.85 * baseline, (seq.source, error, baseline)


def test_predict_shape_dtype_and_camera_coordinates(data, fitted):
    seq = data[1][0]
    pred = fitted.predict(seq)
    assert pred.shape == (12, 16, 3) and pred.dtype == np.float32
    # camera coordinates: around the person, 2.5–3.1 m in front of the camera
    assert np.abs(pred.mean(axis=(0, 1)) - tracked_joints(seq.joints).mean(axis=(0, 1))).max() < 0.25


def test_camera_independent(fitted):
    poses = family("arms", 4, 0.2)
    small, large = render(poses, "kinect_v1"), render(poses, "azure_kinect")
    assert large.depth_mm.shape[1:] == (576, 640)
    difference = joint_error_mm(fitted.predict(large), fitted.predict(small))
    assert difference.max() < 40.0, difference  # mm: the crop is the same metric square, sampled more finely


def test_crop_is_metric_and_background_constant(data):
    seq = data[0][0]
    crops, centres = depth_crops(seq, 48, 2.2, 1.0)
    assert crops.shape == (40, 1, 48, 48) and crops.dtype == np.float32
    assert np.isclose(crops.max(), BACKGROUND) and -1.0 <= crops.min() < 0.0  # the body lies in front of the far value
    pelvis = seq.joints[:, J["pelvis"]]
    assert np.abs(centres - pelvis).max() < 0.35  # the median of the body is near its middle


def test_onnx_export_parity_and_twin(tmp_path, data, fitted):
    report = fitted.export_onnx(tmp_path / "regressor.onnx")
    assert report["max_abs_diff"] < 1e-4 and report["checked_shape"][1:] == [1, 48, 48]
    twin = OnnxDepthJointRegressor(tmp_path / "regressor.onnx").fit()
    seq = data[1][1]
    np.testing.assert_allclose(twin.predict(seq), fitted.predict(seq), atol=1e-4)
    report = fitted.export_onnx(tmp_path / "again.onnx", sequence=seq)  # parity on every frame of a sequence
    assert report["checked_shape"][0] == seq.num_frames


def test_save_load_round_trip(tmp_path, data, fitted):
    path = fitted.save(tmp_path / "sub" / "regressor.pt")
    loaded = DepthJointRegressor.load(path)
    assert loaded.get_params()["network"] == TINY["network"] and loaded.n_frames_ == 80
    np.testing.assert_array_equal(loaded.predict(data[1][0]), fitted.predict(data[1][0]))
    with pytest.raises(ValueError, match="not a depth joint regressor"):
        DepthJointRegressor.load(tmp_path / "missing.pt")


def test_errors(data, fitted):
    train, test = data
    with pytest.raises(NotFittedError):
        DepthJointRegressor().predict(test[0])
    unlabelled = DepthSequence(train[0].depth_mm, train[0].intrinsics, 30.0, source="no-joints.npz")
    with pytest.raises(DepthInputError, match="no-joints.npz: fit needs the sequence's joints"):
        DepthJointRegressor(steps=1, **TINY).fit([train[1], unlabelled])
    hole = DepthSequence(test[0].depth_mm.copy(), test[0].intrinsics, 30.0, source="hole.npz")
    hole.depth_mm[5] = 0
    with pytest.raises(DepthInputError, match="hole.npz: frame 5 has no depth"):
        fitted.predict(hole)
    with pytest.raises(DepthInputError, match="hole.npz: frame 5: no foreground"):
        depth_crops(hole, 48, 2.2, 1.0)
    with pytest.raises(ValueError, match="crop_size"):
        DepthJointRegressor(crop_size=4).fit(train)
