"""Benchmark: a timing table like Wang 2017 Table 4.1 on HDM05 — TrNN against its ``truncation = 0`` (TSMC-style)
variant and SVT on sequences of the table's lengths (152 … 17,799 frames), with the scaling exponent in frames.

This reuses ``bench/bench_trnn.py`` (its Table 4.1 rows, its clip concatenation and its timed ``refine`` call)
instead of duplicating it; that script reads CMU clips first and prints per-iteration costs, this one takes
**HDM05 clips only** (``hdm05_cuts11``, all performers in a fixed order, concatenated and cut at each length,
each clip shifted on the floor to start where the previous one ended; 56,733 frames at 120 fps in all) and fits
the **scaling exponent** ``b`` of ``seconds ≈ a · frames^b`` by least squares on log–log (over every row, and
over the rows of ≥ 1,000 frames). Each sequence is corrupted by ``random_missing`` (mr = 0.3, seed 0; Wang
2017 §4.2.3) and every method's ``refine`` is timed once (wall seconds, setup included).

Methods: ``TrNN`` (the thesis's MoCap settings, :class:`mocapkit.refinement.trnn.TrNN`), ``TrNN r=0`` (the same
solver without truncation: the nuclear-norm model of Feng et al. 2014b, not Feng's own solver), ``SVT``
(:class:`mocapkit.refinement.svt.SVTCompletion`, a full economy SVD per iteration, capped at ``--svt-iters``;
a capped time is a lower bound, marked ``>``). The thesis's seconds (Matlab 7.10, 2.4 GHz i5) are printed beside
ours, indicative only.

Usage: ``OMP_NUM_THREADS=1 python bench/bench_refine_scaling.py [--max-frames N] [--svt-iters 500]
[--methods trnn,trnn_r0,svt] [--threads 1] [--data DIR]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

from mocapkit.refinement.corruptions import corrupt
from mocapkit.refinement.svt import SVTCompletion
from mocapkit.refinement.trnn import TrNN

HERE = Path(__file__).resolve().parent


def _bench_trnn():
    """``bench/bench_trnn.py`` as a module (``bench/`` is not a package)."""
    spec = importlib.util.spec_from_file_location("bench_trnn", HERE / "bench_trnn.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def scaling_exponent(frames, seconds) -> float:
    """``b`` of the least-squares fit ``log seconds = log a + b · log frames`` (NaN with fewer than 2 points)."""
    frames, seconds = np.asarray(frames, float), np.asarray(seconds, float)
    ok = np.isfinite(seconds) & (seconds > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(frames[ok]), np.log(seconds[ok]), 1)[0])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-frames", type=int, default=None, help="skip Table 4.1 rows longer than this")
    parser.add_argument("--svt-iters", type=int, default=500, help="SVT iteration cap (its own tol is 1e-4)")
    parser.add_argument("--methods", default="trnn,trnn_r0,svt", help="comma-separated: trnn, trnn_r0, svt")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    default_data = Path(os.environ.get("MOCAPKIT_SHARED", HERE.parents[1] / "shared")) / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="folder holding hdm05_cuts11/")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    bt = _bench_trnn()
    makers = {
        "trnn": ("TrNN", lambda: TrNN()),
        "trnn_r0": ("TrNN r=0", lambda: TrNN(truncation=0)),
        "svt": ("SVT", lambda: SVTCompletion(max_iter=args.svt_iters)),
    }
    chosen = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in chosen if m not in makers]
    if unknown:
        raise SystemExit(f"--methods: unknown {unknown}; known: {list(makers)}")
    pool = bt.ClipPool(args.data)
    pool.paths = [p for p in pool.paths if "hdm05_cuts11" in str(p[0])]
    if not pool.paths:
        raise SystemExit(f"no HDM05 clips under {args.data / 'hdm05_cuts11'}")
    rows = [r for r in bt.TABLE_4_1 if args.max_frames is None or r[1] <= args.max_frames]
    print(
        f"# Table 4.1-style timing on HDM05 ({len(pool.paths)} clips); {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, torch {torch.__version__}, {args.threads} thread(s), "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}; random_missing mr = 0.3, seed 0; "
        f"SVT cap {args.svt_iters} iterations",
        flush=True,
    )
    header = f"{'action':11s} {'frames':>6s} | " + " | ".join(
        f"{makers[m][0]:>10s} s {'it':>4s} {'RMSE':>5s}" for m in chosen
    )
    print(header + " | thesis TSMC s  TrNN s | source", flush=True)
    times = {m: [] for m in chosen}
    start = time.perf_counter()
    for action, frames, thesis_tsmc, thesis_trnn in rows:
        clean, source = pool.sequence(frames)
        corruption = corrupt(clean, "random_missing", 0.3, seed=0)
        parts = []
        for m in chosen:
            refiner = makers[m][1]()
            seconds, iters, rmse, converged = bt._run(refiner, corruption.motion, clean, corruption.removed, "cpu")
            times[m].append(seconds)
            capped = ">" if (m == "svt" and not converged) else " "
            parts.append(f"{capped}{seconds:10.2f}   {iters:4d} {rmse:5.2f}")
        print(
            f"{action:11s} {frames:6d} | "
            + " | ".join(parts)
            + f" | {thesis_tsmc:13.2f} {thesis_trnn:7.2f} | {source}  (elapsed {time.perf_counter() - start:.0f} s)",
            flush=True,
        )
    frames = [r[1] for r in rows]
    long_rows = [i for i, f in enumerate(frames) if f >= 1000]
    print("# scaling exponent b of seconds ≈ a·frames^b (least squares on log–log):", flush=True)
    for m in chosen:
        every = scaling_exponent(frames, times[m])
        tail = scaling_exponent([frames[i] for i in long_rows], [times[m][i] for i in long_rows])
        print(f"#   {makers[m][0]:10s} b = {every:.2f} (all rows), {tail:.2f} (rows ≥ 1,000 frames)", flush=True)
    thesis = {"TSMC": [r[2] for r in rows], "TrNN": [r[3] for r in rows]}
    print(
        "#   thesis     "
        + ", ".join(f"{k} b = {scaling_exponent(frames, v):.2f}" for k, v in thesis.items())
        + " (Table 4.1, same rows)",
        flush=True,
    )
    print(
        f"# RMSE = Wang 2017 §4.2.3 matrix RMSE over the removed entries, cm; total "
        f"{time.perf_counter() - start:.0f} s",
        flush=True,
    )


if __name__ == "__main__":
    main()
