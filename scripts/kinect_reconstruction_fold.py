"""One held-out-performer fold of Kinect posture reconstruction on simulated pairs from the real HDM05 cuts.

Every HDM05 cut is turned into a (Kinect, mocap) pair by the default Kinect v1 noise simulator
(:func:`mocapkit.datasets.synthetic.kinect_noise.simulate_pairs`, seed 0); the clips of three performers train,
those of ``ACTOR`` are the test set. Printed (and written as JSON with ``--out``): the raw Kinect error, the
Shen et al. 2012-style random forest, and Zhou 2014 ch. 5's reconstructor with the thesis's weights and every
subset of its three terms (Table 5.3's ablation: one GP fit, the weights changed at prediction). Errors are the
per-frame mean joint error in cm over the test frames (``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md``
§4.6, §7 item 29). Simulated data: not comparable with the thesis's Table 5.2.

Usage (from the repository root; about 9 min on one core)::

    python scripts/kinect_reconstruction_fold.py mm --out checkpoints/kinect_fold_mm.json
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mocapkit.classical.kinect_reconstruction import (
    KinectPostureReconstructor,
    RandomForestPoseCorrector,
    mean_joint_error_cm,
)
from mocapkit.datasets.synthetic.kinect_noise import simulate_pairs

#: (w_spatial, w_temporal, w_reliability) of each row: the thesis's weights, then Table 5.3's subsets.
ABLATION = {"S+T+R": (0.6, 0.2, 0.2), "S": (1, 0, 0), "T": (0, 1, 0), "R": (0, 0, 1),
            "S+T": (0.6, 0.2, 0), "S+R": (0.6, 0, 0.2), "R+T": (0, 0.5, 0.5)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("actor", help="the held-out HDM05 performer (bd, bk, dg, mm)")
    parser.add_argument("--src", default=str(Path(__file__).resolve().parents[2] / "shared/data/hdm05_cuts11"))
    parser.add_argument("--seed", type=int, default=0, help="simulation and model seed")
    parser.add_argument("--out", help="write the figures as JSON here")
    args = parser.parse_args()
    files = sorted(Path(args.src).glob("*/*.amc"))
    if not files:
        raise SystemExit(f"no .amc files under {args.src}")
    pairs, skipped = simulate_pairs(files, seed=args.seed)
    train = [p for p, f in zip(pairs, files) if f.parent.name != args.actor]
    test = [p for p, f in zip(pairs, files) if f.parent.name == args.actor]
    if not test:
        raise SystemExit(f"no clips of performer {args.actor!r} under {args.src}")

    def error(predictions) -> float:
        frames = sum(len(p.clean) for p in test)
        return sum(mean_joint_error_cm(y, p.clean) * len(p.clean) for y, p in zip(predictions, test)) / frames

    result = {"actor": args.actor, "train_clips": len(train), "test_clips": len(test), "skipped": len(skipped),
              "raw": error([p.noisy for p in test])}
    print(f"raw Kinect: {result['raw']:.2f} cm", flush=True)
    start = time.perf_counter()
    forest = RandomForestPoseCorrector(n_estimators=100, max_train_frames=20000, n_jobs=1, random_state=args.seed)
    forest.fit([p.noisy for p in train], [p.clean for p in train])
    result["random_forest"] = error(forest.predict([p.noisy for p in test]))
    print(f"random forest (Shen et al. 2012 style): {result['random_forest']:.2f} cm "
          f"(fit {time.perf_counter() - start:.0f} s)", flush=True)
    start = time.perf_counter()
    model = KinectPostureReconstructor(random_state=args.seed).fit([p.noisy for p in train], [p.clean for p in train])
    print(f"GP fit {time.perf_counter() - start:.0f} s", flush=True)
    for name, (ws, wt, wr) in ABLATION.items():
        model.set_params(w_spatial=ws, w_temporal=wt, w_reliability=wr)
        result[name] = error(model.predict([p.noisy for p in test], state=[p.state for p in test]))
        print(f"Zhou ch. 5, {name}: {result[name]:.2f} cm", flush=True)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
