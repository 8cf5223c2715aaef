"""Benchmark: TrNN (Wang 2017 §4.2, Algorithm 3) against SVT with a full SVD every iteration, per iteration and per
sequence, on real motions of the lengths of the thesis's Table 4.1 (152 … 17,799 frames).

Sequences. Real CMU (and, if more frames are needed or CMU is absent, HDM05) ASF/AMC clips at 120 fps, all on the
same 31-joint skeleton. A row of Table 4.1 whose frame count one clip has exactly uses that clip (CMU 02_01 is a
343-frame walk, 02_07 has 2,251 frames); the others concatenate clips in a fixed order and cut at the length,
each clip shifted on the floor so that its root starts where the previous clip's root ended. Each sequence is
corrupted by ``random_missing`` (thesis §4.2.3 first mode: mr = 0.3 of the markers removed in every frame,
seed 0).

Methods, each timed once per sequence (``refine`` wall time, setup included: gap interpolation and the one
rank-estimating SVD):

* ``TrNN``: the thesis's MoCap settings (r = 15, λ = 100/√max(m,n), μ = 100, ρ = 1.4, η¹ = 1e−5, ε = 1e−4);
* ``TrNN r=0``: the same solver with no truncation, the nuclear-norm model of Feng et al. 2014b (TSMC-style;
  not Feng's partial-SVD solver);
* ``TrNN d=16``: r = 15 with the narrowest factor width the model allows (d = r + 1, what the σ₁-normalised LSJ
  rule gives on real motion), to show the O(m n d) per-iteration cost; the default's literal LSJ rule in CMU
  units gives d up to m = 93 on long sequences;
* ``SVT``: singular value thresholding (Cai, Candès & Shen 2010) with a full (all singular values, economy)
  SVD every iteration, tol 1e-4: :class:`mocapkit.refinement.svt.SVTCompletion` when it is there, else the
  minimal reference below; capped at ``--svt-iters`` iterations (a capped run's per-sequence time is a lower
  bound, marked ``>``).

"s/it" is the sequence time divided by the iterations. Ratios are SVT / TrNN (> 1: TrNN faster). RMSE is over the
removed entries (Wang 2017 §4.2.3 matrix RMSE, cm). The thesis's seconds (Table 4.1: TSMC and TrNN, Matlab 7.10
on a 2.4 GHz Intel i5, 4 GB) are printed beside ours: indicative only.

Usage: ``python bench/bench_trnn.py [--threads 1] [--device cpu|cuda] [--svt-iters 500] [--max-frames N]
[--data DIR]``
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapkit.datasets import read_motion
from mocapkit.motion.container import Motion
from mocapkit.refinement.base import MotionRefiner
from mocapkit.refinement.corruptions import corrupt
from mocapkit.refinement.metrics import matrix_rmse
from mocapkit.refinement.trnn import TrNN

#: Wang 2017 Table 4.1: (action, frames, TSMC seconds, TrNN seconds); Matlab 7.10, Intel i5 2.4 GHz.
TABLE_4_1 = [
    ("Running", 152, 1.61, 2.69),
    ("Walk", 343, 2.99, 4.35),
    ("Jump", 439, 4.07, 6.13),
    ("Gymnastics", 575, 7.63, 8.17),
    ("Score", 801, 8.95, 10.19),
    ("Dance", 1095, 21.23, 14.84),
    ("Varied", 2085, 111.69, 36.30),
    ("Punch", 2251, 93.33, 33.36),
    ("Acrobatics", 2422, 121.93, 34.09),
    ("Boxing", 4840, 267.29, 73.75),
    ("Basketball", 4905, 286.25, 102.42),
    ("Taichi", 17799, 2094.8, 564.85),
]

try:
    from mocapkit.refinement.svt import SVTCompletion
except ImportError:  # the minimal full-SVD SVT reference (Cai, Candès & Shen 2010), same rules as the library's
    SVTCompletion = None


class _MinimalSVT(MotionRefiner):
    """SVT with a full SVD per iteration: ``X = D_τ(Y)``, ``Y += δ P_Ω(M − X)``; τ = 5√(n1 n2), δ = 1.2/p, on the
    column-centred, RMS-scaled matrix; stops at relative residual ``tol`` on Ω or ``max_iter``."""

    def __init__(self, tol: float = 1e-4, max_iter: int = 500, device: str = "cpu"):
        self.tol, self.max_iter, self.device = tol, max_iter, device

    def _refine_matrix(self, X, observed):
        mean = np.where(observed, X, 0).sum(0) / np.maximum(observed.sum(0), 1)
        scale = float(np.sqrt((np.where(observed, X - mean, 0) ** 2).sum() / observed.sum())) or 1.0
        dev = torch.device(self.device)
        mask = torch.as_tensor(observed, device=dev)
        PM = torch.as_tensor(np.where(observed, (X - mean) / scale, 0.0), device=dev)
        n1, n2 = PM.shape
        tau, delta = 5 * math.sqrt(n1 * n2), 1.2 / (observed.sum() / observed.size)
        Y = math.ceil(tau / (delta * float(torch.linalg.matrix_norm(PM, ord=2)))) * delta * PM
        norm, it = float(torch.linalg.norm(PM)), 0
        for it in range(1, self.max_iter + 1):
            U, s, Vh = torch.linalg.svd(Y, full_matrices=False)
            Xk = (U * (s - tau).clamp_min(0)) @ Vh
            R = torch.where(mask, PM - Xk, 0.0)
            if float(torch.linalg.norm(R)) / norm <= self.tol:
                break
            Y = Y + delta * R
        self.info_ = {"iterations": it}
        return np.where(observed, X, Xk.cpu().numpy() * scale + mean), None


def _clip_paths(data: Path) -> list[tuple[Path, Path]]:
    """(amc, asf) pairs in a fixed order: CMU first (sorted), then HDM05 by performer."""
    pairs = []
    cmu = data / "cmu_amc"
    for amc in sorted(cmu.glob("*.amc")) if cmu.is_dir() else []:
        pairs.append((amc, cmu / f"{amc.name[:2]}.asf"))
    hdm = data / "hdm05_cuts11"
    for actor in sorted(p for p in hdm.iterdir() if p.is_dir()) if hdm.is_dir() else []:
        for amc in sorted(actor.glob("*.amc")):
            pairs.append((amc, actor / f"HDM_{actor.name}.asf"))
    return pairs


class ClipPool:
    """Reads clips lazily (in :func:`_clip_paths` order) and builds sequences of a given length."""

    def __init__(self, data: Path):
        self.paths = _clip_paths(data)
        self.clips: list[Motion] = []

    def _load_until(self, frames: int) -> None:
        while sum(c.num_frames for c in self.clips) < frames and len(self.clips) < len(self.paths):
            amc, asf = self.paths[len(self.clips)]
            clip = read_motion(amc, asf=asf)
            if clip.fps != 120 or (self.clips and clip.joint_names != self.clips[0].joint_names):
                raise SystemExit(f"{amc}: expected 120 fps on the first clip's skeleton")
            self.clips.append(clip)

    def sequence(self, frames: int) -> tuple[Motion, str]:
        """A clip of exactly ``frames`` frames among those loaded, else the loaded clips concatenated and cut."""
        self._load_until(frames)
        for clip in self.clips:
            if clip.num_frames == frames:
                return clip, Path(clip.source).stem if clip.source else clip.name
        total = sum(c.num_frames for c in self.clips)
        if total < frames:
            raise SystemExit(f"only {total} frames of clips available, {frames} needed (--data?)")
        parts, used, end = [], [], None
        for clip in self.clips:
            pos = clip.positions.astype(np.float64).copy()
            if end is not None:  # continue on the floor from where the last clip ended
                shift = end - pos[0, 0]
                shift[1] = 0.0  # y is up: keep heights
                pos += shift
            parts.append(pos)
            used.append(Path(clip.source).stem if clip.source else clip.name)
            end = pos[-1, 0].copy()
            if sum(len(p) for p in parts) >= frames:
                break
        pos = np.concatenate(parts)[:frames]
        label = f"{len(used)} clips ({used[0]}…{used[-1]})" if len(used) > 1 else f"{used[0]}[:{frames}]"
        return Motion(pos, self.clips[0].joint_names, 120.0, name=f"concat{frames}"), label


def _run(refiner, motion: Motion, clean: Motion, removed: np.ndarray, device: str) -> tuple[float, int, float, bool]:
    if device == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    out = refiner.refine(motion)
    if device == "cuda":
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    if isinstance(refiner, TrNN):
        iters, converged = refiner.n_iter_, refiner.converged_
    else:
        iters = refiner.info_["iterations"]
        converged = bool(refiner.info_.get("converged", iters < refiner.max_iter))
    return seconds, iters, matrix_rmse(clean, out, removed), converged


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch / BLAS threads")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--svt-iters", type=int, default=500, help="SVT iteration cap (its own tol is 1e-4)")
    parser.add_argument("--max-frames", type=int, default=None, help="skip Table 4.1 rows longer than this")
    default_data = Path(os.environ.get("MOCAPKIT_SHARED", Path(__file__).resolve().parents[2] / "shared")) / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="folder with cmu_amc/ and/or hdm05_cuts11/")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    svt_cls = SVTCompletion or _MinimalSVT
    print(
        f"# TrNN vs full-SVD SVT; {platform.processor() or platform.machine()}, torch {torch.__version__}, "
        f"{args.threads} thread(s), device {args.device}; SVT = "
        f"{'mocapkit.refinement.svt.SVTCompletion' if SVTCompletion else 'minimal reference in this script'}, "
        f"cap {args.svt_iters} iterations",
        flush=True,
    )
    print("# corruption: random_missing mr = 0.3 (seed 0); times are one refine() call, setup included", flush=True)
    print("# thesis columns: Wang 2017 Table 4.1, Matlab 7.10 on a 2.4 GHz i5 — indicative only", flush=True)
    pool = ClipPool(args.data)
    if not pool.paths:
        raise SystemExit(f"no CMU/HDM05 ASF/AMC clips under {args.data}")
    rows = [r for r in TABLE_4_1 if args.max_frames is None or r[1] <= args.max_frames]
    pool._load_until(max(r[1] for r in TABLE_4_1))  # the clips the longest row needs, whatever --max-frames says
    header = (
        f"{'action':11s} {'frames':>6s} | {'TrNN s':>7s} {'it':>3s} {'s/it':>7s} {'d':>3s} | "
        f"{'r=0 s':>7s} {'it':>3s} | {'d=16 s':>7s} {'s/it':>7s} | {'SVT s':>8s} {'it':>4s} {'s/it':>7s} | "
        f"{'SVT/TrNN it':>11s} {'seq':>6s} | {'RMSE cm TrNN/r0/d16/SVT':>27s} | {'thesis TSMC s':>13s} "
        f"{'TrNN s':>7s} | source"
    )
    print(header, flush=True)
    totals = time.perf_counter()
    for action, frames, thesis_tsmc, thesis_trnn in rows:
        clean, source = pool.sequence(frames)
        corruption = corrupt(clean, "random_missing", 0.3, seed=0)
        motion, removed = corruption.motion, corruption.removed
        default = TrNN(device=args.device)
        t, ti, te, tc = _run(default, motion, clean, removed, args.device)
        z, zi, ze, zc = _run(TrNN(truncation=0, device=args.device), motion, clean, removed, args.device)
        w, wi, we, _ = _run(TrNN(rank=16, device=args.device), motion, clean, removed, args.device)
        s, si, se, sc = _run(svt_cls(max_iter=args.svt_iters, device=args.device), motion, clean, removed, args.device)
        capped = " " if sc else ">"
        print(
            f"{action:11s} {frames:6d} | {t:7.2f} {ti:3d}{' ' if tc else '*'}{t / ti:7.4f} {default.width_:3d} | "
            f"{z:7.2f} {zi:3d}{' ' if zc else '*'}| {w:7.2f} {w / wi:7.4f} | "
            f"{capped}{s:7.2f} {si:4d} {s / si:7.4f} | "
            f"{(s / si) / (t / ti):11.2f} {capped}{s / t:5.2f} | {te:6.2f} {ze:6.2f} {we:6.2f} {se:6.2f} | "
            f"{thesis_tsmc:13.2f} {thesis_trnn:7.2f} | {source}",
            flush=True,
        )
    print(
        f"# total {time.perf_counter() - totals:.0f} s; '*' = TrNN stopped at max_iter, '>' = SVT hit the "
        f"iteration cap (lower bound)",
        flush=True,
    )


if __name__ == "__main__":
    main()
