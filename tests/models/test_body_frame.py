"""Body 0's reference frame (mocapkit.models.body_frame): masked medians, and both models shrug off glitch frames."""

import numpy as np
import pytest
import torch

from mocapkit.models import EnergyImage
from mocapkit.models.body_frame import body0_origin, body0_size, masked_median
from mocapkit.models.stgcn import stgcn
from mocapkit.motion.layouts import NTU25
from tests.models.test_energy_image import batch, standing_skeleton


def test_masked_median_matches_numpy_and_gives_zero_without_frames():
    rng = np.random.default_rng(0)
    values = rng.normal(size=(5, 13, 3)).astype(np.float32)
    mask = rng.random((5, 13)) < 0.6
    mask[3] = False  # no frame at all
    mask[4] = False
    mask[4, [2, 7]] = True  # an even count: mean of the two middle values
    got = masked_median(torch.from_numpy(values), torch.from_numpy(mask)).numpy()
    for n in range(5):
        expected = np.median(values[n][mask[n]], axis=0) if mask[n].any() else np.zeros(3)
        np.testing.assert_allclose(got[n], expected, atol=1e-6)


def test_masked_median_has_gradients():
    values = torch.randn(2, 9, 3, requires_grad=True)
    mask = torch.ones(2, 9, dtype=torch.bool)
    masked_median(values, mask).sum().backward()
    assert torch.isfinite(values.grad).all() and values.grad.abs().sum() > 0


def glitched(frames: int = 20, jump: float = 2.0) -> tuple[torch.Tensor, torch.Tensor]:
    """A standing body ``[T, 25, 3]`` and the same whose first frame is a glitch ``jump`` metres aside and away."""
    clean = standing_skeleton(frames=frames)
    glitch = clean.clone()
    glitch[0] += torch.tensor([jump, 0.3, jump])
    return clean, glitch


def test_origin_and_size_ignore_a_glitch_frame():
    clean, glitch = glitched()
    x = batch(glitch, torch.zeros_like(glitch))
    present = x.abs().sum((-1, -2)) > 0
    root, neck = NTU25.index("SpineBase"), NTU25.index("SpineShoulder")
    torch.testing.assert_close(body0_origin(x, present, root)[0], clean[5, root])
    torch.testing.assert_close(body0_size(x, present, root, neck), torch.tensor([0.5]))


def test_graph_network_input_is_not_moved_by_a_glitch_in_the_first_frame():
    """The origin used to be body 0's root in its first present frame: a glitch there moved every frame."""
    clean, glitch = glitched()
    model = stgcn(3, layout="ntu25", scale=True).eval()
    x = batch(glitch, torch.zeros_like(glitch))
    present = x.abs().sum((-1, -2)) > 0
    normalized = model.normalize(x, present)
    root = NTU25.index("SpineBase")
    assert normalized[0, 0, 1:, root].abs().max() < 1e-5  # every real frame centred on its root
    reference = model.normalize(batch(clean, torch.zeros_like(clean)), present)
    torch.testing.assert_close(normalized[0, 0, 1:], reference[0, 0, 1:])


def test_energy_image_is_not_moved_by_a_glitch_in_the_first_frame():
    """With origin="median" (the default origin="first" is moved by it; "start" nearly not: the test below)."""
    clean, glitch = glitched(jump=2.0)  # 4 spine lengths aside and away: off every plane's grid
    energy = EnergyImage(size=48, bone_samples=2, align=False, origin="median")
    zeros = torch.zeros_like(clean)
    torch.testing.assert_close(energy(batch(glitch, zeros)), energy(batch(clean, zeros)), atol=1e-5, rtol=1e-5)


def test_first_frame_origin_is_body0_first_present_frame():
    """origin="first" (the energy image's option): body 0's root where it is first present, 0 without body 0."""
    from mocapkit.models.body_frame import body0_first

    clean, _ = glitched()
    walking = clean + torch.linspace(0, 1, len(clean)).view(-1, 1, 1) * torch.tensor([1.0, 0.0, 0.0])
    x = torch.stack([batch(walking, torch.zeros_like(walking))[0], torch.zeros_like(batch(walking, walking)[0])])
    x[0, 0, :3] = 0  # body 0 enters at frame 3
    present = x.abs().sum((-1, -2)) > 0
    root = NTU25.index("SpineBase")
    origin = body0_first(x, present, root)
    torch.testing.assert_close(origin[0], walking[3, root])
    torch.testing.assert_close(origin[1], torch.zeros(3))
    median = body0_origin(x, present, root)[0]
    assert abs(float(median[0] - origin[0, 0])) > 0.4  # a walk: the median is mid-path
    energy_first = EnergyImage(size=48, bone_samples=2, align=False)  # the default origin
    energy_median = EnergyImage(size=48, bone_samples=2, align=False, origin="median")
    assert not torch.allclose(energy_first(x[:1]), energy_median(x[:1]))
    centred = energy_first.normalize(x[:1], present[:1])
    assert centred[0, 0, 3, root].abs().max() < 1e-6  # the first present frame at the origin
    with pytest.raises(ValueError, match="origin"):
        EnergyImage(origin="mean")


def test_start_origin_is_where_the_walk_began_and_ignores_a_first_frame_glitch():
    """origin="start": the median over body 0's first 5 present frames — start-anchored like "first", yet a
    glitch in the first frame moves neither the origin nor the energy image."""
    from mocapkit.models.body_frame import body0_start

    clean, _ = glitched(frames=30)
    walking = clean + torch.linspace(0, 1.5, len(clean)).view(-1, 1, 1) * torch.tensor([1.0, 0.0, 0.0])
    glitch = walking.clone()
    glitch[0] += torch.tensor([2.0, 0.3, 2.0])
    root = NTU25.index("SpineBase")
    zeros = torch.zeros_like(walking)
    x_clean, x_glitch = batch(walking, zeros), batch(glitch, zeros)
    present = x_clean.abs().sum((-1, -2)) > 0
    start = body0_start(x_clean, present, root)[0]
    torch.testing.assert_close(start, walking[2, root])  # the middle of frames 0-4
    assert abs(float(start[0] - body0_origin(x_clean, present, root)[0, 0])) > 0.6  # not the middle of the walk
    torch.testing.assert_close(body0_start(x_glitch, present, root)[0], walking[3, root])  # one frame on, not 2 m
    energy = EnergyImage(size=48, bone_samples=2, align=False, origin="start")
    moved = EnergyImage(size=48, bone_samples=2, align=False, origin="first")
    change = (energy(x_glitch) - energy(x_clean)).abs().sum()  # the glitch frame's own points, ~2 %
    assert change < 0.05 * (moved(x_glitch) - moved(x_clean)).abs().sum()
    assert change < 0.05 * energy(x_clean).abs().sum()
