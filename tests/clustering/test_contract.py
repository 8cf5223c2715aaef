"""Every registered clustering method (configs/clustering/method/): the estimators keep the scikit-learn
classifier contract on skeleton sequences (mocapkit.testing.estimator_checks); the networks name an experiment of
`mocapkit train` that composes. A new method gets these tests by adding its config file."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.testing.estimator_checks import (
    check_registered_parameters,
    check_sequence_classifier,
    check_training_run_entry,
    kinect_pairs,
    registered_names,
    synthetic_clips,
)
from mocapkit.train.registry import build_method

TASK = "clustering"
#: Small settings that keep a pipeline fast on 8 short sequences (every other parameter is the config's).
WORDS = ["steps.1.1.cv=2", "steps.1.1.Cs=[1.0]"]
FAST = {
    name: [*WORDS, "steps.1.1.clusterer.n_components=4", "steps.1.1.clusterer.max_iter=20"]
    for name in ("nmf", "onmf", "gnmf", "nmc")
}
FAST["kmeans"] = [*WORDS, "steps.1.1.clusterer.n_clusters=4", "steps.1.1.clusterer.n_init=1"]


@pytest.fixture(scope="module")
def sequences(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clips")  # Kinect-20 skeletons (the pipelines' msr20 layout)
    clips = synthetic_clips(folder)
    pairs = kinect_pairs(sorted(folder.rglob("*.amc")))
    return [p.clean for p in pairs], np.array(["squat" in c.name for c in clips], dtype=int)


#: The estimators of the registry, and the networks (entries naming a `mocapkit train` experiment).
ESTIMATORS, NETWORKS = registered_names(TASK)


@pytest.mark.parametrize("name", NETWORKS)
def test_training_run_entry(name):
    check_training_run_entry(TASK, name)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_parameters(name):
    overrides = FAST.get(name, [])
    check_registered_parameters(TASK, name, overrides)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_contract(name, sequences):
    check_sequence_classifier(build_method(TASK, name, FAST.get(name, [])), *sequences)
