"""``mocapkit export ckpt_path=RUN/best.ckpt [out=FILE] [export.KEY=...]``: a checkpoint as one ONNX file.

:func:`export_checkpoint` composes the run's saved config again with the overrides, restores the
LightningModule of ``module._target_`` and calls the exporter named by ``export.exporter._target_``
(:func:`~mocapkit.recognition.export.export_action_module` or
:func:`~mocapkit.gait.export.export_gait_module`). Every exporter writes the file with
:func:`save_checked_onnx` (metadata, ``onnx.checker``) and compares onnxruntime with PyTorch on
shapes other than those traced; a mismatch raises :class:`ParityError`. The parity figures go
beside the model as ``<stem>.parity.json``. Both files are written atomically (a temporary file in the same
folder, fsynced, then renamed: :mod:`mocapkit.io_atomic`), and the run's config and the checkpoint are
vetted before anything is built (:mod:`mocapkit.train.safety`).
"""

from __future__ import annotations

import json
from pathlib import Path

import onnx

from mocapkit.io_atomic import atomic_path, atomic_write_text

#: ONNX opset of every dynamo export (the configs' ``export.opset``): from opset 20 GELU is ONNX's own operator,
#: which onnxruntime runs fused (the refiner transformer's export 3–4 % faster than at opset 18:
#: bench/RESULTS.md#onnx-runtime-costs).
DEFAULT_OPSET = 20


class ParityError(RuntimeError):
    """onnxruntime and PyTorch disagree on the exported model."""


def save_checked_onnx(proto: onnx.ModelProto, meta: dict[str, str], out: Path) -> None:
    """Add ``meta`` as the model's metadata, run ``onnx.checker`` (full check) and write ``out``."""
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto, full_check=True)
    with atomic_path(out) as tmp:  # a kill mid-write leaves the previous model
        onnx.save(proto, str(tmp))


def export_checkpoint(ckpt_path: str | Path, out: str | None = None, overrides: list[str] | None = None) -> dict:
    """``mocapkit export ckpt_path=... [out=FILE] [export.KEY=...]``: export as the run's task does."""
    from mocapkit.train.checkpoints import checkpoint_config, load_module
    from mocapkit.train.config import ConfigError
    from mocapkit.train.training import build

    ckpt_path = Path(ckpt_path)
    cfg = checkpoint_config(ckpt_path, [o for o in overrides or [] if not o.startswith("ckpt_path=")])
    target = Path(out or cfg.export.out or ckpt_path.parent / "model.onnx")
    key = "out" if out else "export.out"
    if target.is_dir() or str(out or "").endswith(("/", "\\")):
        raise ConfigError(f"{key}={target}: is a folder; expected the ONNX file to write, e.g. {target / 'model.onnx'}")
    if target.parent.exists() and not target.parent.is_dir():
        raise ConfigError(f"{key}={target}: {target.parent} is not a folder")
    module = load_module(cfg, ckpt_path)
    report = build(cfg.export.exporter)(module, target, cfg.export)
    atomic_write_text(target.parent / (target.stem + ".parity.json"), json.dumps(report, indent=2))
    print(f"[mocapkit] wrote {target} (onnx.checker passed)")
    diff = report["max_abs_diff"]  # one number, or one per output for multi-output models
    diff = max(diff.values()) if isinstance(diff, dict) else diff
    top1 = f", same top-1: {report['same_top1']}" if "same_top1" in report else ""
    print(
        f"[mocapkit] parity on {report['checked_shape']} (traced with {report['traced_shape']}): "
        f"max |onnxruntime - torch| = {diff:.2e}{top1}"
    )
    print(f"[mocapkit] wrote {target.parent / (target.stem + '.parity.json')}")
    return report
