"""Every registered refinement method (configs/refinement/method/) keeps the MotionRefiner contract
(mocapkit.testing.estimator_checks). A new method gets these tests by adding its config file."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from mocapkit.testing.estimator_checks import check_parameters, check_refiner, synthetic_clips
from mocapkit.train.errors import ConfigError
from mocapkit.train.registry import build_method, method_config, method_names

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
    if required:  # a trained network (checkpoint / ONNX file): its own tests train one (test_refine_learned_cli)
        with pytest.raises(ConfigError, match=required[0]):
            build_method(TASK, name)
        pytest.skip(f"{name} needs a trained model file ({', '.join(required)})")
    check_refiner(build_method(TASK, name, FAST.get(name, [])), clips[1:], clips[0])
