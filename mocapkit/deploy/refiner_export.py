"""ONNX export of a learned refiner run: ``mocapkit export ckpt_path=RUN/best.ckpt`` for ``task=refine``.

The graph takes the raw take and returns refined positions; the normalisation (centre, heading, body size),
the cubic first guess and the inverse normalisation are inside it (:mod:`mocapkit.models.refiners`):

    positions  float32 [batch, frames, joints, 3]   metres (anything where missing)
    missing    bool    [batch, frames, joints]      True where a joint is not observed
    refined    float32 [batch, frames, joints, 3]   metres

``batch`` and ``frames`` are dynamic. Recurrent networks go through the TorchScript exporter (ONNX's GRU
op; opset ≤ 17), the others through ``torch.export`` (``dynamo=True``). The skeleton (joint names, parents, up axis, frame rate, training window)
is stored as JSON in the metadata key ``mocapkit_skeleton``, which :class:`~mocapkit.refinement.learned.OnnxRefiner`
(``mocapkit refine --onnx FILE IN OUT``) reads. Parity with PyTorch is checked on a batch size and a length other
than the traced ones, with gaps, a joint missing throughout and NaN in missing entries.
"""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

import numpy as np
import onnx
import torch

from mocapkit.deploy.export import DEFAULT_OPSET, ParityError, save_checked_onnx
from mocapkit.deploy.runtime import cpu_session


def example_take(batch: int, frames: int, joints: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """A smooth random take ``[batch, frames, joints, 3]`` (metres, about a body's size) with gaps: 20 % of the
    entries missing at random, a 30-frame gap in joint 1 and joint 2 missing in every frame (NaN there)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, frames)[None, :, None, None]
    base = rng.normal(0, 0.4, (batch, 1, joints, 3)) + 0.05 * np.sin(t + rng.uniform(0, 6, (batch, 1, joints, 3)))
    missing = rng.random((batch, frames, joints)) < 0.2
    missing[:, frames // 3 : frames // 3 + min(30, frames // 3), 1 % joints] = True
    missing[:, :, 2 % joints] = True
    missing[:, 0, 0] = False
    positions = np.where(missing[..., None], np.nan, base).astype(np.float32)
    return torch.from_numpy(positions), torch.from_numpy(missing)


def export_refiner(
    model: torch.nn.Module,
    out: str | Path,
    skeleton: dict,
    opset: int = DEFAULT_OPSET,
    trace_shape: tuple[int, int] = (2, 64),
    check_shape: tuple[int, int] = (3, 150),
    atol: float = 1e-4,
    rtol: float = 1e-3,
) -> dict:
    """Export ``model`` (positions, missing → refined) to ``out``, check it with onnxruntime, return the figures.

    Raises:
        ParityError: onnxruntime differs from PyTorch beyond ``atol + rtol · |reference|`` (metres).
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval().cpu()
    joints = len(skeleton["joint_names"])
    trace = example_take(trace_shape[0], trace_shape[1], joints, seed=0)
    recurrent = any(isinstance(m, torch.nn.RNNBase) for m in model.modules())
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        if recurrent:
            # torch.export unrolls a GRU frame by frame over the traced length (slow, and a second export in one
            # process came out with the frame count fixed); the TorchScript exporter writes ONNX's own GRU op
            buffer = io.BytesIO()
            torch.onnx.export(
                model,
                trace,
                buffer,
                input_names=["positions", "missing"],
                output_names=["refined"],
                dynamic_axes={name: {0: "batch", 1: "frames"} for name in ("positions", "missing", "refined")},
                dynamo=False,
                opset_version=min(opset, 17),
            )
            proto = onnx.load_from_string(buffer.getvalue())
        else:
            batch = torch.export.Dim("batch", min=1, max=65536)
            frames = torch.export.Dim("frames", min=2, max=100_000)
            proto = torch.onnx.export(
                model,
                trace,
                None,
                input_names=["positions", "missing"],
                output_names=["refined"],
                dynamic_shapes={"positions": {0: batch, 1: frames}, "missing": {0: batch, 1: frames}},
                dynamo=True,
                opset_version=opset,
                optimize=False,
                verbose=False,
            ).model_proto
    meta = {
        "mocapkit_skeleton": json.dumps(skeleton),
        "producer": "mocapkit",
        "input": f"positions float32 [batch, frames, {joints}, 3] metres; missing bool [batch, frames, {joints}]",
        "output": f"refined float32 [batch, frames, {joints}, 3] metres",
    }
    save_checked_onnx(proto, meta, out)
    session = cpu_session(str(out))
    checks = []
    for shape, seed in ((check_shape, 1), ((1, max(2, check_shape[1] // 3 + 7)), 2)):
        positions, missing = example_take(shape[0], shape[1], joints, seed=seed)
        with torch.no_grad():
            reference = model(positions, missing).numpy()
        result = session.run(["refined"], {"positions": positions.numpy(), "missing": missing.numpy()})[0]
        diff = float(np.abs(result - reference).max())
        checks.append(
            {"shape": list(positions.shape), "max_abs_diff": diff, "max_abs_value": float(np.abs(reference).max())}
        )
        if not np.all(np.isfinite(result)) or not np.allclose(result, reference, atol=atol, rtol=rtol):
            raise ParityError(
                f"onnxruntime differs from PyTorch on input {list(positions.shape)}: max |diff| = "
                f"{diff:.3g} m > atol {atol} + rtol {rtol}·|ref|"
            )
    return {
        "onnx": str(out),
        "opset": min(opset, 17) if recurrent else opset,
        "exporter": "torchscript" if recurrent else "dynamo",
        "traced_shape": list(trace[0].shape),
        "checked_shape": checks[0]["shape"],
        "checks": checks,
        "max_abs_diff": max(c["max_abs_diff"] for c in checks),
        "atol": atol,
        "rtol": rtol,
    }


def export_refinement_module(module, target: Path, export_cfg) -> dict:
    """Export a :class:`~mocapkit.train.refine_module.MotionRefinementModule` with the ``export`` config node."""
    return export_refiner(
        module.model,
        target,
        dict(module.hparams.skeleton),
        opset=export_cfg.opset,
        trace_shape=(export_cfg.trace_batch, export_cfg.trace_frames),
        check_shape=(export_cfg.check_batch, export_cfg.check_frames),
        atol=export_cfg.atol,
        rtol=export_cfg.rtol,
    )
