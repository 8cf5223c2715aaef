"""Skeleton action recognition: the Lightning module, evaluation, ONNX export and onnxruntime prediction, and the NTU, MSR Action3D and HDM05 benchmarks."""
