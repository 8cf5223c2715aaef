"""Held-out-subject accuracy over several training seeds, for README / RESULTS tables.

Trains and evaluates one configuration per (variant, seed) with the real
`mocapkit train` / `mocapkit eval` commands and prints mean ± sd of top-1 and
mean-class accuracy, plus training time. Example (the README's table):

    python scripts/seed_study.py --data .demo/ntu_cache --seeds 0 1 2 \\
        --variant linear= --variant none=model.energy.temporal_weighting=none
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="prepared cache")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--variant", action="append", default=[],
                        help="NAME=override[,override...] (empty overrides: the default configuration)")
    parser.add_argument("--output-root", default="checkpoints/seed_study")
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    args = parser.parse_args()
    variants = dict(v.split("=", 1) for v in (args.variant or ["default="]))
    results = {}
    for name, overrides in variants.items():
        extra = [o for o in overrides.split(",") if o]
        rows = []
        for seed in args.seeds:
            run = f"{name}-seed{seed}"
            start = time.time()
            subprocess.run([sys.executable, "-m", "mocapkit", "train", "experiment=ntu_energy_vgg",
                            f"data.root={args.data}", f"seed={seed}", f"run_name={run}",
                            f"output_root={args.output_root}", "trainer.enable_progress_bar=false", *extra],
                           check=True, stdout=subprocess.DEVNULL)
            train_s = time.time() - start
            run_dir = Path(args.output_root) / "ntu_energy_vgg" / run
            subprocess.run([sys.executable, "-m", "mocapkit", "eval", f"ckpt_path={run_dir / 'best.ckpt'}",
                            "trainer.enable_progress_bar=false"], check=True, stdout=subprocess.DEVNULL)
            metrics = json.loads((run_dir / "eval" / "metrics.json").read_text())
            rows.append({"seed": seed, "top1": metrics["top1"], "mean_class": metrics["mean_class_accuracy"],
                         "top5": metrics["top5"], "train_s": train_s})
            print(f"{name} seed {seed}: top-1 {metrics['top1']:.2%}, train {train_s:.0f} s", flush=True)
        results[name] = {"overrides": extra, "runs": rows}
    print("\n| variant | overrides | top-1 (mean ± sd) | mean-class | top-5 | train time / run |")
    print("|---|---|---:|---:|---:|---:|")
    for name, r in results.items():
        col = lambda k: [x[k] for x in r["runs"]]  # noqa: E731
        sd = lambda v: statistics.stdev(v) if len(v) > 1 else 0.0  # noqa: E731
        print(f"| {name} | {' '.join(r['overrides']) or '(default)'} | {statistics.mean(col('top1')):.1%} ± "
              f"{sd(col('top1')):.1%} | {statistics.mean(col('mean_class')):.1%} | {statistics.mean(col('top5')):.1%} "
              f"| {statistics.mean(col('train_s')):.0f} s |")
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
