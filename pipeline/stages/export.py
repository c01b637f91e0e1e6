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

The panorama frame and pixel directions: see :mod:`pipeline.panorama`.

Radiance is linear in decoded units; PNGs and videos show ``srgb(clip(x, 0, 1))`` (1 decoded unit, the white
level of the reference exposure, is white), as ``orca evaluate`` tone-maps. Everything is in the model's
(normalized) frame: the object's bounding sphere is the unit sphere, so depths are in object radii. Writes
``OUT/`` atomically with ``export.json`` (what was written, sizes, timing), ``overview.png`` and
``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, write_json, write_manifest
from ..cameras import Camera, CameraSet, save_cameras, select_views
from ..config import ExportConfig, add_config_arguments, config_from_arguments
from ..imageio import to_srgb8, write_png
from ..layout import (
    CAMERAS_JSON,
    ENVIRONMENT,
    EXPORT_JSON,
    FLYTHROUGH_VIDEO,
    OBJECT_VIEWS,
    ORBIT_VIDEO,
    OVERVIEW,
    PANORAMA,
    POINT_CLOUD,
    POINT_CLOUD_COLMAP,
    VIDEOS,
    VIEWS_JSON,
)
from ..log import progress
from ..media import depth_scale, normal_png, overview, write_environment_view, write_point_cloud, write_video
from ..model_io import model_file, training_cameras
from ..object_frame import camera_up
from ..panorama import (
    environment_cameras,
    flythrough_path,
    orbit_path,
    panorama_frame,
    panorama_points,
    render_panorama,
    training_geometry,
)
from ..provenance import common_capture
from ..rendering import (
    load_renderer,
    render_composite_view,
    render_environment_view,
    render_object_view,
    rendered_camera,
    write_views,
)

log = logging.getLogger("orca.export")



# ------------------------------------------------------------------------------------------------ stage


def run_export(train_dir: Path, out_dir: Path, cfg: ExportConfig | None = None, *, cameras: Path | None = None,
               device: str = "auto") -> dict[str, Any]:
    """Export views, panorama, point cloud, videos and object renders of ``train_dir``'s model into
    ``out_dir`` (atomically); returns ``export.json``."""
    started = time.time()
    cfg = cfg if cfg is not None else ExportConfig()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    weights = model_file(train_dir)
    capture = common_capture([train_dir, cameras], force=True)  # --cameras of another capture: a warning
    train_cams, cams_from = training_cameras(train_dir, cameras)
    if train_cams is None:
        log.warning("export: no training cameras (%s): z is up, the orbit uses defaults and there are no object "
                    "renders; pass --cameras", cams_from)
    up = camera_up(train_cams.c2w()) if train_cams is not None else np.array([0.0, 0.0, 1.0])
    frame = panorama_frame(up)
    geometry = training_geometry(train_cams, up)
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
        (tmp / PANORAMA).mkdir()
        write_environment_view(tmp / PANORAMA, PANORAMA, pano, scale)
        points, colors = panorama_points(pano["rgb"], pano["depth"], centre, frame, cfg.point_cloud_max_depth)
        write_point_cloud(tmp / POINT_CLOUD, points, colors)
        if to_colmap is not None:
            write_point_cloud(tmp / POINT_CLOUD_COLMAP, points, colors, np.asarray(to_colmap))
        timing["panorama"] = time.time() - t

        t = time.time()
        (tmp / ENVIRONMENT).mkdir()
        env_views: dict[str, dict[str, np.ndarray]] = {}
        task = bar.add_task("environment views", total=len(env_cams))
        for cam in env_cams:
            env_views[cam.name] = render_environment_view(model, cam)
            write_environment_view(tmp / ENVIRONMENT, cam.name, env_views[cam.name], scale)
            bar.advance(task)
        save_cameras(tmp / ENVIRONMENT / CAMERAS_JSON, CameraSet(cameras=[
            c.model_copy(update={"image": f"{c.name}_rgb.exr"}) for c in env_cams]))
        timing["environment_views"] = time.time() - t

        (tmp / VIDEOS).mkdir()
        t = time.time()
        task = bar.add_task("flythrough video", total=len(fly))
        frames = []
        for cam in fly:
            frames.append(to_srgb8(render_environment_view(model, cam)["rgb"]))
            bar.advance(task)
        write_video(tmp / VIDEOS / FLYTHROUGH_VIDEO, frames, cfg.video_fps)
        timing["flythrough_video"] = time.time() - t

        t = time.time()
        task = bar.add_task("orbit video", total=len(orbit))
        frames = []
        for cam in orbit:
            rgb = render_composite_view(model, cam) if cfg.background else render_object_view(model, cam)["rgb"]
            frames.append(to_srgb8(rgb))
            bar.advance(task)
        write_video(tmp / VIDEOS / ORBIT_VIDEO, frames, cfg.video_fps)
        timing["orbit_video"] = time.time() - t

        t = time.time()
        objects: dict[str, dict[str, np.ndarray]] = {}
        if object_cams:
            (tmp / OBJECT_VIEWS).mkdir()
            task = bar.add_task("object renders", total=len(object_cams))
            k = cfg.object_downscale
            for cam in object_cams:
                view = render_object_view(model, cam, k)
                objects[cam.name] = view
                write_views(tmp / OBJECT_VIEWS, cam.name, view)
                for part in ("diffuse", "specular"):
                    write_png(tmp / OBJECT_VIEWS / f"{cam.name}_{part}.png", to_srgb8(view[part]))
                write_png(tmp / OBJECT_VIEWS / f"{cam.name}_normal.png", normal_png(view["normal"]))
                bar.advance(task)
            save_cameras(tmp / OBJECT_VIEWS / VIEWS_JSON, CameraSet(frame=train_cams.frame, cameras=[
                rendered_camera(c, k, f"{c.name}_rgb.exr") for c in object_cams]))
        timing["object_renders"] = time.time() - t

        overview(tmp / OVERVIEW, pano, env_views, objects, scale)
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
