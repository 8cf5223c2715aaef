"""Benchmark: throughput of the learned refiners (PyTorch eager and ONNX Runtime) against TrNN and PCA gap filling,
refining the same real HDM05 sequences in one run.

Sequences. ``--clips`` real HDM05 clips of ``../shared/data/hdm05_cuts11`` (read with
:mod:`mocapkit.datasets.mocap.folders`; taken round-robin over the actors, the largest files of each actor
first, keeping those with at least ``--frames`` frames: in ``hdm05_cuts11`` only the lieDownFloor takes of bd, bk
and mm reach 600), cropped to their first ``--frames`` frames (120 fps, 31 joints) and corrupted with ``corrupt(m, "continuous_missing", 40, seed=i)`` (10 markers, each missing for
40 consecutive frames; Wang 2017 §4.2.3).

Methods, each refining every sequence through the refiner contract (``refine(motion) -> Motion``, the layout
checks, windows, blending and report included):

* ``TrNN`` (:class:`mocapkit.refinement.trnn.TrNN`) and ``PCA`` (:class:`mocapkit.refinement.gap_filling.
  PCAGapFilling`), built from ``configs/refinement/method/trnn.yaml`` / ``pca.yaml`` (the comparison runner's settings);
* every ``--ckpt``: ``<label> eager`` (:class:`~mocapkit.refinement.learned.LearnedRefiner` on the checkpoint,
  PyTorch on the CPU) and, with ``--onnx``, ``<label> ORT`` (:class:`~mocapkit.refinement.learned.OnnxRefiner`
  on its export with :func:`~mocapkit.deploy.refiner_export.export_refiner`, written to a temporary folder).
  ``<label>`` is the checkpoint's folder
  name. Without ``--ckpt`` a tiny BiGRU (8 units, one epoch of 64 windows) is trained here on other HDM05 clips so
  that the benchmark always runs: its figures time the code path, not a real model.

Timing. One untimed warm-up ``refine`` per method, then ``--repeat`` rounds; in every round each sequence is
refined by every method in turn (interleaved, so that load changes hit all methods alike). A method's time on
a sequence is the median over the rounds; throughput = all frames / the sum of those medians. "× TrNN" is a
method's throughput over TrNN's (> 1: faster than TrNN). ``RMSE`` is Wang 2017 §4.2.3's matrix RMSE over the
removed entries (cm) and ``unfilled`` the removed entries a method left missing, as sanity checks that every
method did the work. Threads: ``torch.set_num_threads(--threads)`` (TrNN, PCA and the eager networks) and
onnxruntime ``threads=--threads``; set ``OMP_NUM_THREADS`` to the same for the BLAS calls.

Usage: ``OMP_NUM_THREADS=1 python bench/bench_refine_learned.py [--ckpt RUN/best.ckpt ...] [--onnx]
[--clips 8] [--frames 600] [--repeat 5] [--threads 1] [--data DIR]``
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent

from mocapkit.refinement.corruptions import corrupt
from mocapkit.refinement.learned import LearnedRefiner, OnnxRefiner, train_on_motions
from mocapkit.refinement.metrics import matrix_rmse

TINY = [
    "model.hidden=8",
    "model.layers=1",
    "data.window=32",
    "data.windows_per_epoch=64",
    "data.batch_size=16",
    "trainer.max_epochs=1",
    "data.eval_windows_per_clip=1",
]


# ------------------------------------------------------------------------------------------------ data
def hdm05_sequences(root: Path, clips: int, frames: int):
    """``(clean, corruption, name)`` of ``clips`` HDM05 clips with ≥ ``frames`` frames, cropped to ``frames``, and
    the clips not used (for training a tiny model)."""
    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    listed = list_clips("hdm05", root)
    by_actor: dict[str, list[dict]] = {}
    for clip in listed:
        by_actor.setdefault(clip["group"], []).append(clip)
    for of_actor in by_actor.values():
        of_actor.sort(key=lambda c: (-c["path"].stat().st_size, c["name"]))
    chosen, used, rank = [], set(), 0
    while len(chosen) < clips and any(rank < len(v) for v in by_actor.values()):
        for actor in sorted(by_actor):
            if len(chosen) < clips and rank < len(by_actor[actor]):
                clip = by_actor[actor][rank]
                motion = read_clips([clip])[0]
                used.add(clip["name"])
                if motion.num_frames >= frames:
                    chosen.append(motion)
        rank += 1
    if len(chosen) < clips:
        raise SystemExit(f"only {len(chosen)} HDM05 clips under {root} have ≥ {frames} frames ({clips} asked)")
    sequences = []
    for i, motion in enumerate(chosen):
        clean = replace(motion, positions=motion.positions[:frames], missing=motion.missing[:frames])
        sequences.append((clean, corrupt(clean, "continuous_missing", 40, seed=i), motion.name))
    rest = [c for c in listed if c["name"] not in used]
    return sequences, rest


# ------------------------------------------------------------------------------------------------ models
def classical(name: str):
    """The refiner of ``configs/refinement/method/<name>.yaml`` (the comparison runner's settings)."""
    from mocapkit.train.registry import build_method

    return build_method("refinement", name)


def train_tiny(clips: list[dict], folder: Path, count: int = 12) -> Path:
    """Train the tiny BiGRU on ``count`` HDM05 clips (spread over the list) and save a checkpoint that
    :class:`LearnedRefiner` loads."""
    import lightning as L

    from mocapkit.datasets.mocap.folders import read_clips

    picks = [clips[i] for i in np.linspace(0, len(clips) - 1, min(count, len(clips))).round().astype(int)]
    module = train_on_motions("refine_bigru", read_clips(picks), TINY)
    path = folder / "tiny_bigru" / "best.ckpt"
    path.parent.mkdir(parents=True)
    torch.save(
        {
            "state_dict": module.state_dict(),
            "hyper_parameters": dict(module.hparams),
            "pytorch-lightning_version": L.__version__,
        },
        path,
    )
    return path


def export_one(ckpt: Path, out: Path, trace_frames: int) -> str:
    """Export one checkpoint with :func:`~mocapkit.deploy.refiner_export.export_refiner`; its parity line."""
    from mocapkit.deploy.refiner_export import export_refiner

    module = LearnedRefiner._load(ckpt)
    info = export_refiner(module.model, out, dict(module.hparams.skeleton), trace_shape=(2, trace_frames))
    return f"{info['exporter']} exporter, max |ORT - torch| = {info['max_abs_diff']:.2g} m on {info['checked_shape']}"


def _labels(paths: list[Path]) -> list[str]:
    """The checkpoints' folder names; the last two folders where those repeat."""
    names = [p.parent.name for p in paths]
    if len(set(names)) < len(names):
        names = [f"{p.parent.parent.name}/{p.parent.name}" for p in paths]
    return names


# ------------------------------------------------------------------------------------------------ timing
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ckpt", type=Path, nargs="+", default=[], help="refiner checkpoints (RUN/best.ckpt)")
    parser.add_argument("--onnx", action="store_true", help="also time each checkpoint's ONNX export (onnxruntime)")
    parser.add_argument("--clips", type=int, default=8, help="HDM05 sequences")
    parser.add_argument("--frames", type=int, default=600, help="frames per sequence (clips cropped to it)")
    parser.add_argument("--repeat", type=int, default=5, help="timed rounds (median per sequence)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads and onnxruntime intra-op threads")
    parser.add_argument(
        "--trace-frames",
        type=int,
        default=24,
        help="frames of the export's trace (the graph is dynamic in frames; parity is checked at 150)",
    )
    default_data = Path(os.environ.get("MOCAPKIT_SHARED", HERE.parents[1] / "shared")) / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="folder holding hdm05_cuts11/")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    import onnxruntime

    command = shlex.join([os.path.relpath(sys.executable), *(sys.argv if argv is None else [sys.argv[0], *argv])])
    print(f"# command: OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', '(unset)')} {command}", flush=True)
    print(
        f"# machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, torch {torch.__version__}, "
        f"onnxruntime {onnxruntime.__version__}, numpy {np.__version__}",
        flush=True,
    )
    print(
        f"# threads: torch.set_num_threads({args.threads}) (torch reports {torch.get_num_threads()}), onnxruntime "
        f"threads={args.threads}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', '(unset)')}",
        flush=True,
    )
    root = args.data / "hdm05_cuts11"
    sequences, rest = hdm05_sequences(root, args.clips, args.frames)
    total_frames = sum(c.num_frames for c, _, _ in sequences)
    print(
        f"# sequences: {len(sequences)} HDM05 clips cropped to {args.frames} frames ({total_frames} frames, "
        f"{sequences[0][0].fps:g} fps, {sequences[0][0].num_joints} joints), continuous_missing ml = 40 "
        f"(seed = sequence index): {', '.join(n for _, _, n in sequences)}",
        flush=True,
    )

    work = tempfile.TemporaryDirectory(prefix="bench_refine_learned_")
    ckpts = list(args.ckpt)
    if not ckpts:
        start = time.perf_counter()
        ckpts = [train_tiny(rest, Path(work.name))]
        print(
            f"# no --ckpt given: trained a tiny BiGRU here ({' '.join(TINY)}) on 12 other HDM05 clips in "
            f"{time.perf_counter() - start:.0f} s; its figures time the code path, not a real model",
            flush=True,
        )
    methods = {"TrNN": classical("trnn"), "PCA": classical("pca")}
    for label, ckpt in zip(_labels(ckpts), ckpts):
        eager = LearnedRefiner(checkpoint=str(ckpt)).fit()
        model = eager.module_.model
        params = sum(p.numel() for p in model.parameters())
        hp = eager.module_.hparams.model
        print(
            f"# {label}: {ckpt} — {type(model).__name__} "
            f"({', '.join(f'{k}={v}' for k, v in hp.items() if not k.startswith('_'))}), {params:,} parameters, "
            f"window {eager.window_} frames, overlap {eager.overlap_}",
            flush=True,
        )
        methods[f"{label} eager"] = eager
        if args.onnx:
            out = Path(work.name) / f"{label.replace('/', '_')}.onnx"
            start = time.perf_counter()
            parity = export_one(ckpt, out, args.trace_frames)
            print(f"#   exported to {out.name} in {time.perf_counter() - start:.0f} s ({parity})", flush=True)
            methods[f"{label} ORT"] = OnnxRefiner(str(out), threads=args.threads).fit()

    for refiner in methods.values():  # warm-up (first calls, lazy imports), not timed
        refiner.refine(sequences[0][1].motion)
    seconds = {name: [[] for _ in sequences] for name in methods}
    outputs = {}
    for _ in range(args.repeat):
        for i, (_, corruption, _) in enumerate(sequences):
            for name, refiner in methods.items():
                start = time.perf_counter()
                out = refiner.refine(corruption.motion)
                seconds[name][i].append(time.perf_counter() - start)
                outputs[name, i] = out
    medians = {name: [statistics.median(s) for s in per_seq] for name, per_seq in seconds.items()}
    rate = {name: total_frames / sum(m) for name, m in medians.items()}

    print(f"# {args.repeat} rounds, median per sequence; load average {os.getloadavg()[0]:.1f} after", flush=True)
    print(
        f"{'method':28s} | {'frames/s':>9s} | {'ms/seq median':>13s} {'min':>7s} {'max':>7s} | {'× TrNN':>7s} | "
        f"{'RMSE cm':>7s} | {'unfilled':>8s}",
        flush=True,
    )
    for name in methods:
        rmse = np.mean([matrix_rmse(clean, outputs[name, i], c.removed) for i, (clean, c, _) in enumerate(sequences)])
        unfilled = sum(int((outputs[name, i].missing & c.removed).sum()) for i, (_, c, _) in enumerate(sequences))
        ms = [1000 * s for s in medians[name]]
        print(
            f"{name:28s} | {rate[name]:9.0f} | {statistics.median(ms):13.1f} {min(ms):7.1f} {max(ms):7.1f} | "
            f"{rate[name] / rate['TrNN']:7.2f} | {rmse:7.2f} | {unfilled:8d}",
            flush=True,
        )
    print("# per sequence, median ms:", flush=True)
    print(f"{'sequence':40s} " + " ".join(f"{n[:14]:>14s}" for n in methods), flush=True)
    for i, (_, _, seq_name) in enumerate(sequences):
        print(f"{seq_name[:40]:40s} " + " ".join(f"{1000 * medians[n][i]:14.1f}" for n in methods), flush=True)
    work.cleanup()


if __name__ == "__main__":
    main()
