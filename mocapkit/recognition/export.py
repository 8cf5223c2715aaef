"""ONNX export of a skeleton classifier: raw skeletons in, logits out.

The exported graph is the whole skeleton classifier (for the energy-image CNN,
the energy image included): input ``skeletons`` float32
``[batch, bodies, frames, joints, 3]`` (metres, zeros where a body is absent;
batch, bodies and frames dynamic; ``joints`` fixed by the model's layout, 25
for NTU), output ``logits`` ``[batch, classes]``. Deployment needs no Python
preprocessing. Class names and the layout are stored in the model's metadata.
The file is checked with ``onnx.checker`` and onnxruntime is compared with
PyTorch on a batch size, body count and length other than those traced; a
mismatch is an error.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch

from mocapkit.deploy.export import DEFAULT_OPSET, ParityError, save_checked_onnx
from mocapkit.deploy.runtime import cpu_session


def example_skeletons(batch: int, frames: int, bodies: int = 2, joints: int = 25, seed: int = 0) -> torch.Tensor:
    """Plausible random skeletons ``[batch, bodies, frames, joints, 3]`` for tracing and parity checks.

    People stand about 3 m from the camera; the second body is absent (zeros)
    in the first sample and every sample's last frames are zero padding, so
    the checks cover absent bodies and padded frames.
    """
    g = torch.Generator().manual_seed(seed)
    pose = torch.randn(batch, bodies, 1, joints, 3, generator=g) * 0.3
    drift = torch.cumsum(torch.randn(batch, bodies, frames, joints, 3, generator=g) * 0.01, dim=2)
    offset = torch.tensor([0.0, 0.0, 3.0]) + torch.randn(batch, bodies, 1, 1, 3, generator=g) * 0.4
    x = pose + drift + offset
    x[0, 1:] = 0.0
    x[:, :, frames - max(1, frames // 8) :] = 0.0
    return x


def export_onnx(
    model: torch.nn.Module,
    out: str | Path,
    class_names: list[str] | None = None,
    opset: int = DEFAULT_OPSET,
    trace_shape: tuple[int, int] = (2, 64),
    check_shape: tuple[int, int] = (3, 97),
    atol: float = 1e-4,
    rtol: float = 1e-3,
    max_frames: int | None = None,
) -> dict:
    """Export ``model`` (skeletons → logits) to ``out`` and check it; return the parity figures.

    ``max_frames`` (the training data's ``data.max_frames``) goes into the metadata: ``mocapkit predict``
    subsamples a longer input uniformly to that many frames, as the data modules did in training
    (:func:`~mocapkit.motion.frames.uniform_frame_indices`).

    ``trace_shape`` and ``check_shape`` are ``(batch, frames)``; the trace uses 2 bodies and
    the check 1, so the parity check also covers a different body count. The joint count
    comes from ``model.layout`` (25 when the model has none).

    Raises:
        ParityError: onnxruntime differs from PyTorch beyond ``atol + rtol * |reference|``.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval().cpu()
    layout = getattr(model, "layout", None)
    joints = layout.num_joints if layout is not None else 25
    trace_input = example_skeletons(trace_shape[0], trace_shape[1], 2, joints, seed=0)
    batch = torch.export.Dim("batch", min=1, max=65536)
    bodies = torch.export.Dim("bodies", min=1, max=16)
    frames = torch.export.Dim("frames", min=2, max=1_000_000)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        # optimize=False: onnxscript's graph optimiser left this graph out of topological
        # order (rejected by onnx.checker) when we tried it; the unoptimised graph is correct.
        program = torch.onnx.export(
            model,
            (trace_input,),
            None,
            input_names=["skeletons"],
            output_names=["logits"],
            dynamic_shapes={"skeletons": {0: batch, 1: bodies, 2: frames}},
            dynamo=True,
            opset_version=opset,
            optimize=False,
            verbose=False,
        )
    proto = program.model_proto  # weights inline: one self-contained file (VGG16 is ~0.5 GB, under protobuf's 2 GB)
    meta = {
        "class_names": json.dumps(class_names or []),
        "layout": layout.name if layout is not None else "ntu25",
        "joint_names": json.dumps(list(layout.joint_names) if layout is not None else []),
        "input": f"skeletons float32 [batch, bodies, frames, {joints}, 3], metres, zeros where a body is absent",
        "output": "logits float32 [batch, classes]",
        "producer": "mocapkit",
        "max_frames": json.dumps(None if max_frames is None else int(max_frames)),
    }
    save_checked_onnx(proto, meta, out)

    session = cpu_session(str(out))
    checks = []
    for bodies_checked in (2, 1):
        check_input = example_skeletons(check_shape[0], check_shape[1], bodies_checked, joints, seed=bodies_checked)
        with torch.no_grad():
            reference = model(check_input).numpy()
        result = session.run(["logits"], {"skeletons": check_input.numpy()})[0]
        checks.append(
            {
                "shape": list(check_input.shape),
                "max_abs_diff": float(np.abs(result - reference).max()),
                "max_abs_logit": float(np.abs(reference).max()),
                "same_top1": bool((result.argmax(1) == reference.argmax(1)).all()),
            }
        )
        if not np.allclose(result, reference, atol=atol, rtol=rtol):
            raise ParityError(
                f"onnxruntime differs from PyTorch on input {list(check_input.shape)}: "
                f"max |diff| = {checks[-1]['max_abs_diff']:.3g} > atol {atol} + rtol {rtol}·|ref|"
            )
    report = {
        "onnx": str(out),
        "opset": opset,
        "layout": meta["layout"],
        "traced_shape": list(trace_input.shape),
        "checked_shape": checks[0]["shape"],
        "checks": checks,
        "max_abs_diff": max(c["max_abs_diff"] for c in checks),
        "atol": atol,
        "rtol": rtol,
        "same_top1": all(c["same_top1"] for c in checks),
    }
    return report


def export_action_module(module, target: Path, export_cfg) -> dict:
    """Export a skeleton classifier with the ``export`` config node (opset, trace/check shapes, tolerances)."""
    return export_onnx(
        module.model,
        target,
        class_names=module.hparams.class_names,
        opset=export_cfg.opset,
        trace_shape=(export_cfg.trace_batch, export_cfg.trace_frames),
        check_shape=(export_cfg.check_batch, export_cfg.check_frames),
        atol=export_cfg.atol,
        rtol=export_cfg.rtol,
        max_frames=export_cfg.get("max_frames"),
    )
