"""The 3D energy image: geometry, invariances, options and ONNX export."""

import math

import numpy as np
import pytest
import torch

from mocapkit.models import EnergyImage
from mocapkit.motion.layouts import NTU25


def standing_skeleton(frames: int = 10, x: float = 0.0, z: float = 3.0) -> torch.Tensor:
    """A rough upright 25-joint body ``[frames, 25, 3]``: spine base at height 0, spine 0.5 m long."""
    pose = torch.zeros(25, 3)
    heights = {
        "SpineBase": 0.0,
        "SpineMid": 0.25,
        "SpineShoulder": 0.5,
        "Neck": 0.6,
        "Head": 0.75,
        "HipLeft": -0.05,
        "HipRight": -0.05,
        "KneeLeft": -0.5,
        "KneeRight": -0.5,
        "AnkleLeft": -0.9,
        "AnkleRight": -0.9,
        "FootLeft": -0.95,
        "FootRight": -0.95,
    }
    for name, h in heights.items():
        pose[NTU25.index(name), 1] = h
    for side, sx in (("Left", -1.0), ("Right", 1.0)):
        for name, (dx, h) in {
            "Shoulder": (0.2, 0.5),
            "Elbow": (0.25, 0.2),
            "Wrist": (0.27, -0.05),
            "Hand": (0.28, -0.1),
            "HandTip": (0.28, -0.18),
            "Thumb": (0.26, -0.12),
        }.items():
            pose[NTU25.index(name + side)] = torch.tensor([sx * dx, h, 0.0])
        for name in ("Hip", "Knee", "Ankle", "Foot"):
            pose[NTU25.index(name + side), 0] = sx * 0.1
    pose += torch.tensor([x, 0.0, z])
    return pose.expand(frames, 25, 3).clone()


def batch(*bodies: torch.Tensor) -> torch.Tensor:
    """``[1, M, T, 25, 3]`` from per-body ``[T, 25, 3]`` tensors."""
    return torch.stack(bodies)[None]


def test_nearest_splat_is_an_exact_time_averaged_histogram():
    energy = EnergyImage(size=32, splat="nearest", align=False)
    x = batch(standing_skeleton(frames=5), torch.zeros(5, 25, 3))
    image = energy(x)
    assert image.shape == (1, 3, 32, 32)
    # With nearest binning and a static pose every frame hits the same pixels, so the
    # normalised histogram's peak pixel holds the largest number of coincident joints.
    axes = energy.normalize(x, x.abs().sum((-1, -2)) > 0)[0, 0, :1].transpose(1, 2)  # first frame, [1, 3, 25]
    bordered = torch.zeros(3 * 36 * 36)
    energy.splat(bordered, axes, torch.ones(1), torch.zeros(1, dtype=torch.long))
    raw = bordered.view(1, 3, 36, 36)[:, :, 2:-2, 2:-2]
    assert raw.sum((2, 3)).tolist() == [[25.0, 25.0, 25.0]]  # every joint in one pixel of each plane
    assert image.amax() == pytest.approx(1.0)


def test_image_is_invariant_to_translation_and_body_size():
    energy = EnergyImage(size=48, bone_samples=2)
    a = standing_skeleton()
    moved = a + torch.tensor([0.7, 0.2, 1.1])
    bigger = (a - a[:, :1]) * 1.3 + a[:, :1]
    zeros = torch.zeros_like(a)
    base = energy(batch(a, zeros))
    assert torch.allclose(base, energy(batch(moved, zeros)), atol=1e-5)
    assert torch.allclose(base, energy(batch(bigger, zeros)), atol=1e-4)


def test_align_removes_rotation_about_the_vertical_axis():
    a = standing_skeleton(z=0.0)
    angle = math.radians(40)
    rot = torch.tensor([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0], [-math.sin(angle), 0, math.cos(angle)]])
    turned = a @ rot.T
    zeros = torch.zeros_like(a)
    aligned = EnergyImage(size=48, align=True)
    plain = EnergyImage(size=48, align=False)
    assert torch.allclose(aligned(batch(a, zeros)), aligned(batch(turned, zeros)), atol=1e-4)
    assert not torch.allclose(plain(batch(a, zeros)), plain(batch(turned, zeros)), atol=1e-2)


def test_padding_frames_and_absent_bodies_do_not_change_the_image():
    energy = EnergyImage(size=40, bone_samples=1)
    a = standing_skeleton(frames=8)
    a[:, NTU25.index("HandRight"), 1] += torch.linspace(0, 0.5, 8)  # some motion
    zeros = torch.zeros_like(a)
    padded = torch.cat([a, torch.zeros(5, 25, 3)])
    assert torch.allclose(energy(batch(a, zeros)), energy(batch(padded, torch.zeros_like(padded))), atol=1e-6)


def test_planes_show_what_they_should():
    """A body standing to the right of the origin body shows up right of it in xy and xz, not in zy."""
    energy = EnergyImage(size=64, extent=3.0, splat="nearest")
    left = standing_skeleton()
    right = standing_skeleton(x=1.0)
    image = energy(batch(left, right))[0]
    cols_xy = image[0].sum(0).nonzero().flatten()
    cols_zy = image[1].sum(0).nonzero().flatten()
    assert cols_xy.max() - cols_xy.min() > 15  # two people side by side, ~1 m apart
    assert cols_zy.max() - cols_zy.min() < 5  # from the side they overlap (same depth)
    rows_xy = image[0].sum(1).nonzero().flatten()
    head_row = rows_xy.min()
    assert head_row < 32 - 3 and rows_xy.max() > 32  # head above the spine base, feet below


def test_temporal_weighting_and_smoothing_change_the_image():
    a = standing_skeleton(frames=6)
    a[:, NTU25.index("HandRight"), 1] += torch.linspace(0, 0.6, 6)
    x = batch(a, torch.zeros_like(a))
    plain = EnergyImage(size=32)(x)
    assert not torch.allclose(plain, EnergyImage(size=32, temporal_weighting="linear")(x))
    blurred = EnergyImage(size=32, smoothing=1.5)(x)
    assert (blurred > 0).sum() > (plain > 0).sum()


def test_bad_options_and_shapes_are_rejected():
    with pytest.raises(ValueError, match="splat"):
        EnergyImage(splat="cubic")
    with pytest.raises(ValueError, match="expected skeletons"):
        EnergyImage()(torch.zeros(1, 2, 10, 20, 3))


def test_energy_image_exports_to_onnx_with_dynamic_batch_and_frames(tmp_path):
    import onnxruntime as ort

    from mocapkit.recognition.export import example_skeletons

    energy = EnergyImage(size=32, bone_samples=1, align=True).eval()
    path = tmp_path / "energy.onnx"
    torch.onnx.export(
        energy,
        (example_skeletons(2, 16),),
        str(path),
        input_names=["skeletons"],
        output_names=["image"],
        dynamo=True,
        optimize=False,
        dynamic_shapes={"skeletons": {0: torch.export.Dim("b"), 2: torch.export.Dim("t")}},
    )
    x = example_skeletons(3, 120, seed=5)  # 720 body-frames: more than one of the eager module's blocks
    assert x.shape[0] * x.shape[1] * x.shape[2] > EnergyImage.ROWS_PER_BLOCK
    got = ort.InferenceSession(str(path)).run(None, {"skeletons": x.numpy()})[0]
    np.testing.assert_allclose(got, energy(x).numpy(), atol=1e-5)
