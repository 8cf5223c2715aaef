"""Multi-process training: `mocapkit train` with DDP on two CPU processes (gloo).

The command runs in a subprocess because Lightning's DDP launcher re-executes the command line for
the second process. The test checks that the run finishes, writes its checkpoints, and that the
logged ``val/acc`` is synchronised: it must equal the accuracy over the *whole* validation set
recomputed from the checkpoint of that epoch, not the accuracy of one process's half.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
from hydra.utils import instantiate
from omegaconf import OmegaConf

from mocapkit.cli import main
from mocapkit.recognition.module import ActionRecognitionModule

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not (dist.is_available() and dist.is_gloo_available()), reason="torch.distributed with gloo is not available"
    ),
]

REPO = Path(__file__).resolve().parents[2]
# 4 subjects x 4 classes x 3 cameras: X-Sub trains on subjects 1, 2, 4 and validates on one of them,
# 12 samples — an even number, so DistributedSampler pads neither half with a repeated sample
TINY = ["--classes", "4", "--subjects", "4", "--setups", "1", "--replications", "1", "--seed", "0", "--quiet"]


def _val_accuracy(ckpt: Path, batch: dict) -> torch.Tensor:
    """Per-sample hits (1/0) of the checkpoint's network on ``batch``, computed here in one process."""
    module = ActionRecognitionModule.load_from_checkpoint(ckpt, map_location="cpu").eval()
    with torch.no_grad():
        return (module(batch["skeletons"]).argmax(1) == batch["labels"]).double()


def test_ddp_training_logs_a_synchronised_val_acc(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    assert main(["synth", "ntu", "--out", str(tmp_path / "synth"), *TINY]) == 0
    assert main(["prepare", "ntu", "--src", str(tmp_path / "synth"), "--out", str(tmp_path / "cache"), "--quiet"]) == 0
    runs = tmp_path / "runs"
    command = [
        sys.executable,
        "-m",
        "mocapkit",
        "train",
        f"data.root={tmp_path / 'cache'}",
        "trainer.accelerator=cpu",
        "trainer.devices=2",
        "trainer.strategy=ddp",
        "trainer.max_epochs=2",
        f"output_root={runs}",
        "run_name=ddp",
        "experiment=ntu_energy_vgg",
        "model.energy.size=32",
        "data.batch_size=8",
        "trainer.enable_progress_bar=false",
    ]
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    }
    proc = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"

    best = sorted(runs.rglob("best.ckpt"))
    assert len(best) == 1, list(runs.rglob("*"))
    run_dir = best[0].parent
    assert (run_dir / "last.ckpt").is_file()

    events = sorted(run_dir.rglob("events.out.tfevents.*"))
    assert len(events) == 1, events  # one writer: rank 0
    accumulator = EventAccumulator(str(events[0]))
    accumulator.Reload()
    logged = [e.value for e in sorted(accumulator.Scalars("val/acc"), key=lambda e: e.step)]
    assert len(logged) == 2, logged  # one (epoch-level, synchronised) value per epoch

    # the whole validation set, in the order DistributedSampler(shuffle=False) deals it: rank r gets r::2
    cfg = OmegaConf.load(run_dir / "config.yaml")
    datamodule = instantiate(cfg.data, seed=cfg.seed)
    assert len(datamodule.val_idx) == 12
    batch = next(iter(datamodule.val_dataloader()))
    assert len(batch["labels"]) == 12

    halves_differ = False
    for path in (run_dir / "best.ckpt", run_dir / "last.ckpt"):
        epoch = torch.load(path, map_location="cpu", weights_only=False)["epoch"]
        hits = _val_accuracy(path, batch)
        whole, rank0, rank1 = float(hits.mean()), float(hits[0::2].mean()), float(hits[1::2].mean())
        print(
            f"{path.name}: epoch {epoch}, logged val/acc {logged[epoch]:.6f}, whole set {whole:.6f}, "
            f"rank 0 half {rank0:.6f}, rank 1 half {rank1:.6f}"
        )
        assert logged[epoch] == pytest.approx(whole, abs=1e-6), (path.name, logged, whole, rank0, rank1)
        halves_differ |= rank0 != whole or rank1 != whole
    assert torch.load(run_dir / "last.ckpt", map_location="cpu", weights_only=False)["epoch"] == 1
    # best.ckpt was chosen on the synchronised number
    state = torch.load(run_dir / "best.ckpt", map_location="cpu", weights_only=False)
    scores = [s["best_model_score"] for s in state["callbacks"].values() if s.get("monitor") == "val/acc"]
    assert len(scores) == 1 and float(scores[0]) == pytest.approx(max(logged), abs=1e-6)
    # otherwise the check above could not tell a synchronised value from one process's
    assert halves_differ, "both halves of the validation set scored like the whole: the check proves nothing"
