"""Where an exported refiner spends its time in onnxruntime: per operator type, per network part, per node.

Exports a refiner checkpoint (``mocapkit.deploy.refiner_export.export_refiner``, the exporter of ``mocapkit
export``) or takes an ``.onnx`` file, runs it on real HDM05 takes with onnxruntime's profiler
(``SessionOptions.enable_profiling``; one thread, as ``bench/bench_refine_learned.py`` times it) and prints, per
``session.run`` and averaged over the runs:

* the time outside the profiler (median ``session.run`` without profiling: the profiler adds a few µs per node);
* kernel time per operator type (onnxruntime's fused operators, e.g. ``FusedMatMul``, under their own names);
* kernel time per part of the network — the module that produced each node (``blocks.0``, ``gru``, ``embed``,
  ``normalizer``) or, for the code of the refiner itself (first guess, features), the PyTorch operator — read
  from the node metadata the dynamo exporter writes (the TorchScript exporter's node names carry the module path).
  The transformer's layers export through a function (``encoder_layer_forward``), not their modules, so their
  projections, matrix products and softmax are listed as ``refiner: linear / matmul / softmax``, beside the
  refiner's own small matrix products; their layer norms and feed-forward layers keep their ``blocks.<i>``;
* the slowest nodes with their input shapes.

Takes: the first ``--clips`` HDM05 clips with ≥ ``--frames`` frames (``bench/bench_refine_learned.py``'s choice),
cropped to ``--frames`` frames and corrupted with ``continuous_missing`` 40, one take per run (batch 1).

Usage (from the repository root)::

    OMP_NUM_THREADS=1 python bench/profile_refiner_onnx.py checkpoints/refine_transformer/fold_mm/best.ckpt
    OMP_NUM_THREADS=1 python bench/profile_refiner_onnx.py model.onnx --frames 300 --runs 30 --top 25
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))


def module_of(node) -> str:
    """The network part a node comes from: its module path (``blocks.0``, ``normalizer``), else the PyTorch operator
    of the refiner's own code (``where``, ``gather``), from the dynamo exporter's ``namespace`` metadata or, for the
    TorchScript exporter, the ``/module/...`` node name."""
    meta = {p.key: p.value for p in node.metadata_props}
    namespace = meta.get("namespace", "")
    if namespace:
        parts = namespace.split("/")
        inner = parts[1].split(":")[0].strip() if len(parts) > 1 else parts[0]
        if "." in inner or inner in ("normalizer", "embed", "out", "norm", "gru", "inp"):
            return inner.split(".")[0] + ("." + inner.split(".")[1] if inner.startswith("blocks.") else "")
        return "refiner: " + inner.rstrip("_0123456789")
    if node.name.startswith("/") and node.name.count("/") >= 2:
        return node.name.split("/")[1]
    return "refiner: " + node.op_type


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=Path, help="a refiner run's checkpoint (RUN/best.ckpt) or an exported .onnx")
    parser.add_argument("--frames", type=int, default=300, help="frames per take")
    parser.add_argument("--clips", type=int, default=4, help="HDM05 takes, one per run in turn")
    parser.add_argument("--runs", type=int, default=30, help="profiled session.run calls")
    parser.add_argument("--top", type=int, default=20, help="slowest nodes listed")
    default_data = Path(os.environ.get("MOCAPKIT_SHARED", ROOT.parent / "shared")) / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="folder holding hdm05_cuts11/")
    args = parser.parse_args(argv)

    import onnx
    import onnxruntime as ort
    from bench_refine_learned import export_one, hdm05_sequences

    work = tempfile.TemporaryDirectory(prefix="profile_refiner_")
    path = args.model
    if path.suffix != ".onnx":
        path = Path(work.name) / "refiner.onnx"
        print(f"# exported {args.model}: {export_one(args.model, path, 24)}")
    sequences, _ = hdm05_sequences(args.data / "hdm05_cuts11", args.clips, args.frames)
    feeds = [
        {"positions": c.motion.positions[None].astype(np.float32), "missing": c.motion.missing[None]}
        for _, c, _ in sequences
    ]
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    plain = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    for feed in feeds:
        plain.run(["refined"], feed)
    seconds = []
    for i in range(args.runs):
        start = time.perf_counter()
        plain.run(["refined"], feeds[i % len(feeds)])
        seconds.append(time.perf_counter() - start)
    options.enable_profiling = True
    options.profile_file_prefix = str(Path(work.name) / "profile")
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    for i in range(args.runs):
        session.run(["refined"], feeds[i % len(feeds)])
    events = json.loads(Path(session.end_profiling()).read_text())

    part = {node.name: module_of(node) for node in onnx.load(str(path)).graph.node}
    by_op, by_part, by_node = collections.Counter(), collections.Counter(), collections.Counter()
    count_op, count_part, shapes, op_of = collections.Counter(), collections.Counter(), {}, {}
    for event in events:
        if event.get("cat") != "Node" or not event["name"].endswith("_kernel_time"):
            continue
        name, op = event["name"][: -len("_kernel_time")], event["args"]["op_name"]
        where = part.get(name, f"(fused by onnxruntime) {op}")
        by_op[op] += event["dur"]
        by_part[where] += event["dur"]
        by_node[name] += event["dur"]
        count_op[op] += 1
        count_part[where] += 1
        op_of[name] = op
        shapes[name] = [next(iter(s.values())) for s in event["args"].get("input_type_shape", [])]
    per_run = 1000.0 * args.runs  # µs summed over the runs → ms per run
    total = sum(by_op.values()) / per_run
    print(f"# {path.name}: {args.clips} HDM05 takes of {args.frames} frames, batch 1, 1 thread, {args.runs} runs")
    print(
        f"session.run without the profiler: {1000 * statistics.median(seconds):.2f} ms (median); "
        f"kernel time with it: {total:.2f} ms per run, {sum(count_op.values()) // args.runs} nodes"
    )
    print("\nper operator type (ms per run, nodes):")
    for op, us in by_op.most_common():
        print(f"  {us / per_run:7.3f}  {count_op[op] // args.runs:4d}  {op}")
    print("\nper part of the network (ms per run, nodes):")
    for where, us in by_part.most_common():
        print(f"  {us / per_run:7.3f}  {count_part[where] // args.runs:4d}  {where}")
    print(f"\nslowest {args.top} nodes (µs per run, operator, inputs' shapes):")
    for name, us in by_node.most_common(args.top):
        print(f"  {us / args.runs:8.1f}  {op_of[name]:<22s} {name}  {shapes[name]}")


if __name__ == "__main__":
    main()
