"""What the median outlier screen does to clean real takes: the share of samples it flags, and how far PCHIP's refill
moves them (nothing was corrupted, so every flag is a false one and every millimetre moved is error).

Takes (from ../shared): every C3D sample (50–240 fps), every 10th HDM05 clip of performer bd and every 4th CMU take
(120 fps), every 20th Bandai BVH take (30 fps). Printed per take: frame rate, frames, flagged samples (share of the
observed ones), the median and largest distance moved, and the RMS over every observed sample (mm); then per data
set the totals.

Usage (from the repository root)::

    python scripts/screen_clean_takes.py                         # the defaults of MedianScreen
    python scripts/screen_clean_takes.py --n-sigmas 3            # the Hampel rule
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.classical.gap_filling import PchipInterpolation
from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.refinement.screening import (
    SCREEN_HALF_WINDOW,
    SCREEN_N_SIGMAS,
    SCREEN_THRESHOLD,
    MedianScreen,
)

SHARED = Path(__file__).resolve().parents[2] / "shared"


def takes(shared: Path) -> dict[str, list[Path]]:
    return {"C3D samples": sorted((shared / "samples" / "c3d").glob("*.c3d")),
            "HDM05 (bd)": sorted((shared / "data" / "hdm05_cuts11" / "bd").glob("*.amc"))[::10],
            "CMU": sorted((shared / "data" / "cmu_amc").rglob("*.amc"))[::4],
            "Bandai": sorted((shared / "data" / "bandai_motion_1").rglob("*.bvh"))[::20]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--half-window", type=int, default=SCREEN_HALF_WINDOW)
    parser.add_argument("--threshold", type=float, default=SCREEN_THRESHOLD, help="metres")
    parser.add_argument("--n-sigmas", type=float, default=SCREEN_N_SIGMAS)
    args = parser.parse_args(argv)
    screen = MedianScreen(PchipInterpolation(extrapolate="hold"), half_window=args.half_window,
                          threshold=args.threshold, n_sigmas=args.n_sigmas)
    print(f"# MedianScreen(half_window={args.half_window}, threshold={args.threshold:g} m, n_sigmas={args.n_sigmas})")
    print("| take | fps | frames | flagged | moved median / max (mm) | RMS over observed (mm) |\n|---|---:|---:|---:|---:|---:|")
    totals = {}
    for group, paths in takes(args.shared).items():
        flagged = observed = 0
        squared, largest = 0.0, 0.0
        for path in paths:
            motion = read_motion(path)
            out = screen.refine(motion)
            flags = ~motion.missing & (out.positions != motion.positions).any(axis=-1)
            moved = np.linalg.norm(out.positions[flags] - motion.positions[flags], axis=-1) * 1000.0
            seen = int((~motion.missing).sum())
            flagged, observed = flagged + int(flags.sum()), observed + seen
            squared += float((moved ** 2).sum())
            largest = max(largest, float(moved.max(initial=0.0)))
            print(f"| {path.name} | {motion.fps:g} | {motion.num_frames} | {flags.sum()} ({100 * flags.sum() / seen:.2f} %) "
                  f"| {np.median(moved) if moved.size else 0:.1f} / {moved.max(initial=0.0):.1f} "
                  f"| {np.sqrt((moved ** 2).sum() / seen):.2f} |", flush=True)
        totals[group] = (len(paths), flagged, observed, largest, np.sqrt(squared / max(observed, 1)))
    print("\n| data | takes | flagged | largest move (mm) | RMS over observed (mm) |\n|---|---:|---:|---:|---:|")
    for group, (n, flagged, observed, largest, rms) in totals.items():
        print(f"| {group} | {n} | {100 * flagged / max(observed, 1):.2f} % | {largest:.1f} | {rms:.2f} |")


if __name__ == "__main__":
    main()
