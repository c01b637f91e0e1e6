"""Rendering whole images from the model: object views (normals, diffuse, specular, combined, mask, depth)
and environment views from virtual cameras anywhere (RGB + z-depth). Chunked so memory stays bounded."""

from __future__ import annotations

import torch

from .model import OrcaModel
from .rays import camera_rays, pixel_centers


def _rays(K: torch.Tensor, c2w: torch.Tensor, height: int, width: int):
    uv = pixel_centers(height, width, dtype=K.dtype, device=K.device).reshape(-1, 2)
    return camera_rays(uv, K, c2w)


def render_object_image(
    model: OrcaModel, K: torch.Tensor, c2w: torch.Tensor, height: int, width: int, chunk: int = 4096
) -> dict[str, torch.Tensor]:
    """Render the object as seen by a pinhole camera.

    Args:
        K: ``(3, 3)``; c2w: ``(4, 4)``.
    Returns:
        ``rgb``, ``diffuse``, ``specular``, ``normal`` ``(H, W, 3)``; ``opacity``, ``depth`` (z-depth) ``(H, W)``.
    """
    origins, dirs, radii = _rays(K, c2w, height, width)
    axis = c2w[:3, 2]
    parts: dict[str, list[torch.Tensor]] = {k: [] for k in ("rgb", "diffuse", "specular", "normal", "opacity", "depth")}
    for i in range(0, origins.shape[0], chunk):
        sl = slice(i, i + chunk)
        out = model(origins[sl], dirs[sl], radii[sl])
        zscale = (dirs[sl] * axis).sum(-1)
        for key in ("rgb", "diffuse", "specular", "normal", "opacity"):
            parts[key].append(getattr(out, key).detach())
        parts["depth"].append((out.depth * zscale).detach())
    return {k: torch.cat(v).reshape(height, width, -1).squeeze(-1) for k, v in parts.items()}


@torch.no_grad()
def render_environment_image(
    model: OrcaModel, K: torch.Tensor, c2w: torch.Tensor, height: int, width: int, chunk: int = 8192
) -> dict[str, torch.Tensor]:
    """Render the environment field alone (object absent) from any camera: ``rgb`` ``(H, W, 3)`` and
    z-depth ``depth`` ``(H, W)`` along the camera's optical axis."""
    origins, dirs, radii = _rays(K, c2w, height, width)
    axis = c2w[:3, 2]
    rgbs, depths = [], []
    for i in range(0, origins.shape[0], chunk):
        sl = slice(i, i + chunk)
        rgb, depth = model.environment(origins[sl], dirs[sl], radii[sl])
        rgbs.append(rgb)
        depths.append(depth * (dirs[sl] * axis).sum(-1))
    return {"rgb": torch.cat(rgbs).reshape(height, width, 3), "depth": torch.cat(depths).reshape(height, width)}
