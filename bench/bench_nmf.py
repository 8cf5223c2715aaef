"""Benchmark: our torch NMF (Frobenius MU) against scikit-learn's ``NMF(solver="mu")``, plus GNMF / NMC costs.

For each size ``n × d, k`` both solvers start from the same random ``W0, H0`` and run the same number of
iterations (``tol=0``), so they do the same arithmetic; the table gives the wall time of each, the ratio
(sklearn time / ours, > 1 = we are faster) and the largest relative difference of the fitted W as a check.
Our solver also evaluates the objective at every iteration (from products it already has); scikit-learn
evaluates nothing when ``tol=0``.

GNMF and NMC have no scikit-learn counterpart: their table gives the graph construction time (kNN, p=5, on CPU)
and the per-iteration cost of the updates, next to plain NMF's.

Data: uniform random non-negative matrices (seed 0). Timings are the best of ``--repeat`` runs.

Usage: ``python bench/bench_nmf.py [--iters 100] [--repeat 1] [--threads 1] [--device cpu|cuda] [--sizes small]``
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import torch

from mocapkit.clustering.graphs import knn_graph
from mocapkit.clustering.nmf import GNMF, NMC, NMF

SIZES = {"small": [(500, 100, 20)], "default": [(500, 100, 20), (2000, 300, 50), (5000, 500, 100)]}


def _best_time(fn, repeat: int, device: torch.device) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        if device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        result = fn()
        if device.type == "cuda":
            torch.cuda.synchronize()
        best = min(best, time.perf_counter() - start)
    return best, result


def _fit_call(model, X: np.ndarray, W0: np.ndarray, H0: np.ndarray):
    """A no-argument callable fitting ``model`` from copies of ``W0, H0`` (scikit-learn updates them in place)."""
    return lambda: model.fit_transform(X, W=W0.copy(), H=H0.copy())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1, help="torch and BLAS threads (both solvers)")
    parser.add_argument("--device", default="cpu", help="device of our solvers (sklearn always runs on CPU)")
    parser.add_argument("--sizes", choices=sorted(SIZES), default="default")
    args = parser.parse_args(argv)

    from sklearn.decomposition import NMF as SklearnNMF
    from threadpoolctl import threadpool_limits

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        print(f"--device {args.device}: CUDA is not available, skipping")
        return
    device = torch.device(args.device)
    torch.set_num_threads(args.threads)
    gpu = torch.cuda.get_device_name(device) if device.type == "cuda" else "-"
    print(
        f"machine: {platform.machine()} {platform.processor() or ''}, os.cpu_count()={os.cpu_count()}, "
        f"torch {torch.__version__} threads={torch.get_num_threads()}, BLAS threads={args.threads}, "
        f"device={device} ({gpu}), float64, {args.iters} iterations, best of {args.repeat}\n"
    )

    rows_nmf, rows_graph = [], []
    with threadpool_limits(limits=args.threads):
        for n, d, k in SIZES[args.sizes]:
            rng = np.random.default_rng(0)
            X = rng.random((n, d))
            W0, H0 = rng.random((n, k)), rng.random((k, d))

            sklearn_model = SklearnNMF(n_components=k, solver="mu", init="custom", max_iter=args.iters, tol=0)
            t_sk, W_sk = _best_time(_fit_call(sklearn_model, X, W0, H0), args.repeat, torch.device("cpu"))
            ours = NMF(k, max_iter=args.iters, tol=0, device=device)
            t_ours, W_ours = _best_time(_fit_call(ours, X, W0, H0), args.repeat, device)
            diff = np.abs(W_ours - W_sk).max() / np.abs(W_sk).max()
            rows_nmf.append((f"{n}×{d}, k={k}", t_sk, t_ours, t_sk / t_ours, diff))

            start = time.perf_counter()
            S = knn_graph(X, 5)
            t_graph = time.perf_counter() - start
            gnmf = GNMF(k, graph=S, max_iter=args.iters, tol=0, device=device)
            t_gnmf, _ = _best_time(_fit_call(gnmf, X, W0, H0), args.repeat, device)
            nmc = NMC(k, graph=S, max_iter=args.iters, tol=0, device=device)
            t_nmc, _ = _best_time(_fit_call(nmc, X, W0, H0), args.repeat, device)
            per = 1e3 / args.iters
            rows_graph.append((f"{n}×{d}, k={k}", t_graph, t_ours * per, t_gnmf * per, t_nmc * per))

    print("| size | sklearn mu (s) | ours (s) | ratio sklearn/ours | max rel. diff W |")
    print("|---|---:|---:|---:|---:|")
    for name, t_sk, t_ours, ratio, diff in rows_nmf:
        print(f"| {name} | {t_sk:.3f} | {t_ours:.3f} | {ratio:.2f} | {diff:.1e} |")
    print("\n| size | kNN graph (s) | NMF ms/iter | GNMF ms/iter | NMC ms/iter |")
    print("|---|---:|---:|---:|---:|")
    for name, t_graph, t_nmf, t_gnmf, t_nmc in rows_graph:
        print(f"| {name} | {t_graph:.3f} | {t_nmf:.2f} | {t_gnmf:.2f} | {t_nmc:.2f} |")


if __name__ == "__main__":
    main()
