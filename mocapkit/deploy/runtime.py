"""Opening an exported model with onnxruntime on the CPU: one place for every session mocapkit creates (exports'
parity checks, ``predict``, the ONNX refiners, Kinect correctors and embedding indexes). Needs onnxruntime alone."""

from __future__ import annotations

import os


def cpu_session(path: str | os.PathLike, threads: int = 0):
    """An ``onnxruntime.InferenceSession`` of ``path`` on the CPU execution provider.

    Args:
        threads: intra-op threads (0: onnxruntime's default).

    onnxruntime's log is kept to errors: at warning level it prints, for every session of a ``torch.export``
    graph, that it cannot constant-fold the ``CastLike`` nodes the exporter writes (harmless: they run at
    inference), lines a user of ``mocapkit refine --onnx`` or ``kinect-fix apply`` cannot act on.
    """
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.log_severity_level = 3
    if threads:
        options.intra_op_num_threads = int(threads)
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
