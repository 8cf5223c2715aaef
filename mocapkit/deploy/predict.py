"""``mocapkit predict --onnx FILE MOTION...``: classify motion files with onnxruntime alone.

No PyTorch is imported: this is the deployment path. NTU ``.skeleton`` files
are reduced to their two main bodies; other formats are read with
``read_motion`` and mapped onto the model's skeleton layout (stored in the
ONNX metadata) when they use another one.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

from mocapkit.datasets.formats.ntu_skeleton import read_skeleton, select_main_bodies


def softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=-1, keepdims=True)


def model_input(path: str | Path, layout: str) -> np.ndarray:
    """One file as the model's input ``[1, bodies, frames, joints, 3]`` (float32, metres, zeros = absent)."""
    if Path(path).suffix == ".skeleton":
        return select_main_bodies(read_skeleton(path), max_bodies=2).positions[None]
    from mocapkit.datasets.formats.layouts import LAYOUTS
    from mocapkit.datasets.formats.motion_io import read_motion

    motion = read_motion(path)
    if motion.layout_name != layout:
        motion = motion.map_layout(LAYOUTS[layout])
    return motion.filled(0.0)[None, None]


def predict_files(onnx_path: str | Path, files: list[str | Path], top: int = 5) -> list[dict]:
    """Top ``top`` classes per file: ``[{"file", "top": [(name, probability), ...]}]``."""
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    class_names = json.loads(meta.get("class_names", "[]"))
    layout = meta.get("layout", "ntu25")
    results = []
    for path in files:
        logits = session.run(None, {"skeletons": model_input(path, layout)})[0][0]
        probs = softmax(logits)
        order = np.argsort(-probs)[:top]
        names = [class_names[k] if k < len(class_names) else f"A{k + 1:03d}" for k in order]
        results.append({"file": str(path), "top": [(n, float(probs[k])) for n, k in zip(names, order)]})
    return results


def print_predictions(results: list[dict]) -> None:
    for r in results:
        print(Path(r["file"]).name)
        for rank, (name, p) in enumerate(r["top"], 1):
            print(f"  {rank}. {name:<32s} {p:6.1%}")
