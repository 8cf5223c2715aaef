"""Every registered retrieval method (configs/retrieval/method/) keeps the RetrievalMethod contract
(mocapkit.testing.estimator_checks), including the save/load of its state that an index folder holds. A new
method gets these tests by adding its config file."""

from __future__ import annotations

from pathlib import Path

import pytest

from mocapkit.testing.estimator_checks import (
    check_registered_parameters,
    check_retrieval_method,
    required_parameters,
    synthetic_clips,
)
from mocapkit.train.errors import ConfigError
from mocapkit.train.registry import build_method, method_names

TASK = "retrieval"
#: Small settings that keep a method fast on a database of 8 short clips (every other parameter is the config's).
FEATURES = ["n_words=8", "n_features=20", "n_neighbors=2"]
FAST = {
    "hod": FEATURES,
    "gpf": FEATURES,
    "hod_gpf": FEATURES,
    "laplacian_score": FEATURES,
    "spec": FEATURES,
    "udfs": [*FEATURES, "views=[gpf]"],  # UDFS eigen-solves D x D 20 times: HOD alone is 3,192-d
    "amfs": FEATURES,
    "dtw_mutual_proximity": ["n_reference=4"],
    "dtw_world_frame": ["n_reference=4"],
    "tsr_stpm": ["n_atoms=16", "n_nonzero=2", "ksvd_iter=2"],
    "tsr_stpm_thesis": ["n_atoms=16", "n_nonzero=4", "ksvd_iter=2"],
}


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    return synthetic_clips(tmp_path_factory.mktemp("clips"))


@pytest.fixture(scope="module")
def trained_files(tmp_path_factory) -> dict[str, str]:
    """The file the learned entries need, from a tiny supervised-contrastive encoder run: ``checkpoint``."""
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import train
    from tests.shared_data import synthetic_hdm05_folder

    folder = synthetic_hdm05_folder(
        tmp_path_factory, ("hopBothLegs1hops", "squat1Reps"), clips_per_actor=3, max_frames=90
    )
    overrides = [
        "experiment=retrieval_supcon",
        f"data.root={folder}",
        "data.test_groups=[mm]",
        f"output_root={tmp_path_factory.mktemp('runs')}",
        "run_name=tiny",
        "model.channels=[16,16]",
        "model.strides=[2,1]",
        "model.hidden=16",
        "model.embedding_dim=8",
        "data.frames=16",
        "data.batch_size=8",
        "trainer.max_epochs=1",
        "logger=none",
        "trainer.enable_progress_bar=false",
        "data.val_fraction=0.3",
    ]
    return {"checkpoint": str(Path(train(compose_config(overrides))) / "best.ckpt")}


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    overrides = [f"{key}=model.file" for key in required_parameters(TASK, name)] + FAST.get(name, [])
    check_registered_parameters(TASK, name, overrides)


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, clips, request):
    required = required_parameters(TASK, name)
    overrides = list(FAST.get(name, []))
    if required:  # a trained encoder: refused without its file (named), then checked with a tiny run's
        with pytest.raises(ConfigError, match=required[0]):
            build_method(TASK, name)
        files = request.getfixturevalue("trained_files")
        overrides += [f"{key}={files[key]}" for key in required]
    check_retrieval_method(build_method(TASK, name, overrides), clips, clips[::3])
