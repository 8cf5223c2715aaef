"""Benchmark: GEI building throughput, mocapkit's batched builder against a per-frame PIL loop, in one run.

Both build one GEI per sequence (``per="sequence"``: normalise every silhouette, then average)
from the same in-memory sequences, rendered by :mod:`mocapkit.datasets.synthetic.casia_b` at
CASIA-B's 320x240 (no PNG decoding in the timing), and their GEIs are checked to agree first.
The mocapkit builder is also timed with ``per="cycle"`` (period detection + per-cycle means).

The *plain* builder is OpenGait's ``datasets/pretreatment.py`` written with PIL instead of
OpenCV, as it is usually copied: per frame, drop it if nearly empty, crop the rows to the
silhouette, resize to the target height (PIL's BOX filter, the area filter ours uses),
find the median column, pad and cut the width; then ``np.mean`` over the frames. It is part
of this file, so the comparison is reproducible.

Timings are the best of ``--repeat`` rounds, the builders interleaved in every round.
Usage: ``python bench/bench_gei.py [--sequences 12] [--frames 80] [--size 64x44] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from PIL import Image
from timing import best_of  # bench/timing.py, beside this script

from mocapkit.datasets.casia_b.gei import gait_energy_images
from mocapkit.datasets.casia_b.prepare import parse_gei_size
from mocapkit.datasets.formats.casia_b import VIEWS
from mocapkit.datasets.synthetic.casia_b import draw_subject, draw_walk, render_walk


def plain_gei(frames: np.ndarray, height: int = 64, width: int = 44, min_foreground: float = 0.001) -> np.ndarray:
    """One GEI per sequence the per-frame way (OpenGait's pretreatment with PIL), float32 ``[height, width]``."""
    aligned = []
    for img in frames:
        if img.sum() / 255.0 < min_foreground * img.size or not img.any():
            continue
        y_sum = img.sum(axis=1)
        y_top = (y_sum != 0).argmax(axis=0)
        y_btm = (y_sum != 0).cumsum(axis=0).argmax(axis=0)
        img = img[y_top : y_btm + 1]
        ratio = img.shape[1] / img.shape[0]
        img = np.asarray(
            Image.fromarray(img).resize((max(1, int(height * ratio)), height), Image.BOX), dtype=np.float64
        )
        x_csum = img.sum(axis=0).cumsum()
        x_center = int(np.argmax(x_csum > img.sum() / 2))
        half = width // 2
        padded = np.concatenate([np.zeros((height, half)), img, np.zeros((height, width))], axis=1)
        aligned.append(padded[:, x_center : x_center + width] / 255.0)  # columns x_center - half ..
    return np.mean(aligned, axis=0).astype(np.float32)


def render_sequences(count: int, frames: int, height: int = 240, seed: int = 0) -> list[np.ndarray]:
    """``count`` synthetic walks (subjects and views cycled), uint8 ``[frames, height, 4/3 height]`` each."""
    out = []
    for i in range(count):
        rng = np.random.default_rng(seed + i)
        view = VIEWS[(3 + 2 * i) % len(VIEWS)]
        out.append(render_walk(draw_subject(seed, 1 + i % 8), view, "nm", frames, height, rng, walk=draw_walk(rng)))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=12, help="synthetic walks")
    parser.add_argument("--frames", type=int, default=80, help="silhouettes per walk (25 fps)")
    parser.add_argument("--size", type=parse_gei_size, default=(64, 44), help="GEI HEIGHTxWIDTH")
    parser.add_argument("--repeat", type=int, default=3, help="rounds; the best is reported")
    args = parser.parse_args(argv)
    height, width = args.size

    sequences = render_sequences(args.sequences, args.frames)
    worst = 0.0
    for frames in sequences:  # agreement first: the speeds mean nothing otherwise
        ours = gait_energy_images(frames, size=args.size, per="sequence")[0][0]
        theirs = plain_gei(frames, height, width)
        # Same area filter, but the plain loop finds the median column after resizing (whole output
        # pixels: on average it lands half a pixel right of the window centre, ours a third of that)
        # and rounds the scaled width; so the GEIs agree in mass and rows, and in columns within a pixel.
        assert abs(ours.sum() / theirs.sum() - 1) < 0.02, "GEI masses differ"
        for axis in (0, 1):
            profile_ours, profile_theirs = ours.sum(axis=axis), theirs.sum(axis=axis)
            where = np.arange(len(profile_ours))
            shift = (profile_ours * where).sum() / profile_ours.sum() - (
                profile_theirs * where
            ).sum() / profile_theirs.sum()
            assert abs(shift) < 1.0, f"GEI centroids differ by {shift:.2f} px along axis {axis}"
        worst = max(worst, float(np.abs(ours - theirs).mean()))
        assert worst < 0.05, f"GEIs disagree: mean |diff| {worst:.4f}"
    total = sum(len(f) for f in sequences)

    best = best_of(
        {
            "plain": lambda: [plain_gei(f, height, width) for f in sequences],
            "ours": lambda: [gait_energy_images(f, size=args.size, per="sequence") for f in sequences],
            "ours_cycle": lambda: [
                gait_energy_images(f, size=args.size, per="cycle", fallback_period=25) for f in sequences
            ],
        },
        args.repeat,
    )

    load = os.getloadavg()[0]
    print(
        f"\nbest of {args.repeat} rounds; {os.cpu_count()} CPUs, load average {load:.2f}; "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}"
    )
    print(
        f"{args.sequences} synthetic walks x {args.frames} frames of 320x240 -> {height}x{width} GEIs; "
        f"worst mean |ours - plain| per GEI {worst:.4f}\n"
    )
    print("| builder | per | frames | s | frames/s | ours vs plain |")
    print("|---|---|---:|---:|---:|---:|")
    print(f"| plain (PIL per frame) | sequence | {total} | {best['plain']:.3f} | {total / best['plain']:.0f} | |")
    print(
        f"| mocapkit | sequence | {total} | {best['ours']:.3f} | {total / best['ours']:.0f} "
        f"| **{best['plain'] / best['ours']:.1f}x** |"
    )
    print(
        f"| mocapkit | cycle | {total} | {best['ours_cycle']:.3f} | {total / best['ours_cycle']:.0f} "
        f"| {best['plain'] / best['ours_cycle']:.1f}x |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
