"""Speed of the depth tracker: the analytic Jacobian against autodiff, and frames per second against the sensor's 30.

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_depth_tracking.py [--frames 30] [--device cpu]

1. ``body_points_jacobian`` (the chain rule down the bone tree) against ``torch.func.jacfwd`` of ``body_points``
   (the reference: PyTorch's forward-mode autodiff) for 800 body points, the size of one Gauss–Newton iteration's
   surface + edge correspondences; the two agree to 1e-10 (tests/depth_tracking/test_tracker.py).
2. ``DepthTracker.predict`` (the registry's ``tracker``, prior off, the performer's skeleton given) on a
   Kinect v1 depth video rendered from a real HDM05 cut (``../shared/data/hdm05_cuts11``): frames per second,
   against the 30 frames/s the sensor delivers, and the time of one iteration's parts (ray casting at stride 4 and
   1, Canny edges, the Jacobian).
Results: bench/RESULTS.md (Depth tracker).
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import torch
from timing import best_of  # bench/timing.py, beside this script


def main(argv=None) -> None:
    from mocapkit.datasets.formats.motion_io import read_motion
    from mocapkit.datasets.synthetic.depth import render_depth_sequence
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion
    from mocapkit.depth_tracking import body_model as bm
    from mocapkit.depth_tracking.base import tracked_joints
    from mocapkit.depth_tracking.tracker import _edges, _TrackState
    from mocapkit.train.registry import build_method

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--take", default="../shared/data/hdm05_cuts11/bd/HDM_bd_throwBasketball_001_120.amc")
    args = parser.parse_args(argv)
    print(f"torch {torch.__version__}, {platform.processor() or platform.machine()}, threads {torch.get_num_threads()}")

    skeleton = bm.template_skeleton()
    offsets, _ = skeleton.tensors(dtype=torch.float32)
    q = torch.zeros(bm.NUM_DOF)
    q[3] = np.pi
    bone = torch.randint(0, bm.NUM_BONES, (800,))
    local = torch.randn(800, 3) * 0.05
    best = best_of(  # interleaved rounds; the first is the warm-up the minimum leaves out
        {
            "analytic": lambda: bm.body_points_jacobian(q, offsets, bone, local),
            "autodiff": lambda: torch.func.jacfwd(lambda x: bm.body_points(x, offsets, bone, local))(q),
        },
        repeat=6,
    )
    analytic, autodiff = best["analytic"], best["autodiff"]
    print("| Jacobian of 800 points | ms | ratio |\n|---|---:|---:|")
    print(f"| `torch.func.jacfwd` (reference) | {1000 * autodiff:.1f} | 1.00 |")
    print(f"| analytic (`body_points_jacobian`) | {1000 * analytic:.1f} | {autodiff / analytic:.1f}× |")

    if not Path(args.take).exists():
        print(f"{args.take} not found: tracking speed skipped")
        return
    positions = kinect20_from_motion(read_motion(args.take), fps=30.0)[: args.frames]
    seq = render_depth_sequence(positions, 30.0, seed=0, source=args.take)
    tracker = build_method(
        "depth_tracking", "tracker", ["prior=none", "skeleton=ground_truth", f"device={args.device}"]
    ).fit([])
    start = time.perf_counter()
    tracker.predict(seq)
    seconds = time.perf_counter() - start
    fps = seq.num_frames / seconds
    print(f"\ntracking {seq.num_frames} frames: {fps:.2f} frames/s ({fps / 30:.3f}× the sensor's 30 frames/s)")
    sk = bm.skeleton_from_joints(tracked_joints(seq.joints))
    off, rad = sk.tensors()
    state = _TrackState(
        tracker, seq.intrinsics, off, rad, torch.device(args.device), torch.float32, tracked_joints(seq.sensor_joints)
    )
    pose = state.initial_pose(seq)
    frame = state.observe(seq, 1)
    hits, _, _ = state.render(pose, 1)
    depth = hits.full_image(seq.intrinsics)
    points = hits.full_image(seq.intrinsics, hits.points)
    parts = {
        "ray casting, every 4th pixel": lambda: state.render(pose, 4),
        "ray casting, every pixel (for edges)": lambda: state.render(pose, 1),
        "Canny edges of the rendered depth": lambda: _edges(depth, points, 0.08, 0.16),
        "all correspondences of one iteration": lambda: state.correspondences(frame, pose, None),
    }
    print("\n| part of one iteration | ms |\n|---|---:|")
    for name, seconds in best_of(parts, repeat=6).items():
        print(f"| {name} | {1000 * seconds:.1f} |")


if __name__ == "__main__":
    main()
