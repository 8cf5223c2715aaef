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
    args = parser.parse_args(argv)

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
