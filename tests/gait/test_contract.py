"""Every registered gait method (configs/gait/method/): the estimators keep the scikit-learn classifier contract on
gait energy images (mocapkit.testing.estimator_checks); the networks name an experiment of `mocapkit train` that
composes. A new method gets these tests by adding its config file."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.testing.estimator_checks import (
    check_gait_classifier,
    check_registered_parameters,
    check_training_run_entry,
    registered_names,
)
from mocapkit.train.registry import build_method

TASK = "gait"
FAST: dict[str, list[str]] = {}  # small settings per method name, where one is slow on 30 GEIs


@pytest.fixture(scope="module")
def geis():
    """6 subjects × 5 GEIs of 16 × 11 pixels in [0, 1]: a subject's pattern plus noise."""
    rng = np.random.default_rng(0)
    patterns = rng.random((6, 16, 11))
    subjects = np.repeat(np.arange(6), 5)
    images = np.clip(patterns[subjects] + 0.05 * rng.standard_normal((30, 16, 11)), 0.0, 1.0)
    return images, subjects


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
def test_contract(name, geis):
    check_gait_classifier(build_method(TASK, name, FAST.get(name, [])), *geis)
