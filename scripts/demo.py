"""The embedded default (`make demo`): synthesize → prepare → train → evaluate → export → predict.

Every step is the real `mocapkit` command, printed before it runs (evaluation and export, which need only
the trained checkpoint, run side by side and print when both are done). Data goes
to `.demo/`, the run to `checkpoints/ntu_energy_vgg/demo-<time>/`. Options:
`--epochs N` and `--fresh` (re-synthesize the data).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / ".demo"
SYNTH = DEMO / "ntu_synth"
CACHE = DEMO / "ntu_cache"


def run(*args: str) -> float:
    cmd = [sys.executable, "-m", "mocapkit", *args]
    print("\n$ mocapkit " + " ".join(args), flush=True)
    start = time.time()
    subprocess.run(cmd, cwd=ROOT, check=True)
    return time.time() - start


def run_side_by_side(*commands: tuple[str, ...]) -> float:
    """Independent commands at once (each mostly imports and one core's work: together they take about as long as
    the longest); each one's output is printed when it is done, in order; the seconds until all are."""
    start = time.time()
    jobs = [
        subprocess.Popen(
            [sys.executable, "-m", "mocapkit", *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        for args in commands
    ]
    for args, job in zip(commands, jobs):
        output, _ = job.communicate()
        print("\n$ mocapkit " + " ".join(args) + "   (side by side)", flush=True)
        print(output.decode(errors="replace"), end="", flush=True)
        if job.returncode:
            raise subprocess.CalledProcessError(job.returncode, ["mocapkit", *args])
    return time.time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--epochs", type=int, default=None, help="override trainer.max_epochs")
    parser.add_argument("--fresh", action="store_true", help="re-synthesize and re-prepare the data")
    args = parser.parse_args()
    if args.fresh:
        shutil.rmtree(DEMO, ignore_errors=True)
    timings = {}
    start = time.time()
    if not (SYNTH / "synth_config.json").exists():
        timings["synth"] = run(
            "synth", "ntu", "--out", str(SYNTH), "--classes", "12", "--subjects", "20", "--seed", "0", "--workers", "2"
        )
    if not (CACHE / "meta.json").exists():
        timings["prepare"] = run("prepare", "ntu", "--src", str(SYNTH), "--out", str(CACHE), "--workers", "2")
    run_name = "demo-" + datetime.now().strftime("%Y%m%d-%H%M%S")
    run_dir = ROOT / "checkpoints" / "ntu_energy_vgg" / run_name
    overrides = ["experiment=ntu_energy_vgg", f"data.root={CACHE}", f"run_name={run_name}"]
    if args.epochs:
        overrides.append(f"trainer.max_epochs={args.epochs}")
    timings["train"] = run("train", *overrides)
    best = run_dir / "best.ckpt"
    onnx_path = run_dir / "model.onnx"
    timings["eval + export"] = run_side_by_side(
        ("eval", f"ckpt_path={best}"), ("export", f"ckpt_path={best}", f"out={onnx_path}")
    )
    metrics = json.loads((run_dir / "eval" / "metrics.json").read_text())
    held_out = sorted(SYNTH.glob(f"*P{metrics['test_subjects'][0]:03d}R001A00[1-3].skeleton"))[:3]
    timings["predict"] = run("predict", "--onnx", str(onnx_path), "--top", "3", *map(str, held_out))
    parity = json.loads((run_dir / "model.parity.json").read_text())
    total = time.time() - start

    print("\n## mocapkit demo: NTU-style synthetic set, held-out subjects")
    print("| | |\n|---|---|")
    print(
        f"| split | {metrics['split']}: train subjects {metrics['train_subjects']}, test {metrics['test_subjects']} |"
    )
    counts = metrics["sample_counts"]
    print(f"| samples train / val / test | {counts['train']} / {counts['val']} / {counts['test']} |")
    print(f"| top-1 (held-out subjects) | {metrics['top1']:.1%} (chance {metrics['chance']:.1%}) |")
    print(f"| top-5 | {metrics['top5']:.1%} |")
    print(f"| mean-class accuracy | {metrics['mean_class_accuracy']:.1%} |")
    print(f"| ONNX parity, max abs diff | {parity['max_abs_diff']:.2e} on {parity['checked_shape']} |")
    print(f"| wall time | {total:.0f} s (" + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items()) + ") |")
    print("\nWrote:")
    for path in (
        CACHE,
        run_dir / "config.yaml",
        run_dir / "best.ckpt",
        run_dir / "last.ckpt",
        run_dir / "tensorboard",
        run_dir / "eval" / "metrics.json",
        run_dir / "eval" / "confusion_matrix.png",
        onnx_path,
    ):
        print(f"  {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
