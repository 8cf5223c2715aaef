"""Inference latency of the exported model: onnxruntime vs PyTorch eager, batch 1 and 32.

Exports the CPU-sized default (random weights; latency does not depend on them)
and the thesis VGG16 configuration, then times both runtimes on the same
inputs of ``--frames`` frames. Reports milliseconds per batch and eager / ORT
as a ratio. Usage: ``python bench/bench_onnx_latency.py [--frames 100]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import onnxruntime as ort
import torch
from hydra.utils import instantiate

from mocapkit.recognition.export import example_skeletons, export_onnx
from mocapkit.train.config import compose_config


def best_of(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    print(
        f"# inference latency, CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, onnxruntime {ort.__version__}), {args.frames} frames, best of {args.repeats}\n"
    )
    print("| model | batch | torch eager (ms) | onnxruntime (ms) | eager / ORT |")
    print("|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for model_name, batches in (("energy_vgg_cpu", (1, 32)), ("energy_vgg16", (1, 32))):
            cfg = compose_config([f"model={model_name}"])
            torch.manual_seed(0)
            model = instantiate(cfg.model, num_classes=60).eval()
            path = Path(tmp) / f"{model_name}.onnx"
            export_onnx(model, path)
            session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
            for batch in batches:
                x = example_skeletons(batch, args.frames, seed=2)
                repeats = args.repeats if model_name == "energy_vgg_cpu" else max(2, args.repeats // 4)
                with torch.no_grad():
                    eager = best_of(lambda: model(x), repeats)  # noqa: B023 (called here, in this iteration)
                onnx = best_of(lambda: session.run(None, {"skeletons": x.numpy()}), repeats)  # noqa: B023
                print(f"| {model_name} | {batch} | {eager * 1e3:.1f} | {onnx * 1e3:.1f} | {eager / onnx:.2f} |")


if __name__ == "__main__":
    main()
