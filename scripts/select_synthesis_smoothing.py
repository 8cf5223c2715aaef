"""Choose the synthesisers' default ``smoothing_seconds`` on training clips only (rule: bench/RESULTS.md §16,
*Smoothing the variants*).

For each motion type below, the benchmark's seed-0 split gives 10 training clips. For every candidate, SLFM is
fitted on them with its defaults and that smoothing (the automatic noise scale is then chosen on smoothed
variants), samples ``--variants`` variants, and each variant is scored against **the training clips themselves**
(posed on the reference skeleton, as the benchmark poses its references): within their spread on every proxy at
once (:func:`~mocapkit.evaluation.synthesis.within_spread`: feature distance against the training clips'
leave-one-out distances, foot skating, jerk and bone drift no larger than the largest training clip's). No
held-out clip is read. The candidate with the highest mean share over the types wins; a smaller candidate within
``--tie`` of the best wins instead.

Usage (from the repository root; about 2 min per fit on one core)::

    OMP_NUM_THREADS=1 python scripts/select_synthesis_smoothing.py [--types hdm05:hopBothLegs1hops ...]
    OMP_NUM_THREADS=1 python scripts/select_synthesis_smoothing.py --summary     # after runs of single types
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from hydra.utils import instantiate

from mocapkit.evaluation.compare import compose
from mocapkit.evaluation.synthesis import clip_naturalness, feature_distances, variation, within_spread
from mocapkit.synthesis.base import on_skeleton
from mocapkit.synthesis.slfm import SLFMSynthesizer

ROOT = Path(__file__).resolve().parents[1]
TYPES = ("hdm05:hopBothLegs1hops", "hdm05:squat1Reps", "bandai:walk")
CANDIDATES = (0.0, 1 / 30, 2 / 30, 3 / 30)


def training_clips(dataset: str, motion_type: str, seed: int = 0):
    """The seed's 10 training clips of a type, from the benchmark config ``synthesis_<dataset>``."""
    benchmark = instantiate(compose([f"synthesis_{dataset}"]).benchmark)
    train, _ = benchmark.data(benchmark.split(motion_type, seed).train)
    return train


def score(variants, train) -> dict:
    """Shares of ``variants`` within the training clips' spread, per proxy and on all at once, and V / V_train."""
    skeleton = train[0].metadata["asf"]
    posed = [on_skeleton(m, skeleton) for m in train]
    distances = feature_distances(variants, posed)
    ours, theirs = clip_naturalness(variants), clip_naturalness(train)
    within = {name: within_spread(ours[name], theirs[name]) for name in ours}
    within["feature_distance"] = within_spread(distances.variants, distances.real)
    every = np.logical_and.reduce(list(within.values()))
    return {"v_ratio": variation(variants).v / variation(posed).v, "every_proxy": float(every.mean()),
            **{name: float(ok.mean()) for name, ok in within.items()},
            "jerk": float(ours["jerk"].mean()), "foot_skating_cms": float(np.nanmean(ours["foot_skating_cms"]))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--types", nargs="+", default=list(TYPES), help="dataset:type pairs")
    parser.add_argument("--candidates", nargs="+", type=float, default=list(CANDIDATES), help="seconds")
    parser.add_argument("--variants", type=int, default=40)
    parser.add_argument("--tie", type=float, default=0.05)
    parser.add_argument("--out", type=Path, default=ROOT / "checkpoints" / "select_synthesis_smoothing")
    parser.add_argument("--summary", action="store_true",
                        help="only read the rows the runs saved (a run per type may go on its own core) and choose")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for item in [] if args.summary else args.types:
        dataset, motion_type = item.split(":", 1)
        train, rows = training_clips(dataset, motion_type), []
        for seconds in args.candidates:
            start = time.perf_counter()
            model = SLFMSynthesizer(smoothing_seconds=seconds).fit(train)
            row = {"type": item, "smoothing_seconds": seconds, "noise_scale": model.noise_scale_,
                   **score(model.sample(args.variants, seed=0), train), "seconds": time.perf_counter() - start}
            rows.append(row)
            print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}), flush=True)
        (args.out / f"{item.replace(':', '_')}.json").write_text(json.dumps(rows, indent=1))
    rows = [row for item in args.types
            for row in json.loads((args.out / f"{item.replace(':', '_')}.json").read_text())]
    means = {s: float(np.mean([r["every_proxy"] for r in rows if np.isclose(r["smoothing_seconds"], s)]))
             for s in args.candidates}
    best = max(means.values())
    chosen = min(s for s, m in means.items() if m >= best - args.tie)
    print("mean share within the training clips' spread on every proxy:",
          {round(s, 4): round(m, 3) for s, m in means.items()}, "→ chosen", round(chosen, 4))
    (args.out / "selection.json").write_text(json.dumps({"types": args.types, "means": {str(s): m for s, m in means.items()},
                                                         "chosen": chosen}, indent=1))


if __name__ == "__main__":
    main()
