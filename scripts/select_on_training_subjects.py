"""Choose between recipe candidates by leave-one-subject-out inside the training subjects (never the test ones).

For every candidate (a name and Hydra overrides on top of ``--experiment``) and every training subject ``s``,
one run trains on the other training subjects and is scored once on ``s`` (``data.train_subjects`` /
``data.test_subjects``: the test subjects of the benchmark are not in either list), with ``mocapkit train`` then
``mocapkit eval`` on the run's checkpoint. The table (top-1 per held-out training subject, the mean and the
number of wrong clips) goes to ``OUT/selection.md`` and ``OUT/selection.json``; runs already scored are reused
(a run is named by its candidate and subject, and reusing it under other overrides is an error), so an interrupted
selection continues where it stopped and a later round adds candidates to the same table.

Example (README, *MSR Action3D*)::

    OMP_NUM_THREADS=1 python scripts/select_on_training_subjects.py --out checkpoints/msr_aug_selection \\
        --candidate "current=" --candidate "tilt_scale=data.augment.tilt_deg=10 data.augment.scale=0.1" --jobs 2
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def parse_candidate(text: str) -> tuple[str, list[str]]:
    """``"name=override override ..."`` → ``(name, [override, ...])`` (the first ``=`` ends the name)."""
    name, sep, overrides = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"--candidate {text!r}: expected NAME=OVERRIDES (OVERRIDES may be empty)")
    return name.strip(), overrides.split()


def run_fold(experiment: str, name: str, overrides: list[str], subject: int, train: list[int], out: Path,
             seed: int, checkpoint: str) -> dict:
    """Train on ``train``, score on ``subject``; return ``{"top1", "num_samples"}`` (cached in the run folder)."""
    run_dir = out / experiment / f"{name}_s{subject}"
    metrics = run_dir / "eval" / "metrics.json"
    recorded = run_dir / "selection_overrides.json"
    if metrics.is_file() and recorded.is_file() and json.loads(recorded.read_text()) != overrides:
        raise SystemExit(f"{run_dir}: scored with the overrides {json.loads(recorded.read_text())}, not {overrides}; "
                         "give the candidate another name or remove the folder")
    if metrics.is_file() and not recorded.is_file():
        print(f"[select] {run_dir}: reused; its overrides were not recorded (a run of an earlier version)")
    if not metrics.is_file():
        common = [f"experiment={experiment}", f"seed={seed}", f"output_root={out}", f"run_name={name}_s{subject}",
                  f"data.train_subjects=[{','.join(map(str, train))}]", f"data.test_subjects=[{subject}]",
                  "trainer.enable_progress_bar=false"]
        log = (out / f"{name}_s{subject}.log").open("w")
        cli = [sys.executable, "-m", "mocapkit"]
        subprocess.run([*cli, "train", *common, *overrides], check=True, stdout=log, stderr=subprocess.STDOUT)
        subprocess.run([*cli, "eval", f"ckpt_path={run_dir / (checkpoint + '.ckpt')}"], check=True, stdout=log,
                       stderr=subprocess.STDOUT)
        recorded.write_text(json.dumps(overrides))
    values = json.loads(metrics.read_text())
    print(f"[select] {name} held-out subject {subject}: top-1 {values['top1']:.4f} of {values['num_samples']}",
          flush=True)
    return {"top1": values["top1"], "num_samples": values["num_samples"]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--experiment", default="msr3d_gcn_ensemble")
    parser.add_argument("--subjects", type=int, nargs="+", default=[1, 3, 5, 7, 9],
                        help="the benchmark's training subjects (each held out in turn)")
    parser.add_argument("--candidate", type=parse_candidate, action="append", required=True,
                        help='NAME=OVERRIDES, e.g. "tilt=data.augment.tilt_deg=10"; repeat for each candidate')
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--checkpoint", default="last", help="the run's checkpoint scored: last | best")
    parser.add_argument("--jobs", type=int, default=1, help="runs at a time")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    tasks = [(name, overrides, s) for name, overrides in args.candidate for s in args.subjects]
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {(name, s): pool.submit(run_fold, args.experiment, name, overrides, s,
                                          [t for t in args.subjects if t != s], args.out, args.seed, args.checkpoint)
                   for name, overrides, s in tasks}
        scores = {key: future.result() for key, future in futures.items()}
    rows, table = [], {}
    head = "| candidate | overrides | " + " | ".join(f"subject {s}" for s in args.subjects) + " | mean | wrong clips |"
    rows += [head, "|" + "---|" * (len(args.subjects) + 4)]
    for name, overrides in args.candidate:
        per = [scores[(name, s)] for s in args.subjects]
        mean = sum(p["top1"] for p in per) / len(per)
        wrong = sum(round((1 - p["top1"]) * p["num_samples"]) for p in per)
        table[name] = {"overrides": overrides, "per_subject": dict(zip(map(str, args.subjects), per)),
                       "mean_top1": mean, "wrong": wrong}
        cells = " | ".join(f"{100 * p['top1']:.1f} %" for p in per)
        rows.append(f"| {name} | `{' '.join(overrides) or '(none)'}` | {cells} | {100 * mean:.1f} % | {wrong} |")
    (args.out / "selection.md").write_text("\n".join(rows) + "\n")
    (args.out / "selection.json").write_text(json.dumps({"experiment": args.experiment, "seed": args.seed,
                                                         "checkpoint": args.checkpoint, "candidates": table},
                                                        indent=2) + "\n")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
