"""``orca render``: any list of cameras (the ``cameras.json`` schema) rendered by a trained model, as EXR.

Object cameras give, per camera ``<name>``: ``<name>_rgb.exr`` (diffuse + specular), ``_diffuse.exr``,
``_specular.exr``, ``_normal.exr`` (world unit normals, 0 off the object), ``_depth.exr`` (z-depth, +inf
off the object, as the ground truth), ``_mask.png`` (0/255, opacity >= 0.5) and ``<name>_rgb.png`` (8-bit
sRGB to look at). ``--environment`` renders the environment field alone (the object removed) from
cameras anywhere (inside the object, translated, rotated): ``<name>_rgb.exr``, ``<name>_depth.exr``,
``<name>_rgb.png``. Cameras live in the frame the model was trained in; ``views.json`` records them as
rendered (with ``--downscale k``: sizes and intrinsics of the written images), so it round-trips.

Rendering is deterministic: a view rendered twice is the same image (see :mod:`pipeline.rendering`).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

from ..artifacts import atomic_dir, write_manifest
from ..cameras import CameraSet, load_cameras, save_cameras
from ..errors import InputError
from ..layout import MODEL, VIEWS_JSON
from ..log import progress
from ..provenance import common_capture
from ..rendering import (
    load_renderer,
    render_environment_view,
    render_object_view,
    rendered_camera,
    write_views,
)

log = logging.getLogger("orca.render")


def run_render(
    train_dir: Path, cameras_path: Path, out_dir: Path, *, environment: bool = False, downscale: int = 1,
    device: str = "auto",
) -> Path:
    """Render every camera of ``cameras_path`` with the model of ``train_dir`` into ``out_dir`` (atomically)."""
    started = time.time()
    if downscale < 1:
        raise InputError(f"downscale must be >= 1, got {downscale}")
    cameras = load_cameras(cameras_path)
    if len(cameras) == 0:
        raise InputError("no cameras to render", cameras_path, "add cameras to the file")
    too_small = [c.name for c in cameras.cameras if c.width < downscale or c.height < downscale]
    if too_small:
        raise InputError(f"camera(s) {', '.join(too_small)} smaller than the downscale {downscale}", cameras_path,
                         "pass a smaller --downscale")
    model = load_renderer(train_dir, device)
    render = render_environment_view if environment else render_object_view
    with atomic_dir(out_dir, "render", [train_dir, cameras_path]) as tmp, progress() as bar:
        task = bar.add_task("render environment" if environment else "render object", total=len(cameras))
        for cam in cameras.cameras:
            write_views(tmp, cam.name, render(model, cam, downscale))
            bar.advance(task)
        save_cameras(tmp / VIEWS_JSON, CameraSet(frame=cameras.frame, cameras=[
            rendered_camera(c, downscale, f"{c.name}_rgb.exr") for c in cameras.cameras]))
        write_manifest(tmp, stage="render", inputs={"model": Path(train_dir) / MODEL, "cameras": cameras_path},
                       config={"environment": environment, "downscale": downscale}, started=started,
                       capture=common_capture([train_dir]))  # any cameras may be rendered: not checked
    log.info("rendered %d %s view(s) -> %s (%.1f s)", len(cameras), "environment" if environment else "object",
             out_dir, time.time() - started)
    return out_dir


EPILOG = """\
examples:
  orca render results/demo/train --cameras captures/demo/ground_truth/cameras.json --out results/demo/views
  orca render results/demo/train --cameras captures/demo/ground_truth/environment/cameras.json \\
              --environment --out results/demo/environment_views
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "render", help="render any cameras.json with a trained model (object or environment field) to EXR",
        description=__doc__, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("train", type=Path, help="train stage folder (with model.pt)")
    p.add_argument("--cameras", type=Path, required=True, help="cameras.json to render")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--environment", action="store_true", help="render the environment field alone (no object)")
    p.add_argument("--downscale", type=int, default=1, help="integer image downscale")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> Path:
    return run_render(args.train, args.cameras, args.out, environment=args.environment,
                      downscale=args.downscale, device=args.device)
