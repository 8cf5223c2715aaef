"""Benchmark: NTU ``.skeleton`` parsing speed and ``prepare_ntu`` throughput.

Compares, in one run and on one core:

* ``read_skeleton`` (mocapkit: one numpy conversion for all joint lines), and
* ``baseline_read_xyz``, a plain line-by-line reader of the kind public repositories
  use (NTU MATLAB ``read_skeleton_file.m`` -> 2s-AGCN / pyskl ``read_skeleton_filter``):
  per line ``.split()`` and ``float()`` per value into nested dicts, then numpy.

then times ``prepare_ntu`` with 1 and 2 workers on the same files. Every figure
is the best of ``--repeat`` runs; the load average is printed because other
processes on the machine mostly hurt the 2-worker figure.

Input: the real samples in ``shared/samples/ntu_skeleton`` (next to the repository),
replicated into a temporary folder under many NTU-style names to get enough
volume. Skips with a message if that folder is absent.

Usage: ``python bench/bench_skeleton_parse.py [--files 400] [--repeat 3] [--src DIR]``
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.ntu_skeleton import read_skeleton
from mocapkit.datasets.ntu.prepare import prepare_ntu

DEFAULT_SRC = Path(__file__).resolve().parents[1].parent / "shared" / "samples" / "ntu_skeleton"

BODY_KEYS = (
    "bodyID",
    "clipedEdges",
    "handLeftConfidence",
    "handLeftState",
    "handRightConfidence",
    "handRightState",
    "isResticted",
    "leanX",
    "leanY",
    "trackingState",
)
JOINT_KEYS = (
    "x",
    "y",
    "z",
    "depthX",
    "depthY",
    "colorX",
    "colorY",
    "orientationW",
    "orientationX",
    "orientationY",
    "orientationZ",
    "trackingState",
)


def baseline_read_skeleton_filter(path: str | Path) -> dict:
    """The common public reader: nested dicts, one ``float()`` per value (body IDs lose precision)."""
    with open(path) as f:
        sequence = {"numFrame": int(f.readline()), "frameInfo": []}
        for _ in range(sequence["numFrame"]):
            frame = {"numBody": int(f.readline()), "bodyInfo": []}
            for _ in range(frame["numBody"]):
                body = {k: float(v) for k, v in zip(BODY_KEYS, f.readline().split())}
                body["numJoint"] = int(f.readline())
                body["jointInfo"] = []
                for _ in range(body["numJoint"]):
                    joint = {k: float(v) for k, v in zip(JOINT_KEYS, f.readline().split())}
                    body["jointInfo"].append(joint)
                frame["bodyInfo"].append(body)
            sequence["frameInfo"].append(frame)
    return sequence


def baseline_read_xyz(path: str | Path, max_body: int = 4, num_joint: int = 25) -> np.ndarray:
    """``[max_body, T, 25, 3]`` float32 positions by body slot, as 2s-AGCN's ``read_xyz``."""
    seq = baseline_read_skeleton_filter(path)
    data = np.zeros((max_body, seq["numFrame"], num_joint, 3), dtype=np.float32)
    for t, frame in enumerate(seq["frameInfo"]):
        for m, body in enumerate(frame["bodyInfo"]):
            for j, joint in enumerate(body["jointInfo"]):
                if m < max_body and j < num_joint:
                    data[m, t, j, :] = [joint["x"], joint["y"], joint["z"]]
    return data


def replicate(src: Path, dest: Path, n_files: int) -> list[Path]:
    """Copy the sample files into ``dest`` under ``n_files`` distinct NTU names."""
    samples = sorted(src.glob("*.skeleton"))
    files = []
    for k in range(n_files):
        s = samples[k % len(samples)]
        # Distinct setup / camera / subject / replication / action fields for every copy.
        name = f"S{1 + k % 32:03d}C{1 + k % 3:03d}P{1 + (k // 3) % 106:03d}R{1 + k % 2:03d}A{1 + (k // 7) % 120:03d}"
        path = dest / f"{name}.skeleton"
        if path.exists():
            raise RuntimeError(f"name clash in the benchmark generator: {name}")
        shutil.copyfile(s, path)
        files.append(path)
    return files


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (pool workers), user + system."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def best_of(tasks: dict, repeat: int) -> dict[str, tuple[float, float]]:
    """``{name: (wall s, CPU s)}``, the best of ``repeat`` rounds for each task.

    Tasks run interleaved in every round, so that other load on the machine hits
    them alike. CPU seconds are what a task costs even when it has to share cores.
    """
    best = {name: (float("inf"), float("inf")) for name in tasks}
    for _ in range(repeat):
        for name, task in tasks.items():
            wall, cpu = time.perf_counter(), cpu_seconds()
            task()
            wall, cpu = time.perf_counter() - wall, cpu_seconds() - cpu
            best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", type=Path, default=DEFAULT_SRC, help="folder with real .skeleton samples")
    parser.add_argument("--files", type=int, default=400, help="replicated files to parse")
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement; the best is reported")
    args = parser.parse_args(argv)

    if not args.src.is_dir() or not any(args.src.glob("*.skeleton")):
        print(f"SKIP: no .skeleton samples in {args.src} (the benchmark needs the real NTU sample files)")
        return 0

    load = os.getloadavg()  # other work on the machine skews the 2-worker figure first
    with tempfile.TemporaryDirectory(prefix="bench_ntu_") as tmp:
        tree = Path(tmp) / "src"
        tree.mkdir()
        files = replicate(args.src, tree, args.files)
        megabytes = sum(f.stat().st_size for f in files) / 1e6

        # Both readers must agree on the positions before their speeds mean anything.
        for f in sorted(args.src.glob("*.skeleton")):
            ours = read_skeleton(f).positions
            theirs = baseline_read_xyz(f)[: ours.shape[0]]
            np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-6, err_msg=str(f))

        for f in files:  # warm the page cache
            read_skeleton(f)

        def prepare(workers):
            def run():
                report = prepare_ntu(tree, Path(tmp) / f"cache_w{workers}", workers=workers, progress=False)
                assert report.samples_written == len(files)

            return run

        best = best_of(
            {"base": lambda: [baseline_read_xyz(f) for f in files], "ours": lambda: [read_skeleton(f) for f in files]},
            args.repeat,
        )
        best.update(best_of({"prep1": prepare(1), "prep2": prepare(2)}, args.repeat))

    n = len(files)
    rows = [
        ("baseline `read_skeleton_filter` + `read_xyz` (line by line)", 1, "base"),
        ("`read_skeleton` (mocapkit)", 1, "ours"),
        ("`prepare_ntu` (parse + select bodies + write cache)", 1, "prep1"),
        ("`prepare_ntu`", 2, "prep2"),
    ]
    print(
        f"\n{n} files, {megabytes:.1f} MB (replicated from {args.src}), best of {args.repeat} runs each; "
        f"{os.cpu_count()} CPUs, load average before the run {load[0]:.2f}\n"
    )
    print("| reader | workers | wall s | CPU s | files/s (wall) | MB/s (wall) |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, workers, key in rows:
        wall, cpu = best[key]
        print(f"| {label} | {workers} | {wall:.2f} | {cpu:.2f} | {n / wall:.0f} | {megabytes / wall:.1f} |")
    ratio_wall = best["base"][0] / best["ours"][0]
    ratio_cpu = best["base"][1] / best["ours"][1]
    verdict = "OK" if min(ratio_wall, ratio_cpu) >= 2 else "BELOW TARGET"
    print(f"\n`read_skeleton` vs baseline: {ratio_wall:.2f}x (wall), {ratio_cpu:.2f}x (CPU); target >= 2x: {verdict}")
    print(f"`prepare_ntu` 2 workers vs 1 (wall): {best['prep1'][0] / best['prep2'][0]:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
