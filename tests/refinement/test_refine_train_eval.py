"""`mocapkit train|eval|export` of a learned refiner, end to end on a tiny HDM05-format folder.

The folder is built from the synthetic HDM05 generator's output, renamed to HDM05's own layout
(``<actor>/HDM_<actor>_<class>_<nnn>_120.amc`` beside ``<actor>/HDM_<actor>.asf``), so it runs in CI.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.shared_data import synthetic_hdm05_folder

TINY = [
    "model.hidden=8",
    "model.layers=1",
    "data.window=48",
    "data.windows_per_epoch=64",
    "data.batch_size=16",
    "data.eval_windows_per_clip=1",
    "trainer.max_epochs=1",
    "logger=none",
    "callbacks.learning_rate=null",
    "trainer.enable_progress_bar=false",
]


@pytest.fixture(scope="module")
def hdm05_folder(tmp_path_factory) -> Path:
    return synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", "hopBothLegs1hops"), clips_per_actor=2, max_frames=160
    )


@pytest.fixture(scope="module")
def refiner_run(hdm05_folder, tmp_path_factory) -> Path:
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import train

    out = tmp_path_factory.mktemp("runs")
    cfg = compose_config(
        [
            "experiment=refine_bigru",
            f"data.root={hdm05_folder}",
            "data.test_groups=[mm]",
            f"output_root={out}",
            "run_name=tiny",
            *TINY,
        ]
    )
    return Path(train(cfg))


def test_train_records_the_layout_and_the_training_performers(refiner_run):
    from mocapkit.refinement.learned import LearnedRefiner

    refiner = LearnedRefiner(checkpoint=str(refiner_run / "best.ckpt")).fit()
    skeleton = refiner.skeleton_
    assert skeleton["train_groups"] == ["bd"]
    assert skeleton["fps"] == 120.0 and skeleton["window"] == 48 and len(skeleton["joint_names"]) == 31
    assert skeleton["hips"] == [1, 6] or tuple(skeleton["hips"]) == (1, 6)


def test_first_guess_rules_are_recorded_and_can_be_restored_for_old_runs(refiner_run):
    """A run records its first-guess rules (the model config); ``LearnedRefiner(first_guess=...)`` sets others on
    the loaded network (how runs trained before the rules existed get theirs back) and rejects bad values."""
    from mocapkit.refinement.learned import LearnedRefiner

    default = LearnedRefiner(checkpoint=str(refiner_run / "best.ckpt")).fit()
    assert (default.module_.model.tangents, default.module_.model.extrapolate) == ("chord", 6)
    old = LearnedRefiner(checkpoint=str(refiner_run / "best.ckpt"), first_guess={"tangents": "zero", "extrapolate": 0})
    old.fit()
    assert (old.module_.model.tangents, old.module_.model.extrapolate) == ("zero", 0)
    with pytest.raises(ValueError, match="tangents"):
        LearnedRefiner(checkpoint=str(refiner_run / "best.ckpt"), first_guess={"tangents": "flat"}).fit()
    with pytest.raises(ValueError, match="extrapolate"):
        LearnedRefiner(checkpoint=str(refiner_run / "best.ckpt"), first_guess={"extrapolate": -1}).fit()


def test_eval_writes_the_benchmark_table_with_classical_rows(refiner_run):
    from mocapkit.evaluation.evaluate import evaluate

    overrides = [
        (
            "eval.overrides=['seeds=[0]','benchmark.protocols=[continuous_missing@10,rdloss@0.3]',"
            "'only=[linear,pchip,learned]','benchmark.clips_per_fold=1','benchmark.max_frames=100',"
            "'benchmark.claims=[]']"
        )
    ]
    report = evaluate(refiner_run / "best.ckpt", overrides)
    assert report["held_out"] == ["mm"]
    results = json.loads((refiner_run / "eval" / "results.json").read_text())
    assert results["benchmark"]["held_out"] == ["mm"]
    methods = {cell["method"] for cell in results["cells"]}
    assert methods == {"linear", "pchip", "learned"}
    for cell in results["cells"]:
        if cell["method"] == "learned":
            fold = cell["detail"]["folds"]["mm"]
            assert fold["fit_groups"] == ["bd"]  # fitted (chosen) on the other performer only
            assert cell["metrics"]["coverage"] > 0.99 and cell["metrics"]["n_failed"] == 0
    table = (refiner_run / "eval" / "results.md").read_text()
    assert "learned (refine_bigru)" in table and "PCHIP" in table


def test_a_checkpoint_trained_on_the_test_performer_is_refused(refiner_run, hdm05_folder):
    from mocapkit.datasets.mocap.folders import list_clips, read_clips
    from mocapkit.refinement.base import RefinementError
    from mocapkit.refinement.learned import LearnedRefiner

    motions = [m for m in read_clips(list_clips("hdm05", hdm05_folder)) if m.metadata["group"] == "mm"]
    with pytest.raises(RefinementError, match=r"\['mm'\]"):
        LearnedRefiner(checkpoint=[str(refiner_run / "best.ckpt")]).fit(motions)


def test_export_writes_onnx_with_parity_on_other_shapes(refiner_run):
    from mocapkit.deploy.export import export_checkpoint

    report = export_checkpoint(refiner_run / "best.ckpt", out=str(refiner_run / "refiner.onnx"))
    assert report["checked_shape"] != report["traced_shape"]
    assert report["max_abs_diff"] < 1e-4
    assert (refiner_run / "refiner.onnx").is_file()
