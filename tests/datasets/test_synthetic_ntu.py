"""Tests for the synthetic NTU stand-in (mocapkit.datasets.synthetic.ntu) and its FK model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.datasets.formats.ntu_skeleton import NTUSampleName, parse_ntu_name, read_skeleton, select_main_bodies
from mocapkit.datasets.synthetic import kinematics as kin
from mocapkit.datasets.synthetic.ntu import (
    ACTIONS,
    NTUSynthConfig,
    class_names,
    perform,
    sample_names,
    synthesize_ntu,
    synthesize_sample,
)
from mocapkit.motion.layouts import NTU25

CLEAN = dict(jitter_m=0.0, drop_frame_prob=0.0, extra_body_prob=0.0)
TINY = dict(num_classes=12, num_subjects=2, setups=(1,), cameras=(1, 2), replications=(1,), length_scale=0.5)
HANDSHAKE, WAVE = 10, 1  # action numbers (1-based)


def bone_lengths(positions: np.ndarray) -> np.ndarray:
    """``[..., 25, 3]`` → ``[..., 24]`` lengths of the NTU25 bones."""
    child, parent = np.array(NTU25.bones).T
    return np.linalg.norm(positions[..., child, :] - positions[..., parent, :], axis=-1)


def file_bytes(paths) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in paths}


@pytest.fixture(scope="module")
def tiny_set(tmp_path_factory):
    """The tiny data set with default sensor artefacts, written once."""
    config = NTUSynthConfig(**TINY)
    out = tmp_path_factory.mktemp("synth")
    return config, out, synthesize_ntu(out, config, progress=False)


# --------------------------------------------------------------------------- files and format


def test_files_are_named_and_read_back(tiny_set):
    config, out, paths = tiny_set
    assert len(paths) == 1 * 2 * 2 * 1 * 12
    assert sorted(p.name for p in out.glob("*.skeleton")) == sorted(p.name for p in paths)
    assert [str(parse_ntu_name(p)) for p in paths] == [str(n) for n in sample_names(config)]
    assert (out / "classes.txt").read_text().splitlines() == class_names(12)
    assert NTUSynthConfig.from_dict(json.loads((out / "synth_config.json").read_text())) == config
    for path in paths[::5]:
        seq = read_skeleton(path)
        assert seq.name == path.stem
        assert seq.joints.shape[2:] == (25, 12)
        assert seq.sample == parse_ntu_name(path.name)
        assert 10 <= seq.num_frames <= 80  # length_scale 0.5
        body = seq.positions[0][seq.present[0]]
        assert np.all(body[..., 2] > 1.5) and np.all(body[..., 2] < 5.0)  # metres in front of the camera


def test_default_lengths_and_heights_are_adult_sized():
    config = NTUSynthConfig(**CLEAN)
    for action in range(1, 13):
        for subject in (1, 2, 3):
            people = perform(config, 1, subject, 1, action)
            assert 35 <= people[0].shape[0] <= 130, (action, subject, people[0].shape)
            # Standing height from the floor (y = 0 in the world) to the Head joint, first frame.
            if action not in (9,):  # "stand up" starts seated
                head = people[0][0, kin.J["Head"], 1]
                assert 1.3 <= head <= 1.85


def test_class_names_and_config_errors():
    names = class_names(20)
    assert len(set(names)) == 20 and names[:12] == class_names(12)
    with pytest.raises(ValueError, match="num_classes"):
        class_names(21)
    for field, value in [
        ("num_classes", 0),
        ("num_classes", 21),
        ("cameras", (4,)),
        ("setups", ()),
        ("drop_frame_prob", 1.5),
        ("jitter_m", -0.1),
        ("style_noise", float("nan")),
        ("height_range_m", (1.9, 1.5)),
        ("length_scale", 0.0),
    ]:
        with pytest.raises(ValueError, match=field):
            NTUSynthConfig(**{field: value})
    with pytest.raises(ValueError, match="unknown"):
        NTUSynthConfig.from_dict({"num_clases": 3})


# --------------------------------------------------------------------------- determinism


def test_same_seed_same_bytes_any_workers(tmp_path, tiny_set):
    config, _, paths = tiny_set
    again = synthesize_ntu(tmp_path / "w1", config, workers=1, progress=False)
    parallel = synthesize_ntu(tmp_path / "w2", config, workers=2, progress=False)
    reference = file_bytes(paths)
    assert file_bytes(again) == reference
    assert file_bytes(parallel) == reference
    other = synthesize_ntu(tmp_path / "seed1", NTUSynthConfig(**{**TINY, "seed": 1}), progress=False)
    other_bytes = file_bytes(other)
    assert other_bytes.keys() == reference.keys()
    assert all(other_bytes[k] != reference[k] for k in reference)


def test_sample_does_not_depend_on_the_rest_of_the_config():
    small = NTUSynthConfig(num_classes=3, num_subjects=2)
    large = NTUSynthConfig(num_classes=12, num_subjects=10, setups=(1, 2, 3))
    name = NTUSampleName(1, 2, 2, 1, 3)
    a, b = synthesize_sample(name, small), synthesize_sample(name, large)
    np.testing.assert_array_equal(a.joints, b.joints)


# --------------------------------------------------------------------------- the motion


def test_forward_kinematics_is_rigid(tmp_path):
    config = NTUSynthConfig(**{**TINY, **CLEAN, "cameras": (1,)})
    for path in synthesize_ntu(tmp_path, config, progress=False):
        seq = read_skeleton(path)
        for b in range(seq.num_bodies):
            lengths = bone_lengths(seq.positions[b][seq.present[b]].astype(np.float64))
            assert np.all(lengths.std(axis=0) < 2e-5), path.name  # 7 printed digits
            assert np.all(lengths.mean(axis=0) > 0.01)
    # With jitter the bone lengths still scatter around fixed values, by about the jitter.
    seq = synthesize_sample(NTUSampleName(1, 1, 1, 1, WAVE), NTUSynthConfig(jitter_m=0.01, drop_frame_prob=0.0))
    spread = bone_lengths(seq.positions[0].astype(np.float64)).std(axis=0)
    assert np.all(spread < 0.04) and np.median(spread) > 0.003


def test_subjects_differ_in_body_size():
    config = NTUSynthConfig(num_subjects=6, **CLEAN)
    chain = [
        kin.J[n]
        for n in (
            "FootLeft",
            "AnkleLeft",
            "KneeLeft",
            "HipLeft",
            "SpineBase",
            "SpineMid",
            "SpineShoulder",
            "Neck",
            "Head",
        )
    ]
    sizes = []
    for subject in range(1, 7):
        pos = perform(config, 1, subject, 1, WAVE)[0][0]
        sizes.append(np.linalg.norm(np.diff(pos[chain], axis=0), axis=-1).sum())
    assert len(set(np.round(sizes, 3))) == 6
    assert max(sizes) - min(sizes) > 0.05
    assert all(1.2 < s < 2.0 for s in sizes)


def test_two_person_classes_have_two_interacting_bodies():
    for action in range(1, 21):
        seq = synthesize_sample(NTUSampleName(1, 1, 1, 1, action), NTUSynthConfig(num_classes=20, **CLEAN))
        assert seq.num_bodies == (2 if ACTIONS[action - 1].two_person else 1), ACTIONS[action - 1].name
    seq = synthesize_sample(NTUSampleName(1, 1, 1, 1, HANDSHAKE), NTUSynthConfig(difficulty=0.0, **CLEAN))
    assert len(set(seq.body_ids)) == 2 and seq.present.all()
    a, b = seq.positions.astype(np.float64)
    # They face each other and the right hands come close during the handshake.
    hands = np.linalg.norm(a[:, kin.J["HandRight"]] - b[:, kin.J["HandRight"]], axis=-1)
    assert hands.min() < 0.25 < 0.8 < hands[0]


def test_actions_are_distinct_motions():
    config = NTUSynthConfig(difficulty=0.0, **CLEAN)
    feats = []
    for action in range(1, 13):
        pos = synthesize_sample(NTUSampleName(1, 1, 1, 1, action), config).positions[0].astype(np.float64)
        rel = pos - pos[:, :1]
        feats.append(np.concatenate([rel.max(0).ravel(), rel.min(0).ravel()]))
    feats = np.array(feats)
    dist = np.linalg.norm(feats[:, None] - feats[None], axis=-1)
    assert dist[~np.eye(12, dtype=bool)].min() > 0.05


def test_wave_raises_the_right_hand_above_the_head():
    seq = synthesize_sample(NTUSampleName(1, 1, 1, 1, WAVE), NTUSynthConfig(difficulty=0.0, **CLEAN))
    pos = seq.positions[0]
    assert pos[:, kin.J["HandRight"], 1].max() > pos[:, kin.J["Head"], 1].max()
    assert pos[:, kin.J["HandLeft"], 1].max() < pos[:, kin.J["SpineMid"], 1].max()
    # Kinect camera space: the right hand of someone facing the camera has the larger x.
    assert pos[0, kin.J["HandRight"], 0] > pos[0, kin.J["HandLeft"], 0]


# --------------------------------------------------------------------------- cameras and sensor artefacts


def _rigid_fit(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Best rotation + translation taking points ``a`` ``[N, 3]`` onto ``b``: (RMS residual, angle in degrees)."""
    ca, cb = a - a.mean(0), b - b.mean(0)
    u, _, vt = np.linalg.svd(ca.T @ cb)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    angle = np.degrees(np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1)))
    return float(np.sqrt(((ca @ rot - cb) ** 2).sum(-1).mean())), float(angle)


def test_cameras_see_the_same_motion_from_different_viewpoints():
    config = NTUSynthConfig(**CLEAN)
    views = [synthesize_sample(NTUSampleName(2, c, 3, 1, 4), config).positions[0].astype(np.float64) for c in (1, 2, 3)]
    assert len({v.shape for v in views}) == 1
    # The same motion (one rigid transform explains every joint of every frame), seen
    # from azimuths 45° apart (C001 → C002 / C003) and 90° apart (C002 → C003).
    for (a, b), expected in {(0, 1): 45, (0, 2): 45, (1, 2): 90}.items():
        residual, angle = _rigid_fit(views[a].reshape(-1, 3), views[b].reshape(-1, 3))
        assert residual < 1e-4
        assert abs(angle - expected) < 8, (a, b, angle)
    # Setups move the cameras: same subject, different height / distance.
    s1 = synthesize_sample(NTUSampleName(1, 1, 3, 1, 4), config).positions[0]
    s2 = synthesize_sample(NTUSampleName(2, 1, 3, 1, 4), config).positions[0]
    assert abs(s1[..., 1].mean() - s2[..., 1].mean()) > 0.2 or abs(s1[..., 2].mean() - s2[..., 2].mean()) > 0.2


def test_dropped_frames_have_no_body():
    seq = synthesize_sample(NTUSampleName(1, 1, 1, 1, WAVE), NTUSynthConfig(**{**CLEAN, "drop_frame_prob": 0.3}))
    lost = ~seq.present.any(axis=0)
    assert 0 < lost.sum() < seq.num_frames // 2
    clean = synthesize_sample(NTUSampleName(1, 1, 1, 1, WAVE), NTUSynthConfig(**CLEAN))
    assert clean.present.all()


def test_extra_bodies_are_removed_by_body_selection(tmp_path):
    config = NTUSynthConfig(**{**TINY, **CLEAN, "extra_body_prob": 1.0})
    reasons = []
    for path in synthesize_ntu(tmp_path, config, progress=False):
        seq = read_skeleton(path)
        actors = 2 if ACTIONS[seq.sample.action - 1].two_person else 1
        assert seq.num_bodies == actors + 1
        assert len(set(seq.body_ids)) == seq.num_bodies
        sel = select_main_bodies(seq, max_bodies=2, denoise_spread=True, min_frames=12)
        assert len(sel.kept) == actors, (path.name, sel.dropped)
        for b in sel.kept:  # the kept tracks are the rigid, always-present actors
            assert seq.present[b].all()
            assert np.all(bone_lengths(seq.positions[b].astype(np.float64)).std(axis=0) < 2e-5)
        reasons += list(sel.dropped.values())
        # Spread denoising alone removes the chair-like blobs.
        spread_only = select_main_bodies(seq, denoise_spread=True)
        reasons_spread = [r for r in spread_only.dropped.values() if "spread" in r]
        if reasons_spread:
            assert len(spread_only.kept) == actors
    assert any("spread" in r for r in reasons)  # chair-like blobs
    assert any("frames" in r for r in reasons)  # short-lived passers-by


def test_kinematics_mirror_and_rest_pose():
    body = kin.BodyProportions.from_height(1.75)
    off = kin.rest_offsets(body)
    values = np.zeros((1, len(kin.DOF_NAMES)))
    values[0, kin.DOF_NAMES.index("r_shoulder_abd")] = 90
    values[0, kin.DOF_NAMES.index("l_shoulder_abd")] = 90
    pos = kin.forward_kinematics(off, kin.euler_to_matrix(kin.dofs_to_euler(values)))[0]
    right, left = pos[kin.J["HandRight"]], pos[kin.J["HandLeft"]]
    np.testing.assert_allclose(right * [-1, 1, 1], left, atol=1e-9)  # mirror images
    assert right[0] > 0.6 and abs(right[1] - pos[kin.J["ShoulderRight"], 1]) < 0.08  # arm horizontal, to the right
    rest = kin.forward_kinematics(off, kin.euler_to_matrix(np.zeros((1, 25, 3))))[0]
    assert abs(rest[kin.J["Head"], 1] - rest[kin.J["FootLeft"], 1] + 0.09 - body.height) < 0.06
