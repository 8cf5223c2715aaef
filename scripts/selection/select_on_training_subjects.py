"""Choose between recipe candidates by leave-one-subject-out inside the training subjects (never the test ones).

For every candidate (a name and Hydra overrides on top of ``--experiment``), every seed and every training subject
``s``, one run trains on the other training subjects and is scored once on ``s`` (``--split-keys``: by default
``data.train_subjects`` / ``data.test_subjects``, HDM05's data module takes ``data.train_actors`` /
``data.test_actors``; the test subjects of the benchmark are in neither list), with ``mocapkit train`` then
``mocapkit eval`` on the run's checkpoint. The table (top-1 per held-out training subject, the mean and the number
of wrong clips, summed over the seeds) goes to ``OUT/selection.md`` and ``OUT/selection.json``, with the
candidate the rule picks: the fewest wrong clips, ties to the candidate listed first (list the incumbent recipe
first). Runs already scored are reused (a run is named by its candidate, seed and subject, and reusing it under
other overrides is an error), so an interrupted selection continues where it stopped and a later round adds
candidates to the same table.

``--outer`` makes it nested: each of ``--subjects`` is in turn the benchmark's test subject (the
leave-one-performer-out protocol of HDM05), and the selection above runs on the others alone, one table and one
choice per outer fold (``OUT/outer_<subject>/``), so that the recipe scored on a performer was chosen without it.

Examples (docs/decisions.md#msr-action3d-augmentation and docs/decisions.md#hdm05-ensemble)::

    OMP_NUM_THREADS=1 python scripts/selection/select_on_training_subjects.py --out checkpoints/msr_aug_selection \\
        --candidate "current=" --candidate "tilt_scale=data.augment.tilt_deg=10 data.augment.scale=0.1" --jobs 2
    OMP_NUM_THREADS=1 python scripts/selection/select_on_training_subjects.py --experiment hdm05_gcn --outer \\
        --subjects bd bk dg mm --split-keys data.train_actors data.test_actors --seeds 0 1 --checkpoint auto \\
        --candidate "recipe=" --candidate "ensemble=experiment=hdm05_gcn_ensemble" --out checkpoints/hdm05_selection
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


def training_overrides(experiment: str, overrides: list[str]) -> tuple[str, list[str]]:
    """The experiment a candidate trains and its other overrides: a candidate may name another experiment
    (``experiment=NAME`` among its overrides), which then replaces ``--experiment``."""
    named = [o.split("=", 1)[1] for o in overrides if o.startswith("experiment=")]
    return (named[-1] if named else experiment), [o for o in overrides if not o.startswith("experiment=")]


def run_fold(
    experiment: str,
    name: str,
    overrides: list[str],
    subject: str,
    train: list[str],
    out: Path,
    seed: int,
    checkpoint: str,
    split_keys: tuple[str, str] = ("data.train_subjects", "data.test_subjects"),
    common: tuple[str, ...] = (),
) -> dict:
    """Train on ``train``, score on ``subject``; return ``{"top1", "num_samples"}`` (cached in the run folder).

    ``checkpoint``: ``last``, ``best`` or ``auto`` (``best.ckpt`` where the run has one, i.e. a validation part,
    else ``last.ckpt``). ``common``: overrides for every run that are not part of the candidate (e.g. the
    accelerator), not recorded.
    """
    experiment, rest = training_overrides(experiment, overrides)
    out.mkdir(parents=True, exist_ok=True)
    run_dir = out / experiment / f"{name}_seed{seed}_s{subject}"
    metrics = run_dir / "eval" / "metrics.json"
    recorded = run_dir / "selection_overrides.json"
    if metrics.is_file() and recorded.is_file() and json.loads(recorded.read_text()) != overrides:
        raise SystemExit(
            f"{run_dir}: scored with the overrides {json.loads(recorded.read_text())}, not {overrides}; "
            "give the candidate another name or remove the folder"
        )
    if metrics.is_file() and not recorded.is_file():
        print(f"[select] {run_dir}: reused; its overrides were not recorded (a run of an earlier version)")
    if not metrics.is_file():
        train_key, test_key = split_keys
        common_args = [
            f"experiment={experiment}",
            f"seed={seed}",
            f"output_root={out}",
            f"run_name={run_dir.name}",
            f"{train_key}=[{','.join(map(str, train))}]",
            f"{test_key}=[{subject}]",
            "trainer.enable_progress_bar=false",
            *common,
        ]
        cli = [sys.executable, "-m", "mocapkit"]
        with (out / f"{run_dir.name}.log").open("w") as log:
            subprocess.run([*cli, "train", *common_args, *rest], check=True, stdout=log, stderr=subprocess.STDOUT)
            chosen = checkpoint
            if checkpoint == "auto":
                chosen = "best" if (run_dir / "best.ckpt").is_file() else "last"
            subprocess.run(
                [*cli, "eval", f"ckpt_path={run_dir / (chosen + '.ckpt')}"],
                check=True,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        recorded.write_text(json.dumps(overrides))
    values = json.loads(metrics.read_text())
    print(
        f"[select] {name} seed {seed}, held-out subject {subject}: top-1 {values['top1']:.4f} of "
        f"{values['num_samples']}",
        flush=True,
    )
    return {"top1": values["top1"], "num_samples": values["num_samples"]}


def selection_table(
    candidates: list[tuple[str, list[str]]], subjects: list[str], seeds: list[int], scores: dict
) -> tuple[dict, list[str], str]:
    """``scores[(name, seed, subject)]`` → (the per-candidate table, its markdown rows, the chosen candidate).

    The rule: the fewest wrong clips over every seed and held-out subject; ties to the candidate listed first.
    """
    head = "| candidate | overrides | " + " | ".join(f"subject {s}" for s in subjects) + " | mean | wrong clips |"
    rows, table = [head, "|" + "---|" * (len(subjects) + 4)], {}
    for name, overrides in candidates:
        per = {s: [scores[(name, seed, s)] for seed in seeds] for s in subjects}
        top1 = {s: sum(p["top1"] for p in runs) / len(runs) for s, runs in per.items()}
        mean = sum(top1.values()) / len(top1)
        wrong = sum(round((1 - p["top1"]) * p["num_samples"]) for runs in per.values() for p in runs)
        table[name] = {
            "overrides": overrides,
            "per_subject": {
                str(s): {
                    "top1": top1[s],
                    "num_samples": runs[0]["num_samples"],
                    "per_seed": dict(zip(map(str, seeds), (p["top1"] for p in runs))),
                }
                for s, runs in per.items()
            },
            "mean_top1": mean,
            "wrong": wrong,
        }
        cells = " | ".join(f"{100 * top1[s]:.1f} %" for s in subjects)
        rows.append(f"| {name} | `{' '.join(overrides) or '(none)'}` | {cells} | {100 * mean:.1f} % | {wrong} |")
    chosen = min(table, key=lambda name: (table[name]["wrong"], list(table).index(name)))
    return table, rows, chosen


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--experiment", default="msr3d_gcn_ensemble")
    parser.add_argument(
        "--subjects",
        nargs="+",
        default=["1", "3", "5", "7", "9"],
        help="the benchmark's training subjects (each held out in turn); with --outer, every subject",
    )
    parser.add_argument(
        "--split-keys",
        nargs=2,
        default=["data.train_subjects", "data.test_subjects"],
        metavar=("TRAIN_KEY", "TEST_KEY"),
        help="the data module's keys for the two subject lists",
    )
    parser.add_argument(
        "--outer",
        action="store_true",
        help="nested: each subject in turn is the test subject, the selection runs on the others",
    )
    parser.add_argument(
        "--candidate",
        type=parse_candidate,
        action="append",
        required=True,
        help='NAME=OVERRIDES, e.g. "tilt=data.augment.tilt_deg=10"; repeat for each candidate '
        "(the incumbent first: ties go to the first)",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument(
        "--checkpoint",
        default="last",
        choices=["last", "best", "auto"],
        help="the run's checkpoint scored (auto: best where the run validates, else last)",
    )
    parser.add_argument(
        "--common",
        nargs="*",
        default=[],
        help="overrides for every run, not part of a candidate (e.g. trainer.accelerator=gpu)",
    )
    parser.add_argument("--jobs", type=int, default=1, help="runs at a time")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    names = [name for name, _ in args.candidate]
    if len(set(names)) != len(names):
        raise SystemExit(f"--candidate: names must differ, got {names}")
    folds = (
        {f"outer_{o}": [s for s in args.subjects if s != o] for o in args.subjects}
        if args.outer
        else {"": list(args.subjects)}
    )
    for inner in folds.values():
        if len(inner) < 2:
            raise SystemExit(
                f"--subjects {args.subjects}: leaving one out needs at least two training subjects per selection"
            )
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {
            (fold, name, seed, s): pool.submit(
                run_fold,
                args.experiment,
                name,
                overrides,
                s,
                [t for t in inner if t != s],
                args.out / fold,
                seed,
                args.checkpoint,
                tuple(args.split_keys),
                tuple(args.common),
            )
            for fold, inner in folds.items()
            for seed in args.seeds
            for name, overrides in args.candidate
            for s in inner
        }
        scores = {key: future.result() for key, future in futures.items()}
    for fold, inner in folds.items():
        table, rows, chosen = selection_table(
            args.candidate, inner, args.seeds, {k[1:]: v for k, v in scores.items() if k[0] == fold}
        )
        out = args.out / fold
        (out / "selection.md").write_text("\n".join(rows) + f"\n\nchosen (fewest wrong, ties to the first): {chosen}\n")
        (out / "selection.json").write_text(
            json.dumps(
                {
                    "experiment": args.experiment,
                    "seeds": args.seeds,
                    "checkpoint": args.checkpoint,
                    "subjects": inner,
                    "split_keys": args.split_keys,
                    "candidates": table,
                    "chosen": chosen,
                },
                indent=2,
            )
            + "\n"
        )
        print(f"\n{fold or 'selection'}:\n" + "\n".join(rows) + f"\nchosen: {chosen}", flush=True)


if __name__ == "__main__":
    main()
