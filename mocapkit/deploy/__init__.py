"""Deployment: ONNX export with an onnxruntime parity check (``export``, ``skeleton_export``,
``gait_export``) and ONNX-only prediction (``predict``, which needs onnxruntime and numpy alone:
nothing in this package is imported here)."""
