"""Rendering whole images from the model: object views (normals, diffuse, specular, combined, opacity, depth),
environment views from virtual cameras anywhere (RGB + z-depth), and the object over its environment.
Chunked so memory stays bounded; no gradients."""

from __future__ import annotations

import torch

from .model import OrcaModel
from .rays import camera_rays, pixel_centers
from .sampling import ray_sphere_bounds

OBJECT_KEYS = ("rgb", "diffuse", "specular", "normal", "opacity", "depth")

# Environment rays per chunk. A CPU renders them faster in small chunks, whose samples' activations (rays x ~120
# samples x the MLP's width) stay in its caches: 7 500 rays/s at 512 or 1024 a chunk against 4 300 at 8192 on 2
# Xeon cores; a GPU needs large ones to be busy.
ENVIRONMENT_CHUNK = {"cpu": 1024, "cuda": 8192}


def environment_chunk(device: torch.device) -> int:
    """Environment rays per chunk on ``device`` (:data:`ENVIRONMENT_CHUNK`; a GPU's for other devices)."""
    return ENVIRONMENT_CHUNK.get(device.type, ENVIRONMENT_CHUNK["cuda"])


def image_rays(
    K: torch.Tensor, c2w: torch.Tensor, height: int, width: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rays through the pixel centres of a pinhole camera, row-major.

    Args:
        K: ``(3, 3)``; c2w: ``(4, 4)``.
    Returns:
        origins ``(H W, 3)``, unit directions ``(H W, 3)``, cone radii ``(H W,)``.
    """
    uv = pixel_centers(height, width, dtype=K.dtype, device=K.device).reshape(-1, 2)
    return camera_rays(uv, K, c2w)


@torch.no_grad()
def render_object_rays(
    model: OrcaModel, origins: torch.Tensor, dirs: torch.Tensor, radii: torch.Tensor, chunk: int = 4096,
    skip_misses: bool = False,
) -> dict[str, torch.Tensor]:
    """The object along rays, in chunks.

    Args:
        origins, dirs: ``(N, 3)``; radii: ``(N,)``.
        skip_misses: rays that miss the model's bounding sphere (``spec.render.object_radius``) are zeros
            without being traced. The renderer gives them an empty interval, so this only saves time; but a
            spec that draws random samples draws fewer of them, which changes every later draw.
    Returns:
        ``rgb``, ``diffuse``, ``specular``, ``normal`` ``(N, 3)``; ``opacity`` and ray ``depth`` ``(N,)``.
    """
    n = origins.shape[0]
    out = {k: torch.zeros((n, 3) if k in ("rgb", "diffuse", "specular", "normal") else (n,), device=origins.device)
           for k in OBJECT_KEYS}
    if skip_misses:
        _, _, hit = ray_sphere_bounds(origins, dirs, model.spec.render.object_radius)
        index = torch.nonzero(hit).squeeze(-1)
    else:
        index = torch.arange(n, device=origins.device)
    for i in range(0, index.numel(), chunk):
        sl = index[i : i + chunk]
        r = model(origins[sl], dirs[sl], radii[sl])
        for key in OBJECT_KEYS:
            out[key][sl] = getattr(r, key).detach().to(out[key].dtype)
    return out


def render_object_image(
    model: OrcaModel, K: torch.Tensor, c2w: torch.Tensor, height: int, width: int, chunk: int = 4096,
    skip_misses: bool = False,
) -> dict[str, torch.Tensor]:
    """Render the object as seen by a pinhole camera (``skip_misses``: see :func:`render_object_rays`).

    Args:
        K: ``(3, 3)``; c2w: ``(4, 4)``.
    Returns:
        ``rgb``, ``diffuse``, ``specular``, ``normal`` ``(H, W, 3)``; ``opacity``, ``depth`` (z-depth) ``(H, W)``.
    """
    origins, dirs, radii = image_rays(K, c2w, height, width)
    out = render_object_rays(model, origins, dirs, radii, chunk, skip_misses)
    out["depth"] = out["depth"] * (dirs * c2w[:3, 2]).sum(-1)  # ray distance -> z-depth
    return {k: v.reshape(height, width, -1).squeeze(-1) for k, v in out.items()}


@torch.no_grad()
def render_environment_image(
    model: OrcaModel, K: torch.Tensor, c2w: torch.Tensor, height: int, width: int, chunk: int | None = None
) -> dict[str, torch.Tensor]:
    """Render the environment field alone (object absent) from any camera: ``rgb`` ``(H, W, 3)`` and
    z-depth ``depth`` ``(H, W)`` along the camera's optical axis (``chunk``: rays at a time, by default
    :func:`environment_chunk`'s), both traced with the spec's samples for a depth (``RenderSpec.for_depth``)."""
    origins, dirs, radii = image_rays(K, c2w, height, width)
    chunk = chunk or environment_chunk(origins.device)
    axis = c2w[:3, 2]
    spec = model.spec.render.for_depth()
    rgbs, depths = [], []
    for i in range(0, origins.shape[0], chunk):
        sl = slice(i, i + chunk)
        rgb, depth = model.environment(origins[sl], dirs[sl], radii[sl], render=spec)
        rgbs.append(rgb)
        depths.append(depth * (dirs[sl] * axis).sum(-1))
    return {"rgb": torch.cat(rgbs).reshape(height, width, 3), "depth": torch.cat(depths).reshape(height, width)}


@torch.no_grad()
def render_composite_image(
    model: OrcaModel, K: torch.Tensor, c2w: torch.Tensor, height: int, width: int, chunk: int | None = None
) -> torch.Tensor:
    """What a camera would photograph: the object over the environment field, ``(H, W, 3)`` linear
    (``rgb + (1 - opacity) * environment``; the environment is traced only where the object lets it through,
    ``chunk`` rays at a time, by default :func:`environment_chunk`'s; the object only where rays meet its
    bounding sphere)."""
    origins, dirs, radii = image_rays(K, c2w, height, width)
    chunk = chunk or environment_chunk(origins.device)
    obj = render_object_rays(model, origins, dirs, radii, skip_misses=True)
    rgb = obj["rgb"].clone()
    through = torch.nonzero(obj["opacity"] < 1 - 1e-3).squeeze(-1)
    for i in range(0, through.numel(), chunk):
        sl = through[i : i + chunk]
        env, _ = model.environment(origins[sl], dirs[sl], radii[sl])
        rgb[sl] += (1 - obj["opacity"][sl, None]) * env
    return rgb.reshape(height, width, 3)
