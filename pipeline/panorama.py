"""The panorama frame, equirectangular rays, and the virtual cameras of the export: cube faces, shifted and
turned views, an orbit of the object and a flythrough inside it.

The panorama frame: ``up`` is the training cameras' mean up vector (-y in OpenCV), ``forward`` the world x
axis made perpendicular to it (the world y axis if x is nearly up), ``left = up x forward``. Pixel (row i,
column j) of a W x H panorama looks at longitude ``phi = pi (1 - 2 (j + 0.5) / W)`` (0: forward, pi/2: left;
the image runs left to right as one turns right) and elevation ``theta = pi (1/2 - (i + 0.5) / H)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .cameras import Camera, CameraSet, look_at
from .config import ExportConfig
from .imageio import linear_to_srgb

DEFAULT_DISTANCE = 3.0  # orbit without training cameras: object radii from the centre ...
DEFAULT_FOV_DEG = 40.0  # ... and vertical field of view


# ------------------------------------------------------------------------------------------- the frame


def panorama_frame(up: np.ndarray) -> np.ndarray:
    """``(3, 3)`` world-from-panorama rotation, columns ``forward, left, up`` (see the module doc)."""
    up = np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    axis = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    forward = axis - (axis @ up) * up
    forward /= np.linalg.norm(forward)
    return np.stack([forward, np.cross(up, forward), up], 1)


def equirect_directions(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions ``(H, W, 3)`` in the panorama frame (forward, left, up) through the pixel centres of a
    ``width`` x ``height`` equirectangular image, and each pixel's solid angle ``(H, W)`` (they sum to 4 pi)."""
    phi = np.pi * (1 - 2 * (np.arange(width) + 0.5) / width)  # (W,)
    theta = np.pi * (0.5 - (np.arange(height) + 0.5) / height)  # (H,)
    c = np.cos(theta)[:, None]
    dirs = np.stack(np.broadcast_arrays(c * np.cos(phi)[None], c * np.sin(phi)[None], np.sin(theta)[:, None]), -1)
    half = np.pi / height / 2
    band = np.sin(theta + half) - np.sin(theta - half)  # exact area of a latitude band per unit longitude
    solid = np.broadcast_to((2 * np.pi / width) * band[:, None], (height, width)).copy()
    return dirs, solid


def equirect_rays(width: int, height: int, centre: np.ndarray, frame: np.ndarray):
    """Cones through an equirectangular image's pixels: origins ``(N, 3)``, world directions ``(N, 3)``, radii
    ``(N,)`` (numpy, N = H W, row-major). A pixel's cone radius per unit distance is mip-NeRF's 2/sqrt(12)
    times the side of a square with the pixel's solid angle."""
    from orca.rays import PIXEL_RADIUS_FACTOR

    dirs, solid = equirect_directions(width, height)
    world = dirs.reshape(-1, 3) @ np.asarray(frame, np.float64).T
    origins = np.broadcast_to(np.asarray(centre, np.float64), world.shape)
    return origins, world, PIXEL_RADIUS_FACTOR * np.sqrt(solid.reshape(-1))


# -------------------------------------------------------------------------------------------- cameras


def pinhole(name: str, c2w: np.ndarray, width: int, height: int, fov_deg: float) -> Camera:
    """A camera with vertical field of view ``fov_deg`` and square pixels, principal point at the centre."""
    f = 0.5 * height / math.tan(math.radians(fov_deg) / 2)
    return Camera(name=name, width=width, height=height, fx=f, fy=f, cx=width / 2, cy=height / 2,
                  camera_to_world=np.asarray(c2w, np.float64).tolist())


def environment_cameras(cfg: ExportConfig, frame: np.ndarray) -> list[Camera]:
    """The virtual cameras of ``environment/`` (see the module doc), in the world frame."""
    forward, left, up = frame.T
    origin = np.zeros(3)
    size, fov = cfg.view_size, cfg.view_fov_deg
    faces = (("px", forward, up), ("nx", -forward, up), ("py", left, up), ("ny", -left, up),
             ("pz", up, -forward), ("nz", -up, forward))
    cams = [pinhole(f"cube_{n}", look_at(origin, d, u), size, size, 90.0) for n, d, u in faces]
    for k, offset in enumerate(cfg.translated_offsets):
        c2w = look_at(origin, forward, up)
        c2w[:3, 3] = offset * left
        cams.append(pinhole(f"shift_{k}", c2w, size, size, fov))
    for yaw in cfg.rotated_yaw_deg:
        a = math.radians(yaw)
        d = math.cos(a) * forward + math.sin(a) * left
        cams.append(pinhole(f"turn_{yaw:g}", look_at(origin, d, up), size, size, fov))
    return cams


def training_geometry(cameras: CameraSet | None, up: np.ndarray) -> dict[str, float]:
    """Median distance, elevation (deg) and vertical field of view (deg) of the training cameras, and the
    first camera's azimuth about ``up``; defaults without cameras."""
    if cameras is None or len(cameras) == 0:
        return {"distance": DEFAULT_DISTANCE, "elevation_deg": 20.0, "fov_deg": DEFAULT_FOV_DEG}
    centres = np.stack([c.center for c in cameras.cameras])
    dist = np.linalg.norm(centres, axis=1)
    elev = np.degrees(np.arcsin(np.clip(centres @ up / np.maximum(dist, 1e-9), -1, 1)))
    fov = [2 * math.degrees(math.atan(c.height / 2 / c.fy)) for c in cameras.cameras]
    return {"distance": float(np.median(dist)), "elevation_deg": float(np.median(elev)),
            "fov_deg": float(np.median(fov)), "first_camera": cameras.cameras[0].name}


def orbit_path(cfg: ExportConfig, frame: np.ndarray, geometry: dict[str, Any],
               first_centre: np.ndarray | None) -> list[Camera]:
    """``video_frames`` cameras on a circle about ``up`` at the training distance and elevation, starting at
    the first training camera's azimuth, looking at the centre."""
    forward, left, up = frame.T
    a0 = 0.0
    if first_centre is not None:
        a0 = math.atan2(first_centre @ left, first_centre @ forward)
    e = math.radians(geometry["elevation_deg"])
    fov = cfg.video_fov_deg or geometry["fov_deg"]
    cams = []
    for k in range(cfg.video_frames):
        a = a0 + 2 * math.pi * k / cfg.video_frames
        eye = geometry["distance"] * (math.cos(e) * (math.cos(a) * forward + math.sin(a) * left) + math.sin(e) * up)
        cams.append(pinhole(f"orbit_{k:04d}", look_at(eye, np.zeros(3), up), cfg.video_width, cfg.video_height, fov))
    return cams


def flythrough_path(cfg: ExportConfig, frame: np.ndarray) -> list[Camera]:
    """``video_frames`` cameras circling the centre at ``flythrough_radius`` inside the object, each looking
    outwards along its radius (a 360-degree sweep of the room that also translates: parallax)."""
    forward, left, up = frame.T
    cams = []
    for k in range(cfg.video_frames):
        a = 2 * math.pi * k / cfg.video_frames
        d = math.cos(a) * forward + math.sin(a) * left
        c2w = look_at(np.zeros(3), d, up)
        c2w[:3, 3] = cfg.flythrough_radius * d
        cams.append(pinhole(f"fly_{k:04d}", c2w, cfg.video_width, cfg.video_height, cfg.view_fov_deg))
    return cams


# ------------------------------------------------------------------------------------------- rendering


def render_panorama(model, width: int, height: int, centre: np.ndarray, frame: np.ndarray,
                    chunk: int | None = None, bar=None, task=None) -> dict[str, np.ndarray]:
    """The environment field from ``centre`` as an equirectangular panorama: ``rgb`` ``(H, W, 3)`` linear and
    ``depth`` ``(H, W)``, the distance along each ray at the model's ``spec.render.depth_quantile`` of its
    weight (:func:`orca.volume.quantile_depth`), both traced with the samples for a depth
    (``RenderSpec.for_depth``); ``chunk`` rays at a time (default: the device's,
    :func:`orca.imaging.environment_chunk`)."""
    import torch

    from orca.imaging import environment_chunk

    device = next(model.parameters()).device
    chunk = chunk or environment_chunk(device)
    origins, dirs, radii = (torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)
                            for a in equirect_rays(width, height, centre, frame))
    spec = model.spec.render.for_depth()
    rgbs, depths = [], []
    with torch.no_grad():
        for i in range(0, origins.shape[0], chunk):
            rgb, depth = model.environment(origins[i : i + chunk], dirs[i : i + chunk], radii[i : i + chunk],
                                           render=spec)
            rgbs.append(rgb.float().cpu())
            depths.append(depth.float().cpu())
            if bar is not None:
                bar.advance(task, rgb.shape[0])
    return {"rgb": torch.cat(rgbs).reshape(height, width, 3).numpy(),
            "depth": torch.cat(depths).reshape(height, width).numpy()}


def panorama_points(rgb: np.ndarray, depth: np.ndarray, centre: np.ndarray, frame: np.ndarray,
                    max_depth: float) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(M, 3)`` and sRGB colours ``(M, 3)`` in [0, 1] of a panorama's pixels with finite depth
    below ``max_depth``."""
    h, w = depth.shape
    _, dirs, _ = equirect_rays(w, h, centre, frame)
    d = depth.reshape(-1).astype(np.float64)
    keep = np.isfinite(d) & (d > 0) & (d < max_depth)
    points = np.asarray(centre, np.float64) + d[keep, None] * dirs[keep]
    return points, linear_to_srgb(rgb.reshape(-1, 3)[keep]).astype(np.float64)
