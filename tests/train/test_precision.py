"""``trainer.precision=auto``: bf16-mixed where the device has bfloat16, float32 elsewhere, overridable; a run
trained in bf16-mixed still evaluates and exports in float32."""

from __future__ import annotations

import pytest
import torch

import mocapkit.train.training as training
from mocapkit.train.config import compose_config


def test_the_default_is_auto_and_resolves_by_the_cpu(monkeypatch):
    assert compose_config(config_name="trainer/default").trainer.precision == "auto"
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(training, "cpu_has_bf16", lambda: True)
    assert training.auto_precision("auto") == training.auto_precision("cpu") == "bf16-mixed"
    assert training.build_trainer(logger=False, enable_checkpointing=False).precision == "bf16-mixed"
    monkeypatch.setattr(training, "cpu_has_bf16", lambda: False)
    assert training.auto_precision("auto") == "32-true"
    assert training.build_trainer(logger=False, enable_checkpointing=False).precision == "32-true"


def test_a_gpu_decides_by_its_own_bf16_support(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(training, "cpu_has_bf16", lambda: True)
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda *a, **k: False)
    assert training.auto_precision("auto") == training.auto_precision("gpu") == "32-true"
    assert training.auto_precision("cpu") == "bf16-mixed"  # an explicit CPU run on a GPU machine
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda *a, **k: True)
    assert training.auto_precision("cuda") == "bf16-mixed"
    assert training.auto_precision("mps") == "32-true"


def test_an_explicit_precision_wins_and_estimators_stay_float32(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(training, "cpu_has_bf16", lambda: True)
    cfg = compose_config(["trainer.precision=32-true"])
    assert training.build_trainer(cfg.trainer, logger=False, enable_checkpointing=False).precision == "32-true"
    assert training.build_trainer(precision="bf16-mixed", logger=False).precision == "bf16-mixed"
    assert training.build_estimator_trainer(3).precision == "32-true"
    assert training.build_estimator_trainer(3, {"precision": "auto"}).precision == "bf16-mixed"


def test_the_cpu_check_reads_the_flags(monkeypatch, tmp_path):
    """AVX-512 BF16 among the /proc/cpuinfo flags counts (torch reports AMX only; this CPU is an AMD EPYC)."""
    monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: False)
    real = training.Path

    def fake_path(flags):
        info = tmp_path / "cpuinfo"
        info.write_text(f"processor : 0\nflags : fpu sse2 avx2 {flags}\n")
        return lambda p, *a: real(info) if str(p) == "/proc/cpuinfo" else real(p, *a)

    monkeypatch.setattr(training, "Path", fake_path("avx512f avx512_bf16"))
    assert training.cpu_has_bf16()
    monkeypatch.setattr(training, "Path", fake_path("avx512f avx512_vnni"))
    assert not training.cpu_has_bf16()


@pytest.mark.slow
def test_a_bf16_run_exports_a_float32_onnx(tmp_path):
    import onnx

    from mocapkit.cli import main
    from tests.shared_data import tiny_energy_vgg_run

    run = tiny_energy_vgg_run(tmp_path, "trainer.precision=bf16-mixed")
    state = torch.load(run / "best.ckpt", weights_only=True)["state_dict"]
    assert {v.dtype for v in state.values() if v.is_floating_point()} == {torch.float32}
    assert main(["export", f"ckpt_path={run / 'best.ckpt'}", f"out={tmp_path / 'm.onnx'}"]) == 0
    graph = onnx.load(str(tmp_path / "m.onnx")).graph
    float32 = onnx.TensorProto.FLOAT
    assert [i.type.tensor_type.elem_type for i in graph.input] == [float32]
    assert {o.type.tensor_type.elem_type for o in graph.output} == {float32}
    assert all(t.data_type != onnx.TensorProto.BFLOAT16 for t in graph.initializer)
