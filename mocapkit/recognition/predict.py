"""``mocapkit predict --onnx FILE MOTION...``: classify motion files with onnxruntime alone.

No PyTorch is imported: this is the deployment path. NTU ``.skeleton`` files
are reduced to their two main bodies; other formats are read with
``read_motion`` and mapped onto the model's skeleton layout (stored in the
ONNX metadata) when they use another one. A file longer than the ``max_frames`` the model was trained
with (also in the metadata) is subsampled uniformly to that many frames, as the data modules did.

Only an ONNX file is ever loaded (never a checkpoint or a pickle); a file that is not an ONNX model,
a model without a ``skeletons`` input, or a motion with non-finite coordinates is refused with a
``ValueError`` naming the file.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

from mocapkit.datasets.formats.ntu_skeleton import read_skeleton, select_main_bodies
from mocapkit.deploy.runtime import cpu_session
from mocapkit.motion.frames import uniform_frame_indices


def softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=-1, keepdims=True)


def model_input(path: str | Path, layout: str) -> np.ndarray:
    """One file as the model's input ``[1, bodies, frames, joints, 3]`` (float32, metres, zeros = absent)."""
    if Path(path).suffix == ".skeleton":
        return select_main_bodies(read_skeleton(path), max_bodies=2).positions[None]
    from mocapkit.datasets.formats.motion_io import read_motion
    from mocapkit.motion.layouts import LAYOUTS

    motion = read_motion(path)
    if motion.layout_name == layout and layout in LAYOUTS and motion.joint_names != LAYOUTS[layout].joint_names:
        motion = motion.select(list(LAYOUTS[layout].joint_names))  # a C3D labelled with the joints, in its order
    elif motion.layout_name != layout:
        if layout not in LAYOUTS:
            raise ValueError(f"the model's metadata names the skeleton layout {layout!r}; known: {', '.join(LAYOUTS)}")
        motion = motion.map_layout(LAYOUTS[layout])
    return motion.filled(0.0)[None, None]


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return (text.splitlines()[0] if text else type(exc).__name__)[:300]


def open_session(onnx_path: str | Path) -> ort.InferenceSession:
    """An onnxruntime CPU session of ``onnx_path``; anything but a readable ONNX model is a one-line error."""
    onnx_path = Path(onnx_path)
    if not onnx_path.is_file():
        raise FileNotFoundError(f"--onnx {onnx_path}: no such file")
    try:
        return cpu_session(str(onnx_path))
    except Exception as exc:  # onnxruntime's InvalidProtobuf, Fail, ...
        raise ValueError(f"--onnx {onnx_path}: not an ONNX model onnxruntime can load: {_first_line(exc)}") from exc


def predict_files(onnx_path: str | Path, files: list[str | Path], top: int = 5) -> list[dict]:
    """Top ``top`` classes per file: ``[{"file", "top": [(name, probability), ...]}]``."""
    session = open_session(onnx_path)
    meta = session.get_modelmeta().custom_metadata_map
    inputs = [i.name for i in session.get_inputs()]
    if inputs != ["skeletons"]:
        raise ValueError(
            f"--onnx {onnx_path}: expected a skeleton classifier with the one input 'skeletons' "
            f"(mocapkit export of an action run), got inputs {inputs}"
        )
    try:
        class_names = [str(n) for n in json.loads(meta.get("class_names", "[]"))]
    except (ValueError, TypeError) as exc:
        raise ValueError(f"--onnx {onnx_path}: metadata class_names is not a JSON list of names") from exc
    layout = meta.get("layout", "ntu25")
    try:
        max_frames = json.loads(meta.get("max_frames", "null"))
    except (ValueError, TypeError) as exc:
        raise ValueError(f"--onnx {onnx_path}: metadata max_frames is not a JSON number or null") from exc
    results = []
    for path in files:
        x = np.asarray(model_input(path, layout), dtype=np.float32)
        x = x[:, :, uniform_frame_indices(x.shape[2], max_frames)]  # the frames training sampled
        if not np.isfinite(x).all():
            raise ValueError(
                f"{path}: the motion holds {int((~np.isfinite(x)).sum())} NaN or infinite coordinates; "
                "expected finite positions (absent joints as zeros)"
            )
        try:
            logits = session.run(None, {"skeletons": x})[0][0]
        except Exception as exc:  # a shape the model does not take (another layout's joint count, ...)
            raise ValueError(
                f"{path}: the model {Path(onnx_path).name} cannot run on it (input {list(x.shape)}): {_first_line(exc)}"
            ) from exc
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
