"""Every registered retrieval method (configs/retrieval/method/) keeps the RetrievalMethod contract
(mocapkit.testing.estimator_checks), including the save/load of its state that an index folder holds. A new
method gets these tests by adding its config file."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from mocapkit.testing.estimator_checks import check_parameters, check_retrieval_method, synthetic_clips
from mocapkit.train.errors import ConfigError
from mocapkit.train.registry import build_method, method_config, method_names

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
    "tsr_stpm": ["n_atoms=16", "n_nonzero=2", "ksvd_iter=2"],
    "tsr_stpm_thesis": ["n_atoms=16", "n_nonzero=4", "ksvd_iter=2"],
}


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    return synthetic_clips(tmp_path_factory.mktemp("clips"))


def _required(name: str) -> list[str]:
    node = OmegaConf.to_container(method_config(TASK, name))
    return [key for key, value in node.items() if value == "???"]


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    overrides = [f"{key}=model.file" for key in _required(name)] + FAST.get(name, [])
    check_parameters(build_method(TASK, name, overrides), OmegaConf.to_container(method_config(TASK, name, overrides)))


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, clips):
    required = _required(name)
    if required:  # a trained encoder: test_retrieval_embedding.py trains one and indexes with it
        with pytest.raises(ConfigError, match=required[0]):
            build_method(TASK, name)
        pytest.skip(f"{name} needs a trained model file ({', '.join(required)})")
    check_retrieval_method(build_method(TASK, name, FAST.get(name, [])), clips, clips[::3])
