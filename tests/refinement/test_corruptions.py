"""Corruption protocols: exact amounts, gap geometry, reproducibility, clamping, errors, stated lengths."""

import re

import numpy as np
import pytest

from mocapkit.motion.container import Motion
from mocapkit.refinement import PROTOCOLS, Corruption, CorruptionError, corrupt
from tests.shared_data import SHARED, needs

HDM05_CLIP = SHARED / "data" / "hdm05_cuts11" / "bd" / "HDM_bd_depositFloorR_001_120.amc"


def smooth_motion(frames=600, joints=31, fps=120.0, seed=0, name="synthetic"):
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    phase = rng.uniform(0, 2 * np.pi, size=(joints, 3))
    offset = rng.normal(scale=0.5, size=(joints, 3))
    positions = offset + 0.1 * np.sin(2 * np.pi * 0.7 * t[:, None, None] + phase)
    return Motion(positions=positions, joint_names=[f"m{j}" for j in range(joints)], fps=fps, name=name)


def runs(column):
    edges = np.diff(np.concatenate([[0], column.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


ALL = [(name, level) for name, info in PROTOCOLS.items() for level in info.levels]


@pytest.mark.parametrize("protocol,level", ALL)
def test_every_protocol_is_consistent_reproducible_and_seed_dependent(protocol, level):
    clean = smooth_motion()
    before = clean.positions.copy()
    a = corrupt(clean, protocol, level, seed=3)
    b = corrupt(clean, protocol, level, seed=3)
    c = corrupt(clean, protocol, level, seed=4)
    assert isinstance(a, Corruption) and a.protocol == protocol and a.level == level
    assert np.array_equal(clean.positions, before)  # input untouched
    assert np.array_equal(a.removed, b.removed) and np.array_equal(a.perturbed, b.perturbed)
    assert np.array_equal(a.motion.positions, b.motion.positions, equal_nan=True)
    assert not (
        np.array_equal(a.removed, c.removed)
        and np.array_equal(a.perturbed, c.perturbed)
        and np.array_equal(a.motion.positions, c.motion.positions, equal_nan=True)
    )
    # removed entries are NaN and missing; perturbed ones moved; everything else bit-identical
    assert np.array_equal(a.motion.missing, clean.missing | a.removed)
    assert np.isnan(a.motion.positions[a.removed]).all()
    assert not (a.removed & a.perturbed).any()
    moved = ~(a.motion.positions == clean.positions).all(axis=2) & ~a.removed
    assert np.array_equal(moved, a.perturbed)
    assert a.removed.any() or a.perturbed.any()
    assert a.motion.metadata["corruption"]["protocol"] == protocol
    assert "fps" in a.description and "frames" in a.description


@pytest.mark.parametrize(
    "protocol,level", [("rdloss", 0.3), ("missing_ratio", 0.1), ("missing_ratio", 0.2), ("missing_ratio", 0.3)]
)
def test_random_entry_loss_removes_exactly_the_fraction(protocol, level):
    clean = smooth_motion()
    c = corrupt(clean, protocol, level)
    assert c.removed.sum() == round(level * clean.missing.size)
    assert not c.perturbed.any()


def test_rdcrypt_noise_has_sigma_2cm_on_30_percent():
    clean = smooth_motion(frames=1000)
    c = corrupt(clean, "rdcrypt")
    assert c.perturbed.sum() == round(0.3 * clean.missing.size) and not c.removed.any()
    noise = (c.motion.positions - clean.positions)[c.perturbed]
    assert abs(noise.std() - 0.02) < 0.001 and abs(noise.mean()) < 0.001


def test_mxcrypt_removes_30_percent_then_perturbs_30_percent_of_the_rest():
    clean = smooth_motion()
    c = corrupt(clean, "mxcrypt")
    n = clean.missing.size
    assert c.removed.sum() == round(0.3 * n)
    assert c.perturbed.sum() == round(0.3 * (n - c.removed.sum()))


@pytest.mark.parametrize("mr", [0.2, 0.3, 0.4, 0.5, 0.6])
def test_random_missing_removes_the_fraction_of_markers_in_every_frame(mr):
    clean = smooth_motion()
    c = corrupt(clean, "random_missing", mr)
    assert (c.removed.sum(axis=1) == round(mr * 31)).all()


@pytest.mark.parametrize(
    "protocol,level,length", [("rgloss", None, 60)] + [("continuous_missing", ml, ml) for ml in (20, 30, 40, 50, 60)]
)
def test_gap_protocols_remove_10_markers_for_consecutive_frames_away_from_the_ends(protocol, level, length):
    clean = smooth_motion()
    c = corrupt(clean, protocol, level, seed=1)
    markers = np.flatnonzero(c.removed.any(axis=0))
    assert len(markers) == 10 and c.removed.sum() == 10 * length
    for j in markers:
        ((start, stop),) = runs(c.removed[:, j])
        assert stop - start == length and start >= 1 and stop <= clean.num_frames - 1
    assert len(c.gaps) == 10 and all(g[2] == length for g in c.gaps)
    assert f"{length} frames = {length / 120:.3g} s at 120 fps" in c.description


def test_long_gaps_in_seconds_follow_the_frame_rate():
    for fps, frames in [(120.0, 240), (30.0, 60)]:
        clean = smooth_motion(frames=int(10 * fps), fps=fps)
        c = corrupt(clean, "long_gaps", "5x2s", seed=2)
        assert c.removed.sum() == 5 * frames and len(c.gaps) == 5
        assert all(length == frames for _, _, length in c.gaps)
        assert f"{frames} frames = 2 s at {fps:g} fps" in c.description


def test_long_gaps_may_put_several_separated_gaps_on_one_marker():
    clean = smooth_motion(frames=500, joints=8)
    c = corrupt(clean, "long_gaps", "20x100", seed=0)
    assert c.removed.sum() == 20 * 100 and len(c.gaps) == 20
    for j in range(8):
        gaps = runs(c.removed[:, j])
        assert sum(stop - start for start, stop in gaps) == 100 * sum(g[0] == j for g in c.gaps)
        assert all(stop - start == 100 and start >= 1 and stop <= 499 for start, stop in gaps)  # separated
    assert max(sum(g[0] == j for g in c.gaps) for j in range(8)) >= 2  # 20 gaps, 8 markers


def test_swaps_exchange_marker_trajectories():
    clean = smooth_motion()
    c = corrupt(clean, "swaps", "3x0.25s", seed=5)
    assert not c.removed.any() and c.perturbed.sum() > 0
    out = c.motion.positions
    # every perturbed entry now holds another marker's clean position from the same frame
    for t, j in np.argwhere(c.perturbed):
        assert any(np.array_equal(out[t, j], clean.positions[t, k]) for k in range(clean.num_joints) if k != j)
    assert c.perturbed[[0, -1]].sum() == 0
    assert "30 frames = 0.25 s at 120 fps" in c.description


def test_spikes_are_isolated_single_frame_jumps_of_10_to_30_cm():
    clean = smooth_motion()
    c = corrupt(clean, "spikes", 0.01, seed=1)
    assert c.perturbed.sum() == round(0.01 * clean.missing.size) and not c.removed.any()
    jump = np.linalg.norm(c.motion.positions - clean.positions, axis=2)[c.perturbed]
    assert jump.min() >= 0.0999 and jump.max() <= 0.3001
    assert not (c.perturbed[1:] & c.perturbed[:-1]).any()  # never two frames in a row
    assert c.perturbed[[0, -1]].sum() == 0


def test_fewer_markers_than_asked_take_all_markers():
    clean = smooth_motion(joints=5)
    c = corrupt(clean, "rgloss")
    assert (c.removed.sum(axis=0) == 60).all()


def test_a_sequence_shorter_than_the_gap_is_an_error_naming_motion_and_protocol():
    short = smooth_motion(frames=50, name="short_take")
    for protocol, level in [("rgloss", None), ("continuous_missing", 60), ("long_gaps", "5x2s")]:
        with pytest.raises(CorruptionError, match=rf"short_take.*{protocol}"):
            corrupt(short, protocol, level)
    with pytest.raises(CorruptionError, match="unknown corruption protocol"):
        corrupt(short, "nonsense")
    with pytest.raises(CorruptionError, match="level"):
        corrupt(smooth_motion(), "long_gaps", "five gaps")


def test_already_missing_entries_are_never_counted():
    clean = smooth_motion()
    positions = clean.positions.copy()
    positions[100:400, :8] = np.nan  # long real gaps on 8 markers
    holey = Motion(positions=positions, joint_names=clean.joint_names, fps=clean.fps, name="holey")
    observed = int((~holey.missing).sum())
    for protocol, level in ALL:
        c = corrupt(holey, protocol, level, seed=7)
        assert not (c.removed & holey.missing).any() and not (c.perturbed & holey.missing).any()
        assert np.array_equal(c.motion.missing, holey.missing | c.removed)
    assert corrupt(holey, "rdloss").removed.sum() == round(0.3 * observed)
    assert (corrupt(holey, "random_missing", 0.3).removed.sum(axis=1) == 9).all()


def test_registry_lists_the_thesis_levels():
    assert PROTOCOLS["random_missing"].levels == (0.2, 0.3, 0.4, 0.5, 0.6)
    assert PROTOCOLS["continuous_missing"].levels == (20, 30, 40, 50, 60)
    assert PROTOCOLS["missing_ratio"].levels == (0.1, 0.2, 0.3)
    assert set(PROTOCOLS) == {
        "rdcrypt",
        "rdloss",
        "mxcrypt",
        "rgloss",
        "random_missing",
        "continuous_missing",
        "missing_ratio",
        "long_gaps",
        "swaps",
        "spikes",
    }


@needs(HDM05_CLIP)
def test_real_hdm05_clip_rgloss_states_frames_and_seconds():
    from mocapkit.datasets.formats.motion_io import read_motion

    clip = read_motion(HDM05_CLIP)
    c = corrupt(clip, "rgloss", seed=0)
    assert c.removed.sum() == 600 and c.motion.num_frames == clip.num_frames
    assert re.search(r"60 frames = 0\.5 s at 120 fps", c.description)
    assert "HDM_bd_depositFloorR_001_120" in c.description
