"""Choose a default of the synthesisers (``smoothing_seconds``, ``footskate_root``) on training clips only (rules
and results: docs/decisions.md#synthesis-smoothing, docs/decisions.md#synthesis-footskate-root).

For each motion type below, the benchmark's seed-0 split gives 10 training clips. For every candidate value of
``--param``, SLFM is fitted on them with its defaults and that value (the automatic noise scale is then chosen on
the variants so made), samples ``--variants`` variants, and each variant is scored against **the training clips
themselves** (posed on the reference skeleton, as the benchmark poses its references): within their spread on
every proxy at once (:func:`~mocapkit.synthesis.metrics.within_spread`: feature distance against the training
clips' leave-one-out distances, foot skating, jerk and bone drift no larger than the largest training clip's). No
held-out clip is read. The candidate with the highest mean share over the types wins; an earlier-listed candidate
(a smaller smoothing, the former default) within ``--tie`` of the best wins instead.

With ``--param footskate_root`` the footskate cleanup of each candidate is also applied to the training clips
themselves (real motion, whose feet and travel agree: a cleanup should leave it nearly as it is), and their root's
mean horizontal speed after / before and foot skating are printed beside the choice.

Usage (from the repository root; about 1–2 min per fit on one core)::

    OMP_NUM_THREADS=1 python scripts/selection/select_synthesis_defaults.py --param smoothing_seconds 0 0.0333 0.0667 0.1
    OMP_NUM_THREADS=1 python scripts/selection/select_synthesis_defaults.py --param footskate_root full stance
    ... --types hdm05:hopBothLegs1hops          # one type per core, then the same command with --summary
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from hydra.utils import instantiate

from mocapkit.evaluation.compare import compose
from mocapkit.synthesis.clips import on_skeleton
from mocapkit.synthesis.metrics import clip_naturalness, feature_distances, proxies_within, variation
from mocapkit.synthesis.slfm import SLFMSynthesizer

ROOT = Path(__file__).resolve().parents[1]
TYPES = ("hdm05:hopBothLegs1hops", "hdm05:squat1Reps", "bandai:walk")


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
    within = proxies_within(ours, theirs, distances)
    every = within.pop("every_proxy")
    return {
        "v_ratio": variation(variants).v / variation(posed).v,
        "every_proxy": float(every.mean()),
        "per_variant": {**{k: v.tolist() for k, v in ours.items()}, "feature_distance": distances.variants.tolist()},
        "training_clips": {**{k: v.tolist() for k, v in theirs.items()}, "feature_distance": distances.real.tolist()},
        **{f"within_{name}": float(ok.mean()) for name, ok in within.items()},
        "jerk": float(ours["jerk"].mean()),
        "foot_skating_cms": float(np.nanmean(ours["foot_skating_cms"])),
    }


def cleanup_on_real_clips(train, move_root: str) -> dict:
    """The footskate cleanup (SLFM's defaults but ``move_root``) applied to the real training clips: their root's
    mean horizontal speed after / before (mean over clips) and their foot skating before and after (cm/s)."""
    from mocapkit.datasets.formats.asf_amc import amc_motion
    from mocapkit.synthesis.clips import dof_matrix, dof_values
    from mocapkit.synthesis.footskate import cleanup_footskate, planted_ankle_height
    from mocapkit.synthesis.metrics import foot_skating

    floor = planted_ankle_height(train)
    speed = lambda m: float(np.linalg.norm(np.diff(m.positions[:, 0, [0, 2]], axis=0), axis=1).mean() * m.fps)
    ratios, before, after = [], [], []
    for clip in train:
        matrix, layout = dof_matrix(clip)
        values, _ = cleanup_footskate(
            dof_values(matrix, layout), clip.metadata["asf"], clip.fps, floor=floor, move_root=move_root
        )
        cleaned = amc_motion(clip.metadata["asf"], values, fps=clip.fps, angle_unit="deg")
        ratios.append(speed(cleaned) / max(speed(clip), 1e-9))
        before.append(foot_skating(clip))
        after.append(foot_skating(cleaned))
    return {
        "real_speed_ratio": float(np.mean(ratios)),
        "real_skating_before": float(np.nanmean(before)),
        "real_skating_after": float(np.nanmean(after)),
    }


def value(text: str):
    """A candidate from the command line: a number when it reads as one, else the text."""
    try:
        return float(text)
    except ValueError:
        return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--param",
        nargs="+",
        required=True,
        metavar=("NAME", "VALUE"),
        help="the SLFMSynthesizer parameter, then its candidates (smallest / preferred first)",
    )
    parser.add_argument("--types", nargs="+", default=list(TYPES), help="dataset:type pairs")
    parser.add_argument("--variants", type=int, default=40)
    parser.add_argument(
        "--tie", type=float, default=0.05, help="the first-listed candidate within this share of the best wins"
    )
    parser.add_argument("--out", type=Path, default=None, help="default: checkpoints/select_synthesis_<param>")
    parser.add_argument(
        "--summary",
        action="store_true",
        help="only read the rows the runs saved (a run per type may go on its own core) and choose",
    )
    args = parser.parse_args()
    name, candidates = args.param[0], [value(v) for v in args.param[1:]]
    if not candidates:
        parser.error("--param NAME VALUE [VALUE ...]: give at least one candidate")
    args.out = args.out or ROOT / "checkpoints" / f"select_synthesis_{name}"
    args.out.mkdir(parents=True, exist_ok=True)
    for item in [] if args.summary else args.types:
        dataset, motion_type = item.split(":", 1)
        train, rows = training_clips(dataset, motion_type), []
        for candidate in candidates:
            start = time.perf_counter()
            model = SLFMSynthesizer(**{name: candidate}).fit(train)
            row = {
                "type": item,
                name: candidate,
                "noise_scale": model.noise_scale_,
                **score(model.sample(args.variants, seed=0), train),
                "seconds": time.perf_counter() - start,
            }
            if name == "footskate_root":
                row.update(cleanup_on_real_clips(train, candidate))
            rows.append(row)
            print(
                json.dumps(
                    {
                        k: round(v, 4) if isinstance(v, float) else v
                        for k, v in row.items()
                        if k not in ("per_variant", "training_clips")
                    }
                ),
                flush=True,
            )
        (args.out / f"{item.replace(':', '_')}.json").write_text(json.dumps(rows, indent=1))
    rows = [row for item in args.types for row in json.loads((args.out / f"{item.replace(':', '_')}.json").read_text())]
    same = lambda a, b: abs(a - b) < 1e-3 if isinstance(b, float) else a == b  # 0.0333 names 1/30
    means = {c: float(np.mean([r["every_proxy"] for r in rows if same(r[name], c)])) for c in candidates}
    best = max(means.values())
    chosen = next(c for c in candidates if means[c] >= best - args.tie)  # the first listed within the tie
    print(
        f"{name}: mean share within the training clips' spread on every proxy:",
        {c: round(m, 3) for c, m in means.items()},
        "→ chosen",
        chosen,
    )
    summary = {"types": args.types, "means": {str(c): m for c, m in means.items()}, "chosen": chosen}
    (args.out / "selection.json").write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
