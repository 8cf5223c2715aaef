"""Benchmark: a long fuzz run of every motion-file reader (the bounded version is tests/test_fuzz.py).

``--cases`` seeded mutations (``mocapkit/testing/fuzzing.py``: truncation, bit flips, NaN/Inf and odd numbers,
huge counts, line ends, encodings, C3D header/parameter/data damage, PNG chunk damage), spread
evenly over the formats, from the real samples in ``shared/samples`` (CASIA-B: generated
silhouettes), plus the special files (directory, FIFO, ``/dev/zero``, empty, dangling symlink,
``/dev/null``) of each format. Every file is read in a batched worker process under a per-file
timeout and an address-space cap; the outcome of each is classified as ok / clean_error / crash /
hang / memory / raw_exception / non_finite.

Printed: progress, the counts per format × outcome (Markdown), every case that is neither ok nor
a clean error naming the file (``--show`` limits the list), the wall time, and fuzz cases/s
against a plain ``open(path, "rb").read()`` of the same mutated files (the reference: what
reading the bytes alone costs, in the same run).

Usage: ``python bench/bench_fuzz.py [--cases 3000] [--seed 0] [--timeout 10] [--mem-gib 2]
[--formats ntu c3d] [--src DIR] [--json out.json] [--keep DIR]``

``--c3d-exhaustive``: the exhaustive C3D campaign instead (:func:`mocapkit.testing.fuzzing.c3d_mutants`): for each
of ``--c3d-files`` (default: five real files of four systems in ``shared/samples/c3d``), every byte of the 512-byte
header and of the parameter section set to 0x00, 0xFF, byte+1, byte−1 and a random byte, plus ``--data-mutations``
random multi-byte mutations and ``--truncations`` cuts of the data section, each read by ``read_motion`` in the
worker (streamed through one file per source: disk and memory stay at one file). Printed: the mutant counts, progress
with the rate, the table per file (ok, located error, unlocated error, crash = a signal, hang, memory, raw exception,
non-finite), every failing mutant (kept under ``--keep-failures``). ``--json`` writes the table and the failures.

``--batch``: the batch commands on folders of good files plus ``--batch-mutants`` fuzz mutants each
(:mod:`mocapkit.testing.fuzzing`, "batch commands"): ``prepare ntu --skip-bad`` (NTU samples), ``prepare casia-b
--skip-bad`` (generated silhouette sequences, one frame mutated), ``index --skip-bad`` and ``kinect-fix apply
--skip-bad`` (MSR Action3D files; a tiny GP model), and ``refine TAKE OUT --method pose-prior --train FOLDER
--skip-bad`` (HDM05 AMC; ``refine`` reads one take, its folder is the training one). Each runs as ``python -m
mocapkit`` in a child process; printed: a table per command (good files kept, mutants kept / reported, the
mutants the reader alone rejects that the report names, the exit status) and every problem (a good file not kept,
a file neither kept nor reported, an unreadable one not reported, a report entry that does not name its file).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mocapkit.testing import fuzzing

DEFAULT_SRC = Path(__file__).resolve().parents[1].parent / "shared" / "samples"
ALL = ("ntu", "amc", "bvh", "c3d", "msr", "png")
#: Real C3D files of different systems: C3D.ORG sample 1 with integer and DEC float storage, Qualisys (sample 26),
#: AMASS / Vicon 370 (sample 2), Vicon at HDM05.
C3D_FILES = (
    "Eb015pi.c3d",
    "Eb015vr.c3d",
    "Walking_Hybrid_1_1.c3d",
    "pc_real.c3d",
    "HDM_dg_06-03_03_120.c3d",
)


def batch(args) -> int:
    """The batch-command campaigns (module docstring)."""
    root = Path(tempfile.mkdtemp(prefix="mocapkit-batch-fuzz-"))
    hdm05 = args.src.parent / "data" / "hdm05_cuts11" / "mm"
    n, seed = args.batch_mutants, args.seed
    start = time.perf_counter()
    try:
        builders = [
            ("prepare ntu", lambda: fuzzing.batch_prepare_ntu(args.src, root, n, seed)),
            ("prepare casia-b", lambda: fuzzing.batch_prepare_casia_b(root, n, seed)),
            ("index", lambda: fuzzing.batch_index(args.src, root, n, seed)),
            (
                "kinect-fix apply",
                lambda: fuzzing.batch_kinect_fix(args.src, root, fuzzing.tiny_kinect_model(root / "gp.npz"), n, seed),
            ),
            (
                "refine --train",
                lambda: fuzzing.batch_refine_train(hdm05, hdm05 / "HDM_mm_squat1Reps_040_120.amc", root, n, seed),
            ),
        ]
        campaigns = []
        for name, build in builders:
            t = time.perf_counter()
            campaign = fuzzing.run_batch(build())
            campaigns.append(campaign)
            print(
                f"  {name}: {len(campaign.good)} good + {len(campaign.mutants)} mutants ({len(campaign.unreadable)} "
                f"the reader rejects), exit {campaign.returncode}, {time.perf_counter() - t:.0f} s",
                flush=True,
            )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    wall = time.perf_counter() - start
    print(f"\n{wall:.0f} s wall; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}\n")
    print(fuzzing.batch_table(campaigns))
    problems = [p for c in campaigns for p in c.problems()]
    print(f"\n{len(problems)} problems" + (":" if problems else ""))
    for p in problems:
        print(f"- {p}")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "command": " ".join(sys.argv),
                    "wall_s": round(wall, 1),
                    "campaigns": [c.summary() for c in campaigns],
                    "problems": problems,
                },
                indent=1,
            )
        )
    return 0


def c3d_exhaustive(args) -> int:
    """The exhaustive C3D campaign (module docstring)."""
    files = [args.src / "c3d" / name for name in args.c3d_files]
    absent = [str(f) for f in files if not f.is_file()]
    if absent:
        print(f"no such C3D file: {', '.join(absent)}", file=sys.stderr)
        return 2
    plan = {}
    for f in files:
        plan[f.name] = fuzzing.count_c3d_mutants(
            f.read_bytes(), f"{args.seed}:{f.name}", args.data_mutations, args.truncations
        )
    total = sum(sum(c.values()) for c in plan.values())
    print(f"{total:,} mutants (seed {args.seed}, timeout {args.timeout:g} s, RLIMIT_AS {args.mem_gib:g} GiB):")
    for name, c in plan.items():
        print(f"  {name}: " + ", ".join(f"{k} {v:,}" for k, v in c.items()))
    root = Path(tempfile.mkdtemp(prefix="mocapkit-c3d-fuzz-"))
    start = time.perf_counter()
    done = [0]
    step = max(1, total // 40)

    def progress(name, tally, outcome):
        done[0] += 1
        if done[0] % step == 0 or done[0] == total:
            wall = time.perf_counter() - start
            counts = ", ".join(f"{k} {tally[k]:,}" for k in fuzzing.CAMPAIGN_COLUMNS[1:] if tally[k])
            print(
                f"  {done[0]:,}/{total:,} ({wall:.0f} s, {done[0] / wall:.0f}/s, about "
                f"{(total - done[0]) * wall / done[0]:.0f} s left) {name}: {counts}",
                flush=True,
            )

    try:
        counts, bad = fuzzing.run_c3d_campaign(
            files,
            root,
            seed=str(args.seed),
            data_mutations=args.data_mutations,
            truncations=args.truncations,
            timeout=args.timeout,
            mem_limit=int(args.mem_gib * (1 << 30)),
            keep_failures=args.keep_failures,
            progress=progress,
        )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    wall = time.perf_counter() - start
    n = sum(c["mutants"] for c in counts.values())
    print(
        f"\n{n:,} mutants in {wall:.0f} s wall ({n / wall:.0f}/s); {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.2f}\n"
    )
    print(fuzzing.campaign_table(counts))
    print(f"\n{len(bad)} mutants neither ok nor a located error" + (":" if bad else ""))
    for o in bad[: args.show if args.show >= 0 else None]:
        print(f"- {o.line()}")
    if args.keep_failures and bad:
        print(f"failing mutants kept under {args.keep_failures}")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "command": " ".join(sys.argv),
                    "seed": args.seed,
                    "wall_s": round(wall, 1),
                    "counts": {name: dict(c) for name, c in counts.items()},
                    "failures": [fuzzing.outcome_dict(o) for o in bad],
                },
                indent=1,
                default=str,
            )
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=3000, help="mutated files in all (split over the formats)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds per file before it counts as a hang")
    parser.add_argument("--mem-gib", type=float, default=2.0, help="address-space cap of the worker (GiB)")
    parser.add_argument("--formats", nargs="*", default=list(ALL), choices=ALL)
    parser.add_argument("--src", type=Path, default=DEFAULT_SRC, help="the shared samples folder")
    parser.add_argument("--max-seed-bytes", type=int, default=0, help="skip seed files larger than this (0: none)")
    parser.add_argument("--show", type=int, default=-1, help="list at most this many failing cases (-1: all)")
    parser.add_argument("--json", type=Path, default=None, help="write every outcome here")
    parser.add_argument("--keep", type=Path, default=None, help="write the cases here and keep them")
    parser.add_argument("--c3d-exhaustive", action="store_true", help="the exhaustive C3D campaign (docstring)")
    parser.add_argument("--c3d-files", nargs="+", default=list(C3D_FILES), help="file names under SRC/c3d")
    parser.add_argument("--data-mutations", type=int, default=1000, help="random data-section mutations per file")
    parser.add_argument("--truncations", type=int, default=300, help="data-section truncations per file")
    parser.add_argument("--keep-failures", type=Path, default=None, help="copy failing mutants here")
    parser.add_argument("--batch", action="store_true", help="the batch-command campaigns (docstring)")
    parser.add_argument("--batch-mutants", type=int, default=40, help="mutated files per batch command")
    args = parser.parse_args(argv)
    if args.c3d_exhaustive:
        return c3d_exhaustive(args)
    if args.batch:
        return batch(args)

    root = args.keep or Path(tempfile.mkdtemp(prefix="mocapkit-fuzz-"))
    root.mkdir(parents=True, exist_ok=True)
    per = max(1, args.cases // len(args.formats))
    cases, skipped = [], []
    t_gen = time.perf_counter()
    for fmt in args.formats:
        if fmt == "png":
            seeds = fuzzing.make_silhouette_seeds(root / "png-seeds")
        else:
            seeds = [
                p
                for p in fuzzing.sample_files(args.src, fmt)
                if not args.max_seed_bytes or p.stat().st_size <= args.max_seed_bytes
            ]
        if not seeds:
            skipped.append(f"{fmt}: no sample files under {args.src}")
            continue
        cases += fuzzing.make_cases(fmt, seeds, root, per, seed=args.seed)
        companion = fuzzing._asf_for(seeds[0]) if fmt == "amc" else None
        cases += fuzzing.make_special_cases(fmt, root, companion)
    t_gen = time.perf_counter() - t_gen
    print(
        f"{len(cases)} cases ({per} mutated per format + {len(fuzzing.SPECIALS)} special files each), "
        f"generated in {t_gen:.1f} s under {root}; seed {args.seed}, timeout {args.timeout:g} s, "
        f"RLIMIT_AS {args.mem_gib:g} GiB",
        flush=True,
    )

    start = time.perf_counter()
    step = max(1, len(cases) // 20)
    running = Counter()

    def progress(done, total, outcome):
        running[outcome.outcome] += 1
        if done % step == 0 or done == total:
            counts = ", ".join(f"{k} {running[k]}" for k in fuzzing.OUTCOMES if running[k])
            print(f"  {done}/{total} ({time.perf_counter() - start:.0f} s): {counts}", flush=True)

    outcomes = fuzzing.run_cases(
        cases, timeout=args.timeout, mem_limit=int(args.mem_gib * (1 << 30)), progress=progress
    )
    wall = time.perf_counter() - start

    # reference: the bytes alone, same files (regular files only: the specials would block or never end)
    regular = [c.path for c in cases if c.id.split("-")[1] != "special"]
    t = time.perf_counter()
    for p in regular:
        with open(p, "rb") as f:
            f.read()
    plain = time.perf_counter() - t

    print(
        f"\n{len(outcomes)} cases in {wall:.1f} s wall; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}\n"
    )
    print(fuzzing.table(outcomes))
    bad = fuzzing.failures(outcomes)
    print(f"\n{len(bad)} cases neither ok nor a clean error naming the file")
    by_fmt: dict[str, list] = {}
    for o in bad:
        by_fmt.setdefault(o.case.fmt, []).append(o)
    shown = 0
    for fmt, items in by_fmt.items():
        print(f"\n### {fmt} ({len(items)})")
        for o in items:
            if args.show >= 0 and shown >= args.show:
                break
            print(f"- {o.line()}")
            shown += 1
    rate = len(outcomes) / wall
    plain_rate = len(regular) / plain if plain > 0 else float("inf")
    print(
        f"\nfuzz: {rate:.1f} cases/s (isolated worker, classification, restarts, timeouts included); "
        f"plain open().read() of the same {len(regular)} files: {plain_rate:.0f} files/s; "
        f"fuzz vs plain read: **{rate / plain_rate:.4f}x**"
    )
    for s in skipped:
        print(f"skipped: {s}")
    if args.json:
        args.json.write_text(json.dumps([fuzzing.outcome_dict(o) for o in outcomes], indent=1, default=str))
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
