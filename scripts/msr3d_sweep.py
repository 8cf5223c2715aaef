"""Train and evaluate models on MSR Action3D over several seeds, one run at a time; print mean ± sd.

    OMP_NUM_THREADS=1 .venv/bin/python scripts/msr3d_sweep.py --experiments msr3d_gcn msr3d_energy_vgg \
        --seeds 0 1 2 --output-root checkpoints/msr3d_sweep [-- extra Hydra overrides]

Each run is ``python -m mocapkit train experiment=E seed=S run_name=seedS output_root=...`` followed by
``python -m mocapkit eval ckpt_path=<run>/best.ckpt``; the table is written to ``<output-root>/results.md``
and ``results.json``. (On a shared 2-core machine, OMP_NUM_THREADS=1 was several times faster than 2 threads.)
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path


def run(cmd: list[str], log: Path) -> float:
    start = time.time()
    with log.open("w") as fh:
        fh.write(" ".join(cmd) + "\n")
        fh.flush()
        subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, check=True)
    return time.time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--experiments", nargs="+", default=["msr3d_gcn", "msr3d_energy_vgg"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--output-root", default="checkpoints/msr3d_sweep")
    parser.add_argument("overrides", nargs="*", help="extra Hydra overrides for every run (after --)")
    args = parser.parse_args()
    root = Path(args.output_root)
    root.mkdir(parents=True, exist_ok=True)
    py = [sys.executable, "-m", "mocapkit"]
    results = {}
    for exp in args.experiments:
        for seed in args.seeds:
            run_dir = root / exp / f"seed{seed}"
            train_cmd = py + ["train", f"experiment={exp}", f"seed={seed}", f"run_name=seed{seed}",
                              f"output_root={root}", "trainer.enable_progress_bar=false", *args.overrides]
            seconds = run(train_cmd, root / f"{exp}_seed{seed}_train.log")
            run(py + ["eval", f"ckpt_path={run_dir / 'best.ckpt'}", "trainer.enable_progress_bar=false"],
                root / f"{exp}_seed{seed}_eval.log")
            metrics = json.loads((run_dir / "eval" / "metrics.json").read_text())
            results.setdefault(exp, []).append({"seed": seed, "top1": metrics["top1"], "train_seconds": seconds,
                                                "mean_class_accuracy": metrics["mean_class_accuracy"],
                                                "val_subjects": metrics["val_subjects"],
                                                "sample_counts": metrics["sample_counts"], "split": metrics["split"]})
            print(f"{exp} seed {seed}: top-1 {metrics['top1']:.2%} ({seconds:.0f} s)", flush=True)
            (root / "results.json").write_text(json.dumps(results, indent=2))
    lines = ["| experiment | split | seeds | top-1 mean ± sd | per seed | train time / run |", "|---|---|---|---|---|---|"]
    for exp, rows in results.items():
        top1 = [r["top1"] * 100 for r in rows]
        sd = statistics.stdev(top1) if len(top1) > 1 else 0.0
        secs = statistics.mean(r["train_seconds"] for r in rows)
        lines.append(f"| {exp} | {rows[0]['split']} | {len(rows)} | {statistics.mean(top1):.2f} ± {sd:.2f} | "
                     f"{', '.join(f'{t:.2f}' for t in top1)} | {secs / 60:.1f} min |")
    (root / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
