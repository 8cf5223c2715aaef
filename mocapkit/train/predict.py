"""``mocapkit predict --onnx FILE SKELETON...``: classify ``.skeleton`` files with onnxruntime alone.

No PyTorch is imported: this is the deployment path. Files are read with the
numpy reader, reduced to the two main bodies, and fed to the exported model.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

from mocapkit.datasets.ntu_skeleton import read_skeleton, select_main_bodies


def softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=-1, keepdims=True)


def predict_files(onnx_path: str | Path, files: list[str | Path], top: int = 5) -> list[dict]:
    """Top ``top`` classes per file: ``[{"file", "top": [(name, probability), ...]}]``."""
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    class_names = json.loads(meta.get("class_names", "[]"))
    bodies = session.get_inputs()[0].shape[1]
    bodies = bodies if isinstance(bodies, int) else 2
    results = []
    for path in files:
        selection = select_main_bodies(read_skeleton(path), max_bodies=bodies)
        logits = session.run(None, {"skeletons": selection.positions[None]})[0][0]
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
