"""The motion CVAE through the one training entry point: `mocapkit train experiment=synthesis_cvae` on the clips of
one motion type (mocapkit/synthesis/datamodule.py, configs/task/motion_vae.yaml) writes a run that
CVAESynthesizer.from_checkpoint samples from; the estimator's `trainer` parameter reaches its Lightning Trainer."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import mocapkit.train.training as training
from mocapkit.cli import main
from mocapkit.synthesis.clips import SynthesisInputError
from mocapkit.synthesis.cvae import CVAESynthesizer
from mocapkit.synthesis.datamodule import SynthesisClipsDataModule
from mocapkit.synthesis.module import MotionVAEModule
from mocapkit.train.errors import ConfigError
from tests.shared_data import synthetic_hdm05_folder

TYPE = "hopBothLegs1hops"
TINY = [
    "experiment=synthesis_cvae",
    f"data.motion_type={TYPE}",
    "data.max_clips=3",
    "data.val_fraction=0.3",
    "model.hidden=32",
    "model.latent=4",
    "trainer.max_steps=3",
    "trainer.enable_progress_bar=false",
]


@pytest.fixture(scope="module")
def clips_root(tmp_path_factory):
    """Six hops (and walks, which the motion type leaves out) of three performers."""
    return synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", TYPE), actors=("bd", "mm", "dg"), clips_per_actor=2, max_frames=120
    )


@pytest.fixture(scope="module")
def run(clips_root, tmp_path_factory):
    runs = tmp_path_factory.mktemp("runs")
    assert main(["train", *TINY, f"data.root={clips_root}", f"output_root={runs}", "run_name=tiny"]) == 0
    return runs / "synthesis_cvae" / "tiny"


def test_the_data_module_takes_the_clips_synthesize_would_and_validates_on_the_next(clips_root):
    data = SynthesisClipsDataModule(root=str(clips_root), motion_type=TYPE, max_clips=3, val_fraction=0.3)
    names = [p.name for p in data.files["train"] + data.files["val"]]
    assert len(data.files["train"]) == 3 and len(data.files["val"]) == 1 and all(TYPE in n for n in names)
    assert sorted(data.files["train"]) == data.files["train"] and data.files["train"][-1] < data.files["val"][0]
    counts = data.sample_counts()
    assert counts["train"] > 0 and counts["val"] > 0
    batch = next(iter(data.train_dataloader()))
    features = data.label_spaces()["frames"]["features"]
    assert batch["current"].shape[1:] == (features,) and batch["previous"].shape[1:] == (2, features)
    with pytest.raises(SynthesisInputError, match="none is left for validation"):
        SynthesisClipsDataModule(root=str(clips_root), motion_type=TYPE, max_clips=10)


def test_train_writes_a_run_with_best_and_last_checkpoints(run):
    assert (run / "best.ckpt").is_file() and (run / "last.ckpt").is_file() and (run / "config.yaml").is_file()
    checkpoint = torch.load(run / "last.ckpt", map_location="cpu", weights_only=True)
    assert checkpoint["global_step"] == 3
    frames = checkpoint["hyper_parameters"]["frames"]
    assert frames["fps"] == 30.0 and len(frames["mean"]) == frames["features"]


def test_from_checkpoint_samples_with_the_trained_network(run, clips_root):
    synthesizer = CVAESynthesizer.from_checkpoint(run / "best.ckpt", footskate_cleanup=False)
    assert (synthesizer.hidden, synthesizer.latent, synthesizer.fps) == (32, 4, 30.0)
    module = MotionVAEModule.load_from_checkpoint(run / "best.ckpt", map_location="cpu", weights_only=True).eval()
    start = torch.zeros(2, 2, module.model.features)
    with torch.no_grad():
        expected = module.model.rollout(start, 10, generator=torch.Generator().manual_seed(0))
        got = synthesizer.module_.model.rollout(start, 10, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(got, expected, rtol=0, atol=0)
    variants = synthesizer.sample(2, n_frames=30, seed=0)
    assert [v.num_frames for v in variants] == [30, 30] and all(np.isfinite(v.positions).all() for v in variants)
    # the same clips given explicitly sample the same variants; other clips are refused
    data = SynthesisClipsDataModule(root=str(clips_root), motion_type=TYPE, max_clips=3, val_fraction=0.3)
    again = CVAESynthesizer.from_checkpoint(run / "best.ckpt", clips=data.train_clips, footskate_cleanup=False)
    np.testing.assert_array_equal(again.sample(2, n_frames=30, seed=0)[1].positions, variants[1].positions)
    with pytest.raises(ValueError, match="not those the run trained on"):
        CVAESynthesizer.from_checkpoint(run / "best.ckpt", clips=data.train_clips[::-1][:2] + data.val_clips)


def test_the_trainer_parameter_reaches_the_lightning_trainer(clips_root, monkeypatch):
    data = SynthesisClipsDataModule(root=str(clips_root), motion_type=TYPE, max_clips=3, val_fraction=0)
    built, real = [], training.build_trainer
    monkeypatch.setattr(training, "build_trainer", lambda *a, **kw: built.append(real(*a, **kw)) or built[-1])
    small = {"hidden": 16, "latent": 4, "steps": 50, "footskate_cleanup": False}
    model = CVAESynthesizer(**small, trainer={"max_steps": 2, "precision": "bf16-mixed"}).fit(data.train_clips)
    assert len(built) == 1 and built[0].max_steps == 2 and built[0].precision == "bf16-mixed"
    assert len(model.loss_curve_) == 2 and not model.module_.training
    monkeypatch.undo()
    with pytest.raises(ConfigError, match=r"\['max_stpes'\] are not arguments of lightning.Trainer"):
        CVAESynthesizer(**small, trainer={"max_stpes": 2}).fit(data.train_clips)
    with pytest.raises(ValueError, match="trainer must be a dict"):
        CVAESynthesizer(**small, trainer="gpu").fit(data.train_clips)
