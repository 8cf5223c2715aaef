"""Choose the depth tracker's defaults on training performers only (docs/decisions.md#depth-tracker-defaults).

    OMP_NUM_THREADS=1 python scripts/selection/depth_tracker_defaults.py [--root ../shared/data/hdm05_cuts11]
        [--validate dg] [--database bd bk] [--config '{"damping": 0.1}' ...] [--json OUT.json]

Validation data: one take per motion class of the validation performer (``--validate``, dg), the first 2 s,
Kinect v1 depth rendered with render seed 0 (``DepthTrackingBenchmark``'s own choice of takes and rendering, so the
numbers are those of a held-out protocol); the LPCA database is the other training performers' takes
(``--database``), whose renders also train the GP of ``anchor=sensor_gp``. The held-out performer of the reported results (mm) is never read. Each ``--config`` is a JSON
dict of ``DepthTracker`` parameters over the registry's ``tracker`` with the thesis's assumption of a known
performer skeleton (``skeleton=ground_truth``); printed: the mean error over the takes (mm), per take, and the
sensor skeleton's on the same frames.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main(argv=None) -> None:
    from mocapkit.depth_tracking.base import joint_error_mm, tracked_joints
    from mocapkit.depth_tracking.benchmark import DepthTrackingBenchmark
    from mocapkit.train.registry import build_method

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default="../shared/data/hdm05_cuts11")
    parser.add_argument("--validate", default="dg")
    parser.add_argument("--database", nargs="+", default=["bd", "bk"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--config", action="append", default=None, help="JSON dict of DepthTracker parameters")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    configs = [json.loads(c) for c in (args.config or ["{}"])]

    bench = DepthTrackingBenchmark(args.root, protocols=[args.validate, *args.database])
    test = np.flatnonzero(bench.groups == args.validate)
    train = np.flatnonzero(np.isin(bench.groups, args.database))
    sequences = bench.data(test, args.seed)
    training = bench.data(train, args.seed)
    truth = [tracked_joints(s.joints) for s in sequences]
    sensor = np.mean([joint_error_mm(tracked_joints(s.sensor_joints), t).mean() for s, t in zip(sequences, truth)])
    print(f"validation {args.validate}: {len(sequences)} takes; sensor skeleton {sensor:.1f} mm", flush=True)
    rows = []
    for config in configs:
        overrides = ["skeleton=ground_truth"] + [f"{k}={json.dumps(v)}" for k, v in config.items()]
        tracker = build_method("depth_tracking", "tracker", overrides)
        tracker = tracker.fit(training)
        start = time.perf_counter()
        errors = [float(joint_error_mm(tracker.predict(s), t).mean()) for s, t in zip(sequences, truth)]
        seconds = time.perf_counter() - start
        frames = sum(len(t) for t in truth)
        rows.append(
            {
                "config": config,
                "error_mm": float(np.mean(errors)),
                "per_take_mm": errors,
                "seconds_per_frame": seconds / frames,
            }
        )
        print(
            f"{config}: {np.mean(errors):.1f} mm, per take {np.round(errors).astype(int).tolist()}, "
            f"{seconds / frames:.2f} s a frame",
            flush=True,
        )
    if args.json:
        with open(args.json, "w") as handle:
            json.dump({"args": vars(args), "sensor_mm": float(sensor), "rows": rows}, handle, indent=1)


if __name__ == "__main__":
    main()
