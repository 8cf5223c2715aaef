"""``compile=true``: the network is compiled in place before training, and its checkpoints are a plain network's."""

from __future__ import annotations

import pytest
import torch

from mocapkit.train.config import compose_config


def test_compile_is_off_unless_asked():
    assert compose_config().compile is False
    assert compose_config(["compile=true"]).compile is True


@pytest.mark.slow
def test_a_compiled_run_compiles_the_network_and_writes_plain_checkpoints(tmp_path, monkeypatch):
    from mocapkit.models.energy_vgg import EnergyImageClassifier
    from tests.shared_data import tiny_energy_vgg_run

    compiled = []
    # recorded, not compiled: inductor's first compile takes longer than this whole test (bench/RESULTS.md times it)
    monkeypatch.setattr(torch.nn.Module, "compile", lambda self, *a, **k: compiled.append(self))
    run = tiny_energy_vgg_run(tmp_path, "compile=true")
    assert [type(m) for m in compiled] == [EnergyImageClassifier]
    state = torch.load(run / "best.ckpt", weights_only=True)["state_dict"]
    assert all(name.startswith("model.") and "_orig_mod" not in name for name in state)
