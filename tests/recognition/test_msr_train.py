"""End to end on the real MSR Action3D files: `mocapkit train experiment=msr3d_gcn` for one short epoch,
then `mocapkit eval` on its checkpoint (an AS1 subset and a small network keep it to seconds)."""

import json

import pytest

from mocapkit.cli import main
from tests.shared_data import SHARED, needs

MSR_ROOT = SHARED / "data" / "msr_action3d"

pytestmark = [pytest.mark.slow, needs(MSR_ROOT)]


def test_train_and_eval_msr3d_gcn(tmp_path):
    quick = [
        f"data.root={MSR_ROOT}",
        f"output_root={tmp_path}",
        "run_name=r",
        "trainer.max_epochs=1",
        "trainer.enable_progress_bar=false",
        "data.subset=AS1",
        "data.max_frames=16",
        "model.channels=[16,16]",
        "model.strides=[2,1]",
    ]
    assert main(["train", "experiment=msr3d_gcn", *quick]) == 0
    run = tmp_path / "msr3d_gcn" / "r"
    assert (run / "best.ckpt").is_file() and (run / "last.ckpt").is_file()
    assert main(["eval", f"ckpt_path={run / 'best.ckpt'}", "trainer.enable_progress_bar=false"]) == 0
    metrics = json.loads((run / "eval" / "metrics.json").read_text())
    assert metrics["split"] == "AS1_cross_subject"
    assert metrics["test_subjects"] == [2, 4, 6, 8, 10]
    assert metrics["num_samples"] == metrics["sample_counts"]["test"] == 106
    assert len(metrics["confusion_matrix"]) == 8
    assert "a13_s09_e02_skeleton3D.txt" in metrics["excluded"]


def test_energy_vgg_experiment_composes_on_msr20():
    from mocapkit.train.config import compose_config

    cfg = compose_config(["experiment=msr3d_energy_vgg"])
    assert cfg.model.energy.layout == "msr20" and cfg.data.layout == "msr20"
    gcn = compose_config(["experiment=msr3d_gcn"])
    assert gcn.model.layout == "msr20"
    ntu = compose_config(["experiment=ntu_energy_vgg", "model=stgcn", "data.root=x"])
    assert ntu.model.layout == "ntu25"
    assert compose_config(["experiment=ntu_gcn", "data.root=x"]).model.layout == "ntu25"


def test_benchmark_subset_protocols_are_cross_subject_on_the_subset():
    import numpy as np

    from mocapkit.datasets.msr_action3d.datamodule import MSRAction3DDataModule
    from mocapkit.datasets.msr_action3d.dataset import ACTION_SUBSETS
    from mocapkit.recognition.benchmark_msr import MSRActionBenchmark

    bench = MSRActionBenchmark(str(MSR_ROOT))
    assert {"cross_subject", "random_half", "AS1", "AS2", "AS3"} <= set(bench.protocols)
    split = bench.split("AS2", seed=0)
    actions = np.asarray(bench.dataset.actions)
    subjects = np.asarray(bench.dataset.subjects)
    assert set(actions[split.train]) == set(actions[split.test]) == set(ACTION_SUBSETS["AS2"])
    assert set(subjects[split.train]) == {1, 3, 5, 7, 9} and set(subjects[split.test]) == {2, 4, 6, 8, 10}
    overrides = dict(o.split("=", 1) for o in bench.learned_overrides("AS2", 0))
    assert overrides["data.subset"] == "AS2" and overrides["data.split"] == "cross_subject"
    dm = MSRAction3DDataModule(str(MSR_ROOT), split="cross_subject", subset="AS2", val_fraction=0)
    np.testing.assert_array_equal(dm.test_idx, split.test)  # the run scores the same clips
    assert len(dm.val_idx) == 0 and len(dm.train_idx) == len(split.train)
