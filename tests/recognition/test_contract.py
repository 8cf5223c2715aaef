"""Every registered recognition method (configs/recognition/method/): the estimators keep the scikit-learn
classifier contract on skeleton sequences (mocapkit.testing.estimator_checks); the networks name an experiment of
`mocapkit train` that composes. A new method gets these tests by adding its config file."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.testing.estimator_checks import (
    check_registered_parameters,
    check_sequence_classifier,
    check_training_run_entry,
    registered_names,
    synthetic_clips,
)
from mocapkit.train.registry import build_method

TASK = "recognition"
FAST: dict[str, list[str]] = {}  # small settings per method name, where one is slow on 8 clips


@pytest.fixture(scope="module")
def sequences(tmp_path_factory):
    clips = synthetic_clips(tmp_path_factory.mktemp("clips"))
    return [c.positions for c in clips], np.array(["squat" in c.name for c in clips], dtype=int)


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
