"""BVH → ASF/AMC re-rigging (mocapkit.datasets.formats.bvh_to_amc) and BVH training clips for synthesis.

The synthetic rig imitates Bandai's: a static ``Root`` above ``Hips``, position channels on every joint, and
joint frames with their own orientation, so that the zero pose lies on its side; the real Bandai files are used
when ../shared/data is there."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import read_amc
from mocapkit.datasets.formats.bvh import parse_bvh_text, read_bvh
from mocapkit.datasets.formats.bvh_to_amc import BvhConversionError, bvh_rig, bvh_to_amc
from mocapkit.synthesis.clips import SynthesisInputError, as_amc_clips, check_clips
from mocapkit.synthesis.representation import partitions
from mocapkit.synthesis.synthesize import find_clips, synthesize

BANDAI = Path(__file__).resolve().parents[4] / "shared" / "data" / "bandai_motion_1" / "data"

# joint, parent, upright T-pose position (cm; y up, facing +z, left +x)
BODY = [
    ("Root", None, (0, 0, 0)),
    ("Hips", "Root", (0, 95, 0)),
    ("Spine", "Hips", (0, 110, 0)),
    ("Chest", "Spine", (0, 125, 0)),
    ("Neck", "Chest", (0, 145, 0)),
    ("Head", "Neck", (0, 155, 0)),
    ("Shoulder_L", "Chest", (5, 140, 0)),
    ("UpperArm_L", "Shoulder_L", (18, 140, 0)),
    ("LowerArm_L", "UpperArm_L", (45, 140, 0)),
    ("Hand_L", "LowerArm_L", (70, 140, 0)),
    ("Shoulder_R", "Chest", (-5, 140, 0)),
    ("UpperArm_R", "Shoulder_R", (-18, 140, 0)),
    ("LowerArm_R", "UpperArm_R", (-45, 140, 0)),
    ("Hand_R", "LowerArm_R", (-70, 140, 0)),
    ("UpperLeg_L", "Hips", (9, 90, 0)),
    ("LowerLeg_L", "UpperLeg_L", (9, 50, 0)),
    ("Foot_L", "LowerLeg_L", (9, 8, 0)),
    ("Toes_L", "Foot_L", (9, 2, 12)),
    ("UpperLeg_R", "Hips", (-9, 90, 0)),
    ("LowerLeg_R", "UpperLeg_R", (-9, 50, 0)),
    ("Foot_R", "LowerLeg_R", (-9, 8, 0)),
    ("Toes_R", "Foot_R", (-9, 2, 12)),
]


def bandai_like_bvh(
    frames: int = 40, yaw_deg: float = 0.0, seed: int = 0, slide_joint: str | None = None, rotation_only: bool = False
) -> str:
    """BVH text of the body above walking along its facing direction (turned by ``yaw_deg``), with random joint
    orients (the zero pose is not upright) and small random joint motion; ``slide_joint`` gets a moving
    translation; ``rotation_only``: joints below ``Hips`` have rotation channels only (the common BVH)."""
    rng = np.random.default_rng(seed)
    names = [b[0] for b in BODY]
    parent = [names.index(p) if p else -1 for _, p, _ in BODY]
    rest = np.array([b[2] for b in BODY], dtype=float)
    orient = Rotation.random(len(BODY), random_state=1).as_matrix()  # joint frames at the T-pose
    orient[0] = np.eye(3)
    yaw = Rotation.from_euler("y", yaw_deg, degrees=True).as_matrix()
    wiggle = rng.normal(scale=0.15, size=(frames, len(BODY), 3)) * np.linspace(0.3, 1, frames)[:, None, None]
    lines, columns = [], []
    offsets = [rest[0]] + [orient[p].T @ (rest[j] - rest[p]) for j, p in enumerate(parent) if p >= 0]
    glob = np.zeros((frames, len(BODY), 3, 3))
    for j, p in enumerate(parent):
        world = yaw @ Rotation.from_rotvec(wiggle[:, j]).as_matrix() @ orient[j]  # [F, 3, 3]
        if p < 0:
            world = np.broadcast_to(np.eye(3), world.shape)
        glob[:, j] = world
        local = world if p < 0 else np.swapaxes(glob[:, p], 1, 2) @ world
        angles = Rotation.from_matrix(local).as_euler("ZXY", degrees=True)  # Bandai's channel order
        position = np.tile(offsets[j], (frames, 1))
        if names[j] == "Hips":
            position = np.tile(rest[j], (frames, 1)) + np.outer(np.arange(frames) * 3.0, yaw @ [0, 0, 1])
        if names[j] == slide_joint:
            position = position + np.outer(np.arange(frames) * 0.5, [1.0, 0, 0])
        columns.append(angles if rotation_only and j > 1 else np.concatenate([position, angles], axis=1))
    depth = {-1: -1}

    def block(j: int) -> None:
        depth[j] = depth[parent[j]] + 1
        pad = "  " * depth[j]
        lines.append(f"{pad}{'ROOT' if parent[j] < 0 else 'JOINT'} {names[j]}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v:.6f}' for v in offsets[j])}")
        lines.append(
            f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation"
            if rotation_only and j > 1
            else f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        )
        children = [c for c, p in enumerate(parent) if p == j]
        for c in children:
            block(c)
        if not children:
            lines.extend([pad + "  End Site", pad + "  {", pad + "    OFFSET 0 0 0", pad + "  }"])
        lines.append(pad + "}")

    lines.append("HIERARCHY")
    block(0)
    data = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {frames}", "Frame Time: 0.0333333"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


def _motion(text: str, name: str = "clip"):
    return parse_bvh_text(text, source=f"{name}.bvh")


def test_conversion_is_exact_and_the_rest_pose_is_an_upright_t_pose():
    motion = _motion(bandai_like_bvh())
    amc = bvh_to_amc(motion)
    kept = [motion.joint_names.index(n) for n in motion.joint_names[1:]]
    np.testing.assert_allclose(amc.positions, motion.positions[:, kept], atol=1e-5)  # joints named as the BVH's
    assert amc.joint_names[0] == "root" and amc.joint_names[1:] == motion.joint_names[2:]
    assert amc.metadata["bvh_dropped_joints"] == ("Root",)
    skeleton = amc.metadata["asf"]
    rest = dict(zip(skeleton.joint_names, skeleton.rest_positions()))
    up = rest["Head"] - rest["Chest"]
    assert up[1] > 0.99 * np.linalg.norm(up)  # torso straight up
    assert rest["Hand_L"][0] > rest["UpperArm_L"][0] + 0.4 and rest["Hand_R"][0] < rest["UpperArm_R"][0] - 0.4
    shin = rest["Foot_L"] - rest["LowerLeg_L"]
    assert shin[1] < -0.99 * np.linalg.norm(shin)  # legs straight down
    toes = rest["Toes_R"] - rest["Foot_R"]
    assert toes[2] > 0.99 * np.linalg.norm(toes)  # feet forward (+z)
    # the root's children carry no rotation of their own; the others carry their parent joint's three
    assert skeleton.bone("Spine").dof == () and skeleton.bone("UpperLeg_L").dof == ()
    assert skeleton.bone("LowerLeg_L").dof == ("rx", "ry", "rz")
    parts = partitions(skeleton)
    assert parts["LL"] == ("LowerLeg_L", "Foot_L", "Toes_L") and parts["RA"][0] == "Shoulder_R"
    assert parts["TH"] == ("root", "Chest", "Neck", "Head")


def test_a_turned_take_gets_the_same_rest_pose_facing_plus_z():
    ahead = bvh_to_amc(_motion(bandai_like_bvh()))
    turned = bvh_to_amc(_motion(bandai_like_bvh(yaw_deg=120.0)))
    np.testing.assert_allclose(
        turned.metadata["asf"].rest_positions(), ahead.metadata["asf"].rest_positions(), atol=1e-6
    )
    # the walk goes along the take's facing: the AMC root translation turns with it, the joint angles do not
    for bone in ("LowerLeg_L", "Neck", "Hand_R"):
        np.testing.assert_allclose(turned.metadata["amc_values"][bone], ahead.metadata["amc_values"][bone], atol=1e-6)


def test_clips_share_one_rig_and_read_back_through_asf_amc(tmp_path):
    first, second = _motion(bandai_like_bvh(seed=0), "a"), _motion(bandai_like_bvh(seed=3), "b")
    clips = as_amc_clips([first, second])
    assert clips[0].metadata["bvh_rig"] is clips[1].metadata["bvh_rig"]
    assert clips[1].metadata["bvh_rig"].reference == "a.bvh frame 0"
    check_clips(clips)  # one bone hierarchy, the same dofs
    own = bvh_to_amc(second)  # its own frame 0 as rest: other angles, the same positions
    assert not np.allclose(own.metadata["amc_values"]["Neck"], clips[1].metadata["amc_values"]["Neck"])
    np.testing.assert_allclose(own.positions, clips[1].positions, atol=1e-5)
    from mocapkit.datasets.formats.asf_amc import write_amc, write_asf

    write_asf(tmp_path / "rig.asf", clips[1].metadata["asf"])
    write_amc(tmp_path / "b.amc", clips[1])
    back = read_amc(tmp_path / "b.amc", asf=tmp_path / "rig.asf")
    np.testing.assert_allclose(back.positions, clips[1].positions, atol=1e-4)


def test_amc_back_to_the_bvh_rig_is_the_take_itself(tmp_path):
    from mocapkit.datasets.formats.bvh import write_bvh
    from mocapkit.datasets.formats.bvh_to_amc import amc_to_bvh

    take = _motion(bandai_like_bvh(yaw_deg=30.0))
    rig = bvh_rig(take, frame=5)
    back = amc_to_bvh(bvh_to_amc(take, rig), rig)
    np.testing.assert_allclose(back.positions, take.positions, atol=1e-5)
    skeleton = take.metadata["bvh"]
    starts = skeleton.channel_starts
    for j, name in enumerate(skeleton.joint_names):
        if name in ("Head", "Hand_L", "Hand_R", "Toes_L", "Toes_R"):
            continue  # leaf rotations move only End Sites: the conversion drops them
        difference = (
            back.metadata["channels"][:, starts[j] : starts[j] + 6]
            - take.metadata["channels"][:, starts[j] : starts[j] + 6]
        )
        difference[:, 3:] = (difference[:, 3:] + 180.0) % 360.0 - 180.0  # angles: the same up to 360°
        np.testing.assert_allclose(difference, 0.0, atol=1e-6)
    write_bvh(tmp_path / "back.bvh", back)
    np.testing.assert_allclose(read_bvh(tmp_path / "back.bvh").positions, take.positions, atol=1e-5)
    with pytest.raises(BvhConversionError, match="not an AMC motion on the ASF skeleton"):
        amc_to_bvh(take, rig)


def test_bad_bvh_rigs_are_named():
    with pytest.raises(BvhConversionError, match=r"clip\.bvh.*'Neck' moves against its parent"):
        bvh_to_amc(_motion(bandai_like_bvh(slide_joint="Neck")))
    no_sides = bandai_like_bvh().replace("_L", "_A").replace("_R", "_B")
    with pytest.raises(BvhConversionError, match="left from its right"):
        bvh_to_amc(_motion(no_sides))
    other = _motion(bandai_like_bvh().replace("Toes_L", "Toe_L"), "other")
    with pytest.raises(BvhConversionError, match="other.bvh.*differ from the rig's"):
        bvh_to_amc(other, bvh_rig(_motion(bandai_like_bvh())))
    with pytest.raises(BvhConversionError, match="reference frame 99"):
        bvh_rig(_motion(bandai_like_bvh()), frame=99)
    with pytest.raises(BvhConversionError, match="not a BVH motion"):
        bvh_to_amc(bvh_to_amc(_motion(bandai_like_bvh())))


def test_synthesize_takes_bvh_clips_and_writes_bvh(tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    for k in range(3):
        (folder / f"walk_{k}.bvh").write_text(bandai_like_bvh(frames=30, seed=k, yaw_deg=40.0 * k))
    report = synthesize([folder], tmp_path / "out", n_variants=2, method="perlin", progress=False)
    assert report["format"] == "bvh" and report["bvh_rest_pose"].endswith("walk_0.bvh frame 0")
    assert report["bvh_output_rig"].startswith("the input's")
    variant = read_bvh(tmp_path / "out" / report["variants"][0])
    take = read_bvh(folder / "walk_0.bvh")  # written in the input's own rig
    assert variant.num_frames == 30 and variant.joint_names == take.joint_names
    assert variant.metadata["bvh"].channels == take.metadata["bvh"].channels
    np.testing.assert_allclose(variant.metadata["bvh"].offsets, take.metadata["bvh"].offsets, atol=1e-9)
    windows = synthesize(
        [folder], tmp_path / "windows", n_variants=1, method="perlin", progress=False, window_seconds=0.5
    )
    assert len(windows["training_clips"]) == 6 and windows["bvh_output_rig"].startswith("the input's")
    report = synthesize([folder], tmp_path / "amc", n_variants=1, method="perlin", progress=False, output_format="amc")
    back = read_amc(tmp_path / "amc" / report["variants"][0], asf=tmp_path / "amc" / report["skeleton"])
    assert back.joint_names[1:4] == ("Spine", "Chest", "Neck") and "bvh_output_rig" not in report
    # a rig whose shoulders have no position channels cannot hold shoulders sampled apart from the chest: the
    # variants are written on the ASF skeleton instead, and the report says why
    plain = tmp_path / "plain"
    plain.mkdir()
    for k in range(3):
        (plain / f"walk_{k}.bvh").write_text(bandai_like_bvh(frames=30, seed=k, rotation_only=True))
    report = synthesize([plain], tmp_path / "plain_out", n_variants=2, method="perlin", progress=False)
    assert "cannot hold the variants" in report["bvh_output_rig"]
    variant = read_bvh(tmp_path / "plain_out" / report["variants"][0])
    assert variant.joint_names[0] == "root" and "Shoulder_L" in variant.joint_names
    (folder / "walk_9.amc").write_text("")
    with pytest.raises(SynthesisInputError, match=r"mix \.amc and \.bvh"):
        find_clips([folder])


@pytest.mark.skipif(not BANDAI.is_dir(), reason="../shared/data/bandai_motion_1 not present")
def test_real_bandai_takes_convert_exactly_onto_one_t_pose():
    # bow_active_001's End Sites have zero length, bow_normal_001's do not: one skeleton all the same
    files = [BANDAI / "dataset-1_bow_active_001.bvh", BANDAI / "dataset-1_bow_normal_001.bvh"]
    files += sorted(BANDAI.glob("dataset-1_*.bvh"))[::40]
    motions = [read_bvh(f) for f in files]
    clips = as_amc_clips(motions)
    check_clips(clips)
    for motion, clip in zip(motions, clips):
        kept = [motion.joint_names.index(n) for n in ("Hips",) + clip.joint_names[1:]]
        np.testing.assert_allclose(clip.positions, motion.positions[:, kept], atol=1e-4)
        assert clip.metadata["bvh_dropped_joints"] == ("joint_Root",)
    skeleton = clips[0].metadata["asf"]
    assert set(partitions(skeleton)) == {"RA", "LA", "RL", "LL", "TH"}
    # the rest pose of any reference frame splits the same way (dash_musical frame 33 once made the spine an arm)
    dash = read_bvh(BANDAI / "dataset-1_dash_musical_001.bvh")
    for frame in (0, 33, -1):
        assert partitions(bvh_to_amc(dash, bvh_rig(dash, frame)).metadata["asf"]) == partitions(skeleton)
    rest = dict(zip(skeleton.joint_names, skeleton.rest_positions()))
    assert rest["Head"][1] > rest["Chest"][1] > rest["Foot_L"][1] + 0.9
    json.dumps(clips[0].metadata["bvh_rig"].reference)


SAMPLES = Path(__file__).resolve().parents[4] / "shared" / "samples" / "bvh"


@pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/samples/bvh not present")
@pytest.mark.parametrize(
    "name", ["cmu_131_01.bvh", "test_freebvh.bvh", "test_mocapbank.bvh", "AV_8Walk_Meredith_HVHA_Rep1.bvh"]
)
def test_rigs_from_the_wild_convert_split_and_come_back(name):
    """CMU-BVH (zero-length hip joints, clavicles), Mixamo (``mixamorig:`` names, eyes beside the head, fingers),
    and two other exporters: exact both ways, and the five partitions found on the T-pose rest."""
    from mocapkit.datasets.formats.bvh_to_amc import amc_to_bvh

    take = read_bvh(SAMPLES / name)
    amc = bvh_to_amc(take)
    np.testing.assert_allclose(
        amc.positions,
        take.positions[
            :,
            [
                take.joint_names.index(n)
                for n in (take.joint_names[amc.metadata["bvh_rig"].root],) + amc.joint_names[1:]
            ],
        ],
        atol=1e-4,
    )
    parts = partitions(amc.metadata["asf"])
    assert all(len(parts[p]) >= 2 for p in ("RA", "LA", "RL", "LL"))
    np.testing.assert_allclose(amc_to_bvh(amc, amc.metadata["bvh_rig"]).positions, take.positions, atol=1e-4)
