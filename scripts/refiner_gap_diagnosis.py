"""Do the learned refiners fill gaps, or only their first guess does? Measured on one fold's validation clips.

Every refiner network returns ``first guess + correction`` (:mod:`mocapkit.models.refiners`); an untrained one (its
output layer zero) *is* its cubic first guess. This script scores a trained run against that same network with its
output layer zeroed, on the validation clips of the fold's training performers (never a test performer):

1. whole validation clips under ``long_gaps 20x100``, ``long_gaps 5x2s`` and ``continuous_missing 40``: RMS 3-D
   error (mm) over the removed entries, the run as ``LearnedRefiner`` (its inference defaults) and zeroed;
2. the fold's validation windows (the training mixture of corruptions, as checkpoint selection sees them): mean
   3-D error (cm) over the missing and over the perturbed (noisy) entries, and the mean size of the correction;
3. what the other joints know: a per-frame ridge regression of each joint on the other joints (frames centred on
   the root and turned to the hip line, fitted on the training clips), scored on the missing entries of validation
   windows corrupted by ``long_gaps`` only, against the first guess on the same entries (cm).

Usage (from the repository root; ``--runs`` is the ``output_root`` of the run)::

    python scripts/refiner_gap_diagnosis.py --model transformer --fold bd
"""
from __future__ import annotations

import argparse
import copy
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from refiner_inference_settings import score_on_clips

from mocapkit.datasets.formats.layouts import hip_joints
from mocapkit.datasets.mocap.datamodule import FixedWindows, MocapRefinementDataModule
from mocapkit.refinement.learned import LearnedRefiner

ROOT = Path(__file__).resolve().parents[1]


def zeroed(refiner: LearnedRefiner) -> LearnedRefiner:
    """The same refiner with the network's last layer zero: its first guess only."""
    plain = copy.deepcopy(refiner)
    out = plain.module_.model.out
    torch.nn.init.zeros_(out.weight)
    torch.nn.init.zeros_(out.bias)
    return plain


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="transformer")
    parser.add_argument("--fold", default="bd")
    parser.add_argument("--runs", type=Path, default=ROOT / "checkpoints")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    args = parser.parse_args(argv)
    checkpoint = args.runs / f"refine_{args.model}" / f"fold_{args.fold}" / "best.ckpt"
    run = LearnedRefiner(checkpoint=str(checkpoint)).fit()
    guess_only = zeroed(run)
    window = int(run.skeleton_["window"])
    data = MocapRefinementDataModule(dataset="hdm05", root=str(args.data), test_groups=[args.fold], window=window,
                                     eval_windows_per_clip=6)
    print(f"# {checkpoint}: {len(data.val_motions)} validation clips of {data.groups['train']}\n")

    print("## 1. Whole validation clips: RMS mm over the removed entries\n")
    print("| protocol | the run | its first guess (output layer zeroed) |\n|---|---:|---:|")
    protocols = [("long_gaps", "20x100"), ("long_gaps", "5x2s"), ("continuous_missing", 40)]
    for (protocol, level), (a, b) in zip(protocols, score_on_clips(data.val_motions, protocols, [run, guess_only])):
        print(f"| {protocol} {level} | {a:.2f} | {b:.2f} |")

    print("\n## 2. Validation windows (the training mixture): mean 3-D error, cm\n")
    batch = next(iter(torch.utils.data.DataLoader(data.dataset("val"), batch_size=len(data.dataset("val")))))
    with torch.no_grad():
        net = run.module_.model(batch["positions"], batch["missing"])
        first = guess_only.module_.model(batch["positions"], batch["missing"])
    error = {name: 100 * torch.linalg.vector_norm(o - batch["clean"], dim=-1) for name, o in (("run", net),
                                                                                            ("guess", first))}
    correction = 100 * torch.linalg.vector_norm(net - first, dim=-1)
    print("| entries | count | the run | first guess | mean size of the correction |\n|---|---:|---:|---:|---:|")
    for name, mask in (("missing", batch["missing"]), ("perturbed (noisy)", batch["corrupted"] & ~batch["missing"])):
        print(f"| {name} | {int(mask.sum())} | {error['run'][mask].mean():.2f} | {error['guess'][mask].mean():.2f} "
              f"| {correction[mask].mean():.2f} |")

    print("\n## 3. What the other joints know (windows corrupted by long_gaps only), cm\n")
    ref = data.reference
    left, right = hip_joints(ref.joint_names, ref.layout_name)
    pose_frame = lambda P: replace(ref, positions=P, missing=None, rotations=None).torso_aligned(left, right).positions
    train = pose_frame(np.concatenate([m.positions for m in data.train_motions]))
    J = ref.num_joints
    windows = FixedWindows(data.val_motions, window, 2, seed=1, corruption={"whole_joint_rate": 0.0,
                                                                             "weights": {"long_gaps": 1.0}})
    batch = next(iter(torch.utils.data.DataLoader(windows, batch_size=len(windows))))
    with torch.no_grad():
        first = guess_only.module_.model(batch["positions"], batch["missing"]).numpy()
    ridge, guess = [], []
    for j in range(J):
        others = [k for k in range(J) if k != j]
        X, Y = train[:, others].reshape(len(train), -1), train[:, j]
        Xm, Ym = X.mean(0), Y.mean(0)
        A = np.linalg.solve((X - Xm).T @ (X - Xm) + 1e-3 * len(X) * np.eye(X.shape[1]), (X - Xm).T @ (Y - Ym))
        for i in range(len(batch["clean"])):
            gap = batch["missing"][i, :, j].numpy()
            if not gap.any():
                continue
            clean = batch["clean"][i].numpy()
            local = pose_frame(clean)[gap]
            predicted = (local[:, others].reshape(len(local), -1) - Xm) @ A + Ym
            ridge += (100 * np.linalg.norm(predicted - local[:, j], axis=-1)).tolist()
            guess += (100 * np.linalg.norm(first[i][gap, j] - clean[gap, j], axis=-1)).tolist()
    print("| estimate of a missing joint | mean error | entries |\n|---|---:|---:|")
    print(f"| the network's first guess (cubic in time) | {np.mean(guess):.2f} | {len(guess)} |")
    print(f"| ridge on the other joints of the same frame (clean) | {np.mean(ridge):.2f} | {len(ridge)} |")


if __name__ == "__main__":
    main()
