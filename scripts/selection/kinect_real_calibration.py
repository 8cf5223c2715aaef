"""The ``real_sensor`` calibration of the Kinect simulator: real Kinect skeletons' frame-to-frame statistics beside
the simulator's, per calibration (docs/decisions.md#real-sensor-simulator-preset).

Real: every readable MSR Action3D file (Kinect v1 via Li et al. 2010's pipeline, 15 fps, no tracking states) and the
NTU RGB+D samples (Kinect v2, 30 fps, the SDK's per-joint tracking states; the 20 joints Kinect v1 shares).
Simulated: the first ``--max-files`` HDM05 cuts (sorted) through each preset, seed ``--seed``, at 30 fps and at
15 fps (every second frame) beside MSR. Per clip, then the mean over clips: bone-length sd (cm), jitter (cm), the
share of velocity power above 3 Hz (:func:`~mocapkit.kinect.metrics.high_frequency_share`), swap events per
minute (:func:`~mocapkit.kinect.metrics.swap_events`), the shares and mean run lengths of INFERRED and NOT_TRACKED.

    python scripts/selection/kinect_real_calibration.py                      # every preset, 60 cuts
    python scripts/selection/kinect_real_calibration.py --preset real_sensor --set jitter_time_constant_s=0.05
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from mocapkit.datasets.formats.motion_io import find_motion_files, read_motion
from mocapkit.datasets.synthetic.kinect_noise import (
    INFERRED,
    NOISE_PRESETS,
    NOT_TRACKED,
    KinectNoiseConfig,
    simulate_pairs,
)
from mocapkit.kinect.kinect_fix import kinect_clip, ntu_tracking_state
from mocapkit.kinect.metrics import (
    bone_length_sd_cm,
    high_frequency_share,
    jitter_cm,
    state_runs,
    swap_events,
)

SHARED = REPO.parent / "shared"
KEYS = (
    "bone_sd_cm",
    "jitter_cm",
    "hf_share",
    "swaps_per_min",
    "inferred",
    "inferred_s",
    "not_tracked",
    "not_tracked_s",
)


def clip_stats(x: np.ndarray, fps: float, state: np.ndarray | None) -> dict:
    out = {
        "bone_sd_cm": bone_length_sd_cm(x),
        "jitter_cm": jitter_cm(x),
        "hf_share": high_frequency_share(x, fps),
        "swaps_per_min": swap_events(x) / (len(x) / fps / 60.0),
    }
    for name, value in (("inferred", INFERRED), ("not_tracked", NOT_TRACKED)):
        share, seconds = (np.nan, np.nan) if state is None else state_runs(state, value, fps)
        out[name], out[f"{name}_s"] = share, seconds
    return out


def summary(rows: list[dict]) -> dict:
    """The mean over clips of each figure (NaN where no clip has it: MSR's missing states)."""
    out = {}
    for k in KEYS:
        values = np.array([r[k] for r in rows], dtype=np.float64)
        out[k] = float(values[np.isfinite(values)].mean()) if np.isfinite(values).any() else np.nan
    return out


def real_stats() -> dict[str, dict]:
    msr, ntu = [], []
    for path in sorted((SHARED / "data" / "msr_action3d").glob("*_skeleton3D.txt")):
        try:
            motion = read_motion(path)
            x, state, filled = kinect_clip(motion)
        except ValueError:
            continue  # the all-zero file
        msr.append(clip_stats(x, motion.fps, None))
    for path in find_motion_files(SHARED / "samples" / "ntu_skeleton"):
        motion = read_motion(path)
        x, filled_state, _ = kinect_clip(motion)
        ntu.append(clip_stats(x, motion.fps, np.minimum(filled_state, ntu_tracking_state(path, motion))))
    return {
        f"MSR Action3D (real, 15 fps, {len(msr)} files)": summary(msr),
        f"NTU samples (real, 30 fps, {len(ntu)} files)": summary(ntu),
    }


def simulated_stats(config: KinectNoiseConfig, files: list[Path], seed: int) -> dict[str, dict]:
    pairs, _ = simulate_pairs(files, config, seed=seed, fps=30.0, progress=False)
    at30 = [clip_stats(p.noisy, 30.0, p.state) for p in pairs]
    at15 = [clip_stats(p.noisy[::2], 15.0, p.state[::2]) for p in pairs]
    raw = np.mean([np.linalg.norm(p.noisy - p.clean, axis=-1).mean() * 100 for p in pairs])
    return {"30 fps": summary(at30), "15 fps": summary(at15), "raw_error_cm": float(raw)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--preset", action="append", help="presets to simulate (default: all)")
    parser.add_argument("--set", action="append", default=[], help="KEY=VALUE on the (last) preset")
    parser.add_argument("--max-files", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-real", action="store_true")
    args = parser.parse_args()
    fmt = lambda d: " ".join(f"{k} {d[k]:.3f}" for k in KEYS)
    if not args.no_real:
        for name, stats in real_stats().items():
            print(f"{name}: {fmt(stats)}", flush=True)
    files = sorted(find_motion_files(SHARED / "data" / "hdm05_cuts11"))[: args.max_files]
    for preset in args.preset or list(NOISE_PRESETS):
        config = KinectNoiseConfig.preset(preset)
        if args.set and preset == (args.preset or list(NOISE_PRESETS))[-1]:
            config = replace(config, **{k: ast.literal_eval(v) for k, v in (s.split("=", 1) for s in args.set)})
        stats = simulated_stats(config, files, args.seed)
        print(f"{preset} (simulated, {len(files)} HDM05 cuts): raw error {stats['raw_error_cm']:.2f} cm")
        for rate in ("30 fps", "15 fps"):
            print(f"  {rate}: {fmt(stats[rate])}", flush=True)


if __name__ == "__main__":
    main()
