"""Skeleton geometry (mocapkit.motion.geometry) and every place that uses it: headings, turns about the up axis,
facing directions and body frames against reference computations on bodies turned by known yaws; the torch
counterparts (mocapkit.models.body_frame) against the numpy definitions."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import (
    AXES,
    L_HIP,
    R_HIP,
    SkeletonInputError,
    body_origin,
    body_size,
    direction_yaw,
    face_forward,
    facing_direction,
    hip_line_heading,
    horizontal_axes,
    lateral_line,
    to_y_up,
    turn_about_up,
    turn_up_axis,
)
from mocapkit.motion.layouts import LANDMARK_NAMES, MSR20

I = {name: k for k, name in enumerate(LANDMARK_NAMES)}
# A standing body on the 20 landmarks: y up, facing +z, its left side at +x (metres).
STANDING = {
    "pelvis": (0, 1.0, 0),
    "spine": (0, 1.2, 0),
    "neck": (0, 1.5, 0),
    "head": (0, 1.7, 0),
    "l_shoulder": (0.18, 1.5, 0),
    "l_elbow": (0.18, 1.22, 0),
    "l_wrist": (0.18, 0.97, 0),
    "l_hand": (0.18, 0.89, 0),
    "r_shoulder": (-0.18, 1.5, 0),
    "r_elbow": (-0.18, 1.22, 0),
    "r_wrist": (-0.18, 0.97, 0),
    "r_hand": (-0.18, 0.89, 0),
    "l_hip": (0.1, 1.0, 0),
    "l_knee": (0.1, 0.58, 0.02),
    "l_ankle": (0.1, 0.17, 0),
    "l_foot": (0.1, 0.05, 0.14),
    "r_hip": (-0.1, 1.0, 0),
    "r_knee": (-0.1, 0.58, 0.02),
    "r_ankle": (-0.1, 0.17, 0),
    "r_foot": (-0.1, 0.05, 0.14),
}
BODY = np.array([STANDING[name] for name in LANDMARK_NAMES], dtype=np.float64)  # [20, 3]
YAWS = np.array([0.0, 0.3, -1.2, 2.5, -3.0, np.pi / 2])  # rad about +y


def yawed(yaws=YAWS, body=BODY, shift=(0.4, 0.0, -2.0)) -> np.ndarray:
    """``body`` turned about +y (right-handed) by each yaw and moved: ``[len(yaws), J, 3]``; a body facing +z then
    faces ``(sin ψ, 0, cos ψ)``."""
    return np.stack([Rotation.from_rotvec([0.0, y, 0.0]).apply(body) for y in yaws]) + np.asarray(shift)


def wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


# --------------------------------------------------------------------------- the primitives


def test_horizontal_axes_and_bad_arguments():
    assert horizontal_axes("y") == (0, 2) and horizontal_axes("z") == (0, 1) and horizontal_axes("x") == (1, 2)
    with pytest.raises(ValueError, match="up axis"):
        horizontal_axes("w")
    with pytest.raises(ValueError, match="along"):
        hip_line_heading(BODY, L_HIP, R_HIP, along="+z")
    with pytest.raises(ValueError, match="pair up"):
        lateral_line(BODY, [L_HIP, I["l_shoulder"]], [R_HIP])
    assert issubclass(SkeletonInputError, ValueError)


def test_a_body_turned_by_a_known_yaw_gives_that_yaw_back():
    P = yawed()
    # along "-x": the body's yaw (facing +z is 0); along "+x": the hip line's angle from +x towards +z, π − yaw
    np.testing.assert_allclose(hip_line_heading(P, L_HIP, R_HIP, along="-x"), wrap(YAWS), atol=1e-12)
    np.testing.assert_allclose(wrap(hip_line_heading(P, L_HIP, R_HIP, along="+x") - (np.pi - YAWS)), 0, atol=1e-12)
    # the shoulders, or hips and shoulders together, give the same yaw for this body
    both = hip_line_heading(P, [L_HIP, I["l_shoulder"]], [R_HIP, I["r_shoulder"]], along="-x")
    np.testing.assert_allclose(both, wrap(YAWS), atol=1e-12)
    np.testing.assert_allclose(
        lateral_line(P, [L_HIP, I["l_shoulder"]], [R_HIP, I["r_shoulder"]]),
        lateral_line(P, L_HIP, R_HIP) + lateral_line(P, I["l_shoulder"], I["r_shoulder"]),
    )
    # facing direction and its yaw
    forward = facing_direction(P, L_HIP, R_HIP)
    np.testing.assert_allclose(forward, np.stack([np.sin(YAWS), 0 * YAWS, np.cos(YAWS)], axis=1), atol=1e-12)
    np.testing.assert_allclose(direction_yaw(forward), wrap(YAWS), atol=1e-12)
    # a vertical hip line has heading 0
    assert hip_line_heading(np.zeros((1, 20, 3)), L_HIP, R_HIP)[0] == 0.0


@pytest.mark.parametrize("up", ["x", "y", "z"])
@pytest.mark.parametrize("along", ["+x", "-x"])
def test_turn_about_up_lays_the_hip_line_onto_along_and_back(up, along):
    # the y-up bodies with their axes relabelled so that ``up`` is vertical (a proper rotation of the coordinates)
    order = {"y": [0, 1, 2], "z": [0, 2, 1], "x": [1, 0, 2]}[up]
    sign = {"y": [1, 1, 1], "z": [1, -1, 1], "x": [1, 1, -1]}[up]
    P = yawed()[..., order] * sign
    angle = hip_line_heading(P, L_HIP, R_HIP, up=up, along=along)
    turned = turn_about_up(P, angle, up=up, along=along)
    h1, h2 = horizontal_axes(up)
    line = lateral_line(turned, L_HIP, R_HIP)
    np.testing.assert_allclose(line[:, h2], 0, atol=1e-12)
    assert np.all(line[:, h1] * (1 if along == "+x" else -1) > 0.19)
    np.testing.assert_allclose(turned[..., AXES[up]], P[..., AXES[up]])  # heights unchanged
    np.testing.assert_allclose(turn_about_up(turned, angle, up=up, along=along, inverse=True), P, atol=1e-12)
    # the "+x" convention turns by +angle about up (right-handed for y-up), "-x" by −angle
    if up == "y":
        expected = np.stack(
            [Rotation.from_rotvec([0, a if along == "+x" else -a, 0]).apply(p) for a, p in zip(angle, P)]
        )
        np.testing.assert_allclose(turned, expected, atol=1e-12)
    # one angle for every item, and [T, ..., 3] arrays of any rank
    assert turn_about_up(P[0], 0.3, up=up).shape == P[0].shape


def test_face_forward_per_frame_and_per_clip():
    P = yawed(shift=(0, 0, 0)) - yawed(shift=(0, 0, 0))[:, :1]  # pelvis-centred
    framed = face_forward(P, "frame")
    np.testing.assert_allclose(framed, np.broadcast_to(BODY - BODY[0], P.shape), atol=1e-12)
    small = np.array([0.1, 0.2, 0.3])
    clip = face_forward(yawed(small, shift=(0, 0, 0)), "clip")  # turned by the mean, 0.2
    np.testing.assert_allclose(hip_line_heading(clip, L_HIP, R_HIP, along="-x"), small - 0.2, atol=1e-12)
    assert face_forward(P, "none") is P


def test_body_origin_and_size():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(7, 20, 3))
    present = np.array([False, False, True, True, False, True, True])
    np.testing.assert_array_equal(body_origin(P, present, 3, "first"), P[2, 3])
    np.testing.assert_array_equal(body_origin(P, present, 3, "median"), np.median(P[present, 3], axis=0))
    length = np.linalg.norm(P[:, 2] - P[:, 0], axis=-1)
    assert body_size(P, present, 0, 2, "mean") == pytest.approx(length[present].mean())
    assert body_size(P, present, 0, 2, "median") == pytest.approx(np.median(length[present]))
    assert body_size(P, np.zeros(7, bool), 0, 2, "mean", default=1.0) == 1.0
    assert body_size(P, np.zeros(7, bool), 0, 2) == 1e-3
    assert body_size(np.zeros((7, 20, 3)), present, 0, 2, floor=0.01) == 0.01
    with pytest.raises(ValueError, match="statistic"):
        body_size(P, present, 0, 2, "max")


# --------------------------------------------------------------------------- the consumers


def test_kinect_posture_frame_recovers_the_yaw_and_faces_plus_z():
    from mocapkit.kinect.reconstruction import normalise_posture

    P = yawed()
    normalised, transform = normalise_posture(P)
    np.testing.assert_allclose(transform.yaw, wrap(YAWS), atol=1e-12)
    np.testing.assert_allclose(
        facing_direction(normalised, L_HIP, R_HIP), np.tile([0.0, 0.0, 1.0], (len(P), 1)), atol=1e-12
    )
    np.testing.assert_allclose(transform.to_world(normalised), P, atol=1e-9)


def test_retrieval_hip_forward_is_the_facing_direction():
    from mocapkit.retrieval.features import _body_frame

    frame = _body_frame(yawed())
    np.testing.assert_allclose(frame["hip_forward"], np.stack([np.sin(YAWS), 0 * YAWS, np.cos(YAWS)], 1), atol=1e-12)


def _msr_motion(P: np.ndarray, up_axis: str = "y") -> Motion:
    """MSR-20 joints from landmark positions ``[T, 20, 3]``."""
    names = MSR20.joint_names
    from mocapkit.motion.layouts import LANDMARKS

    order = [LANDMARK_NAMES.index(next(k for k, v in LANDMARKS["msr20"].items() if v == name)) for name in names]
    return Motion(P[:, order], names, 30.0, parents=MSR20.parents, up_axis=up_axis, layout_name="msr20")


def test_synthesis_heading_angles_and_root_normalised_positions():
    from mocapkit.synthesis.metrics import heading_angles, root_normalised_positions

    motion = _msr_motion(yawed())
    angles = heading_angles(motion)  # the hip line's angle from +x towards +z: π − yaw
    np.testing.assert_allclose(wrap(angles - (np.pi - YAWS)), 0, atol=1e-6)
    local = root_normalised_positions(motion)
    hips = local[:, MSR20.joint_names.index("HipRight")] - local[:, MSR20.joint_names.index("HipLeft")]
    np.testing.assert_allclose(hips[:, 2], 0, atol=1e-6)
    assert np.all(hips[:, 0] > 0.19)


@pytest.mark.parametrize("up_axis", ["y", "z"])
def test_torso_aligned_and_the_pose_prior_frame(up_axis):
    from mocapkit.refinement.pose_prior import PosePriorRefiner

    P = yawed()
    if up_axis == "z":
        P = P[..., [0, 2, 1]] * np.array([1, -1, 1])
    motion = _msr_motion(P, up_axis)
    left, right = MSR20.joint_names.index("HipLeft"), MSR20.joint_names.index("HipRight")
    aligned = motion.torso_aligned("HipLeft", "HipRight").positions
    h1, h2 = horizontal_axes(up_axis)
    np.testing.assert_allclose((aligned[:, right] - aligned[:, left])[:, h2], 0, atol=1e-6)
    np.testing.assert_allclose(aligned[:, MSR20.parents.index(-1)], 0, atol=1e-6)

    prior = PosePriorRefiner()
    prior.root_, prior.hips_, prior.up_axis_ = MSR20.parents.index(-1), (left, right), up_axis
    Q = motion.positions.astype(np.float64)
    local, root, angle = prior._to_pose_frame(Q)
    np.testing.assert_allclose(local, aligned, atol=1e-6)
    np.testing.assert_allclose(prior._from_pose_frame(local, root, angle), Q, atol=1e-12)


def test_bvh_rig_turn_faces_plus_z():
    from mocapkit.datasets.formats.bvh_to_amc import _facing_yaw

    names = ["Hips", "UpperLeg_L", "UpperLeg_R", "Shoulder_L", "Shoulder_R"]
    body = BODY[[I["pelvis"], I["l_hip"], I["r_hip"], I["l_shoulder"], I["r_shoulder"]]]
    for yaw in YAWS:
        turn = _facing_yaw(Rotation.from_rotvec([0, yaw, 0]).apply(body), names, "test")
        np.testing.assert_allclose(turn, Rotation.from_rotvec([0, -yaw, 0]).as_matrix(), atol=1e-12)


def test_kinect_noise_camera_stands_where_the_body_faces():
    from mocapkit.datasets.synthetic.kinect_noise import KinectNoiseConfig, place_camera

    config = KinectNoiseConfig(facing_yaw_deg=(0.0, 0.0), camera_distance_m=(3.0, 3.0))
    for yaw in (0.4, -2.0):
        P = yawed(np.full(30, yaw), shift=(0, 0, 0))
        camera = place_camera(P, config)
        ahead = camera.position - P[:, I["pelvis"]].mean(0)
        np.testing.assert_allclose(direction_yaw(ahead), yaw, atol=1e-9)


def test_clip_features_origin_and_size():
    from mocapkit.features.clips import normalise_sequence

    landmarks = yawed()
    motion = _msr_motion(landmarks)
    positions = motion.positions.copy()
    positions[0] = 0.0  # an untracked first frame
    normalised, length = normalise_sequence(positions, "msr20")
    root = MSR20.parents.index(-1)
    pelvis, neck = MSR20.joint_names.index("HipCenter"), MSR20.joint_names.index("ShoulderCenter")
    size = np.linalg.norm(positions[1:, neck] - positions[1:, pelvis], axis=-1).mean()
    np.testing.assert_allclose(normalised[1:], (positions[1:] - positions[1, root]) / size, atol=1e-6)
    assert length == len(positions) and not normalised[0].any()


def test_representation_heading_is_the_yaw_of_the_forward_axis():
    from mocapkit.synthesis.representation import heading

    tilt = Rotation.from_rotvec([0.1, 0.0, 0.05])
    np.testing.assert_allclose(heading(Rotation.from_rotvec(np.outer(YAWS, [0, 1, 0])) * tilt), wrap(YAWS), atol=0.02)
    np.testing.assert_allclose(heading(Rotation.from_rotvec(np.outer(YAWS, [0, 1, 0]))), wrap(YAWS), atol=1e-12)


# --------------------------------------------------------------------------- torch counterparts


def test_torch_heading_and_turn_match_numpy():
    from mocapkit.models.body_frame import heading_cos_sin
    from mocapkit.models.body_frame import turn_about_up as turn_torch

    P = yawed()
    for up in "xyz":
        h1, h2 = horizontal_axes(up)
        line = torch.from_numpy(lateral_line(P, L_HIP, R_HIP))
        cos, sin = heading_cos_sin(line[:, h1], line[:, h2])
        angle = hip_line_heading(P, L_HIP, R_HIP, up=up, along="+x")
        np.testing.assert_allclose(cos.numpy(), np.cos(angle), atol=1e-12)
        np.testing.assert_allclose(sin.numpy(), np.sin(angle), atol=1e-12)
        coords = list(torch.from_numpy(P).unbind(-1))
        turned = torch.stack(turn_torch(coords, cos[:, None], sin[:, None], up), dim=-1).numpy()
        np.testing.assert_allclose(turned, turn_about_up(P, angle, up=up, along="+x"), atol=1e-12)
    cos, sin = heading_cos_sin(torch.zeros(2), torch.zeros(2))
    assert cos.tolist() == [1.0, 1.0] and sin.tolist() == [0.0, 0.0]


def test_torch_body0_frame_matches_numpy():
    from mocapkit.models.body_frame import body0_first, body0_origin, body0_size

    rng = np.random.default_rng(1)
    x = rng.normal(size=(1, 2, 9, 20, 3))
    present = np.zeros((1, 2, 9), dtype=bool)
    present[0, 0, [2, 3, 5, 6, 8]] = True
    X, M = torch.from_numpy(x), torch.from_numpy(present)
    np.testing.assert_allclose(body0_first(X, M, 4)[0].numpy(), body_origin(x[0, 0], present[0, 0], 4, "first"))
    np.testing.assert_allclose(body0_origin(X, M, 4)[0].numpy(), body_origin(x[0, 0], present[0, 0], 4, "median"))
    assert float(body0_size(X, M, 0, 2)[0]) == pytest.approx(body_size(x[0, 0], present[0, 0], 0, 2, "median"))


def test_refiner_normalizer_turn_is_the_numpy_turn():
    from mocapkit.models.refiners import PoseNormalizer

    P = yawed()
    for up in "xyz":
        normalizer = PoseNormalizer(list(range(-1, 19)), up_axis=up, hips=(L_HIP, R_HIP))
        angle = hip_line_heading(P, L_HIP, R_HIP, up=up, along="+x")
        coords = torch.from_numpy(P).permute(2, 0, 1)[None]  # [1, 3, T, J]
        c = torch.from_numpy(np.cos(angle)).view(1, 1, -1, 1)
        s = torch.from_numpy(np.sin(angle)).view(1, 1, -1, 1)
        turned = normalizer.turn_cf(coords, c, s)[0].permute(1, 2, 0).numpy()
        np.testing.assert_allclose(turned, turn_about_up(P, angle, up=up, along="+x"), atol=1e-12)


def test_energy_image_align_lays_body0_hips_along_x():
    from mocapkit.models.energy_image import EnergyImage

    P = yawed(np.full(5, 0.7))
    skeletons = torch.from_numpy(_msr_motion(P).positions[None, None].astype(np.float32))
    present = torch.ones(1, 1, 5, dtype=torch.bool)
    out = EnergyImage(MSR20, align=True, scale=False).normalize(skeletons, present)[0, 0].numpy()
    left, right = MSR20.joint_names.index("HipLeft"), MSR20.joint_names.index("HipRight")
    np.testing.assert_allclose((out[:, right] - out[:, left])[:, 2], 0, atol=1e-6)
    assert np.all(out[:, right, 0] > out[:, left, 0])


@pytest.mark.parametrize("up", ["x", "y", "z"])
@pytest.mark.parametrize("to", ["x", "y", "z"])
def test_turn_up_axis_is_an_exact_right_handed_turn(up, to):
    rng = np.random.default_rng(0)
    p = rng.normal(size=(7, 5, 3)).astype(np.float32)
    p[2, 1] = np.nan
    turned = turn_up_axis(p, up, to)
    assert np.array_equal(to_y_up(turned, to), to_y_up(p, up), equal_nan=True)  # the same pose, y-up
    assert np.array_equal(turn_up_axis(turned, to, up), p, equal_nan=True)  # and back, bit for bit
    rotation = np.stack([turn_up_axis(e, up, to) for e in np.eye(3)])
    assert np.isclose(np.linalg.det(rotation), 1.0)  # a rotation, not a mirror
    with pytest.raises(ValueError, match="up axes must be x, y or z"):
        turn_up_axis(p, "w", to)
