"""Kinect v1 noise simulator (mocapkit.datasets.synthetic.kinect_noise): hand-built poses, and real HDM05 cuts
where ``../shared/data/hdm05_cuts11`` is present."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.datasets.synthetic.kinect_noise import (
    COMPONENTS,
    INFERRED,
    NOT_TRACKED,
    TRACKED,
    KinectInputError,
    KinectNoiseConfig,
    VirtualCamera,
    kinect20_from_motion,
    place_camera,
    self_occlusion,
    simulate_kinect,
    simulate_pairs,
)
from mocapkit.kinect.metrics import joint_error_cm
from mocapkit.motion.layouts import LANDMARK_NAMES
from tests.shared_data import SHARED

HDM05 = SHARED / "data" / "hdm05_cuts11"
J = {name: k for k, name in enumerate(LANDMARK_NAMES)}

#: A standing adult facing +z, y up, left = +x (metres), arms hanging at the sides.
STANDING = {
    "pelvis": (0.0, 1.00, 0.0),
    "spine": (0.0, 1.25, 0.0),
    "neck": (0.0, 1.47, 0.0),
    "head": (0.0, 1.65, 0.02),
    "l_shoulder": (0.19, 1.44, 0.0),
    "l_elbow": (0.23, 1.17, -0.02),
    "l_wrist": (0.25, 0.93, 0.02),
    "l_hand": (0.26, 0.85, 0.04),
    "l_hip": (0.09, 0.92, 0.03),
    "l_knee": (0.10, 0.50, 0.04),
    "l_ankle": (0.10, 0.09, 0.0),
    "l_foot": (0.10, 0.03, 0.13),
}


def standing_pose() -> np.ndarray:
    """``[20, 3]`` landmarks of :data:`STANDING`, the right side mirrored."""
    pose = np.zeros((20, 3))
    for name, k in J.items():
        if name.startswith("r_"):
            x, y, z = STANDING["l_" + name[2:]]
            pose[k] = (-x, y, z)
        else:
            pose[k] = STANDING[name]
    return pose


def yaw(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Turn ``[T, 20, 3]`` points about the vertical axis through the origin by ``angle [T]`` radians."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    out = points.copy()
    out[..., 0] = c * points[..., 0] + s * points[..., 2]
    out[..., 2] = -s * points[..., 0] + c * points[..., 2]
    return out


def moving_clip(seconds: float = 4.0, fps: float = 30.0, turns: float = 0.0) -> np.ndarray:
    """float32 ``[T, 20, 3]``: the standing pose with swinging forearms, turning ``turns`` times about y."""
    t = np.arange(int(seconds * fps)) / fps
    clip = np.repeat(standing_pose()[None], len(t), axis=0)
    swing = 0.15 * np.sin(2 * np.pi * 0.8 * t)
    for side, sign in (("l_", 1.0), ("r_", -1.0)):
        for part, reach in (("wrist", 1.0), ("hand", 1.3)):
            clip[:, J[side + part], 2] += sign * reach * swing
    return yaw(clip, 2 * np.pi * turns * t / seconds).astype(np.float32)


def front_camera(distance: float = 2.5) -> VirtualCamera:
    """A camera on the +z side (in front of :func:`standing_pose`) at 0.8 m height."""
    return VirtualCamera(np.array([0.0, 0.8, distance]), np.array([0.0, 0.9, 0.0]))


def test_shapes_dtypes_and_determinism():
    clip = moving_clip()
    noisy, state = simulate_kinect(clip, seed=3)
    assert noisy.shape == clip.shape and noisy.dtype == np.float32
    assert state.shape == clip.shape[:2] and state.dtype == np.int8
    assert set(np.unique(state)) <= {TRACKED, INFERRED, NOT_TRACKED}
    again, state_again = simulate_kinect(clip, seed=3)
    np.testing.assert_array_equal(noisy, again)
    np.testing.assert_array_equal(state, state_again)
    other, _ = simulate_kinect(clip, seed=4)
    assert not np.array_equal(noisy, other)
    # place_camera gives the camera the simulation drew for the same seed
    with_camera, _ = simulate_kinect(clip, seed=3, camera=place_camera(clip, seed=3))
    np.testing.assert_array_equal(with_camera, noisy)
    same_stream, _ = simulate_kinect(clip, seed=np.random.default_rng(7))
    np.testing.assert_array_equal(same_stream, simulate_kinect(clip, seed=np.random.default_rng(7))[0])


def test_every_component_off_returns_the_input_exactly():
    clip = moving_clip(turns=1.0)
    noisy, state = simulate_kinect(clip, KinectNoiseConfig.off(), seed=0)
    np.testing.assert_array_equal(noisy, clip)
    assert (state == TRACKED).all()
    assert KinectNoiseConfig().without(*COMPONENTS) == KinectNoiseConfig.off()


def test_long_turning_clip_has_all_three_states():
    clip = moving_clip(seconds=20.0, turns=2.0)
    _, state = simulate_kinect(clip, seed=0)
    counts = np.bincount(state.ravel(), minlength=3)
    assert counts[TRACKED] > counts[INFERRED] > 0
    assert counts[NOT_TRACKED] > 0
    # without left/right swaps (which move states between sides), NOT_TRACKED only follows a long occlusion
    _, state = simulate_kinect(clip, KinectNoiseConfig().without("swaps"), seed=0)
    t, j = np.nonzero((state[1:] == NOT_TRACKED) & (state[:-1] != NOT_TRACKED))
    assert len(t) and (state[t, j] == INFERRED).all()
    assert all((state[max(k - 14, 0) : k + 1, i] == INFERRED).all() for k, i in zip(t, j))  # 0.5 s at 30 fps


def test_arm_behind_the_back_is_inferred_and_snaps_towards_the_camera():
    pose = standing_pose()
    pose[J["l_elbow"]] = (0.17, 1.18, -0.16)  # left arm bent behind the back
    pose[J["l_wrist"]] = (0.05, 1.05, -0.20)
    pose[J["l_hand"]] = (-0.02, 1.00, -0.20)
    clip = np.repeat(pose[None], 10, axis=0).astype(np.float32)
    camera = front_camera()
    hidden, hit = self_occlusion(clip, camera)
    assert hidden[:, [J["l_wrist"], J["l_hand"]]].all()
    visible = [J[n] for n in ("head", "neck", "r_shoulder", "r_elbow", "r_wrist", "r_hand", "l_knee", "r_foot")]
    assert not hidden[:, visible].any()
    assert np.isfinite(hit[:, J["l_hand"]]).all() and (hit[:, J["l_hand"]] < 2.5).all()

    _, state = simulate_kinect(clip, seed=0, camera=camera)
    assert (state[:, [J["l_wrist"], J["l_hand"]]] == INFERRED).all()
    assert (state[:, visible] == TRACKED).all()
    only_occlusion = KinectNoiseConfig.off(occlusion=True)
    snapped, _ = simulate_kinect(clip, only_occlusion, seed=0, camera=camera)
    # pulled onto the front of the trunk: at least 10 cm nearer the camera (+z) than the true hand
    assert (snapped[:, J["l_hand"], 2] - clip[:, J["l_hand"], 2] > 0.10).all()
    np.testing.assert_array_equal(snapped[:, visible], clip[:, visible])


def test_surface_bias_moves_every_joint_towards_the_camera_by_its_radius():
    clip = moving_clip(seconds=1.0)
    camera = front_camera()
    config = KinectNoiseConfig.off(surface_bias=True)
    noisy, _ = simulate_kinect(clip, config, seed=0, camera=camera)
    before = np.linalg.norm(clip - camera.position, axis=-1)
    after = np.linalg.norm(noisy - camera.position, axis=-1)
    np.testing.assert_allclose(
        before - after, np.broadcast_to(config.per_joint("surface_radius_m"), before.shape), atol=1e-5
    )
    assert config.per_joint("surface_radius_m")[J["spine"]] > config.per_joint("surface_radius_m")[J["l_wrist"]]


def test_error_grows_with_the_noise_level():
    clip = moving_clip(seconds=6.0, turns=0.5)
    errors = [
        joint_error_cm(clip, simulate_kinect(clip, KinectNoiseConfig().scaled(k), seed=1)[0])
        for k in (0.25, 0.5, 1.0, 2.0)
    ]
    assert errors == sorted(errors) and errors[-1] > 1.5 * errors[0]


def test_depth_noise_grows_with_distance():
    clip = np.repeat(standing_pose()[None], 300, axis=0).astype(np.float32)
    config = KinectNoiseConfig.off(depth_noise=True)
    near, far = (simulate_kinect(clip, config, seed=0, camera=front_camera(d))[0] for d in (1.5, 4.0))
    near_error, far_error = joint_error_cm(clip, near), joint_error_cm(clip, far)
    assert far_error > 4 * near_error  # σ ∝ depth²: (4 / 1.5)² ≈ 7


def test_leg_swaps_are_more_frequent_side_on():
    clip = moving_clip(seconds=30.0)
    config = KinectNoiseConfig.off(swaps=True)
    side = VirtualCamera(np.array([2.5, 0.8, 0.0]), np.array([0.0, 0.9, 0.0]))
    swapped = {}
    for name, camera in (("front", front_camera()), ("side", side)):
        noisy, _ = simulate_kinect(clip, config, seed=0, camera=camera)
        swapped[name] = float((noisy[:, J["l_knee"]] != clip[:, J["l_knee"]]).any(axis=-1).mean())
    assert swapped["side"] > 3 * swapped["front"] > 0
    # arms and the trunk stay where they are
    noisy, _ = simulate_kinect(clip, config, seed=0, camera=side)
    np.testing.assert_array_equal(noisy[:, :12], clip[:, :12])


def test_msr_steadiness_preset_cuts_only_the_frame_to_frame_noise():
    from mocapkit.kinect.metrics import bone_length_sd_cm, jitter_cm

    clip = moving_clip(seconds=8.0, turns=0.5)
    default, steady = KinectNoiseConfig.preset("mean_error"), KinectNoiseConfig.preset("msr_steadiness")
    assert default == KinectNoiseConfig()
    assert steady.jitter_sigma_m["hand"] == pytest.approx(0.1 * default.jitter_sigma_m["hand"])
    assert steady.bone_length_sigma == pytest.approx(0.1 * default.bone_length_sigma)
    assert steady.surface_radius_m["pelvis"] == pytest.approx(1.15 * default.surface_radius_m["pelvis"])
    # about the same occlusion (the visible surface moves with the surface radius), a much steadier skeleton
    noisy_default, state_default = simulate_kinect(clip, default, seed=2)
    noisy_steady, state_steady = simulate_kinect(clip, steady, seed=2)
    assert (state_default != TRACKED).mean() > 0.02
    assert abs((state_default == TRACKED).mean() - (state_steady == TRACKED).mean()) < 0.05
    tracked_only = {"occlusion": False, "swaps": False}
    calm_default = simulate_kinect(clip, replace(default, **tracked_only), seed=2)[0]
    calm_steady = simulate_kinect(clip, replace(steady, **tracked_only), seed=2)[0]
    assert bone_length_sd_cm(calm_steady) < 0.5 * bone_length_sd_cm(calm_default)
    assert jitter_cm(calm_steady) < 0.5 * jitter_cm(calm_default)
    assert jitter_cm(noisy_steady) < jitter_cm(noisy_default)
    with pytest.raises(ValueError, match="unknown Kinect noise preset 'v2'"):
        KinectNoiseConfig.preset("v2")


def test_config_is_checked():
    with pytest.raises(ValueError, match="surface_radius_m"):
        KinectNoiseConfig(surface_radius_m={"pelvis": 0.1})
    with pytest.raises(ValueError, match="unknown noise components"):
        KinectNoiseConfig().without("blur")
    with pytest.raises(ValueError, match=r"\[frames, 20, 3\]"):
        simulate_kinect(np.zeros((5, 25, 3)))


@pytest.mark.skipif(not HDM05.exists(), reason=f"real data not found at {HDM05}")
def test_kinect20_from_real_hdm05_clip_is_y_up_and_body_sized():
    path = HDM05 / "bd" / "HDM_bd_squat1Reps_001_120.amc"
    motion = read_motion(path)
    skeleton = kinect20_from_motion(motion, fps=30.0)
    assert skeleton.dtype == np.float32 and skeleton.shape[1:] == (20, 3)
    assert len(skeleton) == int(np.floor((motion.num_frames - 1) / 4 + 1e-6)) + 1  # 120 → 30 fps
    first = skeleton[0]
    height = first[J["head"], 1] - min(first[J["l_foot"], 1], first[J["r_foot"], 1])
    assert 1.4 < height < 2.0
    assert (
        first[J["head"], 1]
        > first[J["neck"], 1]
        > first[J["pelvis"], 1]
        > first[J["l_knee"], 1]
        > first[J["l_ankle"], 1]
    )
    noisy, _ = simulate_kinect(skeleton, seed=0)
    assert 2.0 < joint_error_cm(skeleton, noisy) < 40.0


def test_bad_files_raise_naming_the_file_or_are_reported(tmp_path):
    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    good = synthesize_hdm05(
        tmp_path,
        HDM05SynthConfig(classes=("squat1Reps",), actors=("bd",), clips_per_actor=1, max_frames=90),
        progress=False,
    )[0]
    bad = tmp_path / "broken.bvh"
    bad.write_text("not a bvh file\n")
    with pytest.raises(KinectInputError, match="broken.bvh"):
        simulate_pairs([good, bad])
    with pytest.warns(UserWarning, match="broken.bvh"):
        pairs, skipped = simulate_pairs([good, bad], skip_bad=True)
    assert [p.path for p in pairs] == [good] and [path for path, _ in skipped] == [bad]
    clean, noisy, state = pairs[0]
    assert clean.shape == noisy.shape and state.shape == clean.shape[:2]
    # the same file gives the same pair whatever else is simulated with it
    alone, _ = simulate_pairs([good])
    np.testing.assert_array_equal(alone[0].noisy, noisy)
    # a motion without the Kinect landmarks is refused with its name
    motion = read_motion(good)
    hidden = motion.select([n for n in motion.joint_names if n != "lhipjoint"])
    with pytest.raises(KinectInputError, match="squat1Reps_bd_001"):
        kinect20_from_motion(hidden)
    gappy = motion.positions.copy()
    gappy[10:20, motion.joint_names.index("lhand")] = np.nan
    with pytest.raises(KinectInputError, match=r"squat1Reps_bd_001.*l_hand.*unobserved"):
        kinect20_from_motion(replace(motion, positions=gappy, missing=None))


def test_real_sensor_preset_jitters_white_rarely_swaps_and_never_stops_tracking():
    from mocapkit.datasets.synthetic.kinect_noise import NOISE_PRESETS, REAL_SENSOR_JITTER_SCALE
    from mocapkit.kinect.metrics import high_frequency_share, swap_events

    assert "real_sensor" in NOISE_PRESETS
    default, real = KinectNoiseConfig.preset("mean_error"), KinectNoiseConfig.preset("real_sensor")
    assert real.jitter_sigma_m["hand"] == pytest.approx(REAL_SENSOR_JITTER_SCALE * default.jitter_sigma_m["hand"])
    assert real.surface_radius_m == default.surface_radius_m and real.joint_offset_m == default.joint_offset_m
    clip = moving_clip(seconds=30.0, turns=1.0)
    side = VirtualCamera(np.array([2.5, 0.8, 0.0]), np.array([0.0, 0.9, 0.0]))
    noisy_default, _ = simulate_kinect(clip, default, seed=4, camera=side)
    noisy_real, state_real = simulate_kinect(clip, real, seed=4, camera=side)
    assert (state_real == NOT_TRACKED).sum() == 0 and (state_real == INFERRED).any()
    # side-on for 30 s (the worst view): the default swaps the legs many times, the real sensor's calibration
    # (50 times rarer swaps; the remaining events are inferred joints snapping) a few times
    assert swap_events(noisy_default) > 10 and swap_events(noisy_real) < 0.25 * swap_events(noisy_default)
    # white jitter: more of the velocity power above 3 Hz than the same jitter low-passed as the default's
    calm = {"occlusion": False, "swaps": False}
    low_passed = simulate_kinect(clip, replace(real, jitter_time_constant_s=0.1, **calm), seed=4)[0]
    white = simulate_kinect(clip, replace(real, **calm), seed=4)[0]
    assert high_frequency_share(white, 30.0) > high_frequency_share(low_passed, 30.0) + 0.1
