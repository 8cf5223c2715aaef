"""Every registered refinement method (configs/refinement/method/) keeps the MotionRefiner contract
(mocapkit.testing.estimator_checks). A new method gets these tests by adding its config file."""

from __future__ import annotations

from pathlib import Path

import pytest

from mocapkit.testing.estimator_checks import (
    check_refiner,
    check_registered_parameters,
    required_parameters,
    synthetic_clips,
)
from mocapkit.train.errors import ConfigError
from mocapkit.train.registry import build_method, method_names

TASK = "refinement"
#: Small settings that keep a method fast on 60-frame clips of 31 joints (every other parameter is the config's).
FAST = {
    "psc": ["n_atoms=16", "max_iter=2", "n_neighbors=4", "max_train_windows=200"],
    "pose-prior": ["n_components=8"],
    "filter-bases": ["max_iter=5", "max_windows=500", "window=10", "dilation=1"],
    "dynammo": ["hidden_dim=4", "max_iter=5"],
    "lrmf": ["max_iter=50"],
    "trnn": ["max_iter=50", "truncation=3"],
    "svt": ["max_iter=50"],
    "pca": ["max_iter=5"],
}


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    return synthetic_clips(tmp_path_factory.mktemp("clips"))


@pytest.fixture(scope="module")
def trained_files(tmp_path_factory) -> dict[str, str]:
    """The files the learned entries need, from a tiny BiGRU run at the clips' 30 fps: ``checkpoint`` (best.ckpt)
    and ``path`` (its ONNX export)."""
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import train
    from tests.shared_data import synthetic_hdm05_folder

    folder = synthetic_hdm05_folder(tmp_path_factory, ("hopBothLegs1hops", "squat1Reps"), max_frames=160)
    overrides = [
        "experiment=refine_bigru",
        f"data.root={folder}",
        "data.test_groups=[mm]",
        "data.fps=30",
        f"output_root={tmp_path_factory.mktemp('runs')}",
        "run_name=tiny",
        "model.hidden=8",
        "model.layers=1",
        "data.window=32",
        "data.windows_per_epoch=64",
        "data.batch_size=16",
        "data.eval_windows_per_clip=1",
        "trainer.max_epochs=1",
        "logger=none",
        "trainer.enable_progress_bar=false",
    ]
    run = Path(train(compose_config(overrides)))
    from mocapkit.deploy.refiner_export import export_refiner
    from mocapkit.refinement.learned import LearnedRefiner

    refiner = LearnedRefiner(checkpoint=str(run / "best.ckpt")).fit()
    export_refiner(refiner.module_.model, run / "model.onnx", refiner.skeleton_)
    return {"checkpoint": str(run / "best.ckpt"), "path": str(run / "model.onnx")}


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    overrides = [f"{key}=model.file" for key in required_parameters(TASK, name)] + FAST.get(name, [])
    check_registered_parameters(TASK, name, overrides)


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, clips, request):
    required = required_parameters(TASK, name)
    overrides = list(FAST.get(name, []))
    if required:  # a trained network: refused without its file (named), then checked with a tiny run's
        with pytest.raises(ConfigError, match=required[0]):
            build_method(TASK, name)
        files = request.getfixturevalue("trained_files")
        overrides += [f"{key}={files[key]}" for key in required]
    check_refiner(build_method(TASK, name, overrides), clips[1:], clips[0])
