"""Select the default of ``mocapkit kinect-fix`` (docs/decisions.md#kinect-default): candidates fitted on the HDM05
training performers bd and bk (simulated with ``real_sensor``, seed 100), validated on dg; the real-data proxies on
60 MSR Action3D files of the odd subjects. Performer mm is never read. Prints one line per candidate and the winner;
writes every figure to ``--out`` (JSON).

    OMP_NUM_THREADS=1 python scripts/selection/kinect_default.py --out checkpoints/kinect/selection.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from mocapkit.kinect.benchmark import KinectReconstructionBenchmark
from mocapkit.kinect.learned import LearnedKinectCorrector
from mocapkit.kinect.reconstruction import KinectPostureReconstructor

SHARED = REPO.parent / "shared"
SEED = 100
OPTIONS = [
    {"smooth_window": w, "rigid_bones": r, "tracked_correction": c}
    for w, r, c in itertools.product((0, 7, 15), (False, True), (1.0, 0.5))
]
BASES = {
    "gp_posture": lambda: KinectPostureReconstructor(
        gp_input="posture", energy_unit=0.1, w_spatial=0.6, w_temporal=0.1, w_reliability=0.4, random_state=SEED
    ),
    "bigru": lambda: LearnedKinectCorrector(random_state=SEED),
    "bigru_steady_loss": lambda: LearnedKinectCorrector(bone_weight=1.0, velocity_weight=2.0, random_state=SEED),
}


def admissible(real: dict) -> bool:
    return (
        real["bone_sd_cm_not_worse"] >= 0.95
        and real["jitter_cm_not_worse"] >= 0.95
        and real["bone_sd_cm_after"] < real["bone_sd_cm_before"]
        and real["jitter_cm_after"] < real["jitter_cm_before"]
        and real["new_swap_events"] == 0
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/kinect/selection.json")
    parser.add_argument("--bases", nargs="*", default=list(BASES))
    args = parser.parse_args()
    msr = sorted(p for p in (SHARED / "data" / "msr_action3d").glob("*_skeleton3D.txt") if int(p.name[5:7]) % 2 == 1)
    msr = [msr[i] for i in np.linspace(0, len(msr) - 1, 60).astype(int)]
    bench = KinectReconstructionBenchmark(
        str(SHARED / "data" / "hdm05_cuts11"),
        protocols=["bd", "bk", "dg"],
        noise="real_sensor",
        real_inputs=[str(p) for p in msr],
    )
    train = np.flatnonzero(np.isin(bench.groups, ["bd", "bk"]))
    val = np.flatnonzero(bench.groups == "dg")
    rows = []
    for base in args.bases:
        start = time.perf_counter()
        fitted, seconds, _ = bench._fitted(BASES[base](), train, SEED)
        print(f"[{base}] fitted in {seconds:.0f} s", flush=True)
        for opts in OPTIONS:
            fitted.set_params(**opts)
            score = bench._score(fitted, val, SEED)
            real = bench.real_scores(fitted)["all"]
            row = {
                "base": base,
                **opts,
                "error_cm": score["error_cm"],
                "raw_cm": score["raw_cm"],
                "real": real,
                "admissible": admissible(real),
                "options_on": int(opts["smooth_window"] > 0)
                + int(opts["rigid_bones"])
                + int(opts["tracked_correction"] < 1),
            }
            rows.append(row)
            print(
                f"{base:18s} sw={opts['smooth_window']:2d} rigid={int(opts['rigid_bones'])} tc={opts['tracked_correction']:.1f}: "
                f"error {row['error_cm']:.2f} (raw {row['raw_cm']:.2f}) | bone {real['bone_sd_cm_before']:.2f}→{real['bone_sd_cm_after']:.2f} "
                f"({100 * real['bone_sd_cm_not_worse']:.0f} %) jitter {real['jitter_cm_before']:.2f}→{real['jitter_cm_after']:.2f} "
                f"({100 * real['jitter_cm_not_worse']:.0f} %) angles {real['angle_violations_pct_before']:.2f}→{real['angle_violations_pct_after']:.2f} "
                f"new swaps {real['new_swap_events']:.0f} {'ADMISSIBLE' if row['admissible'] else ''}",
                flush=True,
            )
        print(f"[{base}] {time.perf_counter() - start:.0f} s in all", flush=True)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(rows, indent=1))
    ok = [r for r in rows if r["admissible"]]
    if ok:
        best = min(r["error_cm"] for r in ok)
        near = [r for r in ok if r["error_cm"] <= best + 0.05]
        winner = min(near, key=lambda r: (r["options_on"], r["error_cm"]))
    else:
        winner = max(rows, key=lambda r: min(r["real"]["bone_sd_cm_not_worse"], r["real"]["jitter_cm_not_worse"]))
    print(
        "WINNER",
        json.dumps({k: v for k, v in winner.items() if k != "real"}),
        "admissible" if ok else "NONE admissible",
    )


if __name__ == "__main__":
    main()
