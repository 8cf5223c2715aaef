"""Every registered Kinect method (configs/kinect/method/) keeps the corrector contract (fit on (Kinect, mocap)
pairs, predict, save/load; mocapkit.testing.estimator_checks). A new method gets these tests by adding its config
file."""

from __future__ import annotations

import pytest

from mocapkit.testing.estimator_checks import (
    check_kinect_corrector,
    check_registered_parameters,
    kinect_pairs,
    synthetic_clips,
)
from mocapkit.train.registry import build_method, method_names

TASK = "kinect"
#: Small settings that keep a method fast on 7 simulated clips (every other parameter is the config's).
NETWORK = ["steps=3", "window=16", "batch_size=4"]
FAST = {
    "gp": ["gp_iterations=2", "n_inducing=10", "max_train_frames=200"],
    "zhou_thesis": ["gp_iterations=2", "n_inducing=10", "max_train_frames=200"],
    "random_forest": ["n_estimators=5"],
    "bigru": [*NETWORK, "network={hidden: 8}"],
    "bigru_steady": [*NETWORK, "network={hidden: 8}"],
    "transformer": [*NETWORK, "network={dim: 16, layers: 1, ff: 32}"],
}


@pytest.fixture(scope="module")
def pairs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clips")
    synthetic_clips(folder)
    return kinect_pairs(sorted(folder.rglob("*.amc")))


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    overrides = FAST.get(name, [])
    check_registered_parameters(TASK, name, overrides)


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, pairs, tmp_path):
    check_kinect_corrector(build_method(TASK, name, FAST.get(name, [])), pairs, tmp_path)
