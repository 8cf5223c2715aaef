"""``mocapkit synth depth``: the rendered depth is where the capsules are, the noise model has the published σ(z),
holes sit at silhouettes, labels, joints, the sensor skeleton and camera_to_world agree, and the command works on a
real HDM05 take."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from mocapkit.cli import main
from mocapkit.datasets.formats.depth_images import CameraIntrinsics, read_depth_sequence
from mocapkit.datasets.synthetic.capsule_render import raycast_capsules
from mocapkit.datasets.synthetic.depth import (
    CAPSULE_NAMES,
    GIRTH_RANGE,
    DepthNoiseConfig,
    apply_depth_noise,
    body_radii,
    render_depth_sequence,
    stature_scale,
)
from mocapkit.datasets.synthetic.kinect_noise import CAPSULES
from mocapkit.motion.layouts import LANDMARK_NAMES
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
HDM05_TAKE = HDM05 / "bd" / "HDM_bd_depositFloorR_001_120.amc"
KINECT = CameraIntrinsics.preset("kinect_v1")
_A = np.array([LANDMARK_NAMES.index(a) for a, _ in CAPSULES.values()])
_B = np.array([LANDMARK_NAMES.index(b) for _, b in CAPSULES.values()])

#: A standing performer, metres, y up, facing +z (left is +x); mirrored for the right side.
_POSE = {
    "pelvis": (0, 1.0, 0),
    "spine": (0, 1.2, 0),
    "neck": (0, 1.45, 0),
    "head": (0, 1.62, 0),
    "shoulder": (0.18, 1.42, 0),
    "elbow": (0.22, 1.15, 0),
    "wrist": (0.24, 0.92, 0.02),
    "hand": (0.25, 0.84, 0.04),
    "hip": (0.1, 0.95, 0),
    "knee": (0.11, 0.52, 0.02),
    "ankle": (0.11, 0.1, 0),
    "foot": (0.11, 0.03, 0.13),
}


def standing(frames=6):
    """``[frames, 20, 3]`` Kinect-20 landmarks of a standing performer swaying by a centimetre."""
    pose = []
    for name in LANDMARK_NAMES:
        x, y, z = _POSE[name[2:] if name[:2] in ("l_", "r_") else name]
        pose.append((-x if name.startswith("r_") else x, y, z))
    sway = 0.01 * np.sin(0.5 * np.arange(frames))[:, None, None] * np.array([1.0, 0.0, 0.0])
    return np.array(pose)[None] + sway


@pytest.fixture(scope="module")
def clean():
    return render_depth_sequence(standing(4), 30.0, "kinect_v1", noise="none", seed=1)


def _boundary(parts):
    """bool ``[T, H, W]``: body pixels with a 4-neighbour of another label (background included)."""
    padded = np.pad(parts, ((0, 0), (1, 1), (1, 1)), mode="edge")
    H, W = parts.shape[1:]
    out = np.zeros(parts.shape, dtype=bool)
    for dr, dc in ((0, 1), (2, 1), (1, 0), (1, 2)):
        out |= padded[:, dr : dr + H, dc : dc + W] != parts
    return out & (parts > 0)


def _dilate(mask, steps):
    for _ in range(steps):
        grown = mask.copy()
        grown[:, 1:] |= mask[:, :-1]
        grown[:, :-1] |= mask[:, 1:]
        grown[:, :, 1:] |= mask[:, :, :-1]
        grown[:, :, :-1] |= mask[:, :, 1:]
        mask = grown
    return mask


# ------------------------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("distance", [1.0, 2.0, 3.5])
def test_a_sphere_renders_at_its_distance_in_millimetres(distance):
    centre = np.array([0.05, -0.02, distance])
    radius = 0.1
    ends = torch.tensor(centre[None], dtype=torch.float64)
    hits = raycast_capsules(ends, ends, torch.tensor([radius], dtype=torch.float64), KINECT)
    cos = -(hits.normals * hits.points).sum(-1) / hits.points.norm(dim=-1).clamp_min(1e-9)
    depth = apply_depth_noise(
        hits.full_image(KINECT).numpy(), hits.full_image(KINECT, cos).numpy(), DepthNoiseConfig.preset("none"), None
    )
    u, v = np.rint(KINECT.project(centre)).astype(int)
    ray = np.array([(u - KINECT.cx) / KINECT.fx, (v - KINECT.cy) / KINECT.fy, 1.0])
    ray /= np.linalg.norm(ray)
    along = ray @ centre
    t = along - np.sqrt(along**2 - centre @ centre + radius**2)  # first hit of the ray and the sphere
    assert abs(int(depth[v, u]) - 1000 * t * ray[2]) <= 0.5 + 1e-6


def test_every_pixel_is_the_nearest_capsule_of_its_ray(clean):
    """Depth and part label against a brute-force march along 40 pixels' rays (independent of the ray caster)."""
    radius = np.array([clean.metadata["capsule_radius_m"][name] for name in CAPSULE_NAMES])
    joints = clean.joints[0].astype(np.float64)
    a, b = joints[_A], joints[_B]
    rows, cols = np.nonzero(clean.parts[0])
    pick = np.random.default_rng(0).choice(len(rows), 40, replace=False)
    t = np.arange(0.5, 6.0, 0.001)
    checked = 0
    for v, u in zip(rows[pick], cols[pick]):
        ray = np.array([(u - KINECT.cx) / KINECT.fx, (v - KINECT.cy) / KINECT.fy, 1.0])
        ray /= np.linalg.norm(ray)
        first = []
        for k in range(len(radius)):
            ab = b[k] - a[k]
            points = t[:, None] * ray  # [S, 3]
            s = np.clip(((points - a[k]) @ ab) / max(ab @ ab, 1e-12), 0, 1)
            inside = np.linalg.norm(points - (a[k] + s[:, None] * ab), axis=-1) <= radius[k]
            if not inside.any():
                first.append(np.inf)
                continue
            hi = t[np.argmax(inside)]
            lo = hi - 0.001
            for _ in range(30):  # bisection onto the surface
                mid = 0.5 * (lo + hi)
                p = mid * ray
                s = np.clip(((p - a[k]) @ ab) / max(ab @ ab, 1e-12), 0, 1)
                lo, hi = (lo, mid) if np.linalg.norm(p - (a[k] + s * ab)) <= radius[k] else (mid, hi)
            first.append(hi)
        first = np.array(first)
        order = np.argsort(first)
        assert np.isfinite(first[order[0]])
        assert abs(int(clean.depth_mm[0, v, u]) - 1000 * first[order[0]] * ray[2]) <= 1.0
        if first[order[1]] - first[order[0]] > 0.002:  # not where two capsules meet
            assert clean.parts[0, v, u] == order[0] + 1, CAPSULE_NAMES[order[0]]
            checked += 1
    assert checked >= 20


def test_joints_sensor_skeleton_and_camera_to_world_share_one_frame(clean):
    positions = standing(4)
    world = clean.joints.astype(np.float64) @ clean.camera_to_world[:3, :3].T + clean.camera_to_world[:3, 3]
    assert np.abs(world - positions).max() < 1e-5
    assert clean.camera_to_world[3].tolist() == [0.0, 0.0, 0.0, 1.0]
    # the head is above the pelvis: up in the world is −y in the image convention
    head, pelvis = LANDMARK_NAMES.index("head"), LANDMARK_NAMES.index("pelvis")
    assert (clean.joints[:, head, 1] < clean.joints[:, pelvis, 1]).all()
    offset = np.linalg.norm(clean.sensor_joints - clean.joints, axis=-1).mean()
    assert 0.01 < offset < 0.2, offset  # a Kinect's error, not a different frame
    assert set(np.unique(clean.sensor_state)) <= {0, 1, 2}
    assert clean.joint_names == LANDMARK_NAMES and clean.part_names == CAPSULE_NAMES


def test_body_scale_follows_the_performer_and_a_drawn_girth(clean):
    positions = standing(2)
    assert 0.9 < stature_scale(positions) < 1.1
    assert stature_scale(1.1 * positions) == pytest.approx(1.1 * stature_scale(positions))
    assert np.allclose(body_radii(1.1 * positions, 1.0), 1.1 * body_radii(positions, 1.0))
    girths = {
        render_depth_sequence(positions[:1], 30.0, noise="none", seed=s).metadata["girth_factor"] for s in range(4)
    }
    assert len(girths) == 4 and all(GIRTH_RANGE[0] <= g <= GIRTH_RANGE[1] for g in girths)
    assert clean.metadata["noise"] == "none" and clean.metadata["empty_frames"] == 0


def test_the_output_is_a_function_of_the_seed():
    first, again = (render_depth_sequence(standing(2), 30.0, seed=5) for _ in range(2))
    other = render_depth_sequence(standing(2), 30.0, seed=6)
    for name in ("depth_mm", "colour", "sensor_joints"):
        assert np.array_equal(getattr(first, name), getattr(again, name))
        assert not np.array_equal(getattr(first, name), getattr(other, name))


# ---------------------------------------------------------------------------------------------- noise


def _flat(z, config, seed=0, frames=4, size=64):
    rng = np.random.default_rng(seed)
    depth = np.full((size, size), z)
    cos = np.ones_like(depth)
    return np.stack([apply_depth_noise(depth, cos, config, rng) for _ in range(frames)]).astype(np.float64) / 1000


def test_kinect_noise_has_nguyens_sigma_growing_with_z_squared():
    config = replace(DepthNoiseConfig.preset("kinect_v1"), disparity_step_per_m=0.0, dropout=0.0)
    measured = {}
    for z in (1.0, 2.0, 3.0):
        depth = _flat(z, config)
        assert (depth > 0).all()
        expected = 0.0012 + 0.0019 * (z - 0.4) ** 2  # Nguyen et al. 2012, θ = 0
        measured[z] = np.sqrt(depth.var() - 1e-6 / 12)  # less the variance of whole-millimetre rounding
        assert measured[z] == pytest.approx(expected, rel=0.05)
        assert abs(depth.mean() - z) < 4 * expected / np.sqrt(depth.size)
    assert measured[3.0] / measured[1.0] > 6  # 7.4 for this model: far more than linear growth (3)
    # the full preset: 1/z quantised in steps of 2.85e-3 per metre (Khoshelham & Oude Elberink 2012)
    steps = np.diff(np.unique(_flat(3.0, DepthNoiseConfig.preset("kinect_v1"))))
    assert np.median(steps) == pytest.approx(2.85e-3 * 3.0**2, rel=0.08)
    azure = _flat(3.0, replace(DepthNoiseConfig.preset("azure_kinect"), dropout=0.0))
    assert azure.std() == pytest.approx(0.001 + 0.001 * 3.0, rel=0.1) and azure.std() < measured[3.0] / 3


def test_range_limits_grazing_angles_and_dropout():
    config = DepthNoiseConfig.preset("kinect_v1")
    assert not _flat(0.7, config).any() and not _flat(4.3, config).any()
    assert (_flat(0.6, DepthNoiseConfig.preset("azure_kinect")) > 0).mean() > 0.99
    depth = np.full((64, 64), 2.0)
    rng = np.random.default_rng(0)
    steep = apply_depth_noise(depth, np.full_like(depth, np.cos(np.radians(80))), config, rng)
    assert not steep.any()
    facing = apply_depth_noise(depth, np.full_like(depth, np.cos(np.radians(60))), config, rng)
    assert 0.98 < (facing > 0).mean() < 1.0  # only the 0.5 % random dropout
    with pytest.raises(ValueError, match="edge_dropout must be in"):
        DepthNoiseConfig(edge_dropout=1.5)
    with pytest.raises(ValueError, match="unknown depth noise preset"):
        DepthNoiseConfig.preset("kinect_v2")


def test_holes_sit_at_silhouettes():
    positions = standing(4)
    grazing = render_depth_sequence(positions, 30.0, noise=DepthNoiseConfig(grazing_limit_deg=75.0), seed=1)
    holes = (grazing.parts > 0) & (grazing.depth_mm == 0)
    assert holes.sum() > 50  # the rims of the capsules
    assert not (holes & ~_dilate(_boundary(grazing.parts), 2)).any()
    noisy = render_depth_sequence(positions, 30.0, noise="kinect_v1", seed=1)
    body = noisy.parts > 0
    silhouette = body & _dilate(~body, 1)
    interior = body & ~_dilate(~body, 3)
    holes = noisy.depth_mm == 0
    assert holes[silhouette].mean() > 0.3 and holes[interior].mean() < 0.05
    assert holes[silhouette].mean() > 10 * holes[interior].mean()


# ------------------------------------------------------------------------------------------ real data


@needs(HDM05_TAKE)
def test_a_real_hdm05_take_renders_with_the_body_in_view():
    from mocapkit.datasets.formats.motion_io import read_motion
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion

    positions = kinect20_from_motion(read_motion(HDM05_TAKE))[:10]
    sequence = render_depth_sequence(positions, 30.0, "kinect_v1", seed=0, source=str(HDM05_TAKE))
    depth = sequence.depth_mm
    assert depth.reshape(10, -1).any(axis=1).all()
    assert 800 <= depth[depth > 0].min() and depth.max() <= 4000
    u, v = np.moveaxis(KINECT.project(sequence.joints), -1, 0)
    inside = (u >= 0) & (u < KINECT.width) & (v >= 0) & (v < KINECT.height)
    assert inside.mean() > 0.95
    assert (sequence.parts > 0).sum(axis=(1, 2)).min() > 1000


@needs(HDM05_TAKE)
def test_the_command_end_to_end(tmp_path, capsys):
    bad = tmp_path / "broken.bvh"
    bad.write_text("not a BVH file\n")
    out = tmp_path / "out"
    assert main(["synth", "depth", str(HDM05_TAKE), "--out", str(out), "--max-frames", "10", "--quiet"]) == 0
    written = out / f"{HDM05_TAKE.stem}.npz"
    assert str(written) in capsys.readouterr().out
    sequence = read_depth_sequence(written)
    assert sequence.num_frames == 10 and sequence.intrinsics == KINECT and sequence.fps == 30.0
    assert sequence.metadata["source"] == str(HDM05_TAKE) and sequence.metadata["noise"] == "kinect_v1"

    args = ["synth", "depth", str(HDM05_TAKE), str(bad), "--out", str(out / "png"), "--max-frames", "3"]
    assert main([*args, "--format", "png", "--camera", "azure_kinect", "--noise", "none", "--quiet"]) == 2
    assert "broken.bvh" in capsys.readouterr().err
    with pytest.warns(UserWarning, match="broken.bvh"):
        assert main([*args, "--format", "png", "--camera", "azure_kinect", "--skip-bad", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "skipped" in printed and "broken.bvh" in printed
    sequence = read_depth_sequence(out / "png" / HDM05_TAKE.stem)
    assert sequence.num_frames == 3 and sequence.intrinsics == CameraIntrinsics.preset("azure_kinect")
    assert sequence.colour.shape == (3, 576, 640, 3) and sequence.metadata["noise"] == "azure_kinect"
