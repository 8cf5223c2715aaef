"""ONNX export of the multi-task gait CNN: GEIs in, per-task logits and the gallery embedding out.

The graph takes ``geis`` float32 ``[batch, 1, H, W]`` (GEI pixel values in [0, 1]; batch dynamic,
H and W fixed by ``model.input_size``) and returns, in this order, ``subject_logits``,
``view_logits``, ``condition_logits`` (those the model has) and ``embedding`` ``[batch, 512]``
(the shared FC activation used for gallery/probe matching). Softmax is not in the graph.
The metadata holds the subject names, the view labels (degrees), the conditions and the tasks.
The file is checked with ``onnx.checker`` and onnxruntime is compared with PyTorch on a batch
size other than the traced one; a mismatch raises :class:`~mocapkit.deploy.export.ParityError`.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.deploy.export import DEFAULT_OPSET, ParityError, save_checked_onnx
from mocapkit.deploy.runtime import cpu_session


class _OutputTuple(nn.Module):
    """The gait network with its output dict flattened to a tuple in the exported order."""

    def __init__(self, model: nn.Module, names: list[str]):
        super().__init__()
        self.model, self.keys = model, [n.removesuffix("_logits") for n in names]

    def forward(self, geis: torch.Tensor) -> tuple[torch.Tensor, ...]:
        out = self.model(geis)
        return tuple(out[k] for k in self.keys)


def example_geis(batch: int, height: int, width: int, seed: int = 0) -> torch.Tensor:
    """Plausible random GEIs ``[batch, 1, height, width]`` in [0, 1]: a soft upright body blob plus noise."""
    g = torch.Generator().manual_seed(seed)
    yy = torch.linspace(-1, 1, height).view(1, 1, -1, 1)
    xx = torch.linspace(-1, 1, width).view(1, 1, 1, -1)
    cx = (torch.rand(batch, 1, 1, 1, generator=g) - 0.5) * 0.4
    w = 0.15 + 0.2 * torch.rand(batch, 1, 1, 1, generator=g)
    body = torch.exp(-((yy / 0.7) ** 2 + ((xx - cx) / w) ** 2))
    return (body + 0.1 * torch.rand(batch, 1, height, width, generator=g)).clamp(0, 1)


def export_gait_onnx(
    model: nn.Module,
    out: str | Path,
    subject_names: list[str] | None = None,
    opset: int = DEFAULT_OPSET,
    trace_batch: int = 2,
    check_batch: int = 3,
    atol: float = 1e-4,
    rtol: float = 1e-3,
) -> dict:
    """Export a :class:`~mocapkit.models.gait_cnn.MultiTaskGaitCNN` to ``out`` and check it; return the parity figures.

    Returns:
        ``{"onnx", "opset", "outputs", "traced_shape", "checked_shape", "checks": {output: {...}},
        "max_abs_diff": {output: float}, "same_top1": bool (all logits outputs), "atol", "rtol"}``.
    Raises:
        ParityError: an output of onnxruntime differs from PyTorch beyond ``atol + rtol * |reference|``.
    """
    if trace_batch == check_batch:
        raise ValueError(
            f"export: check_batch={check_batch} must differ from trace_batch so the dynamic batch is checked"
        )
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval().cpu()
    height, width = model.input_size
    names = [f"{task}_logits" for task in model.tasks] + ["embedding"]
    wrapped = _OutputTuple(model, names).eval()
    trace_input = example_geis(trace_batch, height, width, seed=0)
    batch = torch.export.Dim("batch", min=1, max=65536)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        # optimize=False: as in export_onnx, onnxscript's optimiser is skipped; the unoptimised graph is correct.
        program = torch.onnx.export(
            wrapped,
            (trace_input,),
            None,
            input_names=["geis"],
            output_names=names,
            dynamic_shapes={"geis": {0: batch}},
            dynamo=True,
            opset_version=opset,
            optimize=False,
            verbose=False,
        )
    proto = program.model_proto
    meta = {
        "subject_names": json.dumps(list(subject_names or [])),
        "views": json.dumps(list(VIEWS)),
        "conditions": json.dumps(list(CONDITIONS)),
        "tasks": json.dumps(list(model.tasks)),
        "input": f"geis float32 [batch, 1, {height}, {width}], Gait Energy Image pixel values in [0, 1]",
        "outputs": json.dumps(names),
        "producer": "mocapkit",
    }
    save_checked_onnx(proto, meta, out)

    session = cpu_session(str(out))
    check_input = example_geis(check_batch, height, width, seed=1)
    with torch.no_grad():
        reference = [t.numpy() for t in wrapped(check_input)]
    results = session.run(names, {"geis": check_input.numpy()})
    checks = {}
    for name, ref, res in zip(names, reference, results):
        if res.shape != ref.shape:
            raise ParityError(f"onnxruntime output {name} has shape {list(res.shape)}, PyTorch {list(ref.shape)}")
        checks[name] = {
            "shape": list(ref.shape),
            "max_abs_diff": float(np.abs(res - ref).max()),
            "max_abs_value": float(np.abs(ref).max()),
        }
        if name != "embedding":
            checks[name]["same_top1"] = bool((res.argmax(1) == ref.argmax(1)).all())
        if not np.allclose(res, ref, atol=atol, rtol=rtol):
            raise ParityError(
                f"onnxruntime differs from PyTorch on {name} for input {list(check_input.shape)}: "
                f"max |diff| = {checks[name]['max_abs_diff']:.3g} > atol {atol} + rtol {rtol}·|ref|"
            )
    return {
        "onnx": str(out),
        "opset": opset,
        "outputs": names,
        "traced_shape": list(trace_input.shape),
        "checked_shape": list(check_input.shape),
        "checks": checks,
        "max_abs_diff": {name: c["max_abs_diff"] for name, c in checks.items()},
        "same_top1": all(c.get("same_top1", True) for c in checks.values()),
        "atol": atol,
        "rtol": rtol,
    }


def export_gait_module(module, target: str | Path, export_cfg) -> dict:
    """Export a :class:`~mocapkit.gait.module.GaitRecognitionModule` with the ``cfg.export`` settings.

    Uses ``opset``, ``trace_batch``, ``check_batch``, ``atol`` and ``rtol`` of ``export_cfg`` (a DictConfig or dict;
    the skeleton-only ``trace_frames`` / ``check_frames`` are ignored). ``mocapkit export`` writes the returned
    report beside the model as ``<target stem>.parity.json``.
    """
    return export_gait_onnx(
        module.model,
        Path(target),
        subject_names=module.hparams.subject_names,
        **{key: export_cfg[key] for key in ("opset", "trace_batch", "check_batch", "atol", "rtol")},
    )
