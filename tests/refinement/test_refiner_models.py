"""Learned refiners: the networks (:mod:`mocapkit.models.refiners`), their training corruption and data module,
the windowed :class:`~mocapkit.refinement.learned.LearnedRefiner` / :class:`~mocapkit.refinement.learned.OnnxRefiner`.

Everything runs on synthetic CMU31-layout motions (smooth random trajectories, 120 fps) except the HDM05 split
test, which uses a few real clips of ``../shared/data/hdm05_cuts11`` and is skipped without them. One tiny BiGRU
(8 units, one layer, 32-frame windows, one epoch of 64 windows) is trained once for the module.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from mocapkit.datasets.mocap.folders import MocapFolderError
from mocapkit.models.refiners import (
    PoseNormalizer,
    cubic_fill,
    encoder_layer_forward,
    refine_bigru,
    refine_transformer,
)
from mocapkit.motion.container import Motion
from mocapkit.motion.frames import blend_weights, refine_windows, window_starts
from mocapkit.motion.layouts import CMU31
from mocapkit.refinement.base import RefinementError
from mocapkit.refinement.corruptions import TRAINING_MIXTURE, training_corruption
from mocapkit.refinement.datamodule import MocapRefinementDataModule
from mocapkit.refinement.learned import (
    INFERENCE_WINDOW_FACTOR,
    LearnedRefiner,
    OnnxRefiner,
    empty_frames_kept,
    train_on_motions,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
HIPS = (1, 6)  # lhipjoint, rhipjoint of CMU31
TINY = [
    "model.hidden=8",
    "model.layers=1",
    "data.window=32",
    "data.windows_per_epoch=64",
    "data.batch_size=16",
    "trainer.max_epochs=1",
    "data.eval_windows_per_clip=1",
]


def synthetic_motion(frames: int, seed: int, fps: float = 120.0) -> Motion:
    """A CMU31 motion: every joint its parent plus a fixed offset plus a slow wobble; the root walks and sways."""
    rng = np.random.default_rng(seed)
    offsets = rng.normal(0.0, 0.12, (CMU31.num_joints, 3))
    t = np.arange(frames)[:, None] / fps
    positions = np.zeros((frames, CMU31.num_joints, 3))
    for j, p in enumerate(CMU31.parents):
        wobble = 0.03 * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t + rng.uniform(0, 2 * np.pi, 3))
        if p < 0:
            positions[:, j] = np.concatenate([0.5 * np.sin(0.4 * t), 0.9 + 0.02 * np.sin(3 * t), 0.3 * t], axis=1)
        else:
            positions[:, j] = positions[:, p] + offsets[j] + wobble
    return Motion(
        positions, CMU31.joint_names, fps, parents=CMU31.parents, layout_name="cmu31", name=f"synthetic{seed}"
    )


def with_missing(motion: Motion, missing: np.ndarray) -> Motion:
    positions = motion.positions.copy()
    positions[missing] = np.nan
    return replace(motion, positions=positions, missing=missing.copy())


@pytest.fixture(scope="module")
def tiny_module():
    """A BiGRU refiner trained for one tiny epoch on synthetic motions (the LightningModule of its best epoch)."""
    torch.manual_seed(0)
    return train_on_motions("refine_bigru", [synthetic_motion(200, seed) for seed in range(6)], TINY)


@pytest.fixture(scope="module")
def tiny_refiner(tiny_module) -> LearnedRefiner:
    refiner = LearnedRefiner()
    refiner._use(tiny_module)
    return refiner


@pytest.fixture
def gappy():
    """A clean 100-frame motion and a copy with two interior gaps (joints 3 and 20)."""
    clean = synthetic_motion(100, 99)
    missing = np.zeros(clean.missing.shape, bool)
    missing[40:60, 3] = True
    missing[10:31, 20] = True
    return clean, with_missing(clean, missing)


# ------------------------------------------------------------------------------------------------ cubic_fill
def _track(T=30, J=3, seed=0):
    rng = np.random.default_rng(seed)
    t = torch.arange(T, dtype=torch.float64).view(1, T, 1, 1)
    a = torch.as_tensor(rng.normal(size=(1, 1, J, 3)))
    b = torch.as_tensor(rng.normal(size=(1, 1, J, 3)))
    return a, b, a + b * t  # a linear trajectory [1, T, J, 3]


def test_cubic_fill_reproduces_a_linear_trajectory_inside_gaps():
    _, _, x = _track()
    observed = torch.ones(1, 30, 3, dtype=torch.bool)
    observed[0, 2:9, 0] = False  # gaps whose ends have an observed neighbour outside them
    observed[0, 12:27, 1] = False
    observed[0, 5:6, 2] = False
    garbage = torch.where(observed.unsqueeze(-1), x, torch.full_like(x, 123.0))
    out = cubic_fill(garbage, observed)
    torch.testing.assert_close(out, x, atol=1e-5, rtol=0)
    assert torch.equal(out[observed], x[observed])  # observed entries untouched, bit for bit


def test_cubic_fill_ends_hold_the_nearest_observation_without_extrapolation_and_unobserved_joint_is_zero():
    _, _, x = _track(T=20, J=3, seed=1)
    x = x.float()
    observed = torch.ones(1, 20, 3, dtype=torch.bool)
    observed[0, :5, 0] = False  # leading gap
    observed[0, 14:, 0] = False  # trailing gap
    observed[0, :, 1] = False  # never observed
    out = cubic_fill(torch.where(observed.unsqueeze(-1), x, torch.full_like(x, -7.0)), observed, extrapolate=0)
    assert torch.equal(out[0, :5, 0], x[0, 5, 0].expand(5, 3))
    assert torch.equal(out[0, 14:, 0], x[0, 13, 0].expand(6, 3))
    assert torch.equal(out[0, :, 1], torch.zeros(20, 3))
    assert torch.equal(out[0, :, 2], x[0, :, 2])
    assert torch.equal(out[observed], x[observed])


def test_cubic_fill_continues_the_last_observed_step_at_the_ends_then_holds():
    _, _, x = _track(T=30, J=1, seed=2)
    observed = torch.ones(1, 30, 1, dtype=torch.bool)
    observed[0, :10, 0] = False  # 10 frames before the first observation
    observed[0, 22:, 0] = False  # 8 after the last
    out = cubic_fill(torch.where(observed.unsqueeze(-1), x, torch.zeros_like(x)), observed, extrapolate=4)
    torch.testing.assert_close(out[0, 6:10, 0], x[0, 6:10, 0], atol=1e-9, rtol=0)  # 4 frames continued
    torch.testing.assert_close(out[0, :6, 0], x[0, 6, 0].expand(6, 3), atol=1e-9, rtol=0)  # then held
    torch.testing.assert_close(out[0, 22:26, 0], x[0, 22:26, 0], atol=1e-9, rtol=0)
    torch.testing.assert_close(out[0, 26:, 0], x[0, 25, 0].expand(4, 3), atol=1e-9, rtol=0)


@pytest.mark.parametrize("tangents, exact", [("chord", True), ("zero", False)])
def test_cubic_fill_tangent_rule_where_the_gap_ends_outer_neighbours_are_missing(tangents, exact):
    """Frames 5 and 7 missing: each gap has one end whose outer neighbour is missing. The chord rule fills a
    straight track exactly; the zero-tangent rule of the first runs bends it by a quarter of a frame's step."""
    _, _, x = _track(T=21, J=2, seed=3)
    observed = torch.ones(1, 21, 2, dtype=torch.bool)
    observed[0, [5, 7, 12, 14]] = False
    out = cubic_fill(torch.where(observed.unsqueeze(-1), x, torch.zeros_like(x)), observed, tangents)
    error = (out - x).abs().max().item()
    assert (error < 1e-9) if exact else (error > 0.05)


def test_cubic_fill_is_a_smooth_bridge_between_the_gap_ends():
    # a parabola: one-sided tangents are not exact (a straight line would be 1.0 off at the centre); the Hermite
    # bridge with them stays within a few hundredths
    t = torch.arange(40, dtype=torch.float32)
    x = ((t - 20) ** 2 / 100).view(1, 40, 1, 1).expand(1, 40, 1, 3).clone()
    observed = torch.ones(1, 40, 1, dtype=torch.bool)
    observed[0, 10:30, 0] = False
    out = cubic_fill(torch.where(observed.unsqueeze(-1), x, torch.zeros_like(x)), observed)
    gap = out[0, 10:30, 0, 0]
    assert torch.isfinite(gap).all()
    assert (gap - x[0, 10:30, 0, 0]).abs().max() < 0.1


# ------------------------------------------------------------------------------------------------ PoseNormalizer
def _pose_batch(T=12, seed=0):
    motion = synthetic_motion(T, seed)
    x = torch.from_numpy(motion.positions).unsqueeze(0).repeat(2, 1, 1, 1)
    x[1] = x[1] * 1.1 + torch.tensor([0.3, 0.0, -0.2])
    rng = np.random.default_rng(seed)
    observed = torch.from_numpy(rng.random((2, T, CMU31.num_joints)) > 0.25)
    observed[0, :, 0] = True
    observed[1, :, 0] = False  # batch 1: root missing in every frame
    return x, observed


def _normalizer():
    lengths = np.r_[0.0, np.linspace(0.1, 0.3, CMU31.num_joints - 1)]
    return PoseNormalizer(CMU31.parents, "y", HIPS, lengths)


def test_pose_normalizer_inverse_undoes_forward():
    x, observed = _pose_batch()
    norm = _normalizer()
    stats = norm.statistics(torch.where(observed.unsqueeze(-1), x, 0.0), observed)
    torch.testing.assert_close(norm.inverse(norm(x, stats), stats), x, atol=1e-5, rtol=0)


@pytest.mark.parametrize("angle", [0.7, -2.5, math.pi])
def test_pose_normalizer_is_invariant_to_heading_translation_and_scale(angle):
    x, observed = _pose_batch(seed=3)
    norm = _normalizer()
    c, s = math.cos(angle), math.sin(angle)
    rotation = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # about the up (y) axis
    moved = 1.7 * x @ rotation.T + torch.tensor([2.0, -0.5, 3.0])

    def normalised(p):
        clean = torch.where(observed.unsqueeze(-1), p, 0.0)
        return norm(clean, norm.statistics(clean, observed))[observed]

    torch.testing.assert_close(normalised(moved), normalised(x), atol=2e-5, rtol=0)
    # and it really is a normalisation: the mean observed root of batch 0 goes to the origin
    stats = norm.statistics(torch.where(observed.unsqueeze(-1), moved, 0.0), observed)
    root = norm(moved, stats)[0][observed[0, :, 0]][:, 0]
    torch.testing.assert_close(root.mean(0), torch.zeros(3), atol=1e-5, rtol=0)


def test_pose_normalizer_statistics_ignore_missing_entries():
    x, observed = _pose_batch(seed=4)
    norm = _normalizer()
    zero = torch.where(observed.unsqueeze(-1), x, 0.0)
    garbage = torch.where(observed.unsqueeze(-1), x, 1e6)
    for a, b in zip(norm.statistics(zero, observed), norm.statistics(garbage, observed)):
        torch.testing.assert_close(a, b, atol=0, rtol=0)
    # no observed hips: no turn; no observed bone: the training body size (ratio 1)
    nothing = torch.zeros_like(observed)
    nothing[:, :, 0] = True
    _, cos, sin, scale = norm.statistics(zero, nothing)
    assert torch.equal(cos, torch.ones_like(cos)) and torch.equal(sin, torch.zeros_like(sin))
    _, _, _, reference = norm.statistics(torch.zeros_like(zero), torch.zeros_like(observed))
    assert torch.equal(scale, reference)
    # a body twice the size: twice the scale
    _, _, _, single = norm.statistics(zero, observed)
    _, _, _, double = norm.statistics(2 * zero, observed)
    torch.testing.assert_close(double, 2 * single)


# ------------------------------------------------------------------------------------------------ networks
NETWORKS = {
    "bigru": lambda: refine_bigru(joint_names=CMU31.joint_names, parents=CMU31.parents, hips=HIPS, hidden=16, layers=2),
    "transformer-frames": lambda: refine_transformer(
        joint_names=CMU31.joint_names,
        parents=CMU31.parents,
        hips=HIPS,
        tokens="frames",
        dim=16,
        layers=1,
        heads=2,
        ff=32,
    ),
    "transformer-joints": lambda: refine_transformer(
        joint_names=CMU31.joint_names,
        parents=CMU31.parents,
        hips=HIPS,
        tokens="joints",
        dim=16,
        layers=1,
        heads=2,
        ff=32,
    ),
    "bigru-pose-frame": lambda: refine_bigru(
        joint_names=CMU31.joint_names, parents=CMU31.parents, hips=HIPS, hidden=16, layers=2, pose_frame=True
    ),
    "transformer-frames-pose-frame": lambda: refine_transformer(
        joint_names=CMU31.joint_names,
        parents=CMU31.parents,
        hips=HIPS,
        tokens="frames",
        dim=16,
        layers=1,
        heads=2,
        ff=32,
        pose_frame=True,
    ),
}


def _take(T: int, seed: int = 0):
    x = torch.stack([torch.from_numpy(synthetic_motion(T, seed + b).positions) for b in range(2)])
    rng = np.random.default_rng(seed)
    missing = torch.from_numpy(rng.random((2, T, CMU31.num_joints)) < 0.2)
    missing[:, T // 4 : T // 2, 5] = True  # a gap
    missing[1, :, 9] = True  # a joint missing throughout
    missing[:, 0, 0] = False
    return x, missing


@pytest.mark.parametrize("name", sorted(NETWORKS))
@pytest.mark.parametrize("T", [9, 40])
def test_untrained_network_is_the_first_guess(name, T):
    """The last layer starts at zero: an untrained network returns its first guess, i.e. the observed entries, the
    cubic fill of joints observed somewhere in the window, and a joint never observed on its parent."""
    torch.manual_seed(0)
    net = NETWORKS[name]().eval()
    x, missing = _take(T)
    with torch.no_grad():
        out = net(x, missing)
        observed = ~missing
        clean = torch.where(observed.unsqueeze(-1), x, 0.0)
        stats = net.normalizer.statistics(clean, observed)
        normalised = net.normalizer(clean, stats) * observed.unsqueeze(-1)
        cubic = net.normalizer.inverse(cubic_fill(normalised, observed, net.tangents, net.extrapolate), stats)
    assert out.shape == x.shape and out.dtype == torch.float32
    assert torch.isfinite(out).all()
    torch.testing.assert_close(out[observed], x[observed], atol=1e-5, rtol=0)
    seen = observed.any(dim=1, keepdim=True).expand_as(observed)  # joint observed in the window
    torch.testing.assert_close(out[seen], cubic[seen], atol=1e-5, rtol=0)
    never = ~seen
    assert never[1, :, 9].all() and seen[1, :, 8].all()  # joint 9 (rfoot), parent 8
    torch.testing.assert_close(out[1, :, 9], out[1, :, 8], atol=1e-5, rtol=0)


@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_missing_entry_values_do_not_change_the_output(name):
    torch.manual_seed(1)
    net = NETWORKS[name]().eval()
    with torch.no_grad():  # a network that does correct: a non-zero last layer
        torch.nn.init.normal_(net.out.weight, std=0.05)
        torch.nn.init.normal_(net.out.bias, std=0.05)
    x, missing = _take(24, seed=5)
    outs = []
    for fill in (0.0, 1e6, float("nan")):
        with torch.no_grad():
            outs.append(net(torch.where(missing.unsqueeze(-1), fill, x), missing))
    assert torch.isfinite(outs[0]).all()
    assert torch.equal(outs[0], outs[1]) and torch.equal(outs[0], outs[2])
    # the correction is active: observed entries move (an untrained network would leave them)
    assert (outs[0][~missing] - x[~missing]).abs().max() > 1e-3


def _turned_per_frame(T: int, seed: int = 0) -> torch.Tensor:
    """``guess [1, 3, T, J]``: one pose, every frame turned about the up (y) axis through its root by
    its own angle and moved along a path."""
    pose = torch.from_numpy(synthetic_motion(1, seed).positions[0]).float()  # [J, 3]
    pose = pose - pose[0]
    angles = torch.linspace(-2.5, 2.5, T)
    c, s = torch.cos(angles).view(T, 1), torch.sin(angles).view(T, 1)
    x, y, z = pose[:, 0], pose[:, 1], pose[:, 2]
    turned = torch.stack([c * x + s * z, y.expand(T, -1), -s * x + c * z], dim=0)  # [3, T, J]
    path = torch.stack([torch.linspace(0, 3, T), torch.zeros(T), torch.linspace(1, -1, T)]).unsqueeze(-1)
    return (turned + path).unsqueeze(0)


def test_body_frame_reads_every_frame_alike_whichever_way_it_faces():
    """The pose-frame input: one pose turned per frame and moved along a path reads the same in every frame's
    body frame, with the root at the origin and the hip line along the first horizontal axis."""
    net = NETWORKS["transformer-frames-pose-frame"]()
    guess = _turned_per_frame(20)
    root, cos, sin = net.body_frame(guess)
    body = net.normalizer.turn_cf(guess - root, cos, sin)  # [1,3,T,J]
    torch.testing.assert_close(body, body[:, :, :1].expand_as(body), atol=1e-5, rtol=0)
    assert body[0, :, 0, 0].abs().max() < 1e-6  # the root at the origin
    hip_line = body[0, :, 0, HIPS[1]] - body[0, :, 0, HIPS[0]]
    assert hip_line[0] > 0.05 and hip_line[2].abs() < 1e-5  # along x, left -> right
    # the window-frame guess itself differs from frame to frame (the test would pass on a no-op otherwise)
    assert (guess - guess[:, :, :1]).abs().max() > 0.5


def test_pose_frame_correction_is_turned_back_per_frame(monkeypatch):
    """A correction the network gives in the body frame (a constant step along the hip line) comes out along each
    frame's own hip line in the window frame."""
    net = NETWORKS["transformer-frames-pose-frame"]()
    guess = _turned_per_frame(16, seed=2)
    T, J = guess.shape[2], guess.shape[3]
    step = torch.zeros(1, 3, T, J)
    step[:, 0] = 1.0
    monkeypatch.setattr(net, "correction", lambda g, o, body=None: step)
    moved = net.corrected(guess, torch.ones(1, T, J, dtype=torch.bool)) - guess  # [1,3,T,J]
    line = guess[0, :, :, HIPS[1]] - guess[0, :, :, HIPS[0]]  # [3,T]
    line[1] = 0.0
    expected = line / line.norm(dim=0, keepdim=True)
    torch.testing.assert_close(moved[0, :, :, 4], expected, atol=1e-5, rtol=0)


def test_pose_frame_transformer_exports_with_parity(tmp_path):
    """export_refiner raises ParityError where onnxruntime and PyTorch differ (on shapes other than the traced)."""
    from mocapkit.deploy.refiner_export import export_refiner

    torch.manual_seed(3)
    net = NETWORKS["transformer-frames-pose-frame"]().eval()
    with torch.no_grad():
        torch.nn.init.normal_(net.out.weight, std=0.05)
    skeleton = {"joint_names": list(CMU31.joint_names), "parents": list(CMU31.parents)}
    figures = export_refiner(net, tmp_path / "pose_frame.onnx", skeleton, trace_shape=(2, 8), check_shape=(2, 40))
    assert (tmp_path / "pose_frame.onnx").is_file() and figures


# ------------------------------------------------------------------------------------------------ corruption
def _check_corruption(clean: Motion, result):
    moved = result.motion
    assert (~moved.missing).any()  # something stays observed
    assert not (result.removed & clean.missing).any()
    assert moved.missing[result.removed].all() and np.isnan(moved.positions[result.removed]).all()
    assert not (result.removed & result.perturbed).any()
    assert not moved.missing[result.perturbed].any()
    untouched = ~result.corrupted & ~clean.missing
    assert np.array_equal(moved.positions[untouched], clean.positions[untouched])
    assert np.array_equal(moved.missing, clean.missing | result.removed)


def test_training_corruption_contract_and_protocol_coverage():
    clean = synthetic_motion(120, 0)
    rng = np.random.default_rng(0)
    protocols = set()
    for _ in range(60):
        result = training_corruption(clean, rng)
        _check_corruption(clean, result)
        protocols.add(result.protocol)
    assert protocols <= set(TRAINING_MIXTURE)
    assert len(protocols) >= 6, protocols


def test_training_corruption_keeps_an_observation_on_tiny_windows():
    t = np.arange(8)[:, None]
    positions = np.stack(
        [np.concatenate([0.01 * t, t * 0, t * 0], 1), np.concatenate([0.3 + 0.01 * t, t * 0, t * 0], 1)], axis=1
    )
    clean = Motion(positions, ("a", "b"), 120.0, parents=(-1, 0))
    rng = np.random.default_rng(1)
    for _ in range(150):
        _check_corruption(clean, training_corruption(clean, rng, whole_joint_rate=1.0))


def test_training_corruption_is_deterministic_given_the_rng():
    clean = synthetic_motion(64, 2)
    for seed in range(8):
        a = training_corruption(clean, np.random.default_rng(seed))
        b = training_corruption(clean, np.random.default_rng(seed))
        assert a.protocol == b.protocol and a.description == b.description
        assert np.array_equal(a.removed, b.removed) and np.array_equal(a.perturbed, b.perturbed)
        assert np.array_equal(a.motion.positions, b.motion.positions, equal_nan=True)
    draws = {training_corruption(clean, np.random.default_rng(s)).description for s in range(8)}
    assert len(draws) > 1


# ------------------------------------------------------------------------------------------------ windows
@pytest.mark.parametrize("window,overlap", [(32, 8), (32, 0), (10, 9), (120, 30)])
@pytest.mark.parametrize("frames", [1, 5, 31, 32, 33, 100, 257])
def test_window_starts_cover_every_frame(frames, window, overlap):
    starts = window_starts(frames, window, overlap)
    length = min(frames, window)
    covered = np.zeros(frames, int)
    for s in starts:
        assert 0 <= s and s + length <= frames
        covered[s : s + length] += 1
    assert covered.min() >= 1
    assert starts[0] == 0 and starts[-1] + length == frames
    assert all(b > a for a, b in itertools.pairwise(starts))
    for i in range(len(starts)):
        w = blend_weights(length, overlap, first=i == 0, last=i == len(starts) - 1)
        assert w.shape == (length,) and (w > 0).all() and (w <= 1).all()


def test_blend_weights_ramps():
    assert np.array_equal(blend_weights(10, 3, True, True), np.ones(10))
    w = blend_weights(10, 3, first=False, last=False)
    assert np.allclose(w, [0.25, 0.5, 0.75, 1, 1, 1, 1, 0.75, 0.5, 0.25])
    assert np.allclose(blend_weights(10, 3, first=True, last=False)[:3], 1)


@pytest.mark.parametrize("frames", [20, 100, 301])
def test_refine_windows_blend_of_an_identity_predictor_is_the_input(frames):
    rng = np.random.default_rng(frames)
    positions = rng.normal(size=(frames, 4, 3)).astype(np.float32)
    missing = rng.random((frames, 4)) < 0.3
    calls = []

    def identity(p, m):
        calls.append((p.shape, p.dtype, m.shape, m.dtype))
        return p

    out = refine_windows(identity, positions, missing, 32, 8)
    assert len(calls) == 1  # every window in one batch
    n = len(window_starts(frames, 32, 8))
    assert calls[0] == ((n, min(frames, 32), 4, 3), np.float32, (n, min(frames, 32), 4), bool)
    np.testing.assert_allclose(out, positions.astype(np.float64), rtol=0, atol=1e-12)


def test_refine_windows_blends_neighbours_continuously():
    frames, window, overlap = 100, 32, 8
    starts = window_starts(frames, window, overlap)
    index = lambda p, m: np.broadcast_to(np.arange(len(p), dtype=np.float32)[:, None, None, None], p.shape)
    out = refine_windows(index, np.zeros((frames, 1, 3), np.float32), np.zeros((frames, 1), bool), window, overlap)
    value = out[:, 0, 0]
    assert np.all(np.diff(value) >= 0)  # a ramp from one window to the next
    for i, s in enumerate(starts):  # frames only window i weighs fully
        others = [(o, o + window) for k, o in enumerate(starts) if k != i]
        alone = [t for t in range(s, s + window) if not any(a <= t < b for a, b in others)]
        assert np.all(value[alone] == i)


def test_empty_frames_kept():
    missing = np.zeros((80, 3), bool)
    missing[:4] = True  # leading
    missing[10:15] = True  # interior, 5 frames: filled
    missing[20:40] = True  # interior, 20 frames: kept
    missing[50:70, 1] = True  # partly observed frames: never kept
    missing[77:] = True  # trailing
    keep = empty_frames_kept(missing, 12)
    expected = np.zeros(80, bool)
    expected[:4] = expected[20:40] = expected[77:] = True
    assert np.array_equal(keep, expected)
    assert np.array_equal(empty_frames_kept(missing, 20), expected & ~((np.arange(80) >= 20) & (np.arange(80) < 40)))
    assert np.array_equal(empty_frames_kept(missing, 4), expected | ((np.arange(80) >= 10) & (np.arange(80) < 15)))
    assert empty_frames_kept(np.ones((6, 2), bool), 12).all()
    assert not empty_frames_kept(np.zeros((6, 2), bool), 12).any()


# ------------------------------------------------------------------------------------------------ data module
def _synthetic_datamodule(**kw):
    args = {
        "dataset": None,
        "motions": [synthetic_motion(150, s) for s in range(5)],
        "window": 32,
        "windows_per_epoch": 24,
        "batch_size": 8,
        "eval_batch_size": 16,
        "eval_windows_per_clip": 3,
        "val_fraction": 0.2,
    }
    return MocapRefinementDataModule(**{**args, **kw})


def test_datamodule_batches_from_motions():
    dm = _synthetic_datamodule()
    J = CMU31.num_joints
    assert (len(dm.train_motions), len(dm.val_motions), len(dm.test_motions)) == (4, 1, 0)
    assert dm.sample_counts() == {"train": 24, "val": 3, "test": 0}
    batch = next(iter(dm.train_dataloader()))
    assert set(batch) == {"positions", "missing", "clean", "corrupted"}
    assert batch["positions"].shape == batch["clean"].shape == (8, 32, J, 3)
    assert batch["missing"].shape == batch["corrupted"].shape == (8, 32, J)
    assert batch["positions"].dtype == batch["clean"].dtype == torch.float32
    assert batch["missing"].dtype == batch["corrupted"].dtype == torch.bool
    missing, corrupted = batch["missing"], batch["corrupted"]
    assert torch.isfinite(batch["positions"]).all() and torch.isfinite(batch["clean"]).all()
    assert (batch["positions"][missing] == 0).all()
    assert not (missing & ~corrupted).any()  # clean clips: every missing entry was removed
    kept = ~corrupted
    assert torch.equal(batch["positions"][kept], batch["clean"][kept])
    assert missing.any() and (~missing).any()
    skeleton = dm.label_spaces()["skeleton"]
    assert list(skeleton["hips"]) == list(HIPS) and skeleton["fps"] == 120.0 and skeleton["window"] == 32
    assert skeleton["bone_lengths"][0] == 0 and min(skeleton["bone_lengths"][1:]) > 0
    assert skeleton["train_groups"] == ["train"] and skeleton["joint_names"] == list(CMU31.joint_names)


def test_datamodule_validation_windows_are_fixed_and_training_windows_fresh():
    dm = _synthetic_datamodule()
    epochs = [list(dm.val_dataloader()) for _ in range(2)]
    assert sum(len(b["positions"]) for b in epochs[0]) == 3
    for a, b in zip(*epochs):
        for key in a:
            assert torch.equal(a[key], b[key]), key
    train = [next(iter(dm.train_dataloader())) for _ in range(2)]
    assert not torch.equal(train[0]["clean"], train[1]["clean"])


def test_datamodule_short_clips_give_no_window():
    short = synthetic_motion(20, 9)
    dm = _synthetic_datamodule(motions=[synthetic_motion(150, s) for s in range(4)] + [short], val_fraction=0.4)
    assert sum(dm.describe()["clips_shorter_than_window"].values()) == 1
    assert all(m.num_frames >= 32 for m in dm.dataset("train").motions)
    val = dm.dataset("val")
    assert all(val.motions[clip].num_frames >= 32 for clip, _ in val.items)
    assert len(val) == 3 * sum(m.num_frames >= 32 for m in dm.val_motions)


def test_training_windows_can_be_mirrored_and_only_training_windows_are():
    from mocapkit.refinement.datamodule import RandomWindows

    motions = [synthetic_motion(150, s) for s in range(3)]
    plain, mirrored = (RandomWindows(motions, 32, 12, seed=3, mirror=p) for p in (0.0, 1.0))
    for i in range(12):  # the same window is drawn (the mirror draw comes after it), then mirrored
        a, b = plain[i]["clean"].numpy(), mirrored[i]["clean"].numpy()
        window = Motion(a, CMU31.joint_names, 120.0, parents=CMU31.parents)
        assert np.allclose(b, window.mirrored().positions)
        assert not np.allclose(a, b)
    half = RandomWindows(motions, 32, 40, seed=3, mirror=0.5)
    unmirrored = RandomWindows(motions, 32, 40, seed=3)
    flips = [not np.allclose(unmirrored[i]["clean"].numpy(), half[i]["clean"].numpy()) for i in range(40)]
    assert 8 < sum(flips) < 32
    dm = _synthetic_datamodule(mirror=1.0)
    assert dm.dataset("train").mirror == 1.0 and dm.describe()["mirror"] == 1.0
    val = next(iter(dm.val_dataloader()))["clean"]
    assert torch.equal(val, next(iter(_synthetic_datamodule().val_dataloader()))["clean"])
    with pytest.raises(ValueError, match=r"data.mirror=1.5"):
        _synthetic_datamodule(mirror=1.5)


def test_mirroring_a_skeleton_without_sides_is_refused_naming_the_key():
    names = ("Hips", "LeftUpLeg", "Spine")
    motion = Motion(np.random.default_rng(0).normal(size=(40, 3, 3)), names, 120.0, parents=(-1, 0, 0))
    with pytest.raises(MocapFolderError, match=r"data.mirror=0.5: joint 'LeftUpLeg'"):
        MocapRefinementDataModule(dataset=None, motions=[motion, motion], window=16, mirror=0.5, val_fraction=0.5)


@pytest.fixture(scope="module")
def hdm05_subset(tmp_path_factory):
    """Three real clips of every HDM05 actor (the smallest), linked with the actor's ASF into a fresh folder."""
    root = tmp_path_factory.mktemp("hdm05")
    for actor in ("bd", "bk", "dg", "mm"):
        folder = HDM05 / actor
        (root / actor).mkdir()
        (root / actor / f"HDM_{actor}.asf").symlink_to(folder / f"HDM_{actor}.asf")
        for amc in sorted(folder.glob("*.amc"), key=lambda p: (p.stat().st_size, p.name))[:3]:
            (root / actor / amc.name).symlink_to(amc)
    return root


@needs(HDM05)
def test_hdm05_held_out_group(hdm05_subset):
    dm = MocapRefinementDataModule(
        dataset="hdm05",
        root=str(hdm05_subset),
        test_groups=["bd"],
        window=32,
        eval_windows_per_clip=1,
        windows_per_epoch=8,
    )
    assert dm.groups == {"train": ["bk", "dg", "mm"], "test": ["bd"]}
    bd_clips = sorted(p.stem for p in (hdm05_subset / "bd").glob("*.amc"))
    assert sorted(m.metadata["group"] for m in dm.test_motions) == ["bd"] * 3
    assert sorted(m.name for m in dm.test_motions) == bd_clips
    seen = dm.train_motions + dm.val_motions
    assert len(seen) == 9 and not any(m.metadata["group"] == "bd" for m in seen)
    assert "bd" not in dm.label_spaces()["skeleton"]["train_groups"]
    assert len(dm.dataset("test")) == 3


@needs(HDM05)
@pytest.mark.parametrize("arg", ["test_groups", "train_groups"])
def test_hdm05_unknown_group_is_named(hdm05_subset, arg):
    with pytest.raises(MocapFolderError, match="zz9"):
        MocapRefinementDataModule(dataset="hdm05", root=str(hdm05_subset), window=32, **{arg: ["zz9"]})


# ------------------------------------------------------------------------------------------------ LearnedRefiner
def _changed(before: Motion, after: Motion) -> np.ndarray:
    return ~before.missing & (after.positions != before.positions).any(axis=2)


def test_learned_refiner_fills_gaps_and_keeps_observations(tiny_refiner, gappy):
    clean, motion = gappy
    assert tiny_refiner.window_ == INFERENCE_WINDOW_FACTOR * 32 and tiny_refiner.fps_ == 120.0
    out = tiny_refiner.refine(motion)
    report = out.metadata["refinement"]
    assert report["method"] == "LearnedRefiner"
    assert not out.missing.any() and np.isfinite(out.positions).all()
    assert report["filled"] == int(motion.missing.sum()) and report["unfilled"] == {}
    error = np.linalg.norm(out.positions - clean.positions, axis=-1)[motion.missing]
    assert error.mean() < 0.15  # metres: a plausible fill
    changed = _changed(motion, out)  # observed entries: only the repaired ones move
    assert int(changed.sum()) == report["repaired"]
    moved = np.linalg.norm(out.positions - motion.positions, axis=-1)[changed]
    assert (moved > tiny_refiner.repair_threshold).all()
    strict = LearnedRefiner(repair_threshold=math.inf)
    strict._use(tiny_refiner.module_)
    kept = strict.refine(motion)
    assert not _changed(motion, kept).any() and kept.metadata["refinement"]["repaired"] == 0
    observed = ~motion.missing
    assert np.array_equal(kept.positions[observed], motion.positions[observed])
    np.testing.assert_array_equal(kept.positions[motion.missing], out.positions[motion.missing])


def test_learned_refiner_leaves_empty_runs_missing(tiny_refiner, gappy):
    _, motion = gappy
    missing = motion.missing.copy()
    missing[:10] = True  # leading run of empty frames: never invented
    missing[70:75] = True  # a short interior run: filled
    out = tiny_refiner.refine(with_missing(motion, missing))
    assert out.missing[:10].all() and np.isnan(out.positions[:10]).all()
    assert not out.missing[10:].any()
    assert out.metadata["refinement"]["unfilled"] == {name: 10 for name in CMU31.joint_names}


def test_learned_refiner_refines_another_frame_rate_and_up_axis_at_its_own_and_rejects_another_layout(tiny_refiner):
    from dataclasses import replace

    slow = synthetic_motion(100, 1, fps=60.0)
    positions = slow.positions.copy()
    positions[40:52, 5] = np.nan  # a 0.2 s gap: 24 frames at the network's 120 fps
    slow = replace(slow, positions=positions, missing=np.isnan(positions).any(axis=2))
    out = tiny_refiner.refine(slow)
    assert out.fps == 60.0 and out.num_frames == 100 and not out.missing.any()
    assert out.metadata["refinement"]["resampled"] == {
        **out.metadata["refinement"]["resampled"],
        "fps": 60.0,
        "refined_at_fps": 120.0,
    }
    assert out.metadata["refinement"]["filled"] == 12
    np.testing.assert_array_equal(out.positions[~slow.missing], slow.positions[~slow.missing])
    # another up axis is turned to the fitted one and back (tests/refinement/test_learned_frames.py checks values)
    turned = tiny_refiner.refine(replace(slow, up_axis="z"))
    assert turned.up_axis == "z" and turned.metadata["refinement"]["turned"]["refined_at_up_axis"] == "y"
    with pytest.raises(RefinementError, match="2 frames at 240 fps are 1 at the 120 fps"):
        tiny_refiner.refine(synthetic_motion(2, 1, fps=240.0))
    motion = synthetic_motion(100, 1)
    keep = [j for j, n in enumerate(motion.joint_names) if n not in ("lthumb", "rthumb")]
    partial = Motion(motion.positions[:, keep], [motion.joint_names[j] for j in keep], 120.0, name="partial")
    with pytest.raises(RefinementError, match="lthumb") as info:
        tiny_refiner.refine(partial)
    assert "rthumb" in str(info.value)


def test_short_gaps_are_interior_runs_up_to_the_length():
    from mocapkit.refinement.learned import short_gaps

    missing = np.zeros((12, 3), bool)
    missing[0:2, 0] = True  # leading: never short
    missing[4:6, 0] = True  # 2 frames: short for N >= 2
    missing[3:8, 1] = True  # 5 frames
    missing[9:, 2] = True  # trailing
    np.testing.assert_array_equal(short_gaps(missing, 2), np.isin(np.arange(12), [4, 5])[:, None] * [1, 0, 0] > 0)
    assert short_gaps(missing, 5)[3:8, 1].all() and not short_gaps(missing, 4)[:, 1].any()
    assert not short_gaps(missing, 100)[:, 2].any() and not short_gaps(missing, 0).any()


def test_short_gaps_can_be_left_to_the_spline(tiny_refiner, gappy):
    from mocapkit.refinement.gap_filling import SplineInterpolation
    from mocapkit.refinement.learned import SHORT_GAP_FRAMES, SHORT_GAP_POINTS

    _, motion = gappy  # gaps of 20 frames (joint 3) and 21 (joint 20)
    spline = SplineInterpolation().refine(motion)
    try:
        network = tiny_refiner.set_params(short_gap_frames=0).refine(motion)
        mixed = tiny_refiner.set_params(short_gap_frames=20, short_gap_points="observed").refine(motion)
    finally:
        tiny_refiner.set_params(short_gap_frames=SHORT_GAP_FRAMES, short_gap_points=SHORT_GAP_POINTS)
    np.testing.assert_allclose(mixed.positions[40:60, 3], spline.positions[40:60, 3], atol=1e-6)
    np.testing.assert_array_equal(mixed.positions[10:31, 20], network.positions[10:31, 20])
    assert not np.allclose(network.positions[40:60, 3], spline.positions[40:60, 3], atol=1e-4)
    np.testing.assert_array_equal(mixed.positions[~motion.missing], motion.positions[~motion.missing])


def test_the_short_gap_spline_can_pass_through_the_repaired_samples(tiny_refiner, gappy):
    from mocapkit.refinement.learned import (
        SHORT_GAP_FRAMES,
        SHORT_GAP_POINTS,
        spline_fill,
    )

    _, motion = gappy
    try:  # threshold 0: every observed sample the (tiny) network moves is repaired, i.e. takes its value
        tiny_refiner.set_params(short_gap_frames=20, repair_threshold=0.0)
        observed = tiny_refiner.set_params(short_gap_points="observed").refine(motion)
        repaired = tiny_refiner.set_params(short_gap_points="repaired").refine(motion)
        with pytest.raises(ValueError, match="short_gap_points must be 'observed' or 'repaired'"):
            tiny_refiner.set_params(short_gap_points="network").refine(motion)
    finally:
        tiny_refiner.set_params(
            short_gap_frames=SHORT_GAP_FRAMES, short_gap_points=SHORT_GAP_POINTS, repair_threshold=0.02
        )
    assert repaired.metadata["refinement"]["repaired"] > 0
    gap = np.zeros(motion.missing.shape, bool)
    gap[40:60, 3] = True  # joint 3's 20-frame gap: the spline's
    # the spline passes through the samples as the contract returns them (the repaired ones at the network's value)
    expected = spline_fill(repaired.positions, motion.missing, gap)
    np.testing.assert_allclose(repaired.positions[40:60, 3], expected[40:60, 3], atol=1e-5)
    plain = spline_fill(motion.positions, motion.missing, gap)
    np.testing.assert_allclose(observed.positions[40:60, 3], plain[40:60, 3], atol=1e-5)
    assert not np.allclose(observed.positions[40:60, 3], repaired.positions[40:60, 3], atol=1e-4)


def test_learned_refiner_maps_reordered_joints_and_leaves_extra_markers(tiny_refiner, gappy):
    _, motion = gappy
    order = list(range(CMU31.num_joints))[::-1]
    extra = np.full((motion.num_frames, 1, 3), 5.0, np.float32)
    extra[3] = np.nan
    shuffled = Motion(
        np.concatenate([motion.positions[:, order], extra], axis=1),
        [motion.joint_names[j] for j in order] + ["extra_marker"],
        120.0,
        name="shuffled",
    )
    out = tiny_refiner.refine(shuffled)
    direct = tiny_refiner.refine(motion)
    np.testing.assert_array_equal(out.positions[:, :-1], direct.positions[:, order])
    assert np.array_equal(out.positions[:, -1], extra[:, 0], equal_nan=True) and out.missing[3, -1]
    assert out.metadata["refinement"]["filled"] == direct.metadata["refinement"]["filled"]


# ------------------------------------------------------------------------------------------------ ONNX
def test_onnx_refiner_matches_learned_refiner(tiny_module, tiny_refiner, gappy, tmp_path):
    from mocapkit.deploy.refiner_export import export_refiner

    path = tmp_path / "tiny.onnx"
    info = export_refiner(
        tiny_module.model, path, dict(tiny_module.hparams.skeleton), trace_shape=(2, 12), check_shape=(3, 40)
    )
    assert info["max_abs_diff"] < 1e-4
    _, motion = gappy
    missing = motion.missing.copy()
    missing[:3] = True
    motion = with_missing(motion, missing)
    onnx = OnnxRefiner(str(path), threads=1).fit()
    assert (onnx.window_, onnx.overlap_, onnx.fps_, onnx.joint_names_) == (
        tiny_refiner.window_,
        tiny_refiner.overlap_,
        tiny_refiner.fps_,
        tiny_refiner.joint_names_,
    )
    a, b = tiny_refiner.refine(motion), onnx.refine(motion)
    assert np.array_equal(a.missing, b.missing)
    filled = motion.missing & ~a.missing
    assert filled.sum() > 0
    np.testing.assert_allclose(b.positions[filled], a.positions[filled], atol=1e-4, rtol=0)
    assert a.metadata["refinement"]["unfilled"] == b.metadata["refinement"]["unfilled"]


@pytest.mark.parametrize("name", ["transformer-frames", "transformer-joints"])
def test_transformer_exports_with_parity(name, tmp_path):
    """The transformer goes through torch.export with its export-only layer path (encoder_layer_forward):
    onnxruntime matches PyTorch on a batch and lengths other than the traced ones (export_refiner checks (3, 40) and
    (1, 20); a mismatch raises ParityError), with a trained-looking correction (the last layer is not zero)."""
    from mocapkit.deploy.refiner_export import export_refiner

    torch.manual_seed(0)
    net = NETWORKS[name]().eval()
    with torch.no_grad():
        torch.nn.init.normal_(net.out.weight, std=0.05)
        net.mask_token.normal_(0, 0.5)
    skeleton = {
        "joint_names": list(CMU31.joint_names),
        "parents": list(CMU31.parents),
        "fps": 120.0,
        "up_axis": "y",
        "window": 24,
    }
    info = export_refiner(net, tmp_path / "t.onnx", skeleton, trace_shape=(2, 12), check_shape=(3, 40))
    assert info["exporter"] == "dynamo" and info["max_abs_diff"] < 1e-4
    assert [c["shape"][:2] for c in info["checks"]] == [[3, 40], [1, 20]]


@pytest.mark.parametrize("shape", [(2, 17, 16), (5, 3, 16)])
def test_encoder_layer_forward_computes_what_the_layer_computes(shape):
    """The written-out layer (training and export: one projection, the scale on the queries, 2-D projections) is
    the pre-norm, batch-first nn.TransformerEncoderLayer in eval mode, with and without PyTorch's fused path."""
    torch.manual_seed(0)
    layer = torch.nn.TransformerEncoderLayer(
        16, 4, 32, 0.1, activation="gelu", batch_first=True, norm_first=True
    ).eval()
    for p in layer.parameters():  # weights away from their initial symmetry
        p.data.add_(0.1 * torch.randn_like(p))
    h = torch.randn(*shape)
    with torch.no_grad():
        fused = layer(h)  # PyTorch's fast path (no grad, eval)
        mine = encoder_layer_forward(layer, h)
    torch.testing.assert_close(mine, fused, atol=2e-5, rtol=1e-5)
    torch.testing.assert_close(mine.detach(), layer(h).detach(), atol=2e-5, rtol=1e-5)  # the plain path


def test_encoder_layer_forward_trains_as_the_layer_trains():
    """In training mode without dropout the written-out layer has the layer's values and gradients; with dropout
    it drops (two calls differ) as torch's layer does (the same mean and spread over draws)."""
    torch.manual_seed(0)
    layer = torch.nn.TransformerEncoderLayer(16, 4, 32, 0.0, activation="gelu", batch_first=True, norm_first=True)
    layer.train()
    h = torch.randn(3, 11, 16)
    mine, theirs = encoder_layer_forward(layer, h), layer(h)
    torch.testing.assert_close(mine, theirs, atol=2e-5, rtol=1e-5)
    weights = list(layer.parameters())
    for a, b in zip(
        torch.autograd.grad(mine.square().sum(), weights), torch.autograd.grad(theirs.square().sum(), weights)
    ):
        torch.testing.assert_close(a, b, atol=1e-4, rtol=1e-4)
    dropping = torch.nn.TransformerEncoderLayer(16, 4, 32, 0.3, activation="gelu", batch_first=True, norm_first=True)
    dropping.load_state_dict(layer.state_dict())
    dropping.train()
    h = torch.randn(8, 16, 16)
    with torch.no_grad():
        first, second = encoder_layer_forward(dropping, h), encoder_layer_forward(dropping, h)
        assert not torch.allclose(first, second)
        # the same distribution as torch's dropout: over 200 draws the outputs' mean and spread agree
        mine = torch.stack([encoder_layer_forward(dropping, h) for _ in range(200)])
        theirs = torch.stack([dropping(h) for _ in range(200)])
    # (two sets of torch's draws: 0.018 and 0.999 here; without the 1 / (1 - p) scale: 0.09 and 0.51)
    assert float((mine.mean(0) - theirs.mean(0)).abs().mean()) < 0.03
    assert abs(float(mine.std(0).mean() / theirs.std(0).mean()) - 1.0) < 0.05


def test_first_guess_of_an_unobserved_chain_is_its_nearest_observed_ancestor():
    """Foot and knee never observed in a window: both start at the nearest observed ancestor's guess (a chain of
    two, which the pointer jumping must follow twice); with the root missing too, joints whose every ancestor is
    missing start at the root's guess (zero: the root is never observed)."""
    net = NETWORKS["bigru"]()
    parents = list(CMU31.parents)
    foot = 9
    knee, hip = parents[foot], parents[parents[foot]]
    x = torch.randn(2, 12, len(parents), 3)
    observed = torch.rand(2, 12, len(parents)) < 0.7
    observed[:, 0] = True
    observed[0, :, [foot, knee]] = False
    observed[1] = False
    observed[1, :, foot] = True  # only the foot is seen in window 1
    guess = net.first_guess(x, observed)
    cubic = cubic_fill(x, observed)
    torch.testing.assert_close(guess[0, :, foot], cubic[0, :, hip], rtol=0, atol=0)
    torch.testing.assert_close(guess[0, :, knee], cubic[0, :, hip], rtol=0, atol=0)
    seen = observed[0].any(dim=0)
    torch.testing.assert_close(guess[0][:, seen], cubic[0][:, seen], rtol=0, atol=0)

    def below_foot(j):
        while j >= 0 and j != foot:
            j = parents[j]
        return j == foot

    for j in range(len(parents)):  # the foot's descendants start at the foot, the rest at 0
        expected = x[1, :, foot] if below_foot(j) else torch.zeros_like(x[1, :, foot])
        torch.testing.assert_close(guess[1, :, j], expected, rtol=0, atol=0)
    assert any(below_foot(j) and j != foot for j in range(len(parents)))  # the rule is exercised both ways
