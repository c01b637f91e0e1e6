"""``orca export``: what the trained model can show, as files a person opens without this code.

From the environment field alone (the object removed), seen from virtual cameras at and near the object:

- ``environment/``: six 90-degree cube faces from the object centre (``cube_px`` ... ``cube_nz``), views
  translated sideways from it (``shift_<k>``, all looking along the panorama's forward axis: parallax around
  occluders) and rotated between the faces (``turn_<yaw>``). Per view ``<name>_rgb.exr`` (linear),
  ``_depth.exr`` (z-depth, frame units), ``_rgb.png`` (sRGB) and ``_depth.png`` (turbo colours, the scale in
  ``export.json``); ``cameras.json`` holds the views (``orca render --environment`` re-renders them).
- ``panorama/``: an equirectangular panorama from the object centre, ``panorama_rgb.exr|png`` and
  ``panorama_depth.exr|png`` (distance along each ray, not z-depth: a panorama has no optical axis).
- ``environment_points.ply``: the panorama as a coloured point cloud (centre + depth x direction; points
  farther than ``export.point_cloud_max_depth`` left out), and ``environment_points_colmap.ply`` in COLMAP's
  frame when the cameras record ``to_colmap``.
- ``videos/flythrough.mp4``: a camera circling the centre inside the object (``export.flythrough_radius``),
  looking outwards as it goes round.

From the whole model:

- ``videos/orbit.mp4``: the object on an orbit at the training cameras' median distance and elevation, over
  the environment field (``export.background``).
- ``object/``: renders from ``export.object_views`` evenly spaced training cameras at 1/``object_downscale``
  size, as ``orca render`` writes them (``<name>_rgb|diffuse|specular|normal|depth.exr``, ``_mask.png``) plus
  ``_diffuse.png``, ``_specular.png`` and ``_normal.png`` to look at; ``views.json`` holds their cameras.

The panorama frame: ``up`` is the training cameras' mean up vector (-y in OpenCV), ``forward`` the world x
axis made perpendicular to it (the world y axis if x is nearly up), ``left = up x forward``. Pixel (row i,
column j) of a W x H panorama looks at longitude ``phi = pi (1 - 2 (j + 0.5) / W)`` (0: forward, pi/2: left;
the image runs left to right as one turns right) and elevation ``theta = pi (1/2 - (i + 0.5) / H)``.

Radiance is linear in decoded units; PNGs and videos show ``srgb(clip(x, 0, 1))`` (1 decoded unit, the white
level of the reference exposure, is white), as ``orca evaluate`` tone-maps. Everything is in the model's
(normalized) frame: the object's bounding sphere is the unit sphere, so depths are in object radii. Writes
``OUT/`` atomically with ``export.json`` (what was written, sizes, timing), ``overview.png`` and
``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, read_json, write_json, write_manifest
from ..cameras import Camera, CameraSet, load_cameras, look_at, save_cameras, select_views
from ..config import ExportConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..provenance import common_capture

log = logging.getLogger("orca.export")

EXPORT_JSON = "export.json"
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


def _pinhole(name: str, c2w: np.ndarray, width: int, height: int, fov_deg: float) -> Camera:
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
    cams = [_pinhole(f"cube_{n}", look_at(origin, d, u), size, size, 90.0) for n, d, u in faces]
    for k, offset in enumerate(cfg.translated_offsets):
        c2w = look_at(origin, forward, up)
        c2w[:3, 3] = offset * left
        cams.append(_pinhole(f"shift_{k}", c2w, size, size, fov))
    for yaw in cfg.rotated_yaw_deg:
        a = math.radians(yaw)
        d = math.cos(a) * forward + math.sin(a) * left
        cams.append(_pinhole(f"turn_{yaw:g}", look_at(origin, d, up), size, size, fov))
    return cams


def _training_geometry(cameras: CameraSet | None, up: np.ndarray) -> dict[str, float]:
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
        cams.append(_pinhole(f"orbit_{k:04d}", look_at(eye, np.zeros(3), up), cfg.video_width, cfg.video_height, fov))
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
        cams.append(_pinhole(f"fly_{k:04d}", c2w, cfg.video_width, cfg.video_height, cfg.view_fov_deg))
    return cams


# ------------------------------------------------------------------------------------------- rendering


def render_panorama(model, width: int, height: int, centre: np.ndarray, frame: np.ndarray,
                    chunk: int = 8192, bar=None, task=None) -> dict[str, np.ndarray]:
    """The environment field from ``centre`` as an equirectangular panorama: ``rgb`` ``(H, W, 3)`` linear and
    ``depth`` ``(H, W)``, the distance along each ray at the model's ``spec.render.depth_quantile`` of its
    weight (:func:`orca.volume.quantile_depth`)."""
    import torch

    device = next(model.parameters()).device
    origins, dirs, radii = (torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)
                            for a in equirect_rays(width, height, centre, frame))
    rgbs, depths = [], []
    with torch.no_grad():
        for i in range(0, origins.shape[0], chunk):
            rgb, depth = model.environment(origins[i : i + chunk], dirs[i : i + chunk], radii[i : i + chunk])
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
    from ..imageio import linear_to_srgb

    h, w = depth.shape
    _, dirs, _ = equirect_rays(w, h, centre, frame)
    d = depth.reshape(-1).astype(np.float64)
    keep = np.isfinite(d) & (d > 0) & (d < max_depth)
    points = np.asarray(centre, np.float64) + d[keep, None] * dirs[keep]
    return points, linear_to_srgb(rgb.reshape(-1, 3)[keep]).astype(np.float64)


# ---------------------------------------------------------------------------------------------- writing


def depth_scale(depths: list[np.ndarray]) -> tuple[float, float]:
    """One colour scale for depth pictures: the 1st and 99th percentiles of every finite depth."""
    finite = np.concatenate([d[np.isfinite(d)].ravel() for d in depths]) if depths else np.zeros(0)
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = (float(x) for x in np.percentile(finite, [1, 99]))
    return lo, hi if hi > lo else lo + 1.0


def depth_png(depth: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``(H, W)`` depth -> ``(H, W, 3)`` uint8 turbo colours on [lo, hi]; non-finite depth black."""
    from matplotlib import colormaps

    t = np.clip((np.nan_to_num(depth, nan=hi, posinf=hi) - lo) / (hi - lo), 0, 1)
    rgb = colormaps["turbo"](t)[..., :3]
    rgb[~np.isfinite(depth)] = 0
    return np.round(rgb * 255).astype(np.uint8)


def normal_png(normal: np.ndarray) -> np.ndarray:
    """World unit normals ``(H, W, 3)`` -> ``(n + 1) / 2`` as uint8 (zero normals: black)."""
    rgb = np.round(np.clip(normal * 0.5 + 0.5, 0, 1) * 255).astype(np.uint8)
    rgb[np.linalg.norm(normal, axis=-1) < 1e-6] = 0
    return rgb


def write_video(path: Path, frames: list[np.ndarray], fps: int) -> Path:
    """``(H, W, 3)`` uint8 frames -> H.264 MP4 (imageio-ffmpeg's bundled ffmpeg, yuv420p for players)."""
    import imageio_ffmpeg

    h, w = frames[0].shape[:2]
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=2, quality=8)
    writer.send(None)
    try:
        for frame in frames:
            writer.send(np.ascontiguousarray(frame, np.uint8))
    finally:
        writer.close()
    return path


def _write_env_view(folder: Path, name: str, view: dict[str, np.ndarray], scale: tuple[float, float]) -> None:
    from ..imageio import to_srgb8, write_exr, write_png

    write_exr(folder / f"{name}_rgb.exr", view["rgb"].astype(np.float32))
    write_exr(folder / f"{name}_depth.exr", view["depth"].astype(np.float32))
    write_png(folder / f"{name}_rgb.png", to_srgb8(view["rgb"]))
    write_png(folder / f"{name}_depth.png", depth_png(view["depth"], *scale))


def write_point_cloud(path: Path, points: np.ndarray, colors: np.ndarray, transform: np.ndarray | None = None) -> Path:
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.colors = o3d.utility.Vector3dVector(colors)
    if transform is not None:
        pcd.transform(np.asarray(transform, np.float64))
    if not o3d.io.write_point_cloud(str(path), pcd, write_ascii=False):
        raise OSError(f"{path}: open3d could not write the point cloud")
    return path


def overview(path: Path, panorama: dict[str, np.ndarray], env_views: dict[str, dict[str, np.ndarray]],
             objects: dict[str, dict[str, np.ndarray]], scale: tuple[float, float]) -> Path:
    """One picture: the panorama (RGB, depth), the cube faces (RGB, depth), the first object render's parts."""
    from matplotlib.figure import Figure

    from ..imageio import linear_to_srgb

    cube = [n for n in env_views if n.startswith("cube_")]
    columns = max(len(cube), 4)
    columns += columns % 2
    rows = 3 + (1 if objects else 0)
    tile = 1.8
    fig = Figure(figsize=(columns * tile, (rows + 0.6) * tile), dpi=110, layout="constrained")
    grid = fig.add_gridspec(rows, columns, height_ratios=[1.6] + [1] * (rows - 1))
    half = columns // 2
    ax = fig.add_subplot(grid[0, :half])
    ax.imshow(linear_to_srgb(panorama["rgb"]), interpolation="nearest")
    ax.set_title("panorama from the centre (environment field)", fontsize=8)
    ax.set_axis_off()
    ax = fig.add_subplot(grid[0, half:])
    im = ax.imshow(np.where(np.isfinite(panorama["depth"]), panorama["depth"], np.nan), cmap="turbo",
                   vmin=scale[0], vmax=scale[1], interpolation="nearest")
    fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01, label="depth (object radii)")
    ax.set_title("panorama depth", fontsize=8)
    ax.set_axis_off()
    for c, name in enumerate(cube):
        for r, (image, kw) in enumerate(((linear_to_srgb(env_views[name]["rgb"]), {}),
                                         (env_views[name]["depth"], {"cmap": "turbo", "vmin": scale[0],
                                                                     "vmax": scale[1]}))):
            ax = fig.add_subplot(grid[1 + r, c])
            ax.imshow(image, interpolation="nearest", **kw)
            ax.set_axis_off()
            if r == 0:
                ax.set_title(name, fontsize=8)
    if objects:
        name, view = next(iter(objects.items()))
        parts = [("combined", linear_to_srgb(view["rgb"])), ("diffuse", linear_to_srgb(view["diffuse"])),
                 ("specular", linear_to_srgb(view["specular"])), ("normals", normal_png(view["normal"]))]
        for c, (title, image) in enumerate(parts):
            ax = fig.add_subplot(grid[3, c])
            ax.imshow(image, interpolation="nearest")
            ax.set_title(f"{name}: {title}", fontsize=8)
            ax.set_axis_off()
    fig.savefig(path)
    return path


# ------------------------------------------------------------------------------------------------ stage


def training_cameras(train_dir: Path, cameras: Path | None) -> tuple[CameraSet | None, str]:
    """The cameras the model was trained with (explicit, or as the train manifest records them) and where
    they came from; ``(None, reason)`` when there are none."""
    if cameras is not None:
        return load_cameras(cameras), str(cameras)
    try:
        recorded = Path(read_json(Path(train_dir) / "manifest.json")["inputs"]["cameras"]["path"])
    except (OSError, KeyError, TypeError, ValueError):
        return None, "none (no --cameras and no train manifest recording them)"
    if not recorded.is_file():
        return None, f"none (the train manifest's {recorded} is not reachable from here)"
    return load_cameras(recorded), f"{recorded} (from the train manifest)"


def run_export(train_dir: Path, out_dir: Path, cfg: ExportConfig | None = None, *, cameras: Path | None = None,
               device: str = "auto") -> dict[str, Any]:
    """Export views, panorama, point cloud, videos and object renders of ``train_dir``'s model into
    ``out_dir`` (atomically); returns ``export.json``."""
    from ..imageio import to_srgb8, write_png
    from ..log import progress
    from ..object_frame import camera_up
    from .render import (
        load_renderer,
        render_composite_view,
        render_environment_view,
        render_object_view,
        rendered_camera,
        write_views,
    )
    from .train import FINAL_WEIGHTS

    started = time.time()
    cfg = cfg if cfg is not None else ExportConfig()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    weights = train_dir / FINAL_WEIGHTS
    if not weights.is_file():
        raise InputError("no trained model here", weights, "run `orca train` first (it writes model.pt when done)")
    capture = common_capture([train_dir, cameras], force=True)  # --cameras of another capture: a warning
    train_cams, cams_from = training_cameras(train_dir, cameras)
    if train_cams is None:
        log.warning("export: no training cameras (%s): z is up, the orbit uses defaults and there are no object "
                    "renders; pass --cameras", cams_from)
    up = camera_up(train_cams.c2w()) if train_cams is not None else np.array([0.0, 0.0, 1.0])
    frame = panorama_frame(up)
    geometry = _training_geometry(train_cams, up)
    model = load_renderer(train_dir, device)
    centre = np.zeros(3)
    env_cams = environment_cameras(cfg, frame)
    pano_w, pano_h = cfg.panorama_width, max(cfg.panorama_width // 2, 1)
    orbit = orbit_path(cfg, frame, geometry, train_cams.cameras[0].center if train_cams is not None else None)
    fly = flythrough_path(cfg, frame)
    object_cams: list[Camera] = []
    if train_cams is not None and cfg.object_views > 0:
        by_name = train_cams.by_name()
        object_cams = [by_name[n] for n in select_views(list(by_name), cfg.object_views)]
    timing: dict[str, float] = {}
    to_colmap = train_cams.frame.to_colmap if train_cams is not None else None
    log.info("export: %s: %d environment views, %dx%d panorama, 2 videos of %d frames at %dx%d, %d object views",
             train_dir, len(env_cams), pano_w, pano_h, cfg.video_frames, cfg.video_width, cfg.video_height,
             len(object_cams))

    with atomic_dir(out_dir, "export", [train_dir, *([cameras] if cameras else [])]) as tmp, progress() as bar:
        # panorama first: its depth sets the colour scale of every depth picture
        t = time.time()
        task = bar.add_task("panorama", total=pano_w * pano_h)
        pano = render_panorama(model, pano_w, pano_h, centre, frame, bar=bar, task=task)
        scale = depth_scale([pano["depth"]])
        (tmp / "panorama").mkdir()
        _write_env_view(tmp / "panorama", "panorama", pano, scale)
        points, colors = panorama_points(pano["rgb"], pano["depth"], centre, frame, cfg.point_cloud_max_depth)
        write_point_cloud(tmp / "environment_points.ply", points, colors)
        if to_colmap is not None:
            write_point_cloud(tmp / "environment_points_colmap.ply", points, colors, np.asarray(to_colmap))
        timing["panorama"] = time.time() - t

        t = time.time()
        (tmp / "environment").mkdir()
        env_views: dict[str, dict[str, np.ndarray]] = {}
        task = bar.add_task("environment views", total=len(env_cams))
        for cam in env_cams:
            env_views[cam.name] = render_environment_view(model, cam)
            _write_env_view(tmp / "environment", cam.name, env_views[cam.name], scale)
            bar.advance(task)
        save_cameras(tmp / "environment" / "cameras.json", CameraSet(cameras=[
            c.model_copy(update={"image": f"{c.name}_rgb.exr"}) for c in env_cams]))
        timing["environment_views"] = time.time() - t

        (tmp / "videos").mkdir()
        t = time.time()
        task = bar.add_task("flythrough video", total=len(fly))
        frames = []
        for cam in fly:
            frames.append(to_srgb8(render_environment_view(model, cam)["rgb"]))
            bar.advance(task)
        write_video(tmp / "videos" / "flythrough.mp4", frames, cfg.video_fps)
        timing["flythrough_video"] = time.time() - t

        t = time.time()
        task = bar.add_task("orbit video", total=len(orbit))
        frames = []
        for cam in orbit:
            rgb = render_composite_view(model, cam) if cfg.background else render_object_view(model, cam)["rgb"]
            frames.append(to_srgb8(rgb))
            bar.advance(task)
        write_video(tmp / "videos" / "orbit.mp4", frames, cfg.video_fps)
        timing["orbit_video"] = time.time() - t

        t = time.time()
        objects: dict[str, dict[str, np.ndarray]] = {}
        if object_cams:
            (tmp / "object").mkdir()
            task = bar.add_task("object renders", total=len(object_cams))
            k = cfg.object_downscale
            for cam in object_cams:
                view = render_object_view(model, cam, k)
                objects[cam.name] = view
                write_views(tmp / "object", cam.name, view)
                for part in ("diffuse", "specular"):
                    write_png(tmp / "object" / f"{cam.name}_{part}.png", to_srgb8(view[part]))
                write_png(tmp / "object" / f"{cam.name}_normal.png", normal_png(view["normal"]))
                bar.advance(task)
            save_cameras(tmp / "object" / "views.json", CameraSet(frame=train_cams.frame, cameras=[
                rendered_camera(c, k, f"{c.name}_rgb.exr") for c in object_cams]))
        timing["object_renders"] = time.time() - t

        overview(tmp / "overview.png", pano, env_views, objects, scale)
        report: dict[str, Any] = {
            "train": str(train_dir), "cameras": cams_from,
            "frame": {"up": up.tolist(), "forward": frame[:, 0].tolist(), "left": frame[:, 1].tolist(),
                      "units": "the model's normalized frame: object radii", "to_colmap": to_colmap},
            "environment_views": [c.name for c in env_cams], "view_size": cfg.view_size,
            "panorama": {"width": pano_w, "height": pano_h, "centre": centre.tolist(),
                         "depth": "distance along each ray where its accumulated weight reaches "
                                  f"{model.spec.render.depth_quantile:g} of the total (not z-depth)"},
            "depth_png_scale": {"min": scale[0], "max": scale[1], "colormap": "turbo",
                                "meaning": "1st-99th percentile of the panorama's finite depth; black: no depth"},
            "point_cloud": {"points": len(points), "max_depth": cfg.point_cloud_max_depth,
                            "colmap": to_colmap is not None},
            "videos": {"orbit": {"frames": len(orbit), **geometry, "background": cfg.background},
                       "flythrough": {"frames": len(fly), "radius": cfg.flythrough_radius},
                       "size": [cfg.video_width, cfg.video_height], "fps": cfg.video_fps},
            "object_views": [c.name for c in object_cams], "object_downscale": cfg.object_downscale,
            "tone_mapping": "PNG and MP4: srgb(clip(linear, 0, 1)); 1 decoded unit is white",
            "seconds": {k: round(v, 2) for k, v in timing.items()},
        }
        report["seconds"]["total"] = round(time.time() - started, 2)
        write_json(tmp / EXPORT_JSON, report)
        inputs = {"model": weights}
        if train_cams is not None and cameras is not None:
            inputs["cameras"] = Path(cameras)
        write_manifest(tmp, stage="export", inputs=inputs, config=cfg.model_dump(), started=started, capture=capture)
    log.info("export: wrote %s in %.1f s (%s)", out_dir, time.time() - started,
             ", ".join(f"{k} {v:.0f} s" for k, v in timing.items()))
    return report


# -------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca export results/demo/train --cameras captures/demo/ground_truth/cameras.json --preset fast
  orca export results/demo/train --set export.panorama_width=1024 --set export.video_frames=120 \\
              --out /tmp/big_export          a bigger export (a GPU helps)
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export", help="trained model -> environment views + depth, panorama, point cloud, videos, object renders",
        description=__doc__, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("train", type=Path, help="train stage folder (with model.pt)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: export/ beside TRAIN)")
    p.add_argument("--cameras", type=Path, default=None,
                   help="the cameras.json the model was trained with (up vector, orbit, object renders; default: "
                        "as the train manifest records)")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto")
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> dict[str, Any]:
    cfg = config_from_arguments(args, "export").export
    train = Path(args.train)
    out = args.out if args.out is not None else train.parent / "export"
    return run_export(train, out, cfg, cameras=args.cameras, device=args.device)
