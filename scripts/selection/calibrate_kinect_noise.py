"""Calibrate the Kinect v1 noise simulator on real HDM05 cuts: how large is the raw Kinect error it produces?

Zhou 2014 reports a raw Kinect SDK error of 12.5–14.5 cm against mocap on its occlusion-heavy motions
(``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §4.6); the defaults of
:class:`mocapkit.datasets.synthetic.kinect_noise.KinectNoiseConfig` are tuned so that this script's overall figure
falls inside that range. Every file is read once (Kinect-20, 30 fps, y up), then simulated with the default config
(the seed of each file from ``--seed`` and its name, as ``simulate_pairs`` does) and once more with each error
component switched off. Printed: the raw error (cm, mean over frames and joints, frames of all files pooled)
overall, per joint, per class (from ``HDM_<actor>_<class>_<nnn>_120.amc``), the error on tracked vs. inferred
entries, the share of INFERRED / NOT_TRACKED entries, and the overall error without each component.

Usage (from the repository root)::

    python scripts/selection/calibrate_kinect_noise.py                  # all 232 HDM05 cuts
    python scripts/selection/calibrate_kinect_noise.py --max-files 40   # quick check while tuning
    python scripts/selection/calibrate_kinect_noise.py --set snap_weight=0.8 --set depth_sigma_at_1m_m=0.003
    python scripts/selection/calibrate_kinect_noise.py --preset msr_steadiness --no-ablation

Steadiness (the second calibration target, :meth:`KinectNoiseConfig.preset` ``"msr_steadiness"``): the mean over
clips of :func:`~mocapkit.kinect.metrics.bone_length_sd_cm` and :func:`~mocapkit.kinect.metrics.jitter_cm`,
with the simulated clips taken at 15 fps (every second frame) to compare with the real Kinect skeletons of MSR
Action3D (15 fps, ``--msr``, every readable file), once with every component and once with occlusion and swaps
off (tracked joints only, the regime of MSR's mostly unoccluded actions).

Simulated errors are not comparable with the thesis's Table 5.2 (real sensor, other motions).
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mocapkit.datasets.formats.motion_io import read_motion
from mocapkit.datasets.synthetic.kinect_noise import (
    COMPONENTS,
    INFERRED,
    KINECT20_NAMES,
    NOISE_PRESETS,
    NOT_TRACKED,
    TRACKED,
    KinectNoiseConfig,
    file_seed,
    kinect20_from_motion,
    simulate_kinect,
)

CLASS_PATTERN = re.compile(r"HDM_[^_]+_(.+)_\d+_\d+$")


def class_of(path: Path) -> str:
    """The HDM05 class in ``HDM_<actor>_<class>_<nnn>_120.amc`` (the stem itself if it does not match)."""
    match = CLASS_PATTERN.match(path.stem)
    return match.group(1) if match else path.stem


def load(src: Path, max_files: int | None, fps: float) -> list[tuple[Path, np.ndarray]]:
    """``(path, clean [T, 20, 3])`` of the first ``max_files`` AMC files under ``src`` (sorted; spread over the
    actors and classes when limited: every k-th file)."""
    paths = sorted(src.rglob("*.amc"))
    if not paths:
        raise SystemExit(f"no .amc files under {src}")
    if max_files and max_files < len(paths):
        paths = [paths[i] for i in np.linspace(0, len(paths) - 1, max_files).round().astype(int)]
    clips = []
    for path in paths:
        try:
            clips.append((path, kinect20_from_motion(read_motion(path), fps=fps)))
        except ValueError as exc:
            print(f"skipped {exc}", file=sys.stderr)
    return clips


def simulate(clips, config: KinectNoiseConfig, seed: int, fps: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per clip ``(noisy [T, 20, 3] m, state [T, 20])``, each file with its own :func:`file_seed`."""
    return [simulate_kinect(clean, config, seed=file_seed(seed, path), fps=fps) for path, clean in clips]


def simulate_all(clips, config: KinectNoiseConfig, seed: int, fps: float, simulated=None):
    """Per clip ``(distance [T, 20] m, state [T, 20])`` (of ``simulated``, when already simulated)."""
    simulated = simulated if simulated is not None else simulate(clips, config, seed, fps)
    return [
        (np.linalg.norm(noisy.astype(np.float64) - clean, axis=-1), state)
        for (_, clean), (noisy, state) in zip(clips, simulated)
    ]


def mean_steadiness(positions, step: int = 1) -> tuple[float, float]:
    """Mean over clips ``[T, 20, 3]`` (m) of :func:`~mocapkit.kinect.metrics.bone_length_sd_cm` and
    :func:`~mocapkit.kinect.metrics.jitter_cm` (cm), every ``step``-th frame; clips under 3 frames are left out."""
    from mocapkit.kinect.metrics import bone_length_sd_cm, jitter_cm

    kept = [p[::step] for p in positions if len(p[::step]) >= 3]
    return float(np.mean([bone_length_sd_cm(p) for p in kept])), float(np.mean([jitter_cm(p) for p in kept]))


def msr_clips(folder: Path) -> list[np.ndarray]:
    """The real MSR Action3D skeletons in ``folder`` (15 fps, gaps filled as ``mocapkit kinect-fix`` does;
    unusable files reported on stderr); empty when the folder is absent."""
    from mocapkit.kinect.kinect_fix import kinect_clip

    clips = []
    for path in sorted(folder.glob("*_skeleton3D.txt")) if folder.is_dir() else []:
        try:
            clips.append(kinect_clip(read_motion(path))[0])
        except ValueError as exc:
            print(f"skipped {exc}", file=sys.stderr)
    return clips


def parse_set(items: list[str]) -> dict:
    changes = {}
    for item in items:
        key, _, value = item.partition("=")
        try:
            changes[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            changes[key] = value
    return changes


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--src",
        type=Path,
        default=REPO / ".." / "shared" / "data" / "hdm05_cuts11",
        help="folder of HDM05 cuts (default: ../shared/data/hdm05_cuts11 from the repo root)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-files", type=int, default=None, help="use this many files, spread over the folder")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument(
        "--preset",
        choices=NOISE_PRESETS,
        default="mean_error",
        help="the calibration to start from (default: mean_error, the default config)",
    )
    parser.add_argument(
        "--msr",
        type=Path,
        default=REPO / ".." / "shared" / "data" / "msr_action3d",
        help="MSR Action3D folder for the steadiness reference (skipped when absent)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a KinectNoiseConfig field (Python literal), repeatable",
    )
    parser.add_argument("--no-ablation", action="store_true", help="skip the per-component runs")
    args = parser.parse_args(argv)

    start = time.time()
    clips = load(args.src.resolve(), args.max_files, args.fps)
    frames = sum(len(c) for _, c in clips)
    print(
        f"{len(clips)} files, {frames} frames at {args.fps:g} fps from {args.src.resolve()} "
        f"(read in {time.time() - start:.1f} s)"
    )
    config = replace(KinectNoiseConfig.preset(args.preset), **parse_set(args.set))

    simulated = simulate(clips, config, args.seed, args.fps)
    results = simulate_all(clips, config, args.seed, args.fps, simulated)
    distance = np.concatenate([d for d, _ in results]) * 100.0  # [frames, 20] cm
    state = np.concatenate([s for _, s in results])
    print(
        f"\nraw error, preset {args.preset} (seed {args.seed}): {distance.mean():.2f} cm "
        f"(median clip {np.median([d.mean() * 100 for d, _ in results]):.2f} cm)"
    )
    shares = {
        name: float((state == value).mean())
        for name, value in (("TRACKED", TRACKED), ("INFERRED", INFERRED), ("NOT_TRACKED", NOT_TRACKED))
    }
    print("states: " + ", ".join(f"{k} {100 * v:.1f} %" for k, v in shares.items()))
    tracked = state == TRACKED
    print(
        f"error on TRACKED entries {distance[tracked].mean():.2f} cm, on INFERRED/NOT_TRACKED "
        f"{distance[~tracked].mean() if (~tracked).any() else float('nan'):.2f} cm; share of the total error "
        f"from INFERRED/NOT_TRACKED entries {100 * distance[~tracked].sum() / distance.sum():.1f} %"
    )

    print("\nper joint (cm, % not tracked):")
    per_joint = distance.mean(axis=0)
    for j in np.argsort(-per_joint):
        print(f"  {KINECT20_NAMES[j]:<15} {per_joint[j]:6.2f}   {100 * (~tracked[:, j]).mean():5.1f} %")

    by_class = defaultdict(list)
    for (path, _), (d, s) in zip(clips, results):
        by_class[class_of(path)].append((d, s))
    print("\nper class (cm, files, % not tracked):")
    for name in sorted(by_class, key=lambda k: -np.concatenate([d for d, _ in by_class[k]]).mean()):
        d = np.concatenate([d for d, _ in by_class[name]]) * 100.0
        s = np.concatenate([s for _, s in by_class[name]])
        print(f"  {name:<30} {d.mean():6.2f}   {len(by_class[name]):3d}   {100 * (s != TRACKED).mean():5.1f} %")

    step = max(1, round(args.fps / 15.0))
    print(f"\nsteadiness at {args.fps / step:g} fps (cm, mean over clips): bone-length sd, jitter")
    rows = [
        ("clean mocap", [clean for _, clean in clips]),
        ("simulated, every component", [noisy for noisy, _ in simulated]),
        (
            "simulated, no occlusion or swaps",
            [noisy for noisy, _ in simulate(clips, config.without("occlusion", "swaps"), args.seed, args.fps)],
        ),
    ]
    for label, positions in rows:
        bone, jitter = mean_steadiness(positions, step)
        print(f"  {label:<36}{bone:6.2f} {jitter:6.2f}")
    real = msr_clips(args.msr.resolve())
    if real:
        bone, jitter = mean_steadiness(real)
        print(f"  real Kinect, MSR Action3D ({len(real)} files) {bone:6.2f} {jitter:6.2f}")

    if not args.no_ablation:
        print("\ncomponent ablation (overall cm with the component off; drop = its contribution):")
        for name in COMPONENTS:
            without = simulate_all(clips, config.without(name), args.seed, args.fps)
            error = np.concatenate([d for d, _ in without]).mean() * 100.0
            print(f"  without {name:<14} {error:6.2f}   drop {distance.mean() - error:6.2f}")
        for name in COMPONENTS:
            alone = simulate_all(clips, config.without(*[c for c in COMPONENTS if c != name]), args.seed, args.fps)
            error = np.concatenate([d for d, _ in alone]).mean() * 100.0
            print(f"  only    {name:<14} {error:6.2f}")
    print(f"\n{time.time() - start:.1f} s")


if __name__ == "__main__":
    main()
