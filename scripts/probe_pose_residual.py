"""Probe: the pose prior's gap fill corrected frame by frame by a small learned network.

:class:`~mocapkit.classical.pose_prior.PosePriorRefiner` fills a gap by fusing a cubic guess with a Gaussian (PPCA)
model of poses; a Gaussian conditional is the best *linear* guess of a missing joint from the others. This probe
trains a multi-layer perceptron to correct the prior's fill at missing entries, one frame at a time, from

- the filled pose in the frame's own body frame (root-centred, hip line turned onto the first horizontal axis;
  :meth:`PosePriorRefiner._to_pose_frame`), metres;
- the missing mask of the frame (1 = the entry was filled);
- every joint's distance to its nearest observed sample, seconds (capped at ``CAP_S``; the cap where the joint is
  never observed): next to a sample the fill is the cubic guess and needs nothing, far from one it is the prior's.

The network's output layer starts at zero (an untrained probe *is* the pose prior); its correction is applied to
missing entries only (observed samples come back untouched, as from the prior). Training frames come from windows of
the fold's training clips other than the validation clips (mirrored left-right with probability 0.5,
:meth:`~mocapkit.datasets.formats.motion.Motion.mirrored`), corrupted by the gap protocols of the learned refiners'
training mixture (:func:`~mocapkit.refinement.corruptions.training_corruption`, ``whole_joint_rate`` as the recipe)
and filled by the prior; the loss is the mean 3-D distance at missing entries.

Scored on the fold's validation clips (training performers only; :func:`score_on_clips`, RMS mm over the
corrupted entries) beside the prior alone. Rule and result: bench/RESULTS.md §13.

Usage (from the repository root; a few minutes on one core)::

    OMP_NUM_THREADS=1 python scripts/probe_pose_residual.py --fold bd [--min-distance 12]
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from refiner_inference_settings import score_on_clips
from torch import nn

from mocapkit.classical.pose_prior import PosePriorRefiner, nearest_sample_distance
from mocapkit.datasets.formats.motion import turn_about_up
from mocapkit.datasets.mocap.datamodule import MocapRefinementDataModule
from mocapkit.refinement.corruptions import training_corruption

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = [("rdcrypt", 0.3), ("mxcrypt", 0.3), ("random_missing", 0.2), ("continuous_missing", 40),
             ("long_gaps", "20x100"), ("long_gaps", "5x2s")]
GAP_PROTOCOLS = {"rdloss": 1, "random_missing": 1, "continuous_missing": 1, "long_gaps": 1}
CAP_S = 2.0            # distances to the nearest sample are capped here (seconds)
POSE_SCALE = 3.0       # body-frame metres × 3: a body spans about ±3 network units


def frame_inputs(prior: PosePriorRefiner, filled: np.ndarray, missing: np.ndarray, min_distance: int = 0):
    """Per-frame inputs of the network for a filled take ``[T, J, 3]`` (finite) and its mask ``[T, J]``:
    ``(inputs [T, 5J] float32, body-frame pose [T, J, 3], root [T, 3], cos [T], sin [T], corrected [T, J])`` —
    ``corrected``: the missing entries at least ``min_distance`` frames from their joint's nearest sample."""
    local, root, cos, sin = prior._to_pose_frame(filled)
    frames = nearest_sample_distance(~missing)
    distance = np.minimum(frames / prior.fps_, CAP_S)
    T = len(filled)
    inputs = np.concatenate([POSE_SCALE * local.reshape(T, -1), missing.astype(np.float64), distance], axis=1)
    return inputs.astype(np.float32), local, root, cos, sin, missing & (frames >= min_distance)


class Residual(nn.Module):
    """``[N, 5J]`` → ``[N, J, 3]`` correction in metres (body frame)."""

    def __init__(self, joints: int, width: int = 512, dropout: float = 0.2):
        super().__init__()
        self.joints = joints
        self.net = nn.Sequential(nn.Linear(5 * joints, width), nn.GELU(), nn.Dropout(dropout),
                                 nn.Linear(width, width), nn.GELU(), nn.Dropout(dropout), nn.Linear(width, 3 * joints))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.net(inputs).view(len(inputs), self.joints, 3) / POSE_SCALE


class PriorWithResidual:
    """``refine(motion) -> Motion``: the prior's fill, its missing entries corrected by the network."""

    def __init__(self, prior: PosePriorRefiner, network: Residual, min_distance: int = 0):
        self.prior, self.network, self.min_distance = prior, network.eval(), min_distance

    def refine(self, motion):
        done = self.prior.refine(motion)
        filled = done.positions
        usable = np.isfinite(filled).all(axis=(1, 2))                  # frames the prior filled completely
        if not usable.any():
            return done
        # distances from the whole take's mask, then the usable frames
        inputs, local, root, cos, sin, corrected = (a[usable] for a in frame_inputs(
            self.prior, np.where(usable[:, None, None], filled, 0.0), motion.missing, self.min_distance))
        with torch.no_grad():
            correction = self.network(torch.from_numpy(inputs)).numpy().astype(np.float64)
        local = local + corrected[..., None] * correction
        positions = filled.copy()
        positions[usable] = turn_about_up(local, cos, sin, self.prior.up_axis_, inverse=True) + root[:, None]
        return replace(done, positions=positions.astype(filled.dtype))


def training_frames(prior, motions, windows: int, length: int, rng, whole_joint_rate: float, min_distance: int = 0):
    """Inputs ``[N, 5J]``, targets (clean poses in the fill's body frames) ``[N, J, 3]``, fills ``[N, J, 3]`` and
    the entries to correct ``[N, J]`` (:func:`frame_inputs`) of the frames with one, from ``windows`` corrupted
    training windows."""
    spans = np.asarray([m.num_frames - length + 1 for m in motions], float)
    parts = {"inputs": [], "target": [], "local": [], "missing": []}
    for w in range(windows):
        motion = motions[rng.choice(len(motions), p=spans / spans.sum())]
        start = int(rng.integers(motion.num_frames - length + 1))
        clean = replace(motion, positions=motion.positions[start:start + length],
                        missing=motion.missing[start:start + length], rotations=None)
        if rng.random() < 0.5:
            clean = clean.mirrored()
        corrupted = training_corruption(clean, rng, whole_joint_rate=whole_joint_rate, weights=GAP_PROTOCOLS).motion
        filled = prior.refine(corrupted).positions
        usable = np.isfinite(filled).all(axis=(1, 2))
        # distances from the whole window's mask (round 1 computed them on the kept frames only: RESULTS §13)
        inputs, local, root, cos, sin, corrected = frame_inputs(
            prior, np.where(usable[:, None, None], filled, 0.0), corrupted.missing, min_distance)
        some = usable & ~clean.missing.any(axis=1) & corrected.any(axis=1)
        if not some.any():
            continue
        target = turn_about_up(clean.positions[some] - root[some, None], cos[some], sin[some], prior.up_axis_)
        for key, value in (("inputs", inputs[some]), ("target", target), ("local", local[some]),
                           ("missing", corrected[some])):
            parts[key].append(value)
        if (w + 1) % 250 == 0:
            print(f"[probe] {w + 1}/{windows} training windows filled", flush=True)
    return {k: torch.from_numpy(np.concatenate(v).astype(np.float32 if k != "missing" else bool))
            for k, v in parts.items()}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fold", default="bd")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    parser.add_argument("--windows", type=int, default=1000, help="corrupted training windows of 240 frames")
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--min-distance", type=int, default=0,
                        help="frames: only missing entries at least this far from their joint's nearest sample are "
                             "trained on and corrected (round 1: 0, round 2: 12)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "checkpoints" / "probe_pose_residual")
    args = parser.parse_args(argv)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    data = MocapRefinementDataModule(dataset="hdm05", root=str(args.data), test_groups=[args.fold], window=240)
    prior = PosePriorRefiner(short_gap_seconds=0).fit(data.train_motions)        # as it ran (before the hand-over)
    motions = [m for m in data.train_motions if m.num_frames >= 240]
    started = time.time()
    frames = training_frames(prior, motions, args.windows, 240, rng, data.corruption.get("whole_joint_rate", 0.15),
                             args.min_distance)
    n, J = frames["missing"].shape
    print(f"[probe] {n} training frames with an entry to correct ({time.time() - started:.0f} s)", flush=True)
    network = Residual(J)
    optimizer = torch.optim.AdamW(network.parameters(), lr=1e-3, weight_decay=1e-3)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimizer, 1e-3, total_steps=args.steps)
    network.train()
    for step in range(args.steps):
        idx = torch.randint(n, (256,))
        missing = frames["missing"][idx]
        out = frames["local"][idx] + missing.unsqueeze(-1) * network(frames["inputs"][idx])
        loss = torch.linalg.vector_norm(out - frames["target"][idx], dim=-1)[missing].mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()
        if step % 500 == 0 or step == args.steps - 1:
            print(f"[probe] step {step + 1}/{args.steps} loss {1000 * loss.item():.2f} mm", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.save(network.state_dict(), args.out / f"fold_{args.fold}_residual_min{args.min_distance}.pt")
    print(f"\n# fold {args.fold}: RMS mm over the corrupted entries of {len(data.val_motions)} validation clips of "
          f"{data.groups['train']} ({time.time() - started:.0f} s in all)\n")
    print("| protocol | pose prior | pose prior + learned residual (probe) |")
    print("|---|---:|---:|")
    table = score_on_clips(data.val_motions, PROTOCOLS, [prior, PriorWithResidual(prior, network, args.min_distance)])
    for (protocol, level), row in zip(PROTOCOLS, table):
        print(f"| {protocol} {level} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    print("| **mean** | " + " | ".join(f"{v:.2f}" for v in table.mean(axis=0)) + " |")


if __name__ == "__main__":
    main()
