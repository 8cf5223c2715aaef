"""The Kinect reconstruction benchmark through the one comparison runner: held-out performers, selection on the
training performers only, one fit shared by the prediction-parameter variants, the report (real HDM05 cuts)."""

from __future__ import annotations

import importlib
import json

import pytest
from omegaconf import open_dict

from mocapkit.evaluation.compare import ComparisonError, compose, run_comparison
from mocapkit.kinect.benchmark import KinectReconstructionBenchmark
from mocapkit.kinect.reconstruction import KinectPostureReconstructor
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
#: ``(performers fitted on, number of clips)`` of every ``RecordingReconstructor.fit`` in this process.
FITS: list[tuple[set, int]] = []


def recorded_fits() -> list[tuple[set, int]]:
    return importlib.import_module("tests.kinect.test_compare_kinect").FITS


class RecordingReconstructor(KinectPostureReconstructor):
    """Zhou's reconstructor recording how many clips (and frames) each fit saw."""

    def fit(self, kinect_clips, mocap_clips, states=None):
        FITS.append((len(kinect_clips), sum(len(k) for k in kinect_clips)))
        return super().fit(kinect_clips, mocap_clips, states)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("kinect_quick")
    cfg = compose(
        [
            "kinect_hdm05",
            f"out={out}",
            f"benchmark.root={HDM05}",
            "benchmark.clips_per_group=3",
            "protocols=[mm]",
            "seeds=[0]",
            "only=[sdk_filter,forest,zhou,zhou_ST,zhou_S]",
        ]
    )
    tiny = {
        "_target_": "tests.kinect.test_compare_kinect.RecordingReconstructor",
        "gp_iterations": 3,
        "n_inducing": 20,
        "max_train_frames": 400,
    }
    with open_dict(cfg):
        for key in ("zhou", "zhou_ST", "zhou_S"):
            cfg.methods[key].estimator = dict(tiny)
        cfg.methods.forest.estimator.n_estimators = 5
        cfg.methods.sdk_filter.select = {"stages": [{"smoothing": [0.0, 0.5]}], "cv": 3}
        cfg.methods.zhou_ST.select = {"stages": [{"energy_unit": [1.0, 0.01]}], "cv": 3}
    recorded_fits().clear()
    results = run_comparison(cfg)
    return out, results


@needs(HDM05)
def test_cells_metrics_and_report(quick):
    out, _ = quick
    saved = json.loads((out / "results.json").read_text())
    cells = {c["method"]: c for c in saved["cells"]}
    assert set(cells) == {"sdk_filter", "forest", "zhou", "zhou_ST", "zhou_S"}
    raw = {c["metrics"]["raw_cm"] for c in cells.values()}
    assert len(raw) == 1 and 5.0 < raw.pop() < 30.0  # one simulated test set for every method
    for c in cells.values():
        m = c["metrics"]
        assert m["reduction"] == pytest.approx(1 - m["error_cm"] / m["raw_cm"])
        assert m["frames_per_s"] > 0 and len(c["detail"]["per_joint_cm"]) == 20
    assert cells["zhou"]["detail"]["n_test_frames"] == cells["forest"]["detail"]["n_test_frames"]
    assert saved["selection"]["zhou_ST"]["mm"]["params"]["energy_unit"] in (1.0, 0.01)
    assert (out / "per_joint_error.png").stat().st_size > 0
    assert "Over all held-out performers" in (out / "results.md").read_text()


@needs(HDM05)
def test_selection_never_fits_on_the_held_out_performer_and_fits_are_shared(quick):
    fits = recorded_fits()
    # 3 clips per performer: the outer fit sees 9 clips (bd, bk, dg), each inner fit 6 (two of them); never 12.
    assert sorted({n for n, _ in fits}) == [6, 9]
    # zhou, zhou_S and zhou_ST share the fit-relevant parameters: one outer fit, three inner fits, in all.
    assert sum(n == 9 for n, _ in fits) == 1 and sum(n == 6 for n, _ in fits) == 3


@needs(HDM05)
def test_unknown_held_out_performer_is_named(tmp_path):
    with pytest.raises(ComparisonError, match="xx"):
        KinectReconstructionBenchmark(str(HDM05), protocols=["xx"], clips_per_group=1)
    with pytest.raises(ComparisonError, match="no motion files"):
        KinectReconstructionBenchmark(str(tmp_path))


@needs(HDM05)
def test_noise_preset_is_a_benchmark_option():
    from mocapkit.datasets.synthetic.kinect_noise import (
        KinectNoiseConfig,
        file_seed,
        simulate_kinect,
    )

    with pytest.raises(ComparisonError, match="benchmark.noise='loud'"):
        KinectReconstructionBenchmark(str(HDM05), clips_per_group=1, noise="loud")
    bench = KinectReconstructionBenchmark(str(HDM05), clips_per_group=1, noise="msr_steadiness")
    assert bench.describe()["noise"] == "msr_steadiness"
    pair = bench.pairs(0)[0]
    expected, _ = simulate_kinect(
        pair.clean, KinectNoiseConfig.preset("msr_steadiness"), seed=file_seed(0, pair.path), fps=30.0
    )
    assert (pair.noisy == expected).all()


BANDAI = SHARED / "data" / "bandai_motion_1"


@needs(HDM05)
@needs(BANDAI)
def test_another_data_set_is_scored_by_models_of_every_performer(tmp_path):
    bench = KinectReconstructionBenchmark(
        str(HDM05), protocols=["bd", "bandai"], clips_per_group=2, transfer_root=str(BANDAI), transfer_name="bandai"
    )
    groups = bench.groups
    transfer = bench.split("bandai", 0)
    assert set(groups[transfer.test]) == {"bandai"} and len(transfer.test) == 2
    assert set(groups[transfer.train]) == {"bd", "bk", "dg", "mm"}  # every performer, no Bandai take
    held_out = bench.split("bd", 0)
    assert set(groups[held_out.train]) == {"bk", "dg", "mm"}  # Bandai never trains a fold
    assert all(str(bench.files[i]).endswith(".bvh") for i in transfer.test)
    kinect, mocap = bench.data(transfer.test, 0)
    assert kinect[0].shape[1:] == (20, 3) and mocap[0].shape == kinect[0].shape
    with pytest.raises(ComparisonError, match="transfer_name='bd' is a performer folder"):
        KinectReconstructionBenchmark(str(HDM05), clips_per_group=1, transfer_root=str(BANDAI), transfer_name="bd")
    cfg = compose(
        [
            "kinect_hdm05",
            f"out={tmp_path}",
            f"benchmark.root={HDM05}",
            "benchmark.clips_per_group=2",
            f"+benchmark.transfer_root={BANDAI}",
            "+benchmark.transfer_name=bandai",
            "benchmark.protocols=[bd,bandai]",
            "seeds=[0]",
            "only=[forest]",
        ]
    )
    with open_dict(cfg):
        cfg.methods.forest.estimator.n_estimators = 5
    run_comparison(cfg)
    report = (tmp_path / "results.md").read_text()
    assert "Over all held-out performers" in report and "Another data set: `bandai`" in report
    assert (tmp_path / "per_joint_error_bandai.png").stat().st_size > 0


@needs(HDM05)
@needs(SHARED / "data" / "msr_action3d")
@needs(SHARED / "samples" / "ntu_skeleton")
def test_real_inputs_report_the_proxies_of_each_fitted_model():
    from mocapkit.kinect.reconstruction import DoubleExponentialSmoother

    bench = KinectReconstructionBenchmark(
        str(HDM05),
        protocols=["mm"],
        clips_per_group=2,
        real_inputs=[str(SHARED / "data" / "msr_action3d"), str(SHARED / "samples" / "ntu_skeleton")],
        real_max_files=4,
    )
    assert len(bench.real_clips()) == 8  # 4 MSR files and 4 of the 5 NTU samples, read once
    assert bench.describe()["real_max_files"] == 4
    split = bench.split("mm", 0)
    # the SDK filter smooths: lower jitter on average, in most files (it overshoots on some)
    metrics = bench.evaluate_estimator(DoubleExponentialSmoother(smoothing=0.75), split)["metrics"]
    assert metrics["real_jitter_after"] < metrics["real_jitter_before"] and metrics["real_jitter_not_worse"] >= 0.5
    assert metrics["real_new_swap_events"] == 0
    per_set = bench.evaluate_estimator(DoubleExponentialSmoother(), split)["detail"]["real"]
    assert set(per_set) == {"all", *bench.real_inputs} and per_set["all"]["files"] == 8
