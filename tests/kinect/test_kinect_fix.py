"""``mocapkit kinect-fix``'s library: training on simulated pairs of real mocap, saving and loading the model,
correcting real MSR Action3D Kinect files (the all-zero one refused or reported), wild input (missing joints),
and the Kinect SDK smoothing baseline."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.kinect.kinect_fix import (
    KinectFixError,
    fix_kinect_files,
    kinect_clip,
    train_kinect_model,
)
from mocapkit.kinect.reconstruction import DoubleExponentialSmoother, KinectPostureReconstructor
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import LANDMARK_NAMES, MSR20, find_landmarks
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
MSR = SHARED / "data" / "msr_action3d"
TINY = {"gp_iterations": 3, "n_inducing": 20, "max_train_frames": 400}


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    if not HDM05.is_dir():
        pytest.skip(f"{HDM05} is absent")
    out = tmp_path_factory.mktemp("kinect_model") / "model.npz"
    report = train_kinect_model(
        sorted((HDM05 / "bd").glob("*.amc"))[:4], out, method="gp", overrides=[f"{k}={v}" for k, v in TINY.items()]
    )
    assert report["files"] == 4 and report["frames"] > 100 and not report["skipped"]
    return out


@needs(HDM05)
def test_saved_model_predicts_exactly_as_the_fitted_one(tmp_path):
    from mocapkit.datasets.synthetic.kinect_noise import simulate_pairs

    pairs, _ = simulate_pairs(sorted((HDM05 / "bk").glob("*.amc"))[:3], seed=0)
    model = KinectPostureReconstructor(**TINY).fit([p.noisy for p in pairs[:2]], [p.clean for p in pairs[:2]])
    loaded = KinectPostureReconstructor.load(model.save(tmp_path / "sub" / "model.npz"))
    assert loaded.get_params() == model.get_params() and loaded.n_train_frames_ == model.n_train_frames_
    test = pairs[2]
    np.testing.assert_array_equal(
        model.predict(test.noisy, state=test.state), loaded.predict(test.noisy, state=test.state)
    )


def test_a_file_that_is_not_a_model_is_named(tmp_path):
    bad = tmp_path / "notes.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(ValueError, match="notes.npz"):
        KinectPostureReconstructor.load(bad)


@needs(MSR)
def test_msr_files_are_corrected_and_the_all_zero_file_is_refused_or_reported(model_path, tmp_path):
    good = [MSR / "a01_s01_e01_skeleton3D.txt", MSR / "a02_s03_e01_skeleton3D.txt"]
    empty = MSR / "a13_s09_e02_skeleton3D.txt"
    with pytest.raises(KinectFixError, match="a13_s09_e02"):
        fix_kinect_files(model_path, [empty, *good], tmp_path / "strict")
    report = fix_kinect_files(model_path, [empty, *good], tmp_path / "out", skip_bad=True, plot=1)
    assert [Path(s[0]).name for s in report.skipped] == [empty.name]
    assert len(report.fixed) == 2 and report.frames_per_s > 0
    saved = json.loads((tmp_path / "out" / "report.json").read_text())
    assert saved["skipped"][0][0] == str(empty)
    for entry in saved["fixed"]:
        motion = read_motion(entry["output"])
        source = read_motion(entry["input"])
        assert motion.layout_name == "msr20" and motion.fps == 30.0 and source.fps == 15.0
        assert abs(motion.num_frames - 2 * source.num_frames) <= 2  # 15 → 30 fps over the same duration
        assert np.isfinite(motion.positions).all()
        # corrections are offsets of centimetres, not a different motion
        raw, _, _ = kinect_clip(source.resample(30.0))
        where = find_landmarks(motion.joint_names, motion.layout_name)
        fixed = motion.positions[:, [where[n] for n in LANDMARK_NAMES]]
        assert 0.001 < np.linalg.norm(fixed - raw, axis=-1).mean() < 0.2
    assert (tmp_path / "out" / "a01_s01_e01_skeleton3D_before_after.png").stat().st_size > 0
    assert "skipped" in report.to_text() and "a13_s09_e02" in report.to_text()


def test_missing_joints_are_filled_marked_not_tracked_and_counted():
    t = np.linspace(0, 1, 12)
    positions = np.zeros((12, 20, 3), dtype=np.float32)
    rng = np.random.default_rng(1)
    positions[:] = rng.normal(size=(20, 3)) * 0.3
    positions[:, :, 0] += t[:, None]  # everyone walks 1 m along x
    missing = np.zeros((12, 20), dtype=bool)
    missing[4:7, 5] = True
    positions[missing] = np.nan
    motion = Motion(
        positions=positions,
        joint_names=MSR20.joint_names,
        parents=MSR20.parents,
        fps=30.0,
        missing=missing,
        layout_name="msr20",
        name="gappy",
    )
    clip, state, filled = kinect_clip(motion)
    assert filled == 3 and np.isfinite(clip).all()
    assert (state == 0).sum() == 3 and (state == 2).sum() == 12 * 20 - 3
    k = int(np.flatnonzero((state == 0).any(axis=0))[0])
    np.testing.assert_allclose(clip[4:7, k, 0] - clip[3, k, 0], (t[4:7] - t[3]), atol=1e-5)  # linear in time
    every = motion.positions.copy()
    every[:, 5] = np.nan
    with pytest.raises(KinectFixError, match="gappy.*missing in every frame"):
        kinect_clip(
            Motion(
                positions=every,
                joint_names=MSR20.joint_names,
                parents=MSR20.parents,
                fps=30.0,
                layout_name="msr20",
                name="gappy",
            )
        )


def test_sdk_smoother_keeps_still_joints_bounds_deviation_and_reduces_noise():
    rng = np.random.default_rng(0)
    still = np.repeat(rng.normal(size=(1, 20, 3)), 50, axis=0)
    np.testing.assert_allclose(DoubleExponentialSmoother().fit([still]).predict(still), still, atol=1e-12)
    noisy = still + rng.normal(scale=0.01, size=still.shape)
    smoother = DoubleExponentialSmoother(smoothing=0.75, jitter_radius=0.05, max_deviation=0.04)
    out = smoother.predict(noisy)
    assert np.linalg.norm(out - noisy, axis=-1).max() <= 0.04 + 1e-9
    assert np.linalg.norm(out - still, axis=-1)[5:].mean() < 0.6 * np.linalg.norm(noisy - still, axis=-1)[5:].mean()
    with pytest.raises(ValueError, match="smoothing"):
        DoubleExponentialSmoother(smoothing=1.5).fit([still])


@needs(MSR)
def test_cli_trains_and_applies_and_names_the_bad_file(tmp_path, capsys):
    from mocapkit.cli import main

    model = tmp_path / "m.npz"
    clips = [str(p) for p in sorted((HDM05 / "dg").glob("*.amc"))[:3]]
    tiny = ["--method", "gp", "--set", "gp_iterations=2", "--set", "n_inducing=10", "--set", "max_train_frames=200"]
    assert main(["kinect-fix", "train", "--mocap", *clips, "--out", str(model), *tiny]) == 0
    # without --noise: the default calibration, real_sensor
    assert "noise real_sensor" in (printed := capsys.readouterr().out) and "written to" in printed and model.is_file()
    assert (
        main(
            [
                "kinect-fix",
                "train",
                *clips,
                "--out",
                str(tmp_path / "s.npz"),  # inputs positional
                "--noise",
                "msr_steadiness",
                *tiny,
            ]
        )
        == 0
    )
    assert "noise msr_steadiness" in capsys.readouterr().out
    assert main(["kinect-fix", "train", "--mocap", *clips, "--out", str(tmp_path / "x.npz"), "--noise", "loud"]) == 2
    assert "--noise loud" in capsys.readouterr().err
    good, empty = MSR / "a05_s02_e01_skeleton3D.txt", MSR / "a13_s09_e02_skeleton3D.txt"
    assert (
        main(
            [
                "kinect-fix",
                "apply",
                str(good),
                "--model",
                str(model),
                "--out",
                str(tmp_path / "o"),
                "--set",
                "energy_unit=0.1",
            ]
        )
        == 0
    )
    assert "corrected 1 file" in capsys.readouterr().out and (tmp_path / "o" / f"{good.stem}.c3d").is_file()
    assert main(["kinect-fix", "apply", str(empty), "--model", str(model), "--out", str(tmp_path / "p")]) == 2
    assert "a13_s09_e02" in capsys.readouterr().err
    assert (
        main(
            [
                "kinect-fix",
                "apply",
                str(good),
                "--model",
                str(model),
                "--out",
                str(tmp_path / "q"),
                "--set",
                "w_banana=1",
            ]
        )
        == 2
    )
    assert "w_banana" in capsys.readouterr().err


@needs(MSR)
def test_cli_trains_a_learned_corrector_and_applies_it_to_real_kinect_files(tmp_path, capsys):
    from mocapkit.cli import main
    from mocapkit.kinect.learned import LearnedKinectCorrector

    model = tmp_path / "bigru.pt"
    clips = [str(p) for p in sorted((HDM05 / "dg").glob("*.amc"))[:3]]
    tiny = ["--set", "steps=3", "--set", "window=16", "--set", "network={hidden: 16}"]
    assert main(["kinect-fix", "train", "--mocap", *clips, "--out", str(model), "--method", "bigru", *tiny]) == 0
    assert "(bigru)" in capsys.readouterr().out and model.is_file()
    assert LearnedKinectCorrector.load(model).get_params()["network"] == {"hidden": 16}
    assert (
        main(
            [
                "kinect-fix",
                "train",
                "--mocap",
                *clips,
                "--out",
                str(tmp_path / "x.pt"),
                "--method",
                "bigru",
                "--set",
                "gp_iterations=2",
            ]
        )
        == 2
    )
    assert "gp_iterations" in capsys.readouterr().err
    good = MSR / "a05_s02_e01_skeleton3D.txt"
    assert (
        main(
            [
                "kinect-fix",
                "apply",
                str(good),
                "--model",
                str(model),
                "--out",
                str(tmp_path / "o"),
                "--set",
                "inference_window=32",
            ]
        )
        == 0
    )
    assert "corrected 1 file" in capsys.readouterr().out
    fixed = read_motion(tmp_path / "o" / f"{good.stem}.c3d")
    assert fixed.positions.shape[1:] == (20, 3) and np.isfinite(fixed.positions).all()
    assert (
        main(["kinect-fix", "apply", str(good), "--model", str(tmp_path / "absent.pt"), "--out", str(tmp_path / "p")])
        == 2
    )
    assert "absent.pt: no such file" in capsys.readouterr().err


@needs(MSR)
def test_cli_exports_a_learned_corrector_to_onnx_and_applies_it(tmp_path, capsys):
    from mocapkit.cli import main

    model, onnx_file = tmp_path / "bigru.pt", tmp_path / "bigru.onnx"
    clips = [str(p) for p in sorted((HDM05 / "dg").glob("*.amc"))[:2]]
    tiny = ["--set", "steps=3", "--set", "window=16", "--set", "network={hidden: 16}"]
    assert main(["kinect-fix", "train", "--mocap", *clips, "--out", str(model), "--method", "bigru", *tiny]) == 0
    assert main(["kinect-fix", "export", "--model", str(model), "--out", str(onnx_file)]) == 0
    assert "ONNX Kinect corrector written" in capsys.readouterr().out and onnx_file.is_file()
    good = MSR / "a05_s02_e01_skeleton3D.txt"
    for name, path in (("pt", model), ("onnx", onnx_file)):
        assert main(["kinect-fix", "apply", str(good), "--model", str(path), "--out", str(tmp_path / name)]) == 0
    capsys.readouterr()
    eager, exported = (read_motion(tmp_path / name / f"{good.stem}.c3d").positions for name in ("pt", "onnx"))
    np.testing.assert_allclose(exported, eager, atol=2e-3)  # C3D stores mm as float32: a rounding below 1 mm
    gp = tmp_path / "gp.npz"
    gp.write_bytes(b"")
    assert main(["kinect-fix", "export", "--model", str(gp), "--out", str(tmp_path / "gp.onnx")]) == 2
    assert "gp.npz: a GP reconstructor (.npz) has no network to export" in capsys.readouterr().err
    assert main(["kinect-fix", "export", "--model", str(onnx_file), "--out", str(tmp_path / "again.onnx")]) == 2
    assert "already an ONNX export" in capsys.readouterr().err
