"""Starting the SDF from the photos' silhouettes: the visual hull of the masks, as a signed distance, fitted by
the SDF field before training.

A sphere start has none of an object's holes, handles or necks: training must carve a torus's hole and a mug's
handle out of the sphere through the photometric and mask terms, and on shapes far from a sphere it does not
(docs/method.md, "Shapes beyond the sphere"). The visual hull has them wherever some photo sees through.
"""

from __future__ import annotations

import torch
from torch.nn import functional as F

from .fields import SDFField


def grid_points(resolution: int, bound: float) -> torch.Tensor:
    """``(R, R, R, 3)`` voxel centres of the ``resolution``^3 grid over ``[-bound, bound]^3`` (index order x, y, z)."""
    ax = (torch.arange(resolution, dtype=torch.float32) + 0.5) / resolution * 2 * bound - bound
    return torch.stack(torch.meshgrid(ax, ax, ax, indexing="ij"), dim=-1)


def visual_hull(masks: torch.Tensor, K: torch.Tensor, c2w: torch.Tensor, resolution: int, bound: float,
                carve_share: float, carve_min: int = 2, floor: tuple[torch.Tensor, float] | None = None
                ) -> torch.Tensor:
    """``(R, R, R)`` bool: the voxels of the unit ball inside the masks' visual hull.

    A voxel is cut when the photos that see it (in front of the camera, inside the frame) off the object's
    mask are at least ``carve_share`` of those that see it, and at least ``carve_min``: a few wrong masks (a
    prop in front of the object, a rim missed) do not cut the object. A voxel no photo sees is cut too.

    An object standing on a floor hides the space under it from every photo: each ray through it meets the
    object first, so its mask keeps it. ``floor`` cuts that space: voxels with ``normal . x < offset``.

    Args:
        masks: ``(N, H, W)`` bool object masks; K: ``(N, 3, 3)``; c2w: ``(N, 4, 4)`` camera-to-world (OpenCV).
        resolution: voxels per side of the grid over ``[-bound, bound]^3``.
        floor: ``((3,) unit normal pointing up, offset)``, or None.
    """
    n, h, w = masks.shape
    points = grid_points(resolution, bound).reshape(-1, 3).to(K.device)
    off = torch.zeros(points.shape[0], dtype=torch.int32, device=K.device)
    seen = torch.zeros_like(off)
    for i in range(n):
        rot, centre = c2w[i, :3, :3], c2w[i, :3, 3]
        cam = (points - centre) @ rot  # world -> camera: R^T (x - t)
        pix = cam @ K[i].T
        front = cam[:, 2] > 1e-6
        uv = pix[:, :2] / pix[:, 2:].clamp_min(1e-6)
        col, row = uv[:, 0].floor().long(), uv[:, 1].floor().long()
        inside = front & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        on_object = torch.zeros_like(inside)
        on_object[inside] = masks[i, row[inside], col[inside]]
        seen += inside.int()
        off += (inside & ~on_object).int()
    needed = (carve_share * seen).ceil().clamp_min(carve_min)
    hull = (seen > 0) & (off < needed) & (points.norm(dim=-1) < 1.0)
    if floor is not None:
        normal, offset = floor
        hull &= points @ normal.to(points) >= offset
    return hull.reshape((resolution,) * 3)


def signed_distance(occupancy: torch.Tensor, bound: float, smoothing: float) -> torch.Tensor:
    """``(R, R, R)`` float32 signed distance (negative inside) to the boundary of an ``(R, R, R)`` bool
    occupancy over ``[-bound, bound]^3``, Gaussian-smoothed by ``smoothing`` voxels (a carved hull's facets and
    steps would otherwise become the SDF's bumps). Empty or full occupancy has no boundary: ValueError."""
    import numpy as np
    from scipy.ndimage import distance_transform_edt, gaussian_filter

    occ = occupancy.cpu().numpy()
    if not occ.any() or occ.all():
        raise ValueError("the visual hull is empty or fills the grid: it has no surface")
    voxel = 2 * bound / occ.shape[0]
    # distances between voxel centres; the surface lies half a voxel from the centres on either side of it
    outside = distance_transform_edt(~occ) - 0.5
    inside = distance_transform_edt(occ) - 0.5
    sdf = np.where(occ, -inside, outside) * voxel
    if smoothing > 0:
        sdf = gaussian_filter(sdf, smoothing, mode="nearest")
    return torch.from_numpy(sdf.astype(np.float32)).to(occupancy.device)


def sample_grid(grid: torch.Tensor, x: torch.Tensor, bound: float) -> torch.Tensor:
    """Trilinear lookup of an ``(R, R, R)`` grid over ``[-bound, bound]^3`` (voxel-centred, index order x, y,
    z) at ``(N, 3)`` points -> ``(N,)``; points outside take the border's values."""
    # grid_sample reads (D, H, W) = (z, y, x) and coordinates (x, y, z) in [-1, 1] over the voxels' outer edges
    volume = grid.permute(2, 1, 0)[None, None]
    coords = (x / bound).clamp(-1, 1)[None, :, None, None, :]
    return F.grid_sample(volume, coords, mode="bilinear", padding_mode="border", align_corners=False).reshape(-1)


def fit_sdf(field: SDFField, target: torch.Tensor, bound: float, steps: int, batch: int, lr: float,
            generator: torch.Generator) -> float:
    """Fit ``field``'s SDF to the ``(R, R, R)`` signed-distance grid ``target`` over ``[-bound, bound]^3`` by
    L1 on ``batch`` points a step, half drawn in the grid's cube and half within two voxels of the surface
    (where the distance matters), for ``steps`` Adam steps at ``lr``. Returns the last step's loss."""
    res = target.shape[0]
    voxel = 2 * bound / res
    cells = grid_points(res, bound).reshape(-1, 3).to(target.device)
    near = cells[target.reshape(-1).abs() < 2 * voxel]
    if near.shape[0] == 0:
        raise ValueError("the signed-distance grid has no surface to fit")
    optimizer = torch.optim.Adam(field.parameters(), lr=lr, eps=1e-15)
    loss = torch.zeros(())
    for _ in range(steps):
        uniform = (torch.rand(batch // 2, 3, generator=generator) * 2 - 1) * bound
        pick = torch.randint(0, near.shape[0], (batch - batch // 2,), generator=generator)
        jitter = (torch.rand(pick.shape[0], 3, generator=generator) - 0.5) * voxel
        x = torch.cat([uniform.to(target.device), near[pick.to(target.device)] + jitter.to(target.device)])
        loss = (field.sdf(x) - sample_grid(target, x, bound)).abs().mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return float(loss.detach())
