"""Training throughput of the multi-task gait CNN on CPU, in GEIs per second.

Measures full SGD steps (forward, joint three-task cross-entropy, backward, update) on random
GEIs ``[32, 1, H, W]`` (no data loading, so this is the network's own cost) at the thesis's
124×124 and OpenGait's 64×44, for the three-task network and the single-task (subject) one,
and reports the ratios in the same run. Usage: ``python bench/bench_gait_training.py [--steps 5] [--batch 32]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch
import torch.nn.functional as F

from mocapkit.gait.export import example_geis
from mocapkit.models.gait_cnn import multitask_gait_cnn


def measure(tasks: tuple[str, ...], size: tuple[int, int], batch: int, steps: int, num_subjects: int = 124) -> dict:
    torch.manual_seed(0)
    model = multitask_gait_cnn(num_subjects, tasks=tasks, input_size=size).train()
    optimizer = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.9, weight_decay=5e-4)  # thesis recipe
    x = example_geis(batch, *size)
    labels = {
        "subject": torch.randint(0, num_subjects, (batch,)),
        "view": torch.randint(0, 11, (batch,)),
        "condition": torch.randint(0, 3, (batch,)),
    }

    def step():
        out = model(x)
        loss = sum(F.cross_entropy(out[t], labels[t]) for t in tasks)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    step()  # warm-up
    start = time.perf_counter()
    for _ in range(steps):
        step()
    step_s = (time.perf_counter() - start) / steps
    params = sum(p.numel() for p in model.parameters())
    return {
        "tasks": "+".join(tasks),
        "size": f"{size[0]}x{size[1]}",
        "batch": batch,
        "params_M": params / 1e6,
        "step_s": step_s,
        "geis_per_s": batch / step_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--batch", type=int, default=32)
    args = parser.parse_args()
    print(
        f"# gait CNN training throughput, CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads), batch {args.batch}, 124 subjects\n"
    )
    multi, single = ("subject", "view", "condition"), ("subject",)
    rows = [
        measure(multi, (124, 124), args.batch, args.steps),
        measure(single, (124, 124), args.batch, args.steps),
        measure(multi, (64, 44), args.batch, args.steps),
        measure(single, (64, 44), args.batch, args.steps),
    ]
    print("| network | GEI size | batch | params (M) | s / step | GEIs/s |")
    print("|---|---|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['tasks']} | {r['size']} | {r['batch']} | {r['params_M']:.2f} | {r['step_s']:.3f} "
            f"| {r['geis_per_s']:.1f} |"
        )
    print(
        f"\nratio 64x44 / 124x124 (multi-task): {rows[2]['geis_per_s'] / rows[0]['geis_per_s']:.1f}x; "
        f"single-task / multi-task at 124x124: {rows[1]['geis_per_s'] / rows[0]['geis_per_s']:.2f}x, "
        f"at 64x44: {rows[3]['geis_per_s'] / rows[2]['geis_per_s']:.2f}x"
    )


if __name__ == "__main__":
    main()
