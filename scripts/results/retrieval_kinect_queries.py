"""Kinect skeletons as queries of a mocap library: HDM05 across performers, queries through the Kinect simulator.

    OMP_NUM_THREADS=1 python scripts/results/retrieval_kinect_queries.py [--hdm05 ../shared/data/hdm05_cuts11]
        [--methods dtw_positions,dtw_mutual_proximity] [--fix smoother,gp] [--json OUT.json]

Each HDM05 performer in turn gives the queries; the other three performers' clips (clean ASF/AMC mocap, 31 joints)
are the database, as ``mocapkit compare retrieval_hdm05``'s ``cross_performer`` protocol. Every query is given:

- ``mocap``: the clip itself (the compare protocol's number);
- ``kinect``: the clip through the Kinect v1 simulator (:func:`~mocapkit.datasets.synthetic.kinect_noise.simulate_pairs`,
  the calibrated default error model ``--noise``, seed 0, 30 fps), as a 20-joint MSR-20 skeleton (the joint names
  a Kinect file read by ``read_motion`` has), so that it reaches the library through the shared landmarks exactly
  as an MSR Action3D or NTU file does;
- ``kinect + FIX``: that Kinect skeleton corrected first by a kinect-fix method of the registry (``--fix``):
  ``smoother`` (the SDK's smoothing, learns nothing) or ``gp`` (Zhou 2014 ch. 5), fitted on simulated pairs of the
  **database performers' clips only** (the query performer never seen), seed 0.

mAP and P@1 pooled over every query of every fold (relevance = same class, :mod:`mocapkit.retrieval.metrics`).
Plain DTW (``dtw_plain``) cannot take these queries: it compares joint by joint, and a Kinect skeleton has 20
joints against the library's 31 (it refuses them naming both counts). Results:
docs/results/retrieval.md#kinect-queries.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mocapkit.datasets.synthetic.kinect_noise import KinectNoiseConfig, simulate_pairs
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import LANDMARK_NAMES, MSR20, find_landmarks
from mocapkit.retrieval.benchmark import _pooled
from mocapkit.retrieval.metrics import retrieval_metrics
from mocapkit.train.registry import build_method

FPS = 30.0


def kinect_motion(positions: np.ndarray, name: str) -> Motion:
    """Simulated Kinect-20 landmarks ``[T, 20, 3]`` (:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order, y up,
    m, 30 fps) as the MSR-20 skeleton a Kinect file reads as."""
    found = find_landmarks(MSR20.joint_names, MSR20.name)
    out = np.zeros((len(positions), len(MSR20.joint_names), 3), dtype=np.float32)
    for k, landmark in enumerate(LANDMARK_NAMES):
        out[:, found[landmark]] = positions[:, k]
    return Motion(out, MSR20.joint_names, FPS, parents=MSR20.parents, name=name, layout_name=MSR20.name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hdm05", default="../shared/data/hdm05_cuts11")
    parser.add_argument("--methods", default="dtw_positions,dtw_mutual_proximity")
    parser.add_argument("--fix", default="smoother,gp", help="kinect methods applied to the queries first ('' none)")
    parser.add_argument("--noise", default="mean_error", help="simulator calibration (KinectNoiseConfig.preset)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    clips = list_clips("hdm05", args.hdm05)
    motions = read_clips(clips)
    labels = np.array([c["class"] for c in clips])
    groups = np.array([c["group"] for c in clips])
    config = KinectNoiseConfig.preset(args.noise)
    start = time.perf_counter()
    pairs, _ = simulate_pairs([c["path"] for c in clips], config, seed=0, fps=FPS)
    print(f"simulated {len(pairs)} Kinect clips in {time.perf_counter() - start:.0f} s", flush=True)
    kinect = [kinect_motion(p.noisy, Path(p.path).name) for p in pairs]
    fixes = [f for f in args.fix.split(",") if f]
    conditions = ["mocap", "kinect", *[f"kinect + {f}" for f in fixes]]
    scores = {(m, c): [] for m in args.methods.split(",") for c in conditions}
    timing = {}
    for performer in sorted(set(groups)):
        db = np.flatnonzero(groups != performer)
        q = np.flatnonzero(groups == performer)
        queries = {"mocap": [motions[i] for i in q], "kinect": [kinect[i] for i in q]}
        for fix in fixes:
            model = build_method("kinect", fix, ["random_state=0"] if fix != "smoother" else [])
            begin = time.perf_counter()
            model.fit([pairs[i].noisy for i in db], [pairs[i].clean for i in db], [pairs[i].state for i in db])
            fixed = model.predict([pairs[i].noisy for i in q], [pairs[i].state for i in q])
            timing[f"{fix} {performer}"] = time.perf_counter() - begin
            queries[f"kinect + {fix}"] = [kinect_motion(f, kinect[i].name) for f, i in zip(fixed, q)]
            print(f"{performer}: {fix} fitted and applied in {timing[f'{fix} {performer}']:.0f} s", flush=True)
        for name in args.methods.split(","):
            method = build_method("retrieval", name).fit([motions[i] for i in db])
            for condition in conditions:
                d = method.distances(queries[condition])
                scores[(name, condition)].append(retrieval_metrics(d, labels[q], labels[db]))
                print(performer, name, condition, round(scores[(name, condition)][-1]["metrics"]["map"], 3), flush=True)
    rows = []
    for (name, condition), folds in scores.items():
        pooled = _pooled(folds)
        rows.append({"method": name, "queries": condition, "map": pooled["map"], "p@1": pooled["p@1"]})
        print(f"| {name} | {condition} | {pooled['map']:.3f} | {pooled['p@1']:.3f} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": rows, "fix_seconds": timing}, indent=1))


if __name__ == "__main__":
    main()
