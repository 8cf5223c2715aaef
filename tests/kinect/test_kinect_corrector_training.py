"""The Kinect corrector through the one training entry point: `mocapkit train experiment=kinect_corrector_bigru`
(mocapkit/kinect/datamodule.py, configs/task/kinect_corrector.yaml) writes a run that `mocapkit eval` scores,
`mocapkit export` exports and LearnedKinectCorrector.from_checkpoint loads (mocapkit/kinect/learned.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from mocapkit.cli import main
from mocapkit.kinect.learned import LearnedKinectCorrector, OnnxKinectCorrector
from mocapkit.train.refine_module import MotionRefinementModule
from tests.shared_data import synthetic_hdm05_folder

REPO = Path(__file__).resolve().parents[2]
WINDOW = 32
TINY = [
    "experiment=kinect_corrector_bigru",
    "model.hidden=16",
    "model.layers=1",
    f"data.window={WINDOW}",
    "data.val_fraction=0.25",
    "trainer.max_steps=3",
    "trainer.enable_progress_bar=false",
]


@pytest.fixture(scope="module")
def mocap_root(tmp_path_factory):
    """Three performers of two classes, two clips each: bd held out, mm and dg train (one clip validates)."""
    return synthetic_hdm05_folder(
        tmp_path_factory,
        ("walk2StepsLstart", "hopBothLegs1hops"),
        actors=("bd", "dg", "mm"),
        clips_per_actor=2,
        max_frames=160,
    )


@pytest.fixture(scope="module")
def run(mocap_root, tmp_path_factory):
    runs = tmp_path_factory.mktemp("runs")
    assert main(["train", *TINY, f"data.root={mocap_root}", f"output_root={runs}", "run_name=tiny"]) == 0
    return runs / "kinect_corrector_bigru" / "tiny"


def test_train_writes_a_run_with_best_and_last_checkpoints(run):
    assert (run / "best.ckpt").is_file() and (run / "last.ckpt").is_file() and (run / "config.yaml").is_file()
    checkpoint = torch.load(run / "last.ckpt", map_location="cpu", weights_only=True)
    assert checkpoint["global_step"] == 3
    skeleton = checkpoint["hyper_parameters"]["skeleton"]
    assert skeleton["window"] == WINDOW and skeleton["train_groups"] == ["dg", "mm"]
    assert skeleton["untracked_as_missing"] is False and len(skeleton["bone_lengths"]) == 20


def test_from_checkpoint_predicts_as_the_trained_module(run):
    corrector = LearnedKinectCorrector.from_checkpoint(run / "best.ckpt")
    assert corrector.architecture == "bigru" and corrector.window == WINDOW
    assert corrector.network["hidden"] == 16 and corrector.network["layers"] == 1
    module = MotionRefinementModule.load_from_checkpoint(
        run / "best.ckpt", map_location="cpu", weights_only=True
    ).eval()
    clip = np.random.default_rng(0).normal(0.0, 0.3, (2 * WINDOW, 20, 3)).astype(np.float32)
    with torch.no_grad():  # one inference window of 2 · window frames: the network's output as it is
        expected = module(torch.from_numpy(clip[None]), torch.zeros(1, 2 * WINDOW, 20, dtype=torch.bool))[0].numpy()
    np.testing.assert_allclose(corrector.predict(clip), expected, atol=1e-6)


def test_eval_scores_the_held_out_performer_and_export_runs_in_onnxruntime(run):
    assert main(["eval", f"ckpt_path={run / 'best.ckpt'}"]) == 0
    report = json.loads((run / "eval" / "results.json").read_text())
    assert report["groups"] == ["bd"] and report["clips"] == 4
    assert report["raw_cm"] > 0 and report["error_cm"] > 0
    assert report["reduction"] == pytest.approx(1 - report["error_cm"] / report["raw_cm"])
    assert main(["export", f"ckpt_path={run / 'best.ckpt'}", f"out={run / 'corrector.onnx'}"]) == 0
    clip = np.random.default_rng(1).normal(0.0, 0.3, (150, 20, 3))
    onnx = OnnxKinectCorrector(str(run / "corrector.onnx")).fit()
    np.testing.assert_allclose(
        onnx.predict(clip), LearnedKinectCorrector.from_checkpoint(run / "best.ckpt").predict(clip), atol=1e-4
    )


def test_a_checkpoint_of_another_task_is_refused_naming_it(tmp_path):
    bogus = tmp_path / "bogus.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": {"skeleton": {"joint_names": ["a"]}}}, bogus)
    with pytest.raises(ValueError, match=r"bogus\.ckpt: not a Kinect corrector checkpoint"):
        LearnedKinectCorrector.from_checkpoint(bogus)


@pytest.mark.slow
@pytest.mark.skipif(
    not (torch.distributed.is_available() and torch.distributed.is_gloo_available()),
    reason="torch.distributed with gloo is not available",
)
def test_ddp_on_two_cpu_processes_trains_the_corrector(mocap_root, tmp_path):
    command = [
        sys.executable,
        "-m",
        "mocapkit",
        "train",
        *TINY,
        f"data.root={mocap_root}",
        f"output_root={tmp_path / 'runs'}",
        "run_name=ddp",
        "trainer.accelerator=cpu",
        "trainer.devices=2",
        "trainer.strategy=ddp",
    ]
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    }
    proc = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    run = tmp_path / "runs" / "kinect_corrector_bigru" / "ddp"
    assert (run / "best.ckpt").is_file() and (run / "last.ckpt").is_file()
    assert torch.load(run / "last.ckpt", map_location="cpu", weights_only=True)["global_step"] == 3
    assert LearnedKinectCorrector.from_checkpoint(run / "best.ckpt").predict(np.zeros((40, 20, 3))).shape == (40, 20, 3)
