"""Every registered synthesis method (configs/synthesis/method/) keeps the MotionSynthesizer contract
(mocapkit.testing.estimator_checks). A new method gets these tests by adding its config file."""

from __future__ import annotations

import pytest

from mocapkit.testing.estimator_checks import (
    check_registered_parameters,
    check_synthesizer,
    synthetic_clips,
)
from mocapkit.train.registry import build_method, method_names

TASK = "synthesis"
#: Small settings that keep a method fast on 4 clips of 60 frames (every other parameter is the config's).
FAST = {
    "slfm": ["frame_stride=8", "n_fit=24", "n_inducing=8", "max_iter=2", "noise_scale=1.0"],
    "cvae": ["hidden=16", "latent=4", "steps=5", "batch_size=32"],
}


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    return synthetic_clips(tmp_path_factory.mktemp("clips"), classes=("hopBothLegs1hops",))


@pytest.mark.parametrize("name", method_names(TASK))
def test_parameters(name):
    overrides = FAST.get(name, [])
    check_registered_parameters(TASK, name, overrides)


@pytest.mark.parametrize("name", method_names(TASK))
def test_contract(name, clips):
    check_synthesizer(build_method(TASK, name, FAST.get(name, [])), clips)
