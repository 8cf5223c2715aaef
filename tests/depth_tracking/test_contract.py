"""Every registered depth-tracking method (configs/depth_tracking/method/) keeps the estimator contract (fit on
training performers' depth sequences, predict [T, 16, 3] camera coordinates, save/load, errors naming the file;
mocapkit.testing.estimator_checks). A new method gets these tests by adding its config file."""

from __future__ import annotations

import pytest

from mocapkit.testing.estimator_checks import check_depth_estimator, check_registered_parameters, depth_sequences
from mocapkit.train.registry import build_method, method_names

TASK = "depth_tracking"
#: Small settings that keep a method fast on 3 rendered sequences of 20 frames (every other parameter is the
#: config's): 2 Gauss–Newton iterations and a 5-neighbour prior; 3 steps of a narrow CNN on small crops; 2 Adam
#: steps of a GP with 10 inducing points.
FAST = {
    "tracker": ["iterations=2", "init_iterations=2", "neighbours=5"],
    "lou_thesis": ["iterations=2", "neighbours=5"],
    "tracker_gp": [
        "iterations=2",
        "init_iterations=2",
        "anchor_corrector={gp_iterations: 2, n_inducing: 10, max_train_frames: 200}",
    ],
    "cnn_regressor": ["steps=3", "batch_size=4", "crop_size=32", "network={width: 4, blocks: 2, hidden: 16}"],
    "sensor_gp": ["corrector={gp_iterations: 2, n_inducing: 10, max_train_frames: 200}"],
}


@pytest.fixture(scope="module")
def sequences(tmp_path_factory):
    return depth_sequences(tmp_path_factory.mktemp("clips"), clips=3, frames=20)


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    check_registered_parameters(TASK, name, FAST.get(name, []))


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, sequences, tmp_path):
    check_depth_estimator(build_method(TASK, name, FAST.get(name, [])), sequences, tmp_path)
