"""Choose the learned refiners' inference settings on the runs' own validation clips (training performers only).

Two settings of :class:`~mocapkit.refinement.learned.LearnedRefiner` are not learned and are chosen here, never on
a test performer: each run is scored on its **validation clips** (the 10 % of its training performers' clips that
checkpoint selection held out, rebuilt from the run's data settings: performer ``P`` held out, ``split_seed`` 0).

``--setting threshold`` — ``repair_threshold``: an observed entry comes back unchanged unless the network moves it
    farther than this many metres (then the network's value replaces it). It trades noisy entries left as they
    are (too high) against clean entries moved by the network's own error (too low), and touches only observed
    entries, so the score is the RMS 3-D error over the **observed** entries of the corrupted clip (clean and noisy
    alike); clips cropped to their central ``--frames`` frames.
``--setting short_gaps`` — ``short_gap_frames``: interior gaps of a joint up to this many frames are filled by the
    cubic spline instead of the network; the score is the RMS 3-D error over the **corrupted** entries of the whole
    clips, under random loss and 10–40-frame gaps.
``--setting short_gap_points`` — the spline of the short gaps through the take's observed samples (``24``) or
    through them after the network's repairs (``-24``), against no spline (``0``); the ``short_gaps`` protocols and
    ``mxcrypt`` (gaps in noisy data).
``--setting screen`` — a median outlier screen in front of the refiner
    (:class:`~mocapkit.refinement.screening.MedianScreen`): its ``threshold`` in metres (0: no screen) at the
    ``--half-window`` given; the score is the RMS 3-D error over the **corrupted** entries, under noise (rdcrypt,
    mxcrypt), random loss and gaps (whether the screen helps the first and costs nothing on the others).
    ``--models`` may also name the classical ``pchip`` and ``lrmf`` (no runs; the same validation clips).
``--setting pose_prior`` — the classical :class:`~mocapkit.refinement.pose_prior.PosePriorRefiner` (``--models
    pose_prior``, no runs): its ``drift`` in m/s at the ``--n-components`` and ``--noise-floor`` given (0 by
    default, as in the first two selection rounds), or with ``--sweep noise_floor`` its ``noise_floor`` in metres at
    ``--drift``; fitted on the fold's training clips other than the validation clips (``--train-clips-per-performer
    N``: N seeded clips of each, as the benchmark's fits); the score is the RMS 3-D error over the **corrupted**
    entries of the whole clips under random loss, 10- and 40-frame gaps and both long-gap protocols (it fills gaps
    only); without the short-gap spline (``short_gap_seconds=0``), as selection rounds 1-3 ran.
``--setting pose_prior_short_gaps`` — the pose prior's ``short_gap_seconds`` (interior gaps up to this long filled
    by the cubic spline instead of the fusion; the values in frames at HDM05's 120 fps) at the ``--drift`` and ``--noise-floor`` given; fitted as
    ``--setting pose_prior``; the score is the RMS 3-D error over the **corrupted** entries under random loss, gaps of
    10–60 frames and both long-gap protocols.
``--setting window`` — the inference ``window`` (frames per window; longer takes are refined in overlapping
    windows blended with ramps), as multiples of the training window; the score is the RMS 3-D error over the
    **corrupted** entries (removed or perturbed) of the whole clips (not cropped: a window longer than a clip is
    the whole clip).

Runs: ``checkpoints/refine_<model>/fold_<P>/best.ckpt`` (``--runs`` names another root) for the given models and
folds; clip ``i`` corrupted with ``corrupt(clip, protocol, level, seed=i)``. Printed per model: mm, mean over clips and then over folds, one row per
protocol, one column per value, and the mean over protocols.

Usage (from the repository root)::

    python scripts/selection/refiner_inference_settings.py --setting threshold        # bigru + transformer, folds bd bk mm
    python scripts/selection/refiner_inference_settings.py --setting window --models transformer --folds bd
    python scripts/selection/refiner_inference_settings.py --setting screen --models pchip lrmf bigru --half-window 3
    python scripts/selection/refiner_inference_settings.py --setting pose_prior --models pose_prior --sweep noise_floor
    python scripts/selection/refiner_inference_settings.py --setting pose_prior_short_gaps --models pose_prior --noise-floor 0.005 \
        --train-clips-per-performer 10 --folds bd bk dg mm
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.refinement.benchmark import central_crop
from mocapkit.refinement.corruptions import CorruptionError, corrupt
from mocapkit.refinement.datamodule import MocapRefinementDataModule
from mocapkit.refinement.learned import LearnedRefiner
from mocapkit.refinement.metrics import joint_errors
from mocapkit.refinement.screening import (
    SCREEN_HALF_WINDOW,
    SCREEN_N_SIGMAS,
    MedianScreen,
)

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = {
    "threshold": {
        "values": [0.0, 0.005, 0.01, 0.015, 0.02, 0.03, float("inf")],
        "unit": "m",
        "protocols": [
            ("rdcrypt", 0.3),
            ("mxcrypt", 0.3),
            ("spikes", 0.01),
            ("random_missing", 0.2),
            ("continuous_missing", 40),
        ],
    },
    "short_gaps": {
        "values": [0, 4, 8, 12, 24],
        "unit": "frames",
        "protocols": [
            ("random_missing", 0.2),
            ("random_missing", 0.5),
            ("continuous_missing", 10),
            ("continuous_missing", 20),
            ("continuous_missing", 40),
        ],
    },
    "short_gap_points": {
        "values": [0, 24, -24],
        "unit": "frames (< 0: through the repaired samples)",
        "protocols": [
            ("random_missing", 0.2),
            ("random_missing", 0.5),
            ("continuous_missing", 10),
            ("continuous_missing", 20),
            ("continuous_missing", 40),
            ("mxcrypt", 0.3),
        ],
    },
    "screen": {
        "values": [0.0, 0.005, 0.0075, 0.01, 0.015],
        "unit": "m",
        "protocols": [
            ("rdcrypt", 0.3),
            ("mxcrypt", 0.3),
            ("random_missing", 0.2),
            ("continuous_missing", 10),
            ("continuous_missing", 40),
        ],
    },
    "pose_prior": {
        "values": [0.04, 0.12, 0.38],
        "unit": "m/s",
        "protocols": [
            ("random_missing", 0.2),
            ("continuous_missing", 10),
            ("continuous_missing", 40),
            ("long_gaps", "20x100"),
            ("long_gaps", "5x2s"),
        ],
    },
    "pose_prior_short_gaps": {
        "values": [0, 12, 24, 48, 72, 96],
        "unit": "frames",
        "protocols": [
            ("random_missing", 0.2),
            ("random_missing", 0.5),
            ("continuous_missing", 10),
            ("continuous_missing", 20),
            ("continuous_missing", 40),
            ("continuous_missing", 60),
            ("long_gaps", "20x100"),
            ("long_gaps", "5x2s"),
        ],
    },
    "window": {
        "values": [1, 2, 4],
        "unit": "× training window",
        "protocols": [
            ("rdcrypt", 0.3),
            ("mxcrypt", 0.3),
            ("random_missing", 0.2),
            ("continuous_missing", 40),
            ("long_gaps", "20x100"),
            ("long_gaps", "5x2s"),
        ],
    },
}


def rms_error_mm(clean, refined, entries: np.ndarray) -> float:
    """RMS 3-D distance (mm) between ``refined`` and ``clean`` over ``entries [T, J]``."""
    distance = joint_errors(clean, refined)[entries]
    return float(np.sqrt(np.mean(distance**2)) * 1000.0)


def score_on_clips(clips, protocols, refiners) -> np.ndarray:
    """``[len(protocols), len(refiners)]``: RMS 3-D error (mm, :func:`rms_error_mm`) over the corrupted entries
    (removed or perturbed), mean over ``clips``; clip ``i`` corrupted with ``corrupt(clip, protocol, level,
    seed=i)``, a clip too short for a protocol left out. ``refiners``: anything with ``refine(motion) -> Motion``."""
    table = np.zeros((len(protocols), len(refiners)))
    for p, (protocol, level) in enumerate(protocols):
        scores = []
        for i, clip in enumerate(clips):
            try:
                corruption = corrupt(clip, protocol, level, seed=i)
            except CorruptionError:
                continue
            entries = corruption.removed | corruption.perturbed
            scores.append([rms_error_mm(clip, r.refine(corruption.motion), entries) for r in refiners])
        table[p] = np.mean(scores, axis=0)
    return table


def base_refiner(model: str, checkpoint: str, short_gap_frames: int | None = None):
    """The refiner a ``--models`` name stands for: a run of ``refine_<model>`` (with ``short_gap_frames`` when
    given) or the classical ``pchip`` / ``lrmf``."""
    if model == "pchip":
        from mocapkit.refinement.gap_filling import PchipInterpolation

        return PchipInterpolation(extrapolate="hold")
    if model == "lrmf":
        from mocapkit.refinement.lrmf import LRMF

        return LRMF()
    extra = {} if short_gap_frames is None else {"short_gap_frames": int(short_gap_frames)}
    return LearnedRefiner(checkpoint=checkpoint, **extra).fit()


def _screened(refiner, threshold: float, half_window: int, n_sigmas: float | None):
    return (
        refiner
        if threshold <= 0
        else MedianScreen(refiner, half_window=half_window, threshold=threshold, n_sigmas=n_sigmas)
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setting", choices=sorted(SETTINGS), required=True)
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    parser.add_argument("--models", nargs="+", default=["bigru", "transformer"])
    parser.add_argument("--folds", nargs="+", default=["bd", "bk", "mm"])
    parser.add_argument("--frames", type=int, default=250, help="threshold: clips cropped to this many frames")
    parser.add_argument(
        "--values",
        type=float,
        nargs="+",
        default=None,
        help="the setting's values to score (default: the grid of SETTINGS)",
    )
    parser.add_argument(
        "--half-window",
        type=int,
        default=SCREEN_HALF_WINDOW,
        help="screen: the median's neighbours on each side (default: MedianScreen's)",
    )
    parser.add_argument(
        "--n-sigmas",
        type=float,
        default=SCREEN_N_SIGMAS,
        help="screen: the Hampel rule's n_sigmas (default: the fixed threshold alone)",
    )
    parser.add_argument(
        "--clean", action="store_true", help="screen: also score the uncorrupted clips (RMS over every observed sample)"
    )
    parser.add_argument(
        "--short-gap-frames",
        type=int,
        default=None,
        help="screen: the learned refiners' short_gap_frames (default: theirs)",
    )
    parser.add_argument("--n-components", type=int, default=90, help="pose_prior: PPCA components")
    parser.add_argument(
        "--sweep",
        choices=["drift", "noise_floor"],
        default="drift",
        help="pose_prior: the parameter the values are (drift m/s, or noise_floor m)",
    )
    parser.add_argument("--drift", type=float, default=0.2, help="pose_prior, --sweep noise_floor: the drift, m/s")
    parser.add_argument("--noise-floor", type=float, default=0.0, help="pose_prior, --sweep drift: the noise floor, m")
    parser.add_argument(
        "--train-clips-per-performer",
        type=int,
        default=None,
        help="pose_prior: fit on this many seeded clips per training performer (None: all)",
    )
    parser.add_argument(
        "--runs",
        type=Path,
        default=ROOT / "checkpoints",
        help="the folder holding refine_<model>/fold_<P>/ (the output_root of the runs)",
    )
    args = parser.parse_args(argv)
    setting = SETTINGS[args.setting]
    values, protocols = args.values or setting["values"], list(setting["protocols"])
    if args.setting == "pose_prior_short_gaps":  # the grid in frames at 120 fps (HDM05), the parameter
        values = [int(v) for v in values]  # in seconds
    if args.clean:
        protocols.append(("clean", None))

    for model in args.models:
        table = np.full((len(protocols), len(values), len(args.folds)), np.nan)
        for f, fold in enumerate(args.folds):
            checkpoint = str(args.runs / f"refine_{model}" / f"fold_{fold}" / "best.ckpt")
            data = MocapRefinementDataModule(dataset="hdm05", root=str(args.data), test_groups=[fold])
            if args.setting == "threshold":
                clips = [central_crop(m, args.frames) for m in data.val_motions]
                refiners = [LearnedRefiner(checkpoint=checkpoint, repair_threshold=v).fit() for v in values]
            elif args.setting == "short_gaps":
                clips = list(data.val_motions)
                refiners = [LearnedRefiner(checkpoint=checkpoint, short_gap_frames=int(v)).fit() for v in values]
            elif args.setting == "screen":
                clips = list(data.val_motions)
                refiners = [
                    _screened(
                        base_refiner(model, checkpoint, args.short_gap_frames), v, args.half_window, args.n_sigmas
                    )
                    for v in values
                ]
            elif args.setting in ("pose_prior", "pose_prior_short_gaps"):
                from mocapkit.refinement.pose_prior import PosePriorRefiner

                clips = list(data.val_motions)
                fit = data.train_motions
                if args.train_clips_per_performer:  # as the benchmark's fits: N seeded clips per performer
                    rng, by_group = np.random.default_rng(0), {}
                    for m in fit:
                        by_group.setdefault(m.metadata["group"], []).append(m)
                    fit = [
                        ms[i]
                        for _, ms in sorted(by_group.items())
                        for i in sorted(
                            rng.choice(len(ms), min(len(ms), args.train_clips_per_performer), replace=False)
                        )
                    ]
                if args.setting == "pose_prior_short_gaps":
                    sweep, fixed = "short_gap_seconds", {"drift": args.drift, "noise_floor": args.noise_floor}
                    sweep_values = [v / 120.0 for v in values]
                else:
                    sweep = args.sweep  # rounds 1-3 ran without the short-gap spline
                    fixed = {"drift": args.drift} if sweep == "noise_floor" else {"noise_floor": args.noise_floor}
                    fixed["short_gap_seconds"] = 0
                    sweep_values = values
                refiners = [
                    PosePriorRefiner(n_components=args.n_components, **fixed, **{sweep: v}).fit(fit)
                    for v in sweep_values
                ]
            elif args.setting == "short_gap_points":
                clips = list(data.val_motions)
                refiners = [
                    LearnedRefiner(
                        checkpoint=checkpoint,
                        short_gap_frames=int(abs(v)),
                        short_gap_points="repaired" if v < 0 else "observed",
                    ).fit()
                    for v in values
                ]
            else:
                clips = list(data.val_motions)
                trained = int(LearnedRefiner(checkpoint=checkpoint).fit().skeleton_["window"])  # training window
                refiners = [LearnedRefiner(checkpoint=checkpoint, window=int(v * trained)).fit() for v in values]
            for p, (protocol, level) in enumerate(protocols):
                scores = np.full((len(values), len(clips)), np.nan)
                for i, clip in enumerate(clips):
                    if protocol == "clean":  # what false flags cost: every observed sample
                        corrupted, entries = clip, ~clip.missing
                    else:
                        try:
                            corruption = corrupt(clip, protocol, level, seed=i)
                        except CorruptionError:  # a clip too short for the protocol: not scored
                            continue
                        corrupted = corruption.motion
                        entries = (
                            ~corrupted.missing
                            if args.setting == "threshold"
                            else corruption.removed | corruption.perturbed
                        )
                    for k, refiner in enumerate(refiners):
                        scores[k, i] = rms_error_mm(clip, refiner.refine(corrupted), entries)
                table[p, :, f] = np.nanmean(scores, axis=1)
            print(f"[{model}] fold {fold}: {len(clips)} validation clips of {data.groups['train']}", flush=True)
        what = "observed" if args.setting == "threshold" else "corrupted"
        print(f"\n# {model}: RMS 3-D error over the {what} entries, mm, mean over folds {args.folds}")
        unit = "m (noise_floor)" if args.setting == "pose_prior" and args.sweep == "noise_floor" else setting["unit"]
        print("| protocol | " + " | ".join(f"{v:g} {unit}" for v in values) + " |")
        print("|---|" + "---:|" * len(values))
        for p, (protocol, level) in enumerate(protocols):
            print(f"| {protocol} {level} | " + " | ".join(f"{v:.2f}" for v in table[p].mean(axis=1)) + " |")
        print("| **mean** | " + " | ".join(f"{v:.2f}" for v in table.mean(axis=(0, 2))) + " |\n", flush=True)


if __name__ == "__main__":
    main()
