"""``mocapkit refine IN OUT --method RUN.ckpt`` / ``--onnx FILE``: the trained refiners behind the refine command,
and C3D files whose point labels are the joints of a known layout (what ``refine`` writes for joint data).

A tiny bigru refiner (8 units, window 32, one epoch on synthetic CMU31 takes) is trained once for the module,
saved as a checkpoint and exported to ONNX; nothing here depends on files outside the test's folders (the
HDM05 AMC round trip is skipped without the shared data).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli import main
from mocapkit.datasets.formats.c3d import known_layout, read_c3d, write_c3d
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import CMU31, NTU25
from tests.refinement.test_refine_cli import error_line, refine
from tests.shared_data import SHARED, needs, tiny_bigru_refiner

AMC = SHARED / "data" / "hdm05_cuts11" / "mm" / "HDM_mm_squat1Reps_040_120.amc"
REPO = Path(__file__).resolve().parents[2]
WINDOW = 32
FRAMES = 200  # longer than the window: refined in overlapping windows
GAPS = {"lwrist": slice(50, 80), "rtibia": slice(120, 131), "head": slice(150, 152)}
LEADING = 3  # frames with every joint missing at the start: never invented


def synthetic_take(seed: int, frames: int, names=CMU31.joint_names, parents=CMU31.parents, group="a") -> Motion:
    """Smooth random trajectories about a body-sized rest pose (y up, 120 fps)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None, None] / 120.0
    base = np.asarray([0.0, 1.0, 0.0]) + rng.normal(0.0, 0.3, (len(names), 3))
    freq, phase = rng.uniform(0.3, 1.5, (1, len(names), 3)), rng.uniform(0, 6, (1, len(names), 3))
    positions = base[None] + 0.05 * np.sin(2 * np.pi * freq * t + phase)
    return Motion(
        positions=positions.astype(np.float32),
        joint_names=tuple(names),
        parents=parents,
        fps=120.0,
        up_axis="y",
        name=f"take{seed}",
        metadata={"group": group},
    )


def with_gaps(motion: Motion) -> Motion:
    positions = motion.positions.copy()
    for joint, frames in GAPS.items():
        positions[frames, motion.joint_names.index(joint)] = np.nan
    positions[:LEADING] = np.nan
    return Motion(
        positions=positions,
        joint_names=motion.joint_names,
        parents=motion.parents,
        fps=motion.fps,
        up_axis=motion.up_axis,
        name=motion.name,
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """``(checkpoint, onnx)`` of a tiny refiner trained on synthetic CMU31 takes."""
    motions = [synthetic_take(seed, 96) for seed in range(4)]
    return tiny_bigru_refiner(motions, tmp_path_factory.mktemp("refiner"), WINDOW, windows_per_epoch=64)


@pytest.fixture(scope="module")
def gappy(tmp_path_factory) -> Path:
    """A 200-frame CMU31 take as C3D (labels = joint names, y up) with interior gaps and 3 empty leading frames."""
    path = tmp_path_factory.mktemp("takes") / "gappy.c3d"
    write_c3d(path, with_gaps(synthetic_take(10, FRAMES)))
    return path


def gap_mask(names) -> np.ndarray:
    mask = np.zeros((FRAMES, len(names)), bool)
    for joint, frames in GAPS.items():
        mask[frames, list(names).index(joint)] = True
    return mask


# --------------------------------------------------------------------------- C3D labels of a known layout


def test_c3d_labels_of_a_layout_give_its_hierarchy(tmp_path):
    path = tmp_path / "cmu.c3d"
    write_c3d(path, synthetic_take(0, 10))
    motion = read_c3d(path)
    assert motion.layout_name == "cmu31" and motion.parents == CMU31.parents
    assert motion.joint_names == CMU31.joint_names

    order = np.random.default_rng(1).permutation(CMU31.num_joints)  # the same joints in another order
    names = tuple(CMU31.joint_names[i] for i in order)
    shuffled = synthetic_take(0, 10, names=names, parents=None)
    write_c3d(tmp_path / "shuffled.c3d", shuffled)
    motion = read_c3d(tmp_path / "shuffled.c3d")
    assert motion.joint_names == names and motion.layout_name == "cmu31"  # the file's order is kept
    for j, name in enumerate(names):
        parent = CMU31.parents[CMU31.index(name)]
        expected = -1 if parent < 0 else names.index(CMU31.joint_names[parent])
        assert motion.parents[j] == expected, name
    np.testing.assert_allclose(motion.positions, shuffled.positions, atol=1e-6)

    write_c3d(tmp_path / "ntu.c3d", synthetic_take(0, 10, names=NTU25.joint_names, parents=None))
    ntu = read_c3d(tmp_path / "ntu.c3d")
    assert ntu.layout_name == "ntu25" and ntu.parents == NTU25.parents

    # a superset, a subset or repeated names are marker sets, not the layout
    assert known_layout((*CMU31.joint_names, "extra")) == (None, None)
    assert known_layout(CMU31.joint_names[:-1]) == (None, None)
    assert known_layout((*CMU31.joint_names[:-1], "root")) == (None, None)
    write_c3d(tmp_path / "extra.c3d", synthetic_take(0, 10, names=(*CMU31.joint_names, "extra"), parents=None))
    extra = read_c3d(tmp_path / "extra.c3d")
    assert extra.parents is None and extra.layout_name is None


@needs(AMC)
def test_amc_written_as_c3d_reads_back_as_cmu31(tmp_path, capsys):
    from mocapkit.datasets.formats.motion_io import read_motion, write_motion

    amc = read_motion(AMC)
    write_motion(tmp_path / "squat.c3d", amc)
    back = read_motion(tmp_path / "squat.c3d")
    assert back.layout_name == "cmu31" and back.parents == CMU31.parents == amc.parents
    assert back.up_axis == "y" and back.fps == 120.0 and not back.missing.any()
    np.testing.assert_allclose(back.positions, amc.positions, atol=1e-6)

    rc, _, err = refine(capsys, AMC, tmp_path / "refined.c3d", "--method", "pchip")  # what refine writes
    assert rc == 0, err
    refined = read_c3d(tmp_path / "refined.c3d")
    assert refined.layout_name == "cmu31" and refined.parents == CMU31.parents


# --------------------------------------------------------------------------- refine with a checkpoint / ONNX


def test_checkpoint_and_onnx_fill_the_gaps_alike(trained, gappy, tmp_path, capsys):
    ckpt, onnx = trained
    source = read_c3d(gappy)
    gap = gap_mask(source.joint_names)
    assert np.array_equal(source.missing[LEADING:], gap[LEADING:]) and source.missing[:LEADING].all()

    outputs = {}
    for kind, argv in (("ckpt", ["--method", ckpt]), ("onnx", ["--onnx", onnx])):
        out = tmp_path / f"{kind}.c3d"
        rc, printed, err = refine(capsys, gappy, out, *argv)
        assert rc == 0, err
        name = "LearnedRefiner" if kind == "ckpt" else "OnnxRefiner"
        model = ckpt if kind == "ckpt" else onnx
        assert f"method {model} ({name})" in printed, printed
        assert re.search(r"^lwrist\s+filled 30 samples, longest gap 30 frames", printed, re.MULTILINE), printed
        assert re.search(r"^rtibia\s+filled 11 samples", printed, re.MULTILINE), printed
        assert f"0-{LEADING - 1} (leading)" in printed  # empty frames are not invented
        refined = read_c3d(out)
        assert refined.joint_names == source.joint_names and refined.layout_name == "cmu31"
        assert np.array_equal(refined.missing, source.missing & ~gap)  # every gap filled, the leading frames left
        observed = ~source.missing
        assert np.array_equal(refined.positions[observed], source.positions[observed])  # bit-identical
        assert np.isfinite(refined.positions[gap]).all()
        assert np.abs(refined.positions[gap]).max() < 5.0  # metres: a body, not garbage
        outputs[kind] = refined.positions

    np.testing.assert_allclose(outputs["onnx"][gap], outputs["ckpt"][gap], atol=1e-4, rtol=0)

    rc, _, err = refine(capsys, gappy, tmp_path / "ckpt.npz", "--method", ckpt)  # npz out too
    assert rc == 0, err
    with np.load(tmp_path / "ckpt.npz") as z:
        assert np.array_equal(z["filled"], gap)
        np.testing.assert_allclose(z["positions"][gap], outputs["ckpt"][gap], atol=1e-6)


def test_repair_outliers_changes_observed_samples_only_when_asked(trained, gappy, tmp_path, capsys):
    _, onnx = trained
    source = read_c3d(gappy)
    observed = ~source.missing
    rc, printed, err = refine(
        capsys, gappy, tmp_path / "repaired.c3d", "--onnx", onnx, "--repair-outliers", "--set", "repair_threshold=0.001"
    )
    assert rc == 0, err
    assert "repaired" in printed
    repaired = read_c3d(tmp_path / "repaired.c3d")
    moved = observed & (repaired.positions != source.positions).any(axis=2)
    assert moved.any() and not repaired.missing[LEADING:].any()

    rc, printed, err = refine(capsys, gappy, tmp_path / "kept.c3d", "--onnx", onnx, "--set", "repair_threshold=0.001")
    assert rc == 0, err
    assert "repaired" not in printed
    kept = read_c3d(tmp_path / "kept.c3d")
    assert np.array_equal(kept.positions[observed], source.positions[observed])


def test_screen_outliers_in_front_of_the_onnx_refiner_pulls_a_spike_back(trained, gappy, tmp_path, capsys):
    _, onnx = trained
    source = read_c3d(gappy)
    joint, frame = source.joint_names.index("lhumerus"), 150
    assert not source.missing[frame - 3 : frame + 4, joint].any()
    positions = source.positions.copy()
    positions[frame, joint] += [0.2, 0.0, 0.0]  # a 20 cm spike
    write_c3d(tmp_path / "spiky.c3d", replace(source, positions=positions))
    rc, printed, err = refine(capsys, tmp_path / "spiky.c3d", tmp_path / "out.c3d", "--onnx", onnx, "--screen-outliers")
    assert rc == 0, err
    assert "MedianScreen(OnnxRefiner)" in printed and "repaired" in printed
    out = read_c3d(tmp_path / "out.c3d")
    assert np.linalg.norm(out.positions[frame, joint] - source.positions[frame, joint]) < 0.05


def test_joints_in_another_order_with_an_extra_marker(trained, tmp_path, capsys):
    ckpt, _ = trained
    order = np.random.default_rng(2).permutation(CMU31.num_joints)
    names = (*[CMU31.joint_names[i] for i in order], "extra")
    take = synthetic_take(11, FRAMES, names=names, parents=None)
    positions = take.positions.copy()
    for joint, frames in GAPS.items():
        positions[frames, names.index(joint)] = np.nan
    positions[60:70, names.index("extra")] = np.nan
    write_c3d(tmp_path / "mixed.c3d", Motion(positions=positions, joint_names=names, fps=120.0, up_axis="y"))
    rc, printed, err = refine(
        capsys,
        tmp_path / "mixed.c3d",
        tmp_path / "out.c3d",
        "--method",
        ckpt,
        "--set",
        "window=48",
        "--set",
        "overlap=8",
        "--set",
        "max_empty_frames=0",
    )
    assert rc == 0, err
    out, source = read_c3d(tmp_path / "out.c3d"), read_c3d(tmp_path / "mixed.c3d")
    assert out.joint_names == names
    assert not out.missing[:, :-1].any()  # the trained joints: filled
    assert out.missing[60:70, -1].all()  # the extra marker: left as it was
    assert "interior, not filled by the method" in printed
    assert np.array_equal(out.positions[~source.missing], source.positions[~source.missing])


def test_onnx_path_never_imports_torch(trained, gappy, tmp_path):
    _, onnx = trained
    out = tmp_path / "no_torch.c3d"
    code = (
        "import sys\n"
        "from mocapkit.refinement.apply import refine_file\n"
        f"report = refine_file({str(gappy)!r}, {str(out)!r}, onnx={str(onnx)!r}, screen_outliers=True)\n"
        "assert report.filled > 0, report.to_text()\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'lightning'))\n"
        "assert not heavy, heavy[:5]\n"
        "print('ok', report.filled)\n"
    )
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=False, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("ok ") and out.is_file()


# --------------------------------------------------------------------------- errors


def test_unknown_or_bad_set_keys_fail_listing_the_parameters(trained, gappy, tmp_path, capsys):
    ckpt, onnx = trained
    out = tmp_path / "out.c3d"
    rc, _, err = refine(capsys, gappy, out, "--method", ckpt, "--set", "rank=4")
    line = error_line(err)
    assert rc == 2 and "no parameter 'rank'" in line and str(ckpt) in line
    for key in ("window", "overlap", "repair_threshold", "max_empty_frames"):
        assert key in line, line
    rc, _, err = refine(capsys, gappy, out, "--onnx", onnx, "--set", "hidden=4")
    assert rc == 2 and "OnnxRefiner" in error_line(err) and "repair_threshold" in err
    for setting in ("_target_=builtins.open", "+refiner._target_=builtins.open", "refiner.checkpoint=/etc/passwd"):
        rc, _, err = refine(capsys, gappy, out, "--method", ckpt, "--set", setting)  # only the listed keys
        assert rc == 2 and "has no parameter" in error_line(err), setting
    rc, _, err = refine(capsys, gappy, out, "--method", ckpt, "--set", "window=abc")
    assert rc == 2 and "window must be an integer" in error_line(err) and "'abc'" in error_line(err)
    rc, _, err = refine(capsys, gappy, out, "--onnx", onnx, "--set", "overlap=40", "--set", "window=32")
    assert rc == 2 and "overlap=40" in error_line(err)
    rc, _, err = refine(capsys, gappy, out, "--method", ckpt, "--train", gappy)
    assert rc == 2 and "--train" in error_line(err) and "trained refiner" in err
    rc, _, err = refine(capsys, gappy, out, "--method", tmp_path / "absent.ckpt")
    assert rc == 2 and "absent.ckpt" in error_line(err)
    with pytest.raises(SystemExit):  # argparse: one of --method / --onnx
        main(["refine", str(gappy), str(out), "--method", "linear", "--onnx", str(onnx)])
    capsys.readouterr()
    assert not out.exists()


def test_another_layout_fails_naming_the_missing_joints(trained, tmp_path, capsys):
    ckpt, onnx = trained
    take = synthetic_take(12, 80, names=NTU25.joint_names, parents=None)
    positions = take.positions.copy()
    positions[20:30, 5] = np.nan
    path = tmp_path / "ntu.c3d"
    write_c3d(path, Motion(positions=positions, joint_names=take.joint_names, fps=120.0, up_axis="y"))
    assert read_c3d(path).layout_name == "ntu25"
    for argv in (["--method", ckpt], ["--onnx", onnx]):
        rc, _, err = refine(capsys, path, tmp_path / "out.c3d", *argv)
        line = error_line(err)
        assert rc == 2 and "ntu.c3d" in line and "missing joints" in line, line
        assert "'root'" in line and "'lhipjoint'" in line, line
    assert not (tmp_path / "out.c3d").exists()

    # the right joints in another up axis are turned to the model's and back
    # (tests/refinement/test_learned_frames.py checks the values)
    take = with_gaps(synthetic_take(13, 80))
    write_c3d(
        tmp_path / "zup.c3d", Motion(positions=take.positions, joint_names=take.joint_names, fps=120.0, up_axis="z")
    )
    rc, _, err = refine(capsys, tmp_path / "zup.c3d", tmp_path / "out.c3d", "--onnx", onnx)
    assert rc == 0, err
    assert read_c3d(tmp_path / "out.c3d").up_axis == "z"


def test_a_take_at_another_frame_rate_is_refined_at_the_model_rate_and_brought_back(trained, tmp_path, capsys):
    from mocapkit.refinement.learned import OnnxRefiner

    _, onnx = trained
    slow = with_gaps(synthetic_take(13, FRAMES))  # 120 fps, the network's rate
    fast = slow.resample(240.0)  # the same take at 240 fps (gaps included)
    refiner = OnnxRefiner(str(onnx)).fit()
    at_120, at_240 = refiner.refine(slow), refiner.refine(fast)
    assert at_240.metadata["refinement"]["resampled"]["refined_at_fps"] == 120.0
    # every second 240 fps frame is a 120 fps frame: its filled samples are the network's at 120 fps; the frames
    # between are the mean of their neighbours; observed samples come back bit-identical
    even = fast.missing[::2]
    np.testing.assert_allclose(at_240.positions[::2][even], at_120.positions[even], atol=1e-6)
    odd = fast.missing[1:-1:2] & ~at_240.missing[1:-1:2]
    np.testing.assert_allclose(
        at_240.positions[1:-1:2][odd], 0.5 * (at_120.positions[:-1] + at_120.positions[1:])[odd], atol=1e-6
    )
    np.testing.assert_array_equal(at_240.positions[~fast.missing], fast.positions[~fast.missing])
    assert at_240.missing[: 2 * LEADING].all() and not at_240.missing[2 * LEADING :].any()

    path = tmp_path / "fast.c3d"
    write_c3d(path, fast)
    rc, out, _ = refine(capsys, path, tmp_path / "out.c3d", "--onnx", onnx)
    assert rc == 0 and "refined at the model's 120 fps" in out and "240 fps frames" in out
    written = read_c3d(tmp_path / "out.c3d")
    assert written.fps == 240.0 and not written.missing[2 * LEADING :].any()
    observed = ~read_c3d(path).missing
    np.testing.assert_array_equal(written.positions[observed], read_c3d(path).positions[observed])


def test_weights_of_another_network_version_fail_naming_the_keys(trained, gappy, tmp_path, capsys):
    """A run saved by an earlier version of the network (here: the BiGRU before its LayerNorm) fails with one line
    naming the checkpoint and the keys that do not match, not torch's bare "Error(s) in loading state_dict"."""
    import torch

    ckpt, _ = trained
    checkpoint = torch.load(ckpt, map_location="cpu", weights_only=True)
    checkpoint["state_dict"] = {k: v for k, v in checkpoint["state_dict"].items() if not k.startswith("model.inp.1.")}
    old = tmp_path / "old_version.ckpt"
    torch.save(checkpoint, old)
    rc, _, err = refine(capsys, gappy, tmp_path / "out.c3d", "--method", old)
    line = error_line(err)
    assert rc == 2 and "old_version.ckpt" in line and "another network version" in line, line
    assert "model.inp.1.weight" in line and "model.inp.1.bias" in line, line
    assert not (tmp_path / "out.c3d").exists()


@needs(SHARED / "data" / "hdm05_cuts11")
def test_profile_script_splits_the_time_by_operator_part_and_node(trained, capsys):
    """bench/profile_refiner_onnx.py on an exported refiner: the three tables, the GRU as its own part."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "bench" / "profile_refiner_onnx.py"
    spec = importlib.util.spec_from_file_location("profile_refiner_onnx", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    _, onnx = trained
    script.main(
        [str(onnx), "--frames", "120", "--clips", "2", "--runs", "3", "--top", "3", "--data", str(SHARED / "data")]
    )
    out = capsys.readouterr().out
    operators = out.split("per operator type")[1].split("per part of the network")[0]
    parts = out.split("per part of the network")[1].split("slowest 3 nodes")[0]
    nodes = out.split("slowest 3 nodes")[1].strip().splitlines()
    assert "GRU" in operators and any(line.split()[-1] == "gru" for line in parts.strip().splitlines()[1:])
    assert len(nodes) == 4 and "session.run without the profiler" in out
