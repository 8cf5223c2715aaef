"""Training throughput on CPU: the graph network, the CPU-sized energy-image default and the thesis configuration.

Measures optimiser steps on plausible random skeletons ``[batch, 2, frames, 25, 3]``
(no data loading, so this is the model's own cost) and reports samples/s, the
share of the step spent computing the energy image, and default / faithful as a
ratio. Usage: ``python bench/bench_training.py [--frames 100] [--steps 5]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch
from hydra.utils import instantiate

from mocapkit.recognition.export import example_skeletons
from mocapkit.train.config import compose_config


def measure(model_name: str, batch: int, frames: int, steps: int, num_classes: int = 60) -> dict:
    cfg = compose_config([f"model={model_name}"])
    torch.manual_seed(0)
    model = instantiate(cfg.model, num_classes=num_classes).train()
    optimizer = instantiate(cfg.optimizer)(params=model.parameters())
    x = example_skeletons(batch, frames)
    y = torch.randint(0, num_classes, (batch,))

    def step():
        loss = torch.nn.functional.cross_entropy(model(x), y)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    step()  # warm-up
    start = time.perf_counter()
    for _ in range(steps):
        step()
    step_s = (time.perf_counter() - start) / steps
    energy_s = 0.0
    if hasattr(model, "energy"):  # the energy-image CNNs: how much of the step is the image itself
        with torch.no_grad():
            start = time.perf_counter()
            for _ in range(steps):
                model.energy(x)
            energy_s = (time.perf_counter() - start) / steps
    params = sum(p.numel() for p in model.parameters())
    return {
        "model": model_name,
        "batch": batch,
        "frames": frames,
        "params_M": params / 1e6,
        "step_s": step_s,
        "samples_per_s": batch / step_s,
        "energy_share": energy_s / step_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--steps", type=int, default=5)
    args = parser.parse_args()
    print(
        f"# training throughput, CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads), {args.frames} frames per sample\n"
    )
    rows = [
        measure("stgcn", 32, args.frames, args.steps),
        measure("energy_vgg_cpu", 32, args.frames, args.steps),
        measure("energy_vgg16", 2, args.frames, max(2, args.steps // 2)),
        measure("energy_vgg16", 8, args.frames, max(2, args.steps // 2)),
    ]
    print("| model | batch | params (M) | s / step | samples/s | energy image share |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        share = f"{r['energy_share']:.1%}" if r["energy_share"] else "n/a"
        print(
            f"| {r['model']} | {r['batch']} | {r['params_M']:.2f} | {r['step_s']:.3f} | {r['samples_per_s']:.1f} "
            f"| {share} |"
        )
    print(
        f"\nratio default / faithful (batch 2, the thesis's mini-batch): "
        f"{rows[1]['samples_per_s'] / rows[2]['samples_per_s']:.1f}x; GCN / energy-image default: "
        f"{rows[0]['samples_per_s'] / rows[1]['samples_per_s']:.2f}x"
    )


if __name__ == "__main__":
    main()
