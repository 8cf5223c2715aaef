"""Timing helper shared by the benchmarks (run as scripts: ``python bench/<name>.py``, so this folder is on the path)."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_of(tasks: dict[str, Callable], repeat: int) -> dict[str, float]:
    """``{name: best wall seconds}`` over ``repeat`` interleaved rounds (the load hits every task alike)."""
    best = {name: float("inf") for name in tasks}
    for _ in range(repeat):
        for name, task in tasks.items():
            t = time.perf_counter()
            task()
            best[name] = min(best[name], time.perf_counter() - t)
    return best
