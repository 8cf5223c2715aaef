"""Ray casting of capsule bodies into a pinhole depth camera, in PyTorch (so it runs where the tensors are: CPU or
GPU). ``mocapkit synth depth`` renders its depth images with it, and the depth tracker renders its body model with
it at every Gauss–Newton iteration.

A capsule is a segment ``a → b`` swept by a sphere of radius ``r``: limbs, trunk and head of a body. Every pixel's
ray from the camera centre is intersected with every capsule in closed form (I. Quílez's ray–capsule formula: the
infinite cylinder first, then the end sphere on the side where the cylinder hit falls outside the segment); the
nearest hit wins. Camera coordinates: metres, x right, y down, z forward (:mod:`mocapkit.datasets.formats.depth_images`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mocapkit.datasets.formats.depth_images import CameraIntrinsics


@dataclass
class CapsuleHits:
    """What each ray of a pixel grid hits.

    The grid is pixels ``(u[j], v[i])``: every ``stride``-th pixel of the image inside a bounding box.

    Attributes:
        u: long ``[w]`` pixel columns of the grid.
        v: long ``[h]`` pixel rows of the grid.
        depth: ``[h, w]`` z of the nearest hit (metres), 0 where the ray hits nothing.
        capsule: long ``[h, w]`` index of the capsule hit, −1 where none.
        points: ``[h, w, 3]`` camera coordinates of the hit (0 where none).
        normals: ``[h, w, 3]`` outward unit surface normal at the hit (0 where none).
    """

    u: torch.Tensor
    v: torch.Tensor
    depth: torch.Tensor
    capsule: torch.Tensor
    points: torch.Tensor
    normals: torch.Tensor

    @property
    def hit(self) -> torch.Tensor:
        """bool ``[h, w]``: the ray hits a capsule."""
        return self.capsule >= 0

    def full_image(self, intrinsics: CameraIntrinsics, value: torch.Tensor | None = None, fill: float = 0.0):
        """``value`` (default: ``depth``), ``[h, w, ...]`` on the grid, placed into a full ``[H, W, ...]`` image
        (only for ``stride == 1`` grids); pixels outside the grid get ``fill``."""
        value = self.depth if value is None else value
        image = value.new_full((intrinsics.height, intrinsics.width, *value.shape[2:]), fill)
        image[self.v[0] : self.v[-1] + 1, self.u[0] : self.u[-1] + 1] = value
        return image


def capsule_box(
    a: torch.Tensor, b: torch.Tensor, radius: torch.Tensor, intrinsics: CameraIntrinsics, margin: int = 2
) -> tuple[int, int, int, int] | None:
    """Pixel box ``(u0, v0, u1, v1)`` (end exclusive) that holds the image of every capsule in front of the camera,
    clipped to the image, or None when nothing is in view. Each capsule is bounded by the spheres at its ends."""
    ends = torch.cat([a, b]).detach()
    r = torch.cat([radius, radius]).detach()
    front = ends[:, 2] > 1e-3
    if not bool(front.any()):
        return None
    ends, r = ends[front], r[front]
    z = ends[:, 2].clamp_min(1e-3)
    u = intrinsics.fx * ends[:, 0] / z + intrinsics.cx
    v = intrinsics.fy * ends[:, 1] / z + intrinsics.cy
    ru, rv = intrinsics.fx * r / z, intrinsics.fy * r / z
    u0 = max(int(torch.floor((u - ru).min())) - margin, 0)
    v0 = max(int(torch.floor((v - rv).min())) - margin, 0)
    u1 = min(int(torch.ceil((u + ru).max())) + margin + 1, intrinsics.width)
    v1 = min(int(torch.ceil((v + rv).max())) + margin + 1, intrinsics.height)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, v0, u1, v1


def raycast_capsules(
    a: torch.Tensor,
    b: torch.Tensor,
    radius: torch.Tensor,
    intrinsics: CameraIntrinsics,
    stride: int = 1,
    box: tuple[int, int, int, int] | None = None,
) -> CapsuleHits:
    """Nearest capsule hit of every ``stride``-th pixel's ray.

    Args:
        a, b: ``[C, 3]`` capsule end points in camera coordinates (metres).
        radius: ``[C]`` capsule radii (metres).
        intrinsics: the camera.
        stride: pixel step of the grid (1: every pixel; Lou 2012 sub-samples the rendered points by 4).
        box: ``(u0, v0, u1, v1)`` pixel box to cast (end exclusive); default :func:`capsule_box`, the capsules'
            image. The grid starts at the first multiple of ``stride`` inside the box, so grids of one stride line up.

    Returns:
        :class:`CapsuleHits` on the grid, in ``a``'s dtype and device.
    """
    if a.ndim != 2 or a.shape[-1] != 3 or b.shape != a.shape or radius.shape != a.shape[:1]:
        raise ValueError(
            f"capsules must be a, b [C, 3] and radius [C], got {list(a.shape)}, {list(b.shape)}, {list(radius.shape)}"
        )
    if stride < 1:
        raise ValueError(f"stride must be ≥ 1, got {stride}")
    box = box if box is not None else capsule_box(a, b, radius, intrinsics)
    device, dtype = a.device, a.dtype
    if box is None:  # nothing in view: a one-pixel grid that hits nothing
        box = (0, 0, 1, 1)
    u0, v0, u1, v1 = box
    u = torch.arange(-(-u0 // stride) * stride, u1, stride, device=device)
    v = torch.arange(-(-v0 // stride) * stride, v1, stride, device=device)
    if len(u) == 0 or len(v) == 0:
        u, v = torch.tensor([u0], device=device), torch.tensor([v0], device=device)
    rays = torch.stack(
        torch.broadcast_tensors(
            ((u.to(dtype) - intrinsics.cx) / intrinsics.fx)[None, :],
            ((v.to(dtype) - intrinsics.cy) / intrinsics.fy)[:, None],
            torch.ones((), dtype=dtype, device=device),
        ),
        dim=-1,
    )  # [h, w, 3], z = 1
    rd = rays / rays.norm(dim=-1, keepdim=True)
    t = _ray_capsule_distance(rd.reshape(-1, 3), a, b, radius)  # [P, C], inf = miss
    nearest, capsule = t.min(dim=1)
    hit = torch.isfinite(nearest)
    capsule = torch.where(hit, capsule, torch.full_like(capsule, -1))
    dist = torch.where(hit, nearest, torch.zeros_like(nearest))
    points = rd.reshape(-1, 3) * dist[:, None]
    normals = _capsule_normals(points, a, b, radius, capsule.clamp_min(0)) * hit[:, None]
    h, w = len(v), len(u)
    return CapsuleHits(
        u=u,
        v=v,
        depth=points[:, 2].reshape(h, w),
        capsule=capsule.reshape(h, w),
        points=points.reshape(h, w, 3),
        normals=normals.reshape(h, w, 3),
    )


def _ray_capsule_distance(rd: torch.Tensor, a: torch.Tensor, b: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """Distance along unit rays ``rd`` ``[P, 3]`` from the origin to each capsule ``[C]``: ``[P, C]``, inf on a miss
    (or when the camera is inside the capsule)."""
    ba = (b - a)[None]  # [1, C, 3]
    oa = (-a)[None]
    rd = rd[:, None]  # [P, 1, 3]
    baba = (ba * ba).sum(-1)
    bard = (ba * rd).sum(-1)
    baoa = (ba * oa).sum(-1)
    rdoa = (rd * oa).sum(-1)
    oaoa = (oa * oa).sum(-1)
    r2 = (radius * radius)[None]
    qa = baba - bard * bard
    qb = baba * rdoa - baoa * bard
    qc = baba * oaoa - baoa * baoa - r2 * baba
    disc = qb * qb - qa * qc
    inf = torch.full_like(disc, float("inf"))
    t_body = (-qb - disc.clamp_min(0).sqrt()) / qa.clamp_min(1e-12)
    y = baoa + t_body * bard
    body = (disc >= 0) & (qa > 1e-12) & (y > 0) & (y < baba)
    # an end sphere: the one on the side of the segment where the cylinder hit falls
    centre = torch.where(
        (y <= 0)[..., None],
        a[None].expand_as(torch.broadcast_to(ba, (*y.shape, 3))),
        b[None].expand_as(torch.broadcast_to(ba, (*y.shape, 3))),
    )
    oc = -centre
    sb = (rd * oc).sum(-1)
    sc = (oc * oc).sum(-1) - r2
    sh = sb * sb - sc
    t_cap = -sb - sh.clamp_min(0).sqrt()
    cap = (disc >= 0) & ~body & (sh > 0)
    t = torch.where(body, t_body, torch.where(cap, t_cap, inf))
    return torch.where(t > 1e-6, t, inf)


def _capsule_normals(points, a, b, radius, capsule) -> torch.Tensor:
    """Outward unit normals at ``points`` ``[P, 3]`` on capsules ``capsule`` ``[P]``."""
    pa, pb = a[capsule], b[capsule]
    ba = pb - pa
    s = (((points - pa) * ba).sum(-1) / (ba * ba).sum(-1).clamp_min(1e-12)).clamp(0, 1)
    axis_point = pa + s[:, None] * ba
    n = points - axis_point
    return n / n.norm(dim=-1, keepdim=True).clamp_min(1e-9)


__all__ = ["CapsuleHits", "capsule_box", "raycast_capsules"]
