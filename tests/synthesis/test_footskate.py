"""Footskate cleanup (mocapkit.synthesis.footskate) on a synthetic HDM05-style skeleton: a body that glides over
the floor with its feet planted, floating a few centimetres above it."""

import numpy as np
import pytest

from mocapkit.datasets.formats.asf_amc import forward_kinematics
from mocapkit.datasets.synthetic.hdm05 import actor_skeleton
from mocapkit.synthesis.footskate import cleanup_footskate, detect_contacts, root_shift

FPS = 120.0
T = 60
SPEED = 1.0  # m/s along +x
FLOAT = 0.05  # m above the floor


@pytest.fixture(scope="module")
def skeleton():
    return actor_skeleton("bd")


def _ankles(skeleton, values):
    positions, _ = forward_kinematics(skeleton, values)
    names = skeleton.joint_names
    return positions[:, names.index("ltibia")], positions[:, names.index("rtibia")]


def _gliding(skeleton, lift_left: float = 0.0):
    """Bent knees, the root moving at SPEED and FLOAT above the height at which the feet touch the floor; returns
    the AMC values and that floor (the ankles' height when standing, metres)."""
    values = {b.name: np.zeros((T, len(b.dof))) for b in skeleton.bones if b.dof}
    for side in "lr":
        values[side + "femur"][:, skeleton.bone(side + "femur").dof.index("rx")] = -20.0
        values[side + "tibia"][:, 0] = 35.0
    values["root"] = np.zeros((T, 6))
    floor = float(_ankles(skeleton, values)[0][:, 1].min())
    unit = skeleton.metres_per_unit
    values["root"][:, 0] = SPEED * np.arange(T) / FPS / unit
    values["root"][:, 1] = FLOAT / unit
    if lift_left:
        values["lfemur"][:, skeleton.bone("lfemur").dof.index("rx")] = -100.0  # thigh raised, foot held high
    return values, floor


def test_full_cleanup_grounds_and_halts_planted_feet(skeleton):
    values, floor = _gliding(skeleton)
    before = _ankles(skeleton, values)
    assert all(abs(a[:, 1].mean() - floor - FLOAT) < 1e-6 for a in before)
    out, report = cleanup_footskate(values, skeleton, FPS, floor=floor, move_root="full")
    assert all(mask.all() for mask in report.contacts.values())
    assert report.sliding_before == pytest.approx(SPEED, rel=0.02)
    assert report.sliding_after < 0.01
    for ankle in _ankles(skeleton, out):
        np.testing.assert_allclose(ankle[:, 1], floor, atol=2e-3)
        assert np.ptp(ankle[:, [0, 2]], axis=0).max() < 0.005
    # the root gave back the glide and came down by the float
    np.testing.assert_allclose(report.root_shift[:, 0], -SPEED * np.arange(T) / FPS, atol=1e-6)
    np.testing.assert_allclose(report.root_shift[:, 1], -FLOAT, atol=1e-6)
    for bone in values:
        if bone not in ("root", "lfemur", "rfemur", "ltibia", "rtibia"):
            np.testing.assert_array_equal(out[bone], values[bone])


def test_vertical_cleanup_keeps_the_path_and_pins_with_the_legs(skeleton):
    values, floor = _gliding(skeleton)
    out, report = cleanup_footskate(values, skeleton, FPS, floor=floor, move_root="vertical")
    np.testing.assert_array_equal(out["root"][:, [0, 2]], values["root"][:, [0, 2]])
    assert np.all(report.root_shift[:, [0, 2]] == 0) and report.root_shift[:, 1] == pytest.approx(-FLOAT)
    # the IK keeps the feet on the floor where the bent legs reach; the body still glides away from them
    assert report.sliding_after < 0.5 * report.sliding_before
    left, _ = _ankles(skeleton, out)
    assert abs(left[T // 2, 1] - floor) < 0.01


def test_no_root_move_leaves_the_root_alone(skeleton):
    values, floor = _gliding(skeleton)
    out, report = cleanup_footskate(values, skeleton, FPS, floor=floor, move_root="none")
    np.testing.assert_array_equal(out["root"], values["root"])
    assert not report.root_shift.any()
    with pytest.raises(ValueError, match="move_root='sideways'"):
        cleanup_footskate(values, skeleton, FPS, floor=floor, move_root="sideways")


def test_a_foot_held_still_high_up_is_no_contact(skeleton):
    values, floor = _gliding(skeleton, lift_left=True)
    left, right = _ankles(skeleton, values)
    assert left[:, 1].min() > floor + 0.2
    assert not detect_contacts(left, FPS, floor).any()
    assert detect_contacts(right, FPS, floor).all()
    out, report = cleanup_footskate(values, skeleton, FPS, floor=floor)
    assert not report.contacts["lfemur"].any() and report.contacts["rfemur"].all()
    np.testing.assert_array_equal(out["lfemur"], values["lfemur"])  # the lifted leg is not pinned
    # the planted right foot alone sets the root's correction
    assert report.sliding_after < 0.01


def test_a_foot_moving_up_and_down_is_no_contact():
    t = np.arange(T) / FPS
    ankle = np.stack([np.zeros(T), 0.1 + 0.2 * np.abs(np.sin(2 * np.pi * t)), np.zeros(T)], axis=1)
    contact = detect_contacts(ankle, FPS, floor=0.1)
    # only the turns at the floor, where the foot is slow and low, can be stance; never the climb
    speed = np.abs(np.gradient(ankle[:, 1])) * FPS
    assert not contact[speed > 0.6].any()


def test_root_slack_lets_the_legs_absorb_small_slides():
    t = np.arange(240) / FPS
    floor = 0.1
    swaying = np.stack([0.04 * np.sin(2 * np.pi * t), np.full_like(t, floor), np.zeros_like(t)], axis=1)
    walking = np.stack([-SPEED * t, np.full_like(t, floor), np.zeros_like(t)], axis=1)
    contact = np.ones(len(t), dtype=bool)
    assert np.abs(root_shift([swaying], [contact], floor)[:, 0]).max() == pytest.approx(0.04, abs=2e-3)
    assert np.abs(root_shift([swaying], [contact], floor, slack=0.05)[:, 0]).max() < 1e-9
    # a steady slide is still taken up by the root, lagging by the slack at most
    full = root_shift([walking], [contact], floor)[:, 0]
    lagging = root_shift([walking], [contact], floor, slack=0.05)[:, 0]
    np.testing.assert_allclose(full, SPEED * t, atol=1e-9)
    assert np.abs(lagging - full)[30:-30].max() <= 0.05 + 1e-9 and lagging[-30] > 0.9 * full[-30]


def test_a_three_dof_knee_is_pinned_as_the_hinge_is(skeleton):
    """BVH rigs converted to ASF (mocapkit.datasets.formats.bvh_to_amc) have three-dof knees: the IK bends them
    about the normal of the leg's plane, which for a knee bent about its x axis is the hinge's own axis."""
    import copy

    free = copy.deepcopy(skeleton)
    for side in "lr":
        free.bone(side + "tibia").dof = ("rx", "ry", "rz")
        free.bone(side + "tibia").limits = [(-np.inf, np.inf)] * 3
    values, floor = _gliding(skeleton)
    free_values = {bone: v.copy() for bone, v in values.items()}
    for side in "lr":
        free_values[side + "tibia"] = np.concatenate([values[side + "tibia"], np.zeros((T, 2))], axis=1)
    for move in ("vertical", "full"):
        hinge, hinge_report = cleanup_footskate(values, skeleton, FPS, floor=floor, move_root=move)
        out, report = cleanup_footskate(free_values, free, FPS, floor=floor, move_root=move)
        assert report.skipped_legs == [] and report.sliding_after == pytest.approx(hinge_report.sliding_after, abs=1e-6)
        for a, b in zip(_ankles(free, out), _ankles(skeleton, hinge)):
            np.testing.assert_allclose(a, b, atol=1e-6)
        # the same bend, to within the few thousandths of a degree by which HDM05's thigh and shin leave the plane
        # normal to the hinge axis
        np.testing.assert_allclose(out["ltibia"][:, 0], hinge["ltibia"][:, 0], atol=0.01)
        np.testing.assert_allclose(out["ltibia"][:, 1:], 0.0, atol=0.01)
    # a knee that is also twisted keeps bending about its leg's plane: the feet still stay put
    free_values["ltibia"][:, 1] = 25.0
    out, report = cleanup_footskate(free_values, free, FPS, floor=floor, move_root="vertical")
    assert report.sliding_after < 0.5 * report.sliding_before
    left, _ = _ankles(free, out)
    assert abs(left[T // 2, 1] - floor) < 0.01


def test_stance_root_correction_leaves_a_still_stance_between_swings_alone():
    """A foot planted still for frames 20–39 and swinging forward at 3 m/s around it (a real step): the body should
    keep its travel. With the blend ramps the root loses the swing's steps next to the stance (what slowed real
    clips down); over the contact frames only it loses nothing."""
    t = np.arange(T)
    x = np.where(t < 20, 3.0 * (t - 20) / FPS, np.where(t < 40, 0.0, 3.0 * (t - 39) / FPS))
    ankle = np.stack([x, np.zeros(T), np.zeros(T)], axis=1)
    contact = (t >= 20) & (t < 40)
    ramped = root_shift([ankle], [contact], floor=0.0, blend_frames=6, ramps=True)
    stance = root_shift([ankle], [contact], floor=0.0, blend_frames=6, ramps=False)
    np.testing.assert_allclose(stance, 0.0, atol=1e-12)
    assert np.abs(ramped[:, 0]).max() > 0.05  # the swing's steps taken out of the root's travel
