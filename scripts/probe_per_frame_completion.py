"""Probe: how well can one frame's missing joints be guessed from its other joints — linear against learned?

Poses of HDM05 fold ``bd``'s training clips (other than the validation clips) and of its validation clips (training
performers only), every frame with all joints observed, in the frame's body frame (root-centred, hip line turned onto
the first horizontal axis: :meth:`~mocapkit.classical.pose_prior.PosePriorRefiner._to_pose_frame`). 3,000 validation
frames get ``k`` random non-root joints hidden (k = 1, 3, 6, 10); printed: RMS mm over the hidden joints of

- the full-covariance Gaussian conditional of the training poses (the best linear guess; what the pose prior uses);
- ``--variant plain``: a multi-layer perceptron (3 × 1024, no dropout) from the masked pose and the mask;
- ``--variant regularised``: the same network 2 × 512 with dropout 0.2, weight decay 1e-3, mirrored poses added;
- ``--variant residual``: the Gaussian conditional plus that regularised network's correction (its output starts at
  zero), the network reading the masked pose, the conditional and the mask.

(``regularised`` and ``residual`` fit the Gaussian on the training poses with their mirror images added.)
Results: bench/RESULTS.md §13 (the rule is restated there).

Usage (from the repository root; 2–3 min each on one core)::

    OMP_NUM_THREADS=1 python scripts/probe_per_frame_completion.py --variant residual
"""
import argparse
import time
from pathlib import Path

import numpy as np
import torch

from mocapkit.classical.pose_prior import PosePriorRefiner
from mocapkit.datasets.formats.layouts import mirror_joints
from mocapkit.datasets.mocap.datamodule import MocapRefinementDataModule

ROOT = Path(__file__).resolve().parents[1]


def rms_mm(guess: np.ndarray, truth: np.ndarray, hidden: np.ndarray) -> float:
    """RMS 3-D distance (mm) over the ``hidden [N, J]`` joints of ``guess`` and ``truth`` ``[N, J, 3]`` (metres)."""
    return float(1000 * np.sqrt((np.linalg.norm(guess - truth, axis=-1)[hidden] ** 2).mean()))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variant", choices=["plain", "regularised", "residual"], required=True)
    parser.add_argument("--fold", default="bd")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "hdm05_cuts11")
    args = parser.parse_args(argv)
    variant = args.variant
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    dm = MocapRefinementDataModule(dataset="hdm05", root=str(args.data), test_groups=[args.fold], window=240)
    pp = PosePriorRefiner().fit(dm.train_motions)

    def poses(ms):
        P = np.concatenate([m.positions[~m.missing.any(1)] for m in ms])
        return pp._to_pose_frame(P)[0].astype(np.float32)

    tr, va = poses(dm.train_motions), poses(dm.val_motions)
    J = tr.shape[1]
    print("train frames", len(tr), "validation frames", len(va), "joints", J)
    if variant != "plain":                                      # mirror images: lateral axis x in the body frame
        mirrored = tr[:, mirror_joints(dm.train_motions[0].joint_names)].copy()
        mirrored[..., 0] *= -1
        tr = np.concatenate([tr, mirrored])
    mu = tr.reshape(len(tr), -1).mean(0)
    C = np.cov(tr.reshape(len(tr), -1) - mu, rowvar=False) + 1e-6 * np.eye(3 * J)
    Ct, muv = torch.from_numpy(C).float(), torch.from_numpy(mu).float()
    muT = muv.view(J, 3)

    def gaussian(X, M):
        """Gaussian conditional of the hidden joints ``M [N, J]`` of ``X [N, J, 3]``, batched."""
        N = len(X)
        m = M.repeat_interleave(3, 1).float()
        o = 1 - m
        x = X.reshape(N, -1) - muv
        A = o.unsqueeze(2) * Ct * o.unsqueeze(1) + torch.diag_embed(m)       # C_oo, identity on hidden rows
        a = torch.linalg.solve(A, (x * o).unsqueeze(-1)).squeeze(-1)
        cond = (Ct @ a.unsqueeze(-1)).squeeze(-1)
        return (torch.where(m > 0, cond, x) + muv).view(N, J, 3)

    if variant == "plain":
        W, layers, dropout, decay, steps, batch = 1024, 3, 0.0, 1e-4, 6000, 512
    else:
        W, layers, dropout, decay, steps, batch = 512, 2, 0.2, 1e-3, 4000, 256
    inputs = (7 if variant == "residual" else 4) * J
    blocks = []
    for i in range(layers):
        blocks += [torch.nn.Linear(inputs if i == 0 else W, W), torch.nn.GELU()]
        if dropout:
            blocks.append(torch.nn.Dropout(dropout))
    net = torch.nn.Sequential(*blocks, torch.nn.Linear(W, 3 * J))
    if variant != "plain":
        torch.nn.init.zeros_(net[-1].weight)
        torch.nn.init.zeros_(net[-1].bias)
    opt = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 1e-3, total_steps=steps)
    T = torch.from_numpy(tr)

    def run(X, M):
        x = torch.where(M.unsqueeze(-1), muT, X) - muT
        if variant == "residual":
            g = gaussian(X, M)
            out = g + net(torch.cat([x.reshape(len(X), -1) * 3, (g - muT).reshape(len(X), -1) * 3, M.float()], 1)
                          ).view(len(X), J, 3) / 3
        else:
            out = net(torch.cat([x.reshape(len(X), -1) * 3, M.float()], 1)).view(len(X), J, 3) / 3 + muT
        return torch.where(M.unsqueeze(-1), out, X)

    started = time.time()
    for s in range(steps):
        X = T[torch.randint(len(T), (batch,))]
        k = torch.randint(1, 12, (batch, 1))
        r = torch.rand(batch, J)
        r[:, 0] = 2                                               # the root is never hidden
        M = r < (k.float() / J)
        loss = torch.linalg.vector_norm(run(X, M) - X, dim=-1)[M].mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if s % 1000 == 0:
            print(f"step {s} loss {1000 * loss.item():.1f} mm ({time.time() - started:.0f} s)", flush=True)
    net.eval()
    sub = va[rng.choice(len(va), 3000, replace=False)]
    for k in (1, 3, 6, 10):
        M = np.zeros((len(sub), J), bool)
        for i in range(len(sub)):
            M[i, rng.choice(np.arange(1, J), size=k, replace=False)] = True
        with torch.no_grad():
            g = gaussian(torch.from_numpy(sub), torch.from_numpy(M)).numpy()
            o = run(torch.from_numpy(sub), torch.from_numpy(M)).numpy()
        print(f"{variant} k={k}: RMS mm over the hidden joints: Gaussian conditional {rms_mm(g, sub, M):.1f}, "
              f"network {rms_mm(o, sub, M):.1f}", flush=True)


if __name__ == "__main__":
    main()
