"""ONNX export of a motion-embedding run: ``mocapkit export ckpt_path=RUN/best.ckpt`` for ``task=embedding``.

    landmarks  float32 [batch, frames, 20, 3]   normalised landmarks (mocapkit.motion.geometry), metres
    embedding  float32 [batch, dim]             L2-normalised (compare by inner product = cosine)

``batch`` and ``frames`` are dynamic (the network pools over time; it was trained on clips resampled to the
``frames`` of the metadata, which :class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval` does again). The
metadata key ``mocapkit_embedding`` holds JSON: ``fps``, ``frames``, ``heading``, ``landmark_names``,
``embedding_dim``, ``loss``, ``temperature``, ``class_names`` and ``training_data`` (data set, label, groups).
Parity with PyTorch is checked with onnxruntime on a batch size and a length other than the traced ones.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch

from mocapkit.deploy.export import DEFAULT_OPSET, ParityError, save_checked_onnx
from mocapkit.deploy.runtime import cpu_session

#: The metadata key of the model's description (read by :class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval`).
META_KEY = "mocapkit_embedding"


def example_landmarks(batch: int, frames: int, seed: int = 0) -> torch.Tensor:
    """A smooth random ``[batch, frames, 20, 3]`` float32 take of about a body's size (metres)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, frames)[None, :, None, None]
    base = rng.normal(0, 0.4, (batch, 1, 20, 3)) + 0.1 * np.sin(t + rng.uniform(0, 6, (batch, 1, 20, 3)))
    return torch.from_numpy(base.astype(np.float32))


def embedding_metadata(module) -> dict:
    """The ``mocapkit_embedding`` description of a :class:`~mocapkit.retrieval.module.MotionEmbeddingModule`."""
    hp = module.hparams
    source = dict(hp.source or {})
    return {
        "fps": source.get("fps", 30.0),
        "frames": source.get("frames", 64),
        "heading": source.get("heading", "frame"),
        "landmark_names": source.get("landmark_names"),
        "embedding_dim": int(module.model.embedding_dim),
        "loss": hp.loss,
        "temperature": hp.temperature,
        "class_names": list(hp.class_names or []),
        "training_data": {k: source.get(k) for k in ("dataset", "label", "train_groups", "test_groups", "groups")},
    }


def export_encoder(
    model: torch.nn.Module,
    out: str | Path,
    description: dict,
    opset: int = DEFAULT_OPSET,
    trace_shape: tuple[int, int] = (2, 64),
    check_shape: tuple[int, int] = (3, 97),
    atol: float = 1e-4,
    rtol: float = 1e-3,
) -> dict:
    """Export ``model`` (landmarks → embedding) to ``out``, check it with onnxruntime, return the figures.

    Raises:
        ParityError: onnxruntime differs from PyTorch beyond ``atol + rtol · |reference|``.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval().cpu()
    trace = example_landmarks(*trace_shape, seed=0)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        batch = torch.export.Dim("batch", min=1, max=65536)
        frames = torch.export.Dim("frames", min=8, max=100_000)
        proto = torch.onnx.export(
            model,
            (trace,),
            None,
            input_names=["landmarks"],
            output_names=["embedding"],
            dynamic_shapes={"landmarks": {0: batch, 1: frames}},
            dynamo=True,
            opset_version=opset,
            optimize=False,
            verbose=False,
        ).model_proto
    dim = int(description.get("embedding_dim", 0))
    meta = {
        META_KEY: json.dumps(description),
        "producer": "mocapkit",
        "input": "landmarks float32 [batch, frames, 20, 3] (mocapkit.motion.geometry.normalised_landmarks, "
        f"resampled to {description.get('frames')} frames)",
        "output": f"embedding float32 [batch, {dim}] L2-normalised",
    }
    save_checked_onnx(proto, meta, out)
    session = cpu_session(str(out))
    checks = []
    for shape, seed in ((check_shape, 1), ((1, max(8, check_shape[1] // 3 + 5)), 2)):
        landmarks = example_landmarks(*shape, seed=seed)
        with torch.no_grad():
            reference = model(landmarks).numpy()
        result = session.run(["embedding"], {"landmarks": landmarks.numpy()})[0]
        diff = float(np.abs(result - reference).max())
        checks.append({"shape": list(landmarks.shape), "max_abs_diff": diff})
        if (
            result.shape != reference.shape
            or not np.all(np.isfinite(result))
            or not np.allclose(result, reference, atol=atol, rtol=rtol)
        ):
            raise ParityError(
                f"onnxruntime differs from PyTorch on input {list(landmarks.shape)}: max |diff| = "
                f"{diff:.3g} > atol {atol} + rtol {rtol}·|ref|"
            )
    return {
        "onnx": str(out),
        "opset": opset,
        "exporter": "dynamo",
        "traced_shape": list(trace.shape),
        "checked_shape": checks[0]["shape"],
        "checks": checks,
        "max_abs_diff": max(c["max_abs_diff"] for c in checks),
        "atol": atol,
        "rtol": rtol,
    }


def export_embedding_module(module, target: Path, export_cfg) -> dict:
    """Export a :class:`~mocapkit.retrieval.module.MotionEmbeddingModule` with the ``export`` config node."""
    return export_encoder(
        module.model,
        target,
        embedding_metadata(module),
        opset=export_cfg.opset,
        trace_shape=(export_cfg.trace_batch, export_cfg.trace_frames),
        check_shape=(export_cfg.check_batch, export_cfg.check_frames),
        atol=export_cfg.atol,
        rtol=export_cfg.rtol,
    )


__all__ = ["META_KEY", "embedding_metadata", "example_landmarks", "export_embedding_module", "export_encoder"]
