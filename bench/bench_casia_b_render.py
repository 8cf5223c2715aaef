"""Benchmark: the synthetic CASIA-B silhouette renderer against a plain PIL rasteriser, same scenes, in one run.

The scene is what :func:`mocapkit.datasets.synthetic.casia_b.synthesize_casia_b` renders per walk:
one subject's posed capsule body (:func:`body_capsules`) seen from all 11 views, ``--frames``
frames each, for ``--subjects`` subjects and the three conditions. Both rasterisers get the
same projected capsules (:func:`project_capsules`), so only the rasterisation differs:

* **mocapkit**: :func:`render_views` without noise, i.e. posing, projection, the vectorised numpy
  rasteriser (:func:`rasterize_capsules`, all frames and views of a walk at once) and the threshold;
* **plain**: the usual way, posing and projection as above, then per frame and per capsule
  ``PIL.ImageDraw`` (a polygon for the tapered side and two discs for the ends).

The two silhouettes are checked to agree (mean intersection over union over all frames; they
differ only by one-pixel edge decisions), then frames/s and the ratio are printed as a Markdown
table. A third row gives mocapkit with the default segmentation noise (not comparable with plain).
Timings are the best of ``--repeat`` rounds, the renderers interleaved in every round.

Usage: ``python bench/bench_casia_b_render.py [--heights 64 128] [--subjects 2] [--frames 40] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from timing import best_of  # bench/timing.py, beside this script

from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.datasets.synthetic.casia_b import (
    SegmentationNoise,
    WalkVariation,
    body_capsules,
    draw_subject,
    project_capsules,
    render_views,
)


def plain_render_walk(subject, views, condition: str, frames: int, height: int, walk: WalkVariation) -> list:
    """Silhouettes of one walk from each view with PIL: one polygon and two ellipses per capsule and frame.

    Returns one uint8 ``[T, H, W]`` (0 / 255) per view, like :func:`render_views` with ``noise=None``.
    """
    from PIL import Image, ImageDraw

    width = height * 4 // 3
    capsules = body_capsules(subject, condition, frames, walk)
    out = []
    for view in views:
        a, b, ra, rb, _ = project_capsules(capsules, view, height, width)
        # PIL fills every pixel its outline touches: about half a pixel more than the distance test
        ra, rb = np.maximum(ra - 0.5, 0), np.maximum(rb - 0.5, 0)
        masks = np.empty((frames, height, width), dtype=np.uint8)
        for t in range(frames):
            image = Image.new("L", (width, height), 0)
            draw = ImageDraw.Draw(image)
            for i in range(a.shape[1]):
                (ax, ay), (bx, by), r0, r1 = a[t, i], b[t, i], ra[t, i], rb[t, i]
                dx, dy = bx - ax, by - ay
                norm = np.hypot(dx, dy)
                if norm > 1e-9:
                    nx, ny = -dy / norm, dx / norm
                    draw.polygon(
                        [
                            (ax + nx * r0, ay + ny * r0),
                            (bx + nx * r1, by + ny * r1),
                            (bx - nx * r1, by - ny * r1),
                            (ax - nx * r0, ay - ny * r0),
                        ],
                        fill=255,
                    )
                draw.ellipse([ax - r0, ay - r0, ax + r0, ay + r0], fill=255)
                draw.ellipse([bx - r1, by - r1, bx + r1, by + r1], fill=255)
            masks[t] = np.asarray(image)
        out.append(masks)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heights", type=int, nargs="+", default=[64, 128], help="image heights, pixels")
    parser.add_argument("--subjects", type=int, default=2, help="subjects (each: 3 conditions x 11 views)")
    parser.add_argument("--frames", type=int, default=40, help="frames per sequence")
    parser.add_argument("--repeat", type=int, default=3, help="rounds; the best is reported")
    args = parser.parse_args(argv)

    walks = [(draw_subject(0, s), c) for s in range(1, args.subjects + 1) for c in CONDITIONS]
    walk = WalkVariation()
    rngs = [np.random.default_rng(k) for k in range(len(VIEWS))]
    rows = []
    for height in args.heights:

        def ours(noise=None, height=height):
            return [render_views(p, VIEWS, c, args.frames, height, rngs, walk, noise) for p, c in walks]

        def plain(height=height):
            return [plain_render_walk(p, VIEWS, c, args.frames, height, walk) for p, c in walks]

        mine, theirs = ours(), plain()  # agreement first (also warms up)
        ious = []
        for views_m, views_p in zip(mine, theirs):
            for m, p in zip(views_m, views_p):
                inter = ((m > 0) & (p > 0)).sum(axis=(1, 2))
                union = ((m > 0) | (p > 0)).sum(axis=(1, 2))
                ious.append(inter[union > 0] / union[union > 0])
        iou = float(np.concatenate(ious).mean())
        if iou < 0.85:
            raise SystemExit(f"height {height}: renderers disagree (mean IoU {iou:.3f})")
        best = best_of({"plain": plain, "ours": ours, "ours+noise": lambda: ours(SegmentationNoise())}, args.repeat)
        frames = len(walks) * len(VIEWS) * args.frames
        rows.append((height, frames, iou, best))

    load = os.getloadavg()[0]
    print(
        f"\nbest of {args.repeat} rounds; {os.cpu_count()} CPUs, load average {load:.2f}; "
        f"{args.subjects} subjects x {len(CONDITIONS)} conditions x {len(VIEWS)} views x {args.frames} frames\n"
    )
    print("| height x width | frames | renderer | s | frames/s | IoU vs plain | ours vs plain |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for height, frames, iou, best in rows:
        size = f"{height}x{height * 4 // 3}"
        print(
            f"| {size} | {frames} | plain (PIL ImageDraw per capsule) | {best['plain']:.3f} "
            f"| {frames / best['plain']:.0f} | | |"
        )
        print(
            f"| {size} | {frames} | mocapkit (numpy, vectorised) | {best['ours']:.3f} | {frames / best['ours']:.0f} "
            f"| {iou:.3f} | **{best['plain'] / best['ours']:.1f}x** |"
        )
        print(
            f"| {size} | {frames} | mocapkit + segmentation noise | {best['ours+noise']:.3f} "
            f"| {frames / best['ours+noise']:.0f} | | {best['plain'] / best['ours+noise']:.1f}x |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
