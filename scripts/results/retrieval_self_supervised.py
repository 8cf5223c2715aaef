"""Train and score the self-supervised retrieval embeddings on every fold of the retrieval benchmarks, over seeds.

    OMP_NUM_THREADS=1 python scripts/results/retrieval_self_supervised.py \
        [--experiments retrieval_simclr,retrieval_dtw_neighbours] [--seeds 0,1,2] [--jobs 2] [--json OUT.json]
        [--set KEY=VALUE ... --tag NAME]      # an ablation: Hydra overrides for every run, its runs named by the tag
        [--checkpoint last]                   # score another checkpoint of the same runs (default best)

For each experiment (``configs/experiment/NAME.yaml``), seed and fold of the four retrieval cells, one
``mocapkit train`` run on the fold's database groups, then ``mocapkit eval`` of its ``best.ckpt``: the fold's
held-out groups' clips as queries against every database clip (the folds of ``mocapkit compare retrieval_*``):

- ``hdm05``: each performer held out in turn (bd, bk, dg, mm);
- ``bandai_content`` / ``bandai_style``: Bandai's styles (content label) or contents (style label) dealt into 3
  folds, as :meth:`~mocapkit.retrieval.benchmark.RetrievalBenchmark.folds` deals them;
- ``msr``: subjects 2 4 6 8 10 against 1 3 5 7 9.

A cell's mAP and P@1 pool every query of its folds (each fold's figure weighted by its query count); reported as
mean ± sd over the seeds. Runs go to ``checkpoints/<experiment>/ss_<cell>_<fold>_s<seed>[_<tag>]``; a run whose
``last.ckpt`` exists is not trained again (delete the run folder to retrain). ``--jobs`` runs go side by side, one
thread each. Results: docs/results/retrieval.md#trained-embeddings.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOTS = {
    "hdm05": "../shared/data/hdm05_cuts11",
    "bandai": "../shared/data/bandai_motion_1",
    "msr": "../shared/data/msr_action3d",
}
CELLS = ("hdm05", "bandai_content", "bandai_style", "msr")


def folds(cell: str) -> list[tuple[str, list[str], list[str]]]:
    """``[(fold name, held-out groups, data overrides)]`` of a cell."""
    if cell == "hdm05":
        return [(p, [p], ["data.dataset=hdm05", f"data.root={ROOTS['hdm05']}"]) for p in ("bd", "bk", "dg", "mm")]
    if cell == "msr":
        data = ["data.dataset=msr", f"data.root={ROOTS['msr']}", "data.label=action"]
        return [("even", ["2", "4", "6", "8", "10"], data)]
    from mocapkit.datasets.mocap.folders import list_clips

    label = cell.split("_")[1]
    clips = list_clips("bandai", ROOTS["bandai"])
    # the data module's groups: the style when the label is the content, the content when it is the style
    groups = sorted({c["group"] if label == "content" else c["class"] for c in clips})
    data = ["data.dataset=bandai", f"data.root={ROOTS['bandai']}", f"data.label={label}"]
    return [(f"fold{i}", groups[i::3], data) for i in range(3)]


def run(
    experiment: str,
    cell: str,
    fold: str,
    held: list[str],
    data: list[str],
    seed: int,
    extra=(),
    tag: str = "",
    checkpoint: str = "best",
) -> dict:
    """Train (unless done) and evaluate one run (``extra``: more overrides, ``tag``: its name's suffix); the
    ``metrics.json`` of its ``<checkpoint>.ckpt`` (``eval/``, or ``eval_<checkpoint>/`` for another than best)."""
    name = f"ss_{cell}_{fold}_s{seed}" + (f"_{tag}" if tag else "")
    run_dir = Path("checkpoints") / experiment / name
    out_dir = run_dir / ("eval" if checkpoint == "best" else f"eval_{checkpoint}")
    metrics = out_dir / "metrics.json"
    if not metrics.exists():
        cli = [sys.executable, "-m", "mocapkit"]
        groups = "data.test_groups=[" + ",".join(held) + "]"
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        log = run_dir.parent / f"{name}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        with open(log, "a") as out:
            if not (run_dir / "last.ckpt").exists():
                train = [
                    *cli,
                    "train",
                    f"experiment={experiment}",
                    *data,
                    groups,
                    f"run_name={name}",
                    f"seed={seed}",
                    *extra,
                ]
                subprocess.run(train, check=True, stdout=out, stderr=subprocess.STDOUT, env=env)
            subprocess.run(
                [*cli, "eval", f"ckpt_path={run_dir / f'{checkpoint}.ckpt'}", f"eval.out_dir={out_dir}"],
                check=True,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
            )
        print(f"{experiment} {name} {checkpoint}: {time.perf_counter() - start:.0f} s", flush=True)
    return json.loads(metrics.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--experiments", default="retrieval_simclr,retrieval_dtw_neighbours")
    parser.add_argument("--cells", default=",".join(CELLS))
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--jobs", type=int, default=2, help="runs side by side")
    parser.add_argument("--json", default=None, help="write the results here")
    parser.add_argument("--set", action="append", default=[], help="a Hydra override for every run (repeatable)")
    parser.add_argument("--tag", default="", help="suffix of the runs' names (required with --set)")
    parser.add_argument(
        "--checkpoint", default="best", help="the checkpoint of each run to score: best (default), last, or another"
    )
    args = parser.parse_args()
    if args.set and not args.tag:
        parser.error("--set needs --tag: the runs of an ablation must not take the names of the plain runs")
    experiments, cells = args.experiments.split(","), args.cells.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    unknown = set(cells) - set(CELLS)
    if unknown:
        parser.error(f"--cells: unknown {sorted(unknown)}; one or more of {list(CELLS)}")
    jobs = [(e, c, f, held, data, s) for e in experiments for c in cells for f, held, data in folds(c) for s in seeds]
    print(f"{len(jobs)} runs, {args.jobs} at a time", flush=True)
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        reports = list(pool.map(lambda job: run(*job, extra=args.set, tag=args.tag, checkpoint=args.checkpoint), jobs))
    pooled: dict[tuple[str, str, int], list[dict]] = {}
    for (e, c, _, _, _, s), report in zip(jobs, reports):
        pooled.setdefault((e, c, s), []).append(report)
    table = {}
    for e in experiments:
        for c in cells:
            per_seed = []
            for s in seeds:
                parts = pooled[(e, c, s)]
                n = np.array([p["n_queries"] for p in parts], dtype=float)
                per_seed.append([float(np.dot(n, [p[m] for p in parts]) / n.sum()) for m in ("map", "p1")])
            values = np.array(per_seed)
            table[f"{e} {c}"] = {
                "map_mean": float(values[:, 0].mean()),
                "map_sd": float(values[:, 0].std(ddof=1)) if len(seeds) > 1 else 0.0,
                "p1_mean": float(values[:, 1].mean()),
                "p1_sd": float(values[:, 1].std(ddof=1)) if len(seeds) > 1 else 0.0,
                "per_seed": per_seed,
            }
            row = table[f"{e} {c}"]
            print(
                f"{e + (' ' + args.tag if args.tag else ''):28s} {c:15s} mAP {row['map_mean']:.3f} ± {row['map_sd']:.3f}  "
                f"P@1 {row['p1_mean']:.3f} ± {row['p1_sd']:.3f}",
                flush=True,
            )
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "table": table}, indent=1))


if __name__ == "__main__":
    main()
