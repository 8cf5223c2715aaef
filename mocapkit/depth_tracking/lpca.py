"""The online local-PCA motion prior of Lou 2012 §3.2.6 (digest §2.7): around the current pose, the K nearest poses
of a mocap database and their w successors span a local linear subspace; the prior energy is a pose's distance to
it.

Database poses are the tracker's 28 joint DOF (no root, :mod:`mocapkit.depth_tracking.body_model`), fitted to the
training performers' mocap by inverse kinematics. Where the thesis is silent (digest §4 item 14): the neighbour
search is Euclidean on the 28 joint DOF (radians, the space the prior lives in), and the successors are frames
``i+1 .. i+w`` of the neighbour's own take (fewer where the take ends).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from mocapkit.depth_tracking.body_model import NUM_DOF, ROOT_DOF


@dataclass
class LocalSubspace:
    """The prior of one frame: ``(U_e U_eᵀ − Ĩ)`` as ``projector`` ``[34, 34]`` and the mean pose ``mean`` ``[34]``
    (root entries 0), so ``E_prior(q) = ‖projector (q − mean)‖²``; ``dims`` = e, ``neighbours`` = N."""

    projector: torch.Tensor
    mean: torch.Tensor
    dims: int
    neighbours: int

    def normal_equations(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(A_prior, b_prior)`` at the current iterate ``q`` (eq. 3.13): ``JᵀJ`` and ``Jᵀ J (q̄ − q)``."""
        jq = self.projector
        return jq.T @ jq, jq.T @ (jq @ (self.mean - q))


class LocalPCAPrior:
    """K nearest database poses and their successors → a local PCA subspace (eqs. 3.10–3.13).

    Args:
        poses: float ``[N, 34]`` database poses (the root entries are ignored).
        take: int ``[N]`` the take each pose belongs to (successors stay inside a take; poses are in frame order).
        neighbours: K (50 in the thesis).
        successors: w (3).
        energy: share of the variance the kept components explain (0.95).
    """

    def __init__(
        self,
        poses: np.ndarray,
        take: np.ndarray,
        neighbours: int = 50,
        successors: int = 3,
        energy: float = 0.95,
        device=None,
    ):
        poses = np.asarray(poses, dtype=np.float64)
        take = np.asarray(take)
        if poses.ndim != 2 or poses.shape[1] != NUM_DOF or len(poses) == 0 or take.shape != poses.shape[:1]:
            raise ValueError(
                f"the prior database must be [N, {NUM_DOF}] poses with a take per pose, got "
                f"{list(poses.shape)} and {list(take.shape)}"
            )
        self.neighbours, self.successors, self.energy = int(neighbours), int(successors), float(energy)
        self.joint_dof = torch.as_tensor(poses[:, ROOT_DOF:], dtype=torch.float64, device=device)
        # index of each pose's s-th successor in its take, −1 past the take's end
        n = len(poses)
        index = np.arange(n)
        self.next_index = np.full((n, self.successors), -1)
        for s in range(1, self.successors + 1):
            ok = index + s < n
            ok[ok] &= take[index[ok] + s] == take[index[ok]]
            self.next_index[ok, s - 1] = index[ok] + s
        self.device = device

    def __len__(self) -> int:
        return len(self.joint_dof)

    def subspace(self, q: torch.Tensor) -> LocalSubspace:
        """The local subspace around pose ``q`` ``[34]`` (the previous frame's estimate)."""
        current = q[ROOT_DOF:].to(self.joint_dof)
        k = min(self.neighbours, len(self.joint_dof))
        distance = ((self.joint_dof - current) ** 2).sum(dim=1)
        nearest = torch.topk(distance, k, largest=False).indices.cpu().numpy()
        rows = self.next_index[nearest].reshape(-1)
        rows = rows[rows >= 0]
        if len(rows) < 2:  # the neighbours all end their takes: use the neighbours themselves
            rows = nearest
        data = self.joint_dof[torch.as_tensor(rows, device=self.joint_dof.device)]  # [N, 28]
        mean = data.mean(dim=0)
        centred = data - mean
        cov = centred.T @ centred / max(len(data) - 1, 1)
        values, vectors = torch.linalg.eigh(cov)  # ascending
        values, vectors = values.flip(0).clamp_min(0), vectors.flip(1)
        total = float(values.sum())
        if total <= 0:
            dims = 0
        else:
            share = torch.cumsum(values, 0) / total
            dims = int(torch.searchsorted(share, torch.tensor(self.energy, dtype=share.dtype, device=share.device)))
            dims = min(dims + 1, len(values))
        basis = torch.zeros(NUM_DOF, dims, dtype=torch.float64, device=q.device)
        basis[ROOT_DOF:] = vectors[:, :dims].to(q.device)
        identity = torch.eye(NUM_DOF, dtype=torch.float64, device=q.device)
        identity[:ROOT_DOF, :ROOT_DOF] = 0
        full_mean = torch.zeros(NUM_DOF, dtype=torch.float64, device=q.device)
        full_mean[ROOT_DOF:] = mean.to(q.device)
        return LocalSubspace(basis @ basis.T - identity, full_mean, dims, len(rows))


__all__ = ["LocalPCAPrior", "LocalSubspace"]
