"""The user's path through the CLI: synth → prepare → train → resume → eval → export → predict.

One tiny synthetic set and one short run are shared by the tests of this module.
"""

import json

import pytest
import torch

from mocapkit.cli import main

pytestmark = pytest.mark.slow

TINY = ["--classes", "4", "--subjects", "4", "--setups", "1", "--replications", "1", "--seed", "3", "--quiet"]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    root = tmp_path_factory.mktemp("e2e")
    assert main(["synth", "ntu", "--out", str(root / "synth"), *TINY]) == 0
    assert main(["prepare", "ntu", "--src", str(root / "synth"), "--out", str(root / "cache"), "--quiet"]) == 0
    return root


def train_overrides(root, *extra):
    return [
        "train",
        "experiment=ntu_energy_vgg",
        f"data.root={root / 'cache'}",
        f"output_root={root / 'runs'}",
        "trainer.enable_progress_bar=false",
        "data.batch_size=8",
        "model.energy.size=32",
        *extra,
    ]


@pytest.fixture(scope="module")
def run_dir(workspace):
    assert main(train_overrides(workspace, "run_name=r", "trainer.max_epochs=2")) == 0
    return workspace / "runs" / "ntu_energy_vgg" / "r"


def test_train_writes_the_run_folder(run_dir):
    for name in ("config.yaml", "last.ckpt", "best.ckpt"):
        assert (run_dir / name).is_file(), name
    assert any((run_dir / "tensorboard").glob("events.out.tfevents.*"))
    last = torch.load(run_dir / "last.ckpt", weights_only=False)
    assert last["epoch"] == 1  # 0-based index of the second (last) epoch
    assert last["global_step"] == 2 * 3  # 2 epochs of 3 batches (2 training subjects x 12 samples, batch 8)


def test_resume_continues_where_it_stopped(run_dir, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    steps_before = torch.load(copy / "last.ckpt", weights_only=False)["global_step"]
    assert main(["train", f"resume={copy / 'last.ckpt'}", "trainer.max_epochs=3"]) == 0
    state = torch.load(copy / "last.ckpt", weights_only=False)
    assert state["lr_schedulers"][0]["T_max"] == 3  # the cosine schedule follows the new length
    assert state["epoch"] == 2
    assert state["global_step"] == steps_before * 3 // 2  # one more epoch of the same number of batches


def test_eval_writes_metrics_and_confusion_matrix(run_dir):
    assert main(["eval", f"ckpt_path={run_dir / 'best.ckpt'}", "trainer.enable_progress_bar=false"]) == 0
    metrics = json.loads((run_dir / "eval" / "metrics.json").read_text())
    assert metrics["split"] == "ntu60_xsub"
    assert metrics["test_subjects"] == [3]  # subjects 1, 2, 4 train in NTU-60 X-Sub
    assert 3 not in metrics["train_subjects"]
    assert metrics["sample_counts"]["test"] == metrics["num_samples"] == 3 * 4  # 3 cameras x 4 actions
    assert 0.0 <= metrics["top1"] <= metrics["top5"] <= 1.0
    assert set(metrics["per_subject"]) == {"3"}
    assert len(metrics["confusion_matrix"]) == 4
    assert sum(map(sum, metrics["confusion_matrix"])) == metrics["num_samples"]
    assert (run_dir / "eval" / "confusion_matrix.png").stat().st_size > 1000


def test_eval_with_test_time_views(run_dir, tmp_path):
    def evaluate(name, *views):
        out = tmp_path / name
        assert (
            main(
                [
                    "eval",
                    f"ckpt_path={run_dir / 'best.ckpt'}",
                    "trainer.enable_progress_bar=false",
                    f"eval.out_dir={out}",
                    *views,
                ]
            )
            == 0
        )
        return json.loads((out / "metrics.json").read_text())

    plain = evaluate("plain")
    assert plain["views"] is None
    identity = evaluate("identity", "eval.views={crops:[1.0],rotate_deg:[0]}")  # one view = the clip itself
    assert identity["views"]["n_views"] == 1
    assert identity["confusion_matrix"] == plain["confusion_matrix"] and identity["top1"] == plain["top1"]
    twelve = evaluate("twelve", "eval.views={crops:[1.0,0.9],rotate_deg:[0,-10,10]}")
    assert twelve["views"] == {"crops": [1.0, 0.9], "rotate_deg": [0.0, -10.0, 10.0], "n_views": 12}
    assert twelve["num_samples"] == plain["num_samples"]  # one prediction per clip
    assert "test-time views | 12" in (tmp_path / "twelve" / "summary.md").read_text()


def test_export_checks_parity_and_predict_uses_it(run_dir, workspace, capsys):
    onnx_path = run_dir / "exported.onnx"
    assert main(["export", f"ckpt_path={run_dir / 'best.ckpt'}", f"out={onnx_path}"]) == 0
    parity = json.loads((run_dir / "exported.parity.json").read_text())
    assert parity["checked_shape"][0] != parity["traced_shape"][0]
    assert parity["checked_shape"][2] != parity["traced_shape"][2]
    assert parity["max_abs_diff"] < 1e-4
    files = sorted((workspace / "synth").glob("*.skeleton"))[:2]
    capsys.readouterr()
    assert main(["predict", "--onnx", str(onnx_path), "--top", "2", *map(str, files)]) == 0
    out = capsys.readouterr().out
    classes = (workspace / "synth" / "classes.txt").read_text().split("\n")
    assert files[0].name in out and files[1].name in out
    assert sum(line.strip().startswith("1. ") for line in out.splitlines()) == 2
    assert any(name and name in out for name in classes)


def test_unknown_config_key_is_named(workspace, capsys):
    assert main(train_overrides(workspace, "data.no_such_key=1")) == 2
    assert "data.no_such_key" in capsys.readouterr().err


def test_missing_data_folder_is_named(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert main(["train", f"data.root={missing}", f"output_root={tmp_path}"]) == 2
    assert str(missing) in capsys.readouterr().err


def test_malformed_file_stops_prepare_with_file_and_line(tmp_path, capsys):
    src = tmp_path / "src"
    src.mkdir()
    (src / "S001C001P001R001A001.skeleton").write_text("2\n1\n72057594037931648 0 1 1 1 1 0 0.1 0.2 2\n25\n1 2 x\n")
    assert main(["prepare", "ntu", "--src", str(src), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "S001C001P001R001A001.skeleton" in err and "line" in err


def test_same_seed_deterministic_runs_give_identical_weights(workspace):
    states = []
    for name in ("det_a", "det_b"):
        assert (
            main(train_overrides(workspace, f"run_name={name}", "trainer.max_epochs=1", "deterministic=true", "seed=7"))
            == 0
        )
        states.append(torch.load(workspace / "runs" / "ntu_energy_vgg" / name / "last.ckpt", weights_only=False))
    a, b = (s["state_dict"] for s in states)
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_run_without_logger_trains_with_the_default_callbacks(workspace):
    """logger=none keeps the default callbacks working (the learning-rate monitor, which needs a logger, is left out)."""
    assert main(train_overrides(workspace, "run_name=nolog", "trainer.max_epochs=1", "logger=none")) == 0
    run = workspace / "runs" / "ntu_energy_vgg" / "nolog"
    assert (run / "last.ckpt").is_file() and not (run / "tensorboard").exists()
