"""How good is the learned refiners' first guess on its own? Its rules against linear and PCHIP interpolation.

The refiner networks (:mod:`mocapkit.models.refiners`) correct a cubic Hermite first guess
(:func:`~mocapkit.models.refiners.cubic_fill`); on short gaps the correction is small, so the guess is most of the
answer. This script scores the guess alone, in raw metres (no normalisation, no network), under each rule, on real
HDM05 clips of **one performer** (choose a training performer of the runs you compare: the rules of the shipped
networks were chosen with ``--performer dg``, a training performer of every fold of the learned-refiner table),
beside the linear and PCHIP refiners of ``configs/refiner/``.

Rules: ``tangents`` (``chord`` / ``zero``: the tangent at a gap end whose outer neighbour is missing) and
``extrapolate`` (frames the last observed step is continued past a take's ends; 0 holds the nearest value).
Clips: every ``--stride``-th clip of the performer (by path), at most ``--clips``, cropped to ``--frames``;
corruption ``corrupt(clip, protocol, level, seed=i)`` for clip ``i``. Printed: Wang 2017 §4.2.3's matrix RMSE over
the removed entries (cm), mean over clips, one row per protocol.

Usage (from the repository root)::

    python scripts/refiner_first_guess.py                       # dg, 10 clips, the protocols below
    python scripts/refiner_first_guess.py --performer bd --clips 20
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from mocapkit.datasets.mocap.folders import list_clips, read_clips
from mocapkit.evaluation.refinement import matrix_rmse
from mocapkit.models.refiners import cubic_fill
from mocapkit.refinement.corruptions import corrupt

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = [("random_missing", 0.2), ("random_missing", 0.5), ("continuous_missing", 10),
             ("continuous_missing", 40), ("continuous_missing", 60)]
RULES = {"zero, hold (first runs)": ("zero", 0), "chord, hold": ("chord", 0), "chord, extrapolate 2": ("chord", 2),
         "chord, extrapolate 6": ("chord", 6), "chord, extrapolate 12": ("chord", 12)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    parser.add_argument("--performer", default="dg")
    parser.add_argument("--clips", type=int, default=10)
    parser.add_argument("--stride", type=int, default=4)
    parser.add_argument("--frames", type=int, default=250)
    args = parser.parse_args(argv)

    listed = [c for c in list_clips("hdm05", args.data) if c["group"] == args.performer]
    if not listed:
        raise SystemExit(f"{args.data}: no HDM05 clips of performer {args.performer!r}")
    motions = [replace(m, positions=m.positions[:args.frames], missing=m.missing[:args.frames])
               for m in read_clips(listed[::args.stride][:args.clips])]
    baselines = {name: instantiate(OmegaConf.load(ROOT / "configs" / "refiner" / f"{name}.yaml"))
                 for name in ("linear", "pchip")}
    print(f"# {len(motions)} clips of {args.performer}, ≤ {args.frames} frames; matrix RMSE over removed entries, cm")
    print("| protocol | " + " | ".join([*RULES, *baselines]) + " |")
    print("|---|" + "---:|" * (len(RULES) + len(baselines)))
    for protocol, level in PROTOCOLS:
        scores: dict[str, list[float]] = {}
        for i, motion in enumerate(motions):
            corruption = corrupt(motion, protocol, level, seed=i)
            x = torch.from_numpy(np.nan_to_num(corruption.motion.positions))[None]
            observed = torch.from_numpy(~corruption.motion.missing)[None]
            for name, (tangents, extrapolate) in RULES.items():
                guess = cubic_fill(x, observed, tangents, extrapolate)[0].numpy()
                scores.setdefault(name, []).append(matrix_rmse(motion, guess, corruption.removed))
            for name, refiner in baselines.items():
                scores.setdefault(name, []).append(matrix_rmse(motion, refiner.refine(corruption.motion),
                                                               corruption.removed))
        print(f"| {protocol} {level} | " + " | ".join(f"{np.nanmean(v):.3f}" for v in scores.values()) + " |")


if __name__ == "__main__":
    main()
