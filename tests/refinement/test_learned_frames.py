"""Learned refiners on takes in another frame than the one they were fitted in (issue 42, part 4).

A tiny BiGRU refiner is trained on y-up HDM05 takes at 120 fps (real ASF/AMC from ``../shared``; skipped without
them). The same unseen take, turned to z-up and cut with gaps longer than the short-gap spline's (so the network
fills them), goes through ``LearnedRefiner`` / ``OnnxRefiner`` and through ``mocapkit refine`` as a z-up C3D (the
lab convention) in millimetres: every gap is filled, observed samples come back bit-identical, and the filled values
are those the model gives on the y-up original, turned the same way. At another frame rate as well, the take is
turned and resampled.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import turn_up_axis
from tests.refinement.test_refine_cli import refine
from tests.shared_data import SHARED, needs, tiny_bigru_refiner

HDM05 = SHARED / "data" / "hdm05_cuts11"
TRAIN = [HDM05 / "mm" / f"HDM_mm_{name}_120.amc" for name in ("squat1Reps_040", "depositFloorR_019")]
TAKE = HDM05 / "bd" / "HDM_bd_depositFloorR_001_120.amc"
WINDOW = 32
FRAMES = 200
#: joint → frames missing; 40 frames is longer than the short-gap spline's 24, so the network fills them
GAPS = {"lwrist": slice(40, 80), "rtibia": slice(100, 140), "head": slice(150, 190)}

pytestmark = needs(TAKE)


def _read(path) -> Motion:
    from mocapkit.datasets.formats.motion_io import read_motion

    return read_motion(path)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """``(checkpoint, onnx)`` of a tiny BiGRU refiner trained on y-up HDM05 takes at 120 fps."""
    motions = [replace(_read(p), metadata={"group": "mm"}, rotations=None) for p in TRAIN]
    assert {m.up_axis for m in motions} == {"y"} and {m.fps for m in motions} == {120.0}
    return tiny_bigru_refiner(motions, tmp_path_factory.mktemp("refiner"), WINDOW, windows_per_epoch=32)


@pytest.fixture(scope="module")
def take() -> Motion:
    """The unseen take (another performer), y-up, 120 fps, with :data:`GAPS` cut as NaN."""
    motion = _read(TAKE)
    positions = motion.positions[:FRAMES].copy()
    for joint, frames in GAPS.items():
        positions[frames, motion.joint_names.index(joint)] = np.nan
    return Motion(
        positions=positions,
        joint_names=motion.joint_names,
        parents=motion.parents,
        fps=motion.fps,
        up_axis="y",
        name="take",
        layout_name=motion.layout_name,
    )


def z_up(motion: Motion) -> Motion:
    return replace(motion, positions=turn_up_axis(motion.positions, "y", "z"), up_axis="z", rotations=None)


def _refiners(trained):
    from mocapkit.refinement.learned import LearnedRefiner, OnnxRefiner

    ckpt, onnx = trained
    return {"ckpt": LearnedRefiner(checkpoint=str(ckpt)).fit(), "onnx": OnnxRefiner(str(onnx)).fit()}


def test_z_up_take_into_a_y_up_model_is_turned_and_turned_back(trained, take):
    wild = z_up(take)
    assert not np.array_equal(wild.positions, take.positions, equal_nan=True)
    for kind, refiner in _refiners(trained).items():
        assert refiner.up_axis_ == "y" and refiner.fps_ == 120.0
        reference = refiner.refine(take)  # the model in its own frame
        done = refiner.refine(wild)
        assert done.up_axis == "z" and not done.missing.any(), kind  # every gap filled
        # the network saw the same numbers as in its own frame: the same bits come out, turned
        expected = turn_up_axis(reference.positions, "y", "z")
        assert np.array_equal(done.positions.view(np.uint32), expected.view(np.uint32)), kind
        # observed samples the network does not repair (moves by more than repair_threshold) keep their bits
        kept = ~wild.missing & (reference.positions == take.positions).all(axis=-1)
        assert kept.sum() > 0.9 * (~wild.missing).sum()
        assert np.array_equal(done.positions[kept].view(np.uint32), wild.positions[kept].view(np.uint32))
        report, own = done.metadata["refinement"], reference.metadata["refinement"]
        assert report["turned"] == {"up_axis": "z", "refined_at_up_axis": "y"}
        assert report["filled"] == int(wild.missing.sum()) and report["repaired"] == own["repaired"]

        # the turn matters: the same numbers refined as if y were up fill the gaps elsewhere
        mislabelled = refiner.refine(replace(wild, up_axis="y"))
        gap = wild.missing
        assert np.abs(mislabelled.positions[gap] - done.positions[gap]).max() > 0.005, kind


def test_z_up_take_at_another_rate_is_turned_and_resampled(trained, take):
    refiner = _refiners(trained)["ckpt"]
    half = replace(z_up(take), positions=z_up(take).positions[::2], missing=take.missing[::2], fps=60.0)
    done = refiner.refine(half)
    report = done.metadata["refinement"]
    assert report["turned"]["refined_at_up_axis"] == "y" and report["resampled"]["refined_at_fps"] == 120.0
    assert done.fps == 60.0 and done.up_axis == "z" and not done.missing.any()
    observed = ~half.missing  # not repaired on the resampled path: every observed sample keeps its bits
    assert np.array_equal(done.positions[observed].view(np.uint32), half.positions[observed].view(np.uint32))
    # the same take in the model's frame at 60 fps: the turn commutes with the resampling
    y_half = refiner.refine(replace(take, positions=take.positions[::2], missing=take.missing[::2], fps=60.0))
    np.testing.assert_allclose(done.positions, turn_up_axis(y_half.positions, "y", "z"), atol=1e-6)


def test_refine_command_fills_a_z_up_c3d_in_mm(trained, take, tmp_path, capsys):
    from mocapkit.datasets.formats.c3d import read_c3d, write_c3d

    ckpt, onnx = trained
    source = tmp_path / "lab.c3d"
    write_c3d(source, z_up(take), units="mm")  # POINT:Y_SCREEN +Z: read as z-up, as Vicon and Qualisys files
    given = read_c3d(source)
    assert given.up_axis == "z" and given.source_units == "mm"
    assert np.array_equal(given.missing, take.missing)
    references = {kind: r.refine(take) for kind, r in _refiners(trained).items()}
    for kind, argv in (("ckpt", ["--method", ckpt]), ("onnx", ["--onnx", onnx])):
        out = tmp_path / f"{kind}.c3d"
        rc, printed, err = refine(capsys, source, out, *argv)
        assert rc == 0, err
        refined = read_c3d(out)
        assert refined.up_axis == "z" and not refined.missing.any(), printed  # every gap filled
        assert "refined in the model's y-up frame: the z-up take turned there and back" in printed
        observed = ~given.missing
        assert np.array_equal(refined.positions[observed].view(np.uint32), given.positions[observed].view(np.uint32)), (
            kind
        )
        expected = turn_up_axis(references[kind].positions, "y", "z")
        gap = given.missing
        # the file's millimetres in float32 move the model's input by about 1e-7 m
        np.testing.assert_allclose(refined.positions[gap], expected[gap], atol=1e-4)
