"""The thesis's occlusion experiment (Lou 2012 Fig. 3.6b): a bending motion whose left arm is hidden for 7 frames,
tracked with no prior, with an LPCA prior from a one-motion database and from a mixed database.

    OMP_NUM_THREADS=1 python scripts/results/depth_tracking_occlusion.py [--root ../shared/data/hdm05_cuts11]
        [--performer mm] [--seeds 0 1] [--out checkpoints/depth_occlusion]

Data: the held-out performer's bending takes (HDM05 ``depositFloorR``: bending down to put something on the
floor with the right hand), Kinect v1 depth rendered with sensor noise (``render_depth_sequence``, the render
seed per take and seed); frames ``--occlude-start`` … +6 lose every depth pixel of the left arm (upper arm, forearm,
hand: the rendered part labels), as if something the sensor does not see covered it, and the sensor skeleton's
left elbow, wrist and hand are NOT_TRACKED there (so the tracker's sensor term gives them no weight). Databases (ground-truth joints
of the *other* performers, full takes at 30 fps): ``one-motion`` = their ``depositFloorR`` takes; ``mixed`` =
every take of theirs (11 motion classes). The tracker is the registry's default (``tracker``) with
``prior=none`` or ``lpca``. Reported per variant, mean ± sd over seeds: the mean error of the 16 joints and of the
left-arm joints during the occlusion and over the whole take (mm), and a per-frame plot.
Results: docs/results/depth_tracking.md#occlusion.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

LEFT_ARM_PARTS = ("l_upper_arm", "l_forearm", "l_hand")
LEFT_ARM_JOINTS = ("l_elbow", "l_wrist")


def main(argv=None) -> None:
    from mocapkit.datasets.formats.motion_io import find_motion_files, read_motion
    from mocapkit.datasets.synthetic.depth import render_depth_sequence
    from mocapkit.datasets.synthetic.kinect_noise import file_seed, kinect20_from_motion
    from mocapkit.depth_tracking.base import TRACKED_JOINTS, joint_error_mm, tracked_joints
    from mocapkit.depth_tracking.benchmark import in_view, motion_class
    from mocapkit.evaluation.plots import pyplot, save_figure
    from mocapkit.train.registry import build_method

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default="../shared/data/hdm05_cuts11")
    parser.add_argument("--performer", default="mm")
    parser.add_argument("--motion", default="depositFloorR")
    parser.add_argument("--takes", type=int, default=2, help="bending takes of the performer")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--occlude-start", type=int, default=20)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--out", default="checkpoints/depth_occlusion")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    files = [f for f in find_motion_files(Path(args.root)) if f.parent != Path(args.root)]
    test_files = sorted(f for f in files if f.parent.name == args.performer and motion_class(f) == args.motion)
    test_files = test_files[: args.takes]
    database = [f for f in files if f.parent.name != args.performer]
    clips = {f: tracked_joints(kinect20_from_motion(read_motion(f), fps=30.0)) for f in database}
    databases = {
        "none": None,
        "one-motion": [c for f, c in clips.items() if motion_class(f) == args.motion],
        "mixed": list(clips.values()),
    }
    print({k: (0 if v is None else sum(len(c) for c in v)) for k, v in databases.items()}, "database frames")
    trackers = {}  # one fit per database: the inverse kinematics of every database take
    for name, clips_ in databases.items():
        tracker = build_method("depth_tracking", "tracker", [f"prior={'none' if clips_ is None else 'lpca'}"])
        trackers[name] = tracker.fit([]) if clips_ is None else tracker.fit_mocap(clips_)
    occluded = np.arange(args.occlude_start, args.occlude_start + 7)
    arm = [TRACKED_JOINTS.index(j) for j in LEFT_ARM_JOINTS]
    results: dict[str, dict[str, list[float]]] = {k: {} for k in databases}
    curves: dict[str, np.ndarray] = {}
    for seed in args.seeds:
        for path in test_files:
            positions = kinect20_from_motion(read_motion(path), fps=30.0)[: args.frames]
            seq = in_view(render_depth_sequence(positions, 30.0, seed=file_seed(seed, path), source=str(path)))
            hide = np.isin(seq.parts, [seq.part_names.index(p) + 1 for p in LEFT_ARM_PARTS])
            hide[np.setdiff1d(np.arange(seq.num_frames), occluded)] = False
            seq.depth_mm[hide] = 0
            # the sensor's skeleton loses the arm too: its joints count as not tracked (weight 0 in the tracker)
            arm20 = [seq.joint_names.index(j) for j in (*LEFT_ARM_JOINTS, "l_hand")]
            seq.sensor_state[np.ix_(occluded, arm20)] = 0
            truth = tracked_joints(seq.joints)
            for name, clips_ in databases.items():
                tracker = build_method("depth_tracking", "tracker", [f"prior={'none' if clips_ is None else 'lpca'}"])
                tracker = tracker.fit([]) if clips_ is None else tracker.fit_mocap(clips_)
                estimate = tracker.predict(seq)
                error = joint_error_mm(estimate, truth)
                arm_error = 1000 * np.linalg.norm(estimate[:, arm] - truth[:, arm], axis=-1).mean(axis=1)
                row = results[name]
                for key, value in (
                    ("all_occluded", error[occluded].mean()),
                    ("arm_occluded", arm_error[occluded].mean()),
                    ("all_take", error.mean()),
                    ("arm_take", arm_error.mean()),
                ):
                    row.setdefault(key, []).append(float(value))
                if seed == args.seeds[0] and path == test_files[0]:
                    curves[name] = arm_error
                print(
                    seed,
                    path.name,
                    name,
                    f"{error.mean():.1f} mm, arm while hidden {arm_error[occluded].mean():.1f}",
                    flush=True,
                )
    summary = {
        name: {key: (float(np.mean(v)), float(np.std(v, ddof=1)) if len(v) > 1 else 0.0) for key, v in row.items()}
        for name, row in results.items()
    }
    (out / "occlusion.json").write_text(json.dumps({"args": vars(args), "summary": summary, "raw": results}, indent=1))
    print("| prior | 16 joints, occluded frames | left arm, occluded frames | 16 joints, take | left arm, take |")
    print("|---|---|---|---|---|")
    for name, row in summary.items():
        cells = " | ".join(
            f"{row[k][0]:.1f} ± {row[k][1]:.1f}" for k in ("all_occluded", "arm_occluded", "all_take", "arm_take")
        )
        print(f"| {name} | {cells} |")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.axvspan(occluded[0], occluded[-1], color="0.85", label="left arm hidden")
    for name, curve in curves.items():
        ax.plot(curve, label=f"prior: {name}")
    ax.set_xlabel("frame")
    ax.set_ylabel("left elbow + wrist error (mm)")
    ax.set_title(f"{test_files[0].name}, seed {args.seeds[0]}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    print("wrote", save_figure(fig, out / "occlusion.png"))


if __name__ == "__main__":
    main()
