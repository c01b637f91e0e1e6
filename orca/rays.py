"""Camera rays: pinhole cameras (OpenCV convention, camera-to-world) to per-pixel cones.

Pixel coordinates follow COLMAP: (0, 0) is the top-left corner of the image, so the centre of pixel
(row i, column j) is (j + 0.5, i + 0.5).
"""

from __future__ import annotations

import math

import torch

# mip-NeRF: a pixel's footprint as a cone whose radius at unit distance is the pixel width × 2/√12
# (the disc with the same variance as the square pixel).
PIXEL_RADIUS_FACTOR = 2.0 / math.sqrt(12.0)


def pixel_centers(height: int, width: int, dtype: torch.dtype | None = None, device=None) -> torch.Tensor:
    """``(H, W, 2)`` pixel centres ``(u, v)`` in COLMAP's convention."""
    v, u = torch.meshgrid(
        torch.arange(height, dtype=dtype, device=device) + 0.5,
        torch.arange(width, dtype=dtype, device=device) + 0.5,
        indexing="ij",
    )
    return torch.stack([u, v], dim=-1)


def camera_rays(
    uv: torch.Tensor, K: torch.Tensor, c2w: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rays through image points.

    Args:
        uv: ``(N, 2)`` image points (pixels); K: ``(3, 3)`` or ``(N, 3, 3)``; c2w: ``(4, 4)`` or ``(N, 4, 4)``.
    Returns:
        origins ``(N, 3)``, unit directions ``(N, 3)``, cone radii ``(N,)`` per unit distance along the ray.
    """
    K = K.expand(uv.shape[0], 3, 3) if K.dim() == 2 else K
    c2w = c2w.expand(uv.shape[0], 4, 4) if c2w.dim() == 2 else c2w
    fx, fy, cx, cy = K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]
    x = (uv[:, 0] - cx) / fx
    y = (uv[:, 1] - cy) / fy
    d_cam = torch.stack([x, y, torch.ones_like(x)], dim=-1)
    norm = d_cam.norm(dim=-1)
    dirs = torch.einsum("nij,nj->ni", c2w[:, :3, :3], d_cam) / norm[:, None]
    origins = c2w[:, :3, 3]
    # a pixel subtends 1/f radians at the optical axis and 1/(f |d_cam|) × cos-foreshortening off it;
    # mip-NeRF measures the radius per unit distance along the normalized ray
    pixel = 1.0 / torch.sqrt(fx * fy)
    radii = PIXEL_RADIUS_FACTOR * pixel / norm
    return origins, dirs, radii
