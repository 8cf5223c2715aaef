"""The exp-map / relative-root representation of Zhou 2014 ch. 4 (mocapkit.synthesis.representation)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import amc_motion, read_amc
from mocapkit.synthesis.clips import DofLayout, SynthesisInputError
from mocapkit.synthesis.representation import (
    ROOT_FEATURES,
    FeatureClip,
    continuous_expmap,
    decode,
    decode_flat,
    encode,
    partition_ancestors,
    partitions,
    project_expmap,
    root_start,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
CLIPS = [
    HDM05 / "bd" / "HDM_bd_hopBothLegs1hops_001_120.amc",
    HDM05 / "bk" / "HDM_bk_squat1Reps_021_120.amc",
    HDM05 / "bd" / "HDM_bd_jogLeftCircle4StepsRstart_001_120.amc",
]


@pytest.fixture(scope="module")
def clips():
    return [read_amc(path) for path in CLIPS]


@needs(HDM05)
def test_round_trip_reproduces_joint_positions(clips):
    # every bone, 3-dof or reduced-dof, is encoded from its own dofs, so decoding is exact (float round-off)
    for clip in clips:
        features = encode(clip)
        start_xz, start_yaw = root_start(clip)
        values = decode(features, clip.metadata["asf"], start_xz=start_xz, start_yaw=start_yaw)
        again = amc_motion(clip.metadata["asf"], values)
        error = np.linalg.norm(again.positions.astype(float) - clip.positions.astype(float), axis=-1)
        assert error.max() < 1e-3, f"{clip.name}: {error.max() * 1000:.3f} mm"
        flat = features.flat()
        assert flat.shape == (len(clip.positions), ROOT_FEATURES + 3 * len(features.bones))
        np.testing.assert_allclose(decode(flat, clip.metadata["asf"], start_xz, start_yaw)["lfemur"], values["lfemur"])


@needs(HDM05)
def test_features_shapes_and_relative_root(clips):
    clip = clips[0]
    features = encode(clip)
    layout = DofLayout.of(clip.metadata["asf"])
    assert features.bones == layout.bones[1:]
    assert features.joints.shape == (len(clip.positions), len(layout.bones) - 1, 3)
    np.testing.assert_array_equal(features.root[0, :3], 0.0)
    # moving and turning the whole clip leaves every feature unchanged
    moved = amc_motion(
        clip.metadata["asf"], decode(features, clip.metadata["asf"], start_xz=(40.0, -25.0), start_yaw=2.0)
    )
    np.testing.assert_allclose(encode(moved).flat(), features.flat(), atol=1e-9)
    assert np.linalg.norm(moved.positions[0, 0] - clip.positions[0, 0]) > 1.0


@needs(HDM05)
def test_expmap_hygiene_on_real_clip(clips):
    clip = clips[0]
    features = encode(clip)
    assert np.linalg.norm(features.joints, axis=-1).max() <= np.pi + 1e-9
    # continuity: where a bone turns little between frames, its exp-map moves little too
    layout = DofLayout.of(clip.metadata["asf"])
    for i, bone in enumerate(features.bones):
        rotation = Rotation.from_rotvec(features.joints[:, i])
        turn = (rotation[1:] * rotation[:-1].inv()).magnitude()
        step = np.linalg.norm(np.diff(features.joints[:, i], axis=0), axis=1)
        small = turn < 0.2
        assert np.all(step[small] < 0.5), f"{bone} ({layout.dofs[i + 1]}) jumps"


def test_continuous_expmap_across_pi():
    angles = np.linspace(2.8, 3.6, 30)  # a 1-dof rotation sweeping through pi
    rotvec = Rotation.from_rotvec(np.outer(angles, [1.0, 0.0, 0.0])).as_rotvec()
    assert np.abs(np.diff(rotvec[:, 0])).max() > 6.0  # scipy's |v| <= pi flips sign at pi
    smooth = continuous_expmap(rotvec)
    np.testing.assert_allclose(smooth[:, 0], angles, atol=1e-9)
    assert np.allclose(Rotation.from_rotvec(smooth).as_matrix(), Rotation.from_rotvec(rotvec).as_matrix())


def test_project_expmap_onto_two_dofs():
    rng = np.random.default_rng(0)
    dofs = rng.uniform(-1.0, 1.0, (50, 2))
    exact = Rotation.from_euler("xz", dofs).as_rotvec()
    np.testing.assert_allclose(project_expmap(exact, "xz"), exact, atol=1e-9)
    noisy = exact + 0.05 * rng.standard_normal(exact.shape)
    projected = project_expmap(noisy, "xz")
    angles = Rotation.from_rotvec(projected).as_euler("xzy")
    np.testing.assert_allclose(angles[:, 2], 0.0, atol=1e-9)  # nothing left on the missing axis
    assert np.abs(projected - noisy).max() < 0.3


@needs(HDM05)
def test_partitions_of_hdm05_skeleton(clips):
    skeleton = clips[0].metadata["asf"]
    parts = partitions(skeleton)
    assert set(parts) == {"RA", "LA", "RL", "LL", "TH"}
    assert parts["TH"][0] == "root" and "head" in parts["TH"] and "lowerback" in parts["TH"]
    assert parts["LL"] == ("lfemur", "ltibia", "lfoot", "ltoes")
    assert parts["RA"][:4] == ("rclavicle", "rhumerus", "rradius", "rwrist")
    all_bones = [b for part in parts.values() for b in part]
    assert sorted(all_bones) == sorted(DofLayout.of(skeleton).bones)  # every bone with dofs exactly once
    assert partition_ancestors(skeleton, parts["RA"])["rwrist"] == ("rclavicle", "rhumerus", "rradius")
    assert partition_ancestors(skeleton, parts["RA"])["rclavicle"] == ()


@needs(HDM05)
def test_bad_inputs(clips):
    skeleton = clips[0].metadata["asf"]
    features = encode(clips[0])
    with pytest.raises(ValueError, match="flat features must be"):
        decode(features.flat()[:, :-1], skeleton)
    other = DofLayout(bones=("root",), dofs=(("TX",),))
    with pytest.raises(ValueError, match="layout does not match"):
        decode_flat(features.flat(), other, skeleton)
    with pytest.raises(ValueError, match="bones"):
        decode(FeatureClip(features.root, features.joints[:, :-1], features.bones[:-1]), skeleton)
    import copy

    one_legged = copy.deepcopy(skeleton)
    one_legged.hierarchy["root"] = [b for b in one_legged.hierarchy["root"] if b != "lhipjoint"]
    one_legged.bones = [
        b for b in one_legged.bones if b.name not in ("lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes")
    ]
    for b in ("lhipjoint", "lfemur", "ltibia", "lfoot"):
        one_legged.hierarchy.pop(b, None)
    with pytest.raises(SynthesisInputError, match="LL"):
        partitions(one_legged)
