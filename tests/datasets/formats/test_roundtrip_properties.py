"""Property-based tests (Hypothesis): ``write_motion`` then ``read_motion`` gives the motion back, and the corruption
protocols remove and perturb exactly the entries they report.

Every format :data:`~mocapkit.datasets.formats.motion_io.FORMATS` has a writer for gets generated skeletons and
motions: C3D (any marker set, NaN gaps, units, frame rate, up axis), NTU ``.skeleton`` (the ntu25 layout; gaps are
frames without the body, the only gap the format has), BVH (random hierarchies and channel orders, written from the
source channels and from rotations alone) and ASF/AMC (random skeletons and dofs). The examples are derandomized
(fixed by the test's code), so every run checks the same cases; ``max_examples`` keeps the file under 30 s.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from mocapkit.motion.container import Motion
from mocapkit.refinement.corruptions import PROTOCOLS

FAST = settings(
    max_examples=60,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def _seed_rng(draw) -> np.random.Generator:
    """Arrays drawn from a numpy generator seeded by Hypothesis (``draw`` of a composite strategy): large arrays
    without Hypothesis's per-element cost (the seed is still shrunk and replayed)."""
    return np.random.default_rng(draw(st.integers(0, 2**32 - 1), label="array seed"))


def _read(path: Path, **options) -> Motion:
    from mocapkit.datasets.formats.motion_io import read_motion

    return read_motion(path, **options)


def _write(path: Path, motion: Motion, **options) -> None:
    from mocapkit.datasets.formats.motion_io import write_motion

    write_motion(path, motion, **options)


def _names(count: int):
    """``count`` distinct ASCII names (letters, digits, underscore; a letter first)."""
    name = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True)
    return st.lists(name, min_size=count, max_size=count, unique_by=str.lower)


def _parents_depth_first(rng: np.random.Generator, joints: int) -> list[int]:
    """A random tree over ``joints`` joints, numbered depth first (parents before children, subtrees contiguous)."""
    raw = [-1] + [int(rng.integers(0, j)) for j in range(1, joints)]
    children: dict[int, list[int]] = {}
    for j, p in enumerate(raw):
        children.setdefault(p, []).append(j)
    order: list[int] = []
    stack = [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children.get(j, [])))
    new = {old: k for k, old in enumerate(order)}
    return [-1 if raw[old] < 0 else new[raw[old]] for old in order]


# --------------------------------------------------------------------------------------------------- C3D


@st.composite
def marker_motions(draw):
    """Marker sets (no hierarchy) with NaN gaps anywhere, at any frame rate and up axis."""
    frames = draw(st.integers(1, 40), label="frames")
    markers = draw(st.integers(1, 30), label="markers")
    names = draw(_names(markers), label="names")
    rng = _seed_rng(draw)
    scale = draw(st.sampled_from([0.01, 1.0, 5.0, 20.0]), label="extent (m)")
    positions = rng.uniform(-scale, scale, (frames, markers, 3)).astype(np.float32)
    positions[rng.random((frames, markers)) < draw(st.sampled_from([0.0, 0.1, 0.5, 1.0]), label="gap rate")] = np.nan
    # a sample at exactly (0, 0, 0) is a gap in C3D (the convention of files that store gaps that way)
    zero = (positions == 0).all(axis=-1)
    positions[zero] = 1e-3
    fps = draw(st.one_of(st.sampled_from([25.0, 50.0, 60.0, 100.0, 120.0, 240.0]), st.floats(1.0, 2000.0)))
    return Motion(
        positions=positions,
        joint_names=tuple(names),
        fps=fps,
        up_axis=draw(st.sampled_from("xyz"), label="up"),
        name="gen",
    )


@FAST
@given(motion=marker_motions(), units=st.sampled_from(["mm", "cm", "m"]))
def test_c3d_round_trip(motion, units):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "gen.c3d"
        _write(path, motion, units=units)
        back = _read(path)
    assert back.joint_names == motion.joint_names and back.parents is None
    assert back.up_axis == motion.up_axis and back.source_units == units
    assert back.fps == pytest.approx(motion.fps, rel=1e-6)  # POINT:RATE is a float32
    assert back.num_frames == motion.num_frames
    np.testing.assert_array_equal(back.missing, motion.missing)  # NaN gaps are gaps, nothing else is
    observed = ~motion.missing
    # float32 in the file's units, float32 metres back: a few units in the last place
    np.testing.assert_allclose(back.positions[observed], motion.positions[observed], rtol=1e-6, atol=1e-7)


# --------------------------------------------------------------------------------------------------- NTU


@st.composite
def ntu_motions(draw):
    """One tracked body on the ntu25 layout; frames without the body are the gaps (the format's only kind)."""
    from mocapkit.motion.layouts import NTU25

    frames = draw(st.integers(1, 30), label="frames")
    rng = _seed_rng(draw)
    rest = rng.normal(0.0, 0.3, (1, 25, 3)) + [0.0, 0.0, 3.0]  # about 3 m in front of the sensor
    positions = (rest + rng.normal(0.0, 0.02, (frames, 25, 3))).astype(np.float32)
    absent = rng.random(frames) < draw(st.sampled_from([0.0, 0.2, 0.6]), label="absent rate")
    positions[absent] = np.nan
    return Motion(
        positions=positions,
        joint_names=NTU25.joint_names,
        parents=NTU25.parents,
        fps=30.0,
        name="S001C001P001R001A001",
        layout_name=NTU25.name,
    )


@FAST
@given(motion=ntu_motions())
def test_ntu_round_trip(motion):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "S001C001P001R001A001.skeleton"
        _write(path, motion)
        back = _read(path)
    assert back.joint_names == motion.joint_names and back.parents == motion.parents and back.fps == 30.0
    np.testing.assert_array_equal(back.missing, motion.missing)
    observed = ~motion.missing
    # %.7G: seven significant digits
    np.testing.assert_allclose(back.positions[observed], motion.positions[observed], rtol=1e-6, atol=1e-7)


# --------------------------------------------------------------------------------------------------- BVH


@st.composite
def bvh_sources(draw):
    """``(BvhSkeleton, channel values [frames, channels], frame_time, scale)``: random hierarchies (1–7 joints,
    depth first), channel orders, offsets and values."""
    from mocapkit.datasets.formats.bvh import BvhSkeleton

    joints = draw(st.integers(1, 7), label="joints")
    names = draw(_names(joints), label="names")
    rng = _seed_rng(draw)
    parents = _parents_depth_first(rng, joints)
    rotation = ["Xrotation", "Yrotation", "Zrotation"]
    position = ["Xposition", "Yposition", "Zposition"]
    channels = []
    for j in range(joints):
        order = [rotation[k] for k in rng.permutation(3)]
        moving = parents[j] < 0 or rng.random() < 0.2  # some joints carry position channels too
        channels.append(tuple(([position[k] for k in rng.permutation(3)] if moving else []) + order))
    leaves = [j for j in range(joints) if j not in parents]
    end_sites = tuple((j, rng.uniform(-10.0, 10.0, 3)) for j in leaves if rng.random() < 0.5)
    skeleton = BvhSkeleton(
        joint_names=tuple(names),
        parents=tuple(parents),
        offsets=rng.uniform(-20.0, 20.0, (joints, 3)),
        channels=tuple(channels),
        end_sites=end_sites,
    )
    frames = draw(st.integers(1, 20), label="frames")
    values = np.concatenate(
        [
            np.concatenate(
                [
                    rng.uniform(-100.0, 100.0, (frames, len(c) - 3)),  # positions, file units
                    rng.uniform(-180.0, 180.0, (frames, 3)),  # degrees
                ],
                axis=1,
            )
            for c in channels
        ],
        axis=1,
    )
    frame_time = draw(st.one_of(st.sampled_from([1 / 30, 1 / 120, 0.008333]), st.floats(1e-3, 1.0)))
    scale = draw(st.sampled_from([0.01, 0.001, 0.0254, 1.0]), label="metres per unit")
    return skeleton, values, frame_time, scale


@FAST
@given(source=bvh_sources())
def test_bvh_round_trip_from_its_channels(source):
    """A motion read from a BVH (its hierarchy and raw channels in metadata) is written back value for value."""
    from mocapkit.datasets.formats.bvh import bvh_motion

    skeleton, values, frame_time, scale = source
    motion = bvh_motion(skeleton, values, frame_time, scale)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "gen.bvh"
        _write(path, motion)
        back = _read(path, scale=scale)  # a BVH does not say its unit: give the one it was read with
    assert back.joint_names == motion.joint_names and back.parents == motion.parents
    assert back.fps == motion.fps  # Frame Time printed with repr: the same float
    np.testing.assert_array_equal(back.metadata["channels"], values)  # repr: the same floats
    np.testing.assert_array_equal(back.positions, motion.positions)
    assert not back.missing.any()


@FAST
@given(source=bvh_sources())
def test_bvh_round_trip_from_rotations(source):
    """A motion with a hierarchy and local rotations but no BVH of its own is written from them (ZYX Euler angles,
    position channels where a bone's vector changes) and reads back to the same positions in metres."""
    from mocapkit.datasets.formats.bvh import bvh_motion

    skeleton, values, frame_time, scale = source
    motion = replace(bvh_motion(skeleton, values, frame_time, scale), metadata={})
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "gen.bvh"
        _write(path, motion)
        back = _read(path, units="m")
    assert back.joint_names == motion.joint_names and back.parents == motion.parents
    assert back.fps == pytest.approx(motion.fps, rel=1e-12)
    # the writer checks its channels reproduce the positions to 1e-5 m; float32 positions on top
    extent = float(np.abs(motion.positions).max(initial=1.0))
    np.testing.assert_allclose(back.positions, motion.positions, rtol=0, atol=1e-5 + 2e-7 * extent)


def test_bvh_cannot_hold_gaps_and_says_so(tmp_path):
    from mocapkit.datasets.formats.bvh import BvhSkeleton, bvh_motion

    skeleton = BvhSkeleton(("hips",), (-1,), np.zeros((1, 3)), (("Xposition", "Yposition", "Zposition", "Zrotation"),))
    motion = bvh_motion(
        replace(skeleton, channels=(skeleton.channels[0] + ("Yrotation", "Xrotation"),)), np.zeros((3, 6)), 0.01, 1.0
    )
    positions = motion.positions.copy()
    positions[1] = np.nan
    with pytest.raises(ValueError, match="cannot hold missing"):
        _write(tmp_path / "gap.bvh", replace(motion, positions=positions, missing=None))


# --------------------------------------------------------------------------------------------------- ASF/AMC


@st.composite
def amc_sources(draw):
    """``(AsfSkeleton, per-bone AMC values)``: 1–6 bones on a random tree, random directions, lengths, axes and
    dofs (some bones fixed), angles in degrees, root translation in ASF units."""
    from mocapkit.datasets.formats.asf_amc import AsfBone, AsfSkeleton

    bones = draw(st.integers(1, 6), label="bones")
    names = draw(_names(bones).filter(lambda ns: "root" not in [n.lower() for n in ns]), label="bone names")
    rng = _seed_rng(draw)
    parents = _parents_depth_first(rng, bones + 1)[1:]  # joint 0 is the root
    hierarchy: dict[str, list[str]] = {}
    for b, p in enumerate(parents):
        hierarchy.setdefault("root" if p == 0 else names[p - 1], []).append(names[b])
    asf_bones = []
    for b in range(bones):
        direction = rng.normal(size=3)
        dof = tuple(d for d in ("rx", "ry", "rz") if rng.random() < 0.7)
        asf_bones.append(
            AsfBone(
                id=b + 1,
                name=names[b],
                direction=direction / np.linalg.norm(direction),
                length=float(rng.uniform(0.5, 8.0)),
                axis=rng.uniform(-90.0, 90.0, 3),
                axis_order=str(rng.choice(["XYZ", "ZYX", "XZY"])),
                dof=dof,
                limits=[(-np.inf, np.inf)] * len(dof),
            )
        )
    length = draw(st.sampled_from([0.45, 1.0, 0.1]), label="ASF length unit")
    skeleton = AsfSkeleton(
        name="gen",
        units={"mass": 1.0, "length": length, "angle": "deg"},
        bones=asf_bones,
        hierarchy=hierarchy,
    )
    frames = draw(st.integers(1, 20), label="frames")
    values = {"root": np.concatenate([rng.uniform(-50, 50, (frames, 3)), rng.uniform(-180, 180, (frames, 3))], 1)}
    for bone in asf_bones:
        if bone.dof:
            values[bone.name] = rng.uniform(-180.0, 180.0, (frames, len(bone.dof)))
    return skeleton, values


@FAST
@given(source=amc_sources())
def test_amc_round_trip(source):
    from mocapkit.datasets.formats.asf_amc import amc_motion, write_asf

    skeleton, values = source
    motion = amc_motion(skeleton, values, fps=120.0)
    with tempfile.TemporaryDirectory() as folder:
        write_asf(Path(folder) / "gen.asf", skeleton)
        path = Path(folder) / "gen_take.amc"
        _write(path, motion)
        back = _read(path)  # finds gen.asf beside it
    assert back.joint_names == motion.joint_names and back.parents == motion.parents
    assert back.fps == 120.0 and not back.missing.any()
    for bone, v in values.items():  # ten significant digits
        np.testing.assert_allclose(back.metadata["amc_values"][bone], v, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(back.positions, motion.positions, rtol=1e-6, atol=1e-6)


# --------------------------------------------------------------------------------------------------- corruptions


@st.composite
def clean_motions(draw, min_frames: int = 1):
    """Motions with some entries already missing (at least one observed)."""
    frames = draw(st.integers(min_frames, 80), label="frames")
    joints = draw(st.integers(1, 16), label="joints")
    rng = _seed_rng(draw)
    positions = rng.uniform(-2.0, 2.0, (frames, joints, 3)).astype(np.float32)
    missing = rng.random((frames, joints)) < draw(st.sampled_from([0.0, 0.1, 0.4]), label="missing rate")
    missing.flat[int(rng.integers(missing.size))] = False
    positions[missing] = np.nan
    return Motion(positions=positions, joint_names=tuple(f"m{j}" for j in range(joints)), fps=120.0, name="clean")


def _levels(protocol: str, motion: Motion):
    frames = motion.num_frames
    if protocol in ("rdcrypt", "rdloss", "mxcrypt", "missing_ratio", "random_missing"):
        return st.floats(0.01, 1.0)
    if protocol == "spikes":
        return st.floats(0.001, 0.25)
    if protocol == "continuous_missing":
        return st.integers(1, frames + 2)
    if protocol in ("rgloss", "long_gaps"):
        return st.builds(lambda n, length: f"{n}x{length}", st.integers(1, 12), st.integers(1, frames + 2))
    return st.builds(lambda n, length: f"{n}x{length}", st.integers(1, 4), st.integers(1, max(1, frames)))  # swaps


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
@settings(FAST, max_examples=30)
@given(data=st.data())
def test_corruption_masks_are_exactly_what_changed(protocol, data):
    from mocapkit.refinement.corruptions import CorruptionError, corrupt

    motion = data.draw(clean_motions(), label="motion")
    level = data.draw(_levels(protocol, motion), label="level")
    seed = data.draw(st.integers(0, 2**31 - 1), label="seed")
    try:
        result = corrupt(motion, protocol, level, seed=seed)
    except CorruptionError as exc:  # a motion too short (or too small) for the protocol: said, naming it
        assert "clean" in str(exc) and protocol in str(exc)
        event(f"{protocol}: refused")
        return
    event(f"{protocol}: applied")
    before, after = motion.missing, result.motion.missing
    removed, perturbed = result.removed, result.perturbed
    # removed: exactly the entries that became missing; perturbed: observed, not removed, and really moved
    assert not (removed & before).any() and not (perturbed & (before | removed)).any()
    np.testing.assert_array_equal(after, before | removed)
    assert np.isnan(result.motion.positions[removed]).all()
    moved = ~(result.motion.positions == motion.positions).all(axis=-1) & ~after
    np.testing.assert_array_equal(moved, perturbed)
    untouched = ~removed & ~perturbed
    np.testing.assert_array_equal(
        result.motion.positions[untouched].view(np.uint32), motion.positions[untouched].view(np.uint32)
    )
    observed = int((~before).sum())
    if protocol in ("rdloss", "missing_ratio", "mxcrypt"):
        assert removed.sum() == round(float(level) * observed)
    if protocol == "rdcrypt":
        assert perturbed.sum() == round(float(level) * observed) and not removed.any()
    if protocol == "random_missing":
        per_frame = round(float(level) * motion.num_joints)
        np.testing.assert_array_equal(removed.sum(1), np.minimum(per_frame, (~before).sum(1)))
    if result.gaps and protocol != "swaps":  # gaps: inside frames 1 … T−2, exactly the removed entries
        mask = np.zeros_like(removed)
        for joint, start, length in result.gaps:
            assert 1 <= start and start + length <= motion.num_frames - 1
            mask[start : start + length, joint] = True
        np.testing.assert_array_equal(removed, mask & ~before)
        per_joint: dict[int, list[tuple[int, int]]] = {}
        for joint, start, length in result.gaps:
            per_joint.setdefault(joint, []).append((start, start + length))
        for spans in per_joint.values():  # never overlapping or touching
            spans.sort()
            assert all(b0 > a1 for (_, a1), (b0, _) in zip(spans, spans[1:]))
    if protocol in ("spikes", "swaps"):
        assert not perturbed[[0, -1]].any() and not removed.any()
    # the same seed gives the same corruption
    again = corrupt(motion, protocol, level, seed=seed)
    np.testing.assert_array_equal(again.removed, removed)
    np.testing.assert_array_equal(again.motion.positions.view(np.uint32), result.motion.positions.view(np.uint32))


@FAST
@given(motion=clean_motions(min_frames=4), seed=st.integers(0, 2**31 - 1))
def test_training_corruption_masks(motion, seed):
    from mocapkit.refinement.corruptions import training_corruption

    result = training_corruption(motion, np.random.default_rng(seed), whole_joint_rate=0.5)
    before = motion.missing
    assert not (result.removed & before).any() and not (result.perturbed & (before | result.removed)).any()
    np.testing.assert_array_equal(result.motion.missing, before | result.removed)
    untouched = ~result.removed & ~result.perturbed
    np.testing.assert_array_equal(
        result.motion.positions[untouched].view(np.uint32), motion.positions[untouched].view(np.uint32)
    )
    moved = ~(result.motion.positions == motion.positions).all(axis=-1) & ~result.motion.missing
    np.testing.assert_array_equal(moved, result.perturbed)


# --------------------------------------------------------------------------------------------------- the gap rule


@FAST
@given(data=st.data())
def test_any_non_finite_coordinate_is_a_gap(data):
    """The one rule of arrays given to a Motion (what every reader and the npz inputs go through): an entry with
    any NaN or ±Inf coordinate is missing and all NaN; the others keep their bits; the caller's array is left."""
    frames, joints = data.draw(st.integers(1, 30)), data.draw(st.integers(1, 10))
    rng = _seed_rng(data.draw)
    positions = rng.uniform(-3.0, 3.0, (frames, joints, 3)).astype(np.float32)
    bad = rng.random(positions.shape) < data.draw(st.sampled_from([0.0, 0.05, 0.3]))
    positions[bad] = rng.choice(np.array([np.nan, np.inf, -np.inf], dtype=np.float32), size=int(bad.sum()))
    given_missing = rng.random((frames, joints)) < 0.1 if data.draw(st.booleans()) else None
    before = positions.copy()
    motion = Motion(positions=positions, joint_names=[f"m{j}" for j in range(joints)], fps=30.0, missing=given_missing)
    expected = bad.any(axis=-1) | (False if given_missing is None else given_missing)
    np.testing.assert_array_equal(motion.missing, expected)
    assert np.isnan(motion.positions[expected]).all()
    kept = ~expected
    np.testing.assert_array_equal(motion.positions[kept].view(np.uint32), before[kept].view(np.uint32))
    np.testing.assert_array_equal(positions.view(np.uint32), before.view(np.uint32))  # not written into
