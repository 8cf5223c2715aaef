"""Probe: does a refiner network trained on top of the pose prior's fill beat the pose prior on long gaps?

The learned refiners correct a cubic first guess and never learnt to correct it inside gaps
(``scripts/refiner_gap_diagnosis.py``); :class:`~mocapkit.classical.pose_prior.PosePriorRefiner` fills long gaps far
better. This probe trains the recipe's masked transformer (``experiment=refine_transformer``: the same network,
windows of 240 frames, batches of 16, 1,024 steps, AdamW 2e-3 with weight decay 1e-4 and a cosine schedule, the
same loss) with one change: its first guess at missing entries is the pose prior's fill of the corrupted window
(fitted on the fold's training clips other than the validation ones; the cubic guess where the prior leaves an
entry unfilled). Nothing in the package changes; the probe's forward pass is written out below.

Scored on the fold's validation clips (training performers only; whole clips in one pass, no window blending, no
short-gap spline; an observed sample is replaced where the network moves it more than 2 cm, as ``LearnedRefiner``): RMS 3-D error (mm) over the corrupted entries, beside the pose prior
alone and the recipe's run of the same fold through ``LearnedRefiner`` (its defaults).

Usage (from the repository root; ~15 min on one core)::

    OMP_NUM_THREADS=1 python scripts/probe_prior_first_guess.py --fold bd --out checkpoints/probe_prior
"""
from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from refiner_inference_settings import score_on_clips

from mocapkit.classical.pose_prior import PosePriorRefiner
from mocapkit.datasets.mocap.datamodule import MocapRefinementDataModule
from mocapkit.refinement.corruptions import training_corruption
from mocapkit.refinement.learned import LearnedRefiner

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = [("rdcrypt", 0.3), ("mxcrypt", 0.3), ("random_missing", 0.2), ("continuous_missing", 40),
             ("long_gaps", "20x100"), ("long_gaps", "5x2s")]


def prior_fill(prior: PosePriorRefiner, motion) -> np.ndarray:
    """The pose prior's positions for ``motion`` ``[T, J, 3]`` (NaN where it leaves an entry unfilled)."""
    return prior.refine(motion).positions


def forward(net, positions: torch.Tensor, missing: torch.Tensor, filled: torch.Tensor):
    """The network's ``_refine_cf`` with the first guess at missing entries taken from ``filled`` (normalised
    like the input) where it is finite: ``(refined [B, 3, T, J] normalised, stats)``."""
    observed = ~missing.bool()
    seen = observed.unsqueeze(1)
    clean = torch.where(observed.unsqueeze(-1), positions, 0.0).permute(0, 3, 1, 2)
    stats = net.normalizer.statistics_cf(clean, seen)
    x = seen.to(clean.dtype) * net.normalizer.forward_cf(clean, stats)
    cubic = net.first_guess_cf(x, observed)
    usable = torch.isfinite(filled).all(-1).unsqueeze(1) & ~seen                   # [B,1,T,J]
    from_prior = net.normalizer.forward_cf(torch.nan_to_num(filled).permute(0, 3, 1, 2), stats)
    guess = torch.where(usable, from_prior, cubic)
    return net.corrected(guess, observed), stats


class OnPrior:
    """The probe's network behind ``refine(motion) -> Motion``: the whole take in one pass; missing entries from
    the network, observed ones only where it moves them more than the recipe's ``repair_threshold`` (as
    ``LearnedRefiner``)."""

    def __init__(self, net, prior: PosePriorRefiner, recipe: LearnedRefiner):
        self.net, self.prior, self.threshold = net, prior, recipe.repair_threshold

    def refine(self, m):
        with torch.no_grad():
            refined, stats = forward(self.net, torch.from_numpy(np.nan_to_num(m.filled(0.0)))[None].float(),
                                     torch.from_numpy(m.missing)[None],
                                     torch.from_numpy(prior_fill(self.prior, m))[None].float())
            out = self.net.normalizer.inverse_cf(refined, stats).permute(0, 2, 3, 1)[0].numpy()
        moved = np.linalg.norm(out - m.filled(0.0), axis=-1) > self.threshold
        return replace(m, positions=np.where((m.missing | moved)[..., None], out, m.positions),
                       missing=np.zeros_like(m.missing))


def batch_of(motions, weights, prior, rng, window: int, size: int, corruption: dict) -> dict:
    items = []
    for _ in range(size):
        motion = motions[rng.choice(len(motions), p=weights)]
        start = int(rng.integers(motion.num_frames - window + 1))
        clean = replace(motion, positions=motion.positions[start:start + window],
                        missing=motion.missing[start:start + window], rotations=None)
        c = training_corruption(clean, rng, **corruption)
        items.append((np.nan_to_num(c.motion.filled(0.0)), c.motion.missing, clean.positions, c.corrupted,
                      prior_fill(prior, c.motion)))
    stack = lambda k, dtype: torch.from_numpy(np.stack([it[k] for it in items]).astype(dtype))
    return {"positions": stack(0, np.float32), "missing": stack(1, bool), "clean": stack(2, np.float32),
            "corrupted": stack(3, bool), "filled": stack(4, np.float32)}


def loss_of(module, batch: dict) -> torch.Tensor:
    """:meth:`MotionRefinementModule.losses` with the probe's forward pass."""
    net, hp = module.model, module.hparams
    refined, stats = forward(net, batch["positions"], batch["missing"], batch["filled"])
    refined = refined.permute(0, 2, 3, 1)
    target = net.normalizer(batch["clean"], stats)
    error = torch.linalg.vector_norm(refined - target, dim=-1)
    corrupted = batch["corrupted"].to(error.dtype)
    kept = (~batch["corrupted"] & ~batch["missing"]).to(error.dtype)
    bone = lambda x: torch.linalg.vector_norm(x[:, :, module._child] - x[:, :, module._parent], dim=-1)
    return ((error * corrupted).sum() / corrupted.sum().clamp_min(1)
            + hp.clean_weight * (error * kept).sum() / kept.sum().clamp_min(1)
            + hp.bone_weight * (bone(refined) - bone(target)).abs().mean()
            + hp.velocity_weight * torch.linalg.vector_norm(refined.diff(dim=1) - target.diff(dim=1), dim=-1).mean())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fold", default="bd")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    parser.add_argument("--recipe", type=Path, default=ROOT / "checkpoints" / "refine_transformer",
                        help="the folder with fold_<P>/best.ckpt of the recipe's runs (the reference row)")
    parser.add_argument("--steps", type=int, default=1024)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "checkpoints" / "probe_prior")
    args = parser.parse_args(argv)
    torch.manual_seed(args.seed)
    recipe = LearnedRefiner(checkpoint=str(args.recipe / f"fold_{args.fold}" / "best.ckpt")).fit()
    hp = recipe.module_.hparams
    window = int(hp.skeleton["window"])
    data = MocapRefinementDataModule(dataset="hdm05", root=str(args.data), test_groups=[args.fold], window=window)
    prior = PosePriorRefiner(short_gap_seconds=0).fit(data.train_motions)        # as it ran (before the hand-over)
    module = type(recipe.module_)(hp.model, hp.optimizer, data.label_spaces()["skeleton"], hp.scheduler,
                                  hp.clean_weight, hp.bone_weight, hp.velocity_weight)
    optimizer = torch.optim.AdamW(module.parameters(), lr=float(hp.optimizer["lr"]),
                                  weight_decay=float(hp.optimizer["weight_decay"]))
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: 0.5 * (1 + math.cos(math.pi * s / args.steps)))
    motions = [m for m in data.train_motions if m.num_frames >= window]
    spans = np.asarray([m.num_frames - window + 1 for m in motions], float)
    rng = np.random.default_rng(args.seed)
    module.train()
    for step in range(args.steps):
        batch = batch_of(motions, spans / spans.sum(), prior, rng, window, 16, data.corruption)
        loss = loss_of(module, batch)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(module.parameters(), 1.0)
        optimizer.step()
        schedule.step()
        if step % 64 == 0 or step == args.steps - 1:
            print(f"[probe] step {step + 1}/{args.steps} loss {loss.item():.4f}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.save(module.model.state_dict(), args.out / f"fold_{args.fold}_network.pt")
    module.eval()

    print(f"\n# fold {args.fold}: RMS mm over the corrupted entries of {len(data.val_motions)} validation clips of "
          f"{data.groups['train']}\n")
    print("| protocol | pose prior | recipe run (LearnedRefiner) | network on the pose prior (probe) |")
    print("|---|---:|---:|---:|")
    table = score_on_clips(data.val_motions, PROTOCOLS, [prior, recipe, OnPrior(module.model, prior, recipe)])
    for (protocol, level), row in zip(PROTOCOLS, table):
        print(f"| {protocol} {level} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    print("| **mean** | " + " | ".join(f"{v:.2f}" for v in table.mean(axis=0)) + " |")


if __name__ == "__main__":
    main()
