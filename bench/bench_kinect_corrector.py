"""Benchmark: throughput of the learned Kinect correctors, PyTorch eager against their ONNX export (onnxruntime), on
real Kinect skeletons, with the Kinect SDK's double-exponential filter beside them as the cheapest reference.

Clips. The first ``--files`` MSR Action3D skeleton files of ``--data`` (sorted by name) that ``kinect-fix`` reads,
resampled to the models' 30 fps and read as Kinect-20 joints with their tracking states exactly as ``mocapkit
kinect-fix apply`` does (:func:`mocapkit.kinect.kinect_fix.kinect_clip`).

Methods, each through its ``predict(clip, state=...)``:

* every ``--model`` (a ``.pt`` from ``mocapkit kinect-fix train --method bigru|transformer``): ``<name> eager``
  (:class:`~mocapkit.kinect.learned.LearnedKinectCorrector`, PyTorch on the CPU) and ``<name> ORT``
  (:class:`~mocapkit.kinect.learned.OnnxKinectCorrector` on its
  :meth:`~mocapkit.kinect.learned.LearnedKinectCorrector.export_onnx`, written to a temporary folder);
  without ``--model`` a tiny BiGRU corrector (16 units, 20 steps) is trained here on six HDM05 clips so that the
  benchmark always runs: its figures time the code path, not a real model;
* ``SDK filter``: :class:`~mocapkit.kinect.reconstruction.DoubleExponentialSmoother` (numpy).

Timing. One untimed warm-up per method, then ``--repeat`` rounds; in every round each clip is corrected by every
method in turn (interleaved). A method's time on a clip is the median over the rounds; throughput = all frames /
the sum of those medians; "× eager" is the ORT throughput over the same model's eager one. ``max |ORT − eager|``
(mm) checks that the two give the same skeletons. Threads: ``torch.set_num_threads(--threads)`` and onnxruntime
``threads=--threads``.

Usage: ``OMP_NUM_THREADS=1 python bench/bench_kinect_corrector.py [--model M.pt ...] [--files 60] [--repeat 5]
[--threads 1] [--data DIR]``
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
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent

from mocapkit.kinect.kinect_fix import MODEL_FPS, kinect_clip
from mocapkit.kinect.learned import (
    LearnedKinectCorrector,
    OnnxKinectCorrector,
)
from mocapkit.kinect.reconstruction import DoubleExponentialSmoother


def msr_clips(root: Path, count: int) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(name, positions [T, 20, 3] m, state [T, 20])`` of the first ``count`` readable files under ``root``."""
    from mocapkit.datasets.formats.motion_io import read_motion

    clips = []
    for path in sorted(root.glob("*_skeleton3D.txt")):
        try:
            positions, state, _ = kinect_clip(read_motion(path).resample(MODEL_FPS))
        except ValueError as exc:
            print(f"  skipped {path.name}: {exc}")
            continue
        clips.append((path.name, positions, state))
        if len(clips) == count:
            break
    if not clips:
        raise SystemExit(f"no MSR Action3D skeleton file under {root}")
    return clips


def train_tiny(hdm05: Path) -> LearnedKinectCorrector:
    """A tiny BiGRU corrector on six HDM05 clips of the simulator (the benchmark's fallback)."""
    from mocapkit.datasets.synthetic.kinect_noise import (
        KinectNoiseConfig,
        simulate_pairs,
    )

    files = sorted(hdm05.rglob("*.amc"))[:6]
    if not files:
        raise SystemExit(f"no --model given and no HDM05 clips under {hdm05} to train a tiny corrector on")
    pairs, _ = simulate_pairs(files, KinectNoiseConfig.preset("msr_steadiness"), seed=0, fps=MODEL_FPS)
    return LearnedKinectCorrector(network={"hidden": 16}, window=32, steps=20, batch_size=8).fit(
        [p.noisy for p in pairs], [p.clean for p in pairs], [p.state for p in pairs]
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, nargs="+", default=[], help="learned correctors (.pt)")
    parser.add_argument("--files", type=int, default=60, help="MSR Action3D files")
    parser.add_argument("--repeat", type=int, default=5, help="timed rounds (median per clip)")
    parser.add_argument("--threads", type=int, default=1, help="torch and onnxruntime intra-op threads")
    parser.add_argument(
        "--data",
        type=Path,
        default=HERE.parent.parent / "shared" / "data",
        help="folder holding msr_action3d/ (and hdm05_cuts11/ for the tiny fallback model)",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    import onnxruntime

    print(f"command: {' '.join(shlex.quote(a) for a in sys.argv)}")
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; torch {torch.__version__}, "
        f"onnxruntime {onnxruntime.__version__}, numpy {np.__version__}; OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS', 'unset')}, threads {args.threads}"
    )
    clips = msr_clips(args.data / "msr_action3d", args.files)
    frames = sum(len(c[1]) for c in clips)
    print(
        f"{len(clips)} MSR Action3D clips at {MODEL_FPS:g} fps, {frames} frames "
        f"({min(len(c[1]) for c in clips)}-{max(len(c[1]) for c in clips)} per clip)"
    )
    models = {p.stem: LearnedKinectCorrector.load(p) for p in args.model} or {
        "tiny_bigru": train_tiny(args.data / "hdm05_cuts11")
    }
    methods, gaps = {}, {}
    with tempfile.TemporaryDirectory() as folder:
        for name, model in models.items():
            info = model.export_onnx(Path(folder) / f"{name}.onnx")
            exported = OnnxKinectCorrector(info["onnx"], threads=args.threads).fit()
            methods[f"{name} eager"], methods[f"{name} ORT"] = model, exported
            gaps[name] = max(
                float(np.abs(exported.predict(x, state=s) - model.predict(x, state=s)).max()) for _, x, s in clips
            )
            print(
                f"{name}: {model.architecture}, {info['exporter']} exporter, max |ORT - eager| over the clips "
                f"{1000 * gaps[name]:.3g} mm"
            )
        methods["SDK filter"] = DoubleExponentialSmoother().fit([clips[0][1]])
        for method in methods.values():  # warm-up
            method.predict(clips[0][1], state=clips[0][2])
        seconds = {name: [] for name in methods}
        for _, x, s in clips:
            rounds = {name: [] for name in methods}
            for _ in range(args.repeat):
                for name, method in methods.items():
                    start = time.perf_counter()
                    method.predict(x, state=s)
                    rounds[name].append(time.perf_counter() - start)
            for name in methods:
                seconds[name].append(statistics.median(rounds[name]))
    throughput = {name: frames / sum(v) for name, v in seconds.items()}
    print("\n| method | frames / s | ms per clip (median) | × eager |\n|---|---:|---:|---:|")
    for name in methods:
        model = name.rsplit(" ", 1)[0]
        ratio = throughput[name] / throughput[f"{model} eager"] if f"{model} eager" in throughput else float("nan")
        print(
            f"| {name} | {throughput[name]:,.0f} | {1000 * statistics.median(seconds[name]):.2f} | "
            f"{'–' if np.isnan(ratio) else f'{ratio:.2f}'} |"
        )


if __name__ == "__main__":
    main()
