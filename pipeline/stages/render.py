"""``orca render``: any list of cameras (the ``cameras.json`` schema) rendered by a trained model, as EXR.

Object cameras give, per camera ``<name>``: ``<name>_rgb.exr`` (diffuse + specular), ``_diffuse.exr``,
``_specular.exr``, ``_normal.exr`` (world unit normals, 0 off the object), ``_depth.exr`` (z-depth, +inf
off the object, as the ground truth), ``_mask.png`` (0/255, opacity >= 0.5) and ``<name>_rgb.png`` (8-bit
sRGB to look at). ``--environment`` renders the environment field alone (the object removed) from
cameras anywhere (inside the object, translated, rotated): ``<name>_rgb.exr``, ``<name>_depth.exr``,
``<name>_rgb.png``. Cameras live in the frame the model was trained in; ``views.json`` records them as
rendered (with ``--downscale k``: sizes and intrinsics of the written images), so it round-trips.

Rendering is deterministic (:func:`load_renderer`: evenly spaced instead of random sample quantiles), so a
view rendered twice is the same image. Object rays that miss the model's bounding sphere are not traced:
the renderer gives them an empty interval anyway, and on a photo the object fills a fraction of the frame.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, write_manifest
from ..cameras import Camera, CameraSet, load_cameras, save_cameras, scaled_intrinsics
from ..errors import InputError
from ..imageio import to_srgb8, write_exr, write_png
from ..provenance import common_capture

log = logging.getLogger("orca.render")

OPACITY_THRESHOLD = 0.5  # the object mask, like the ground truth's coverage >= 0.5


def _camera_tensors(cam: Camera, downscale: int, device):
    import torch

    as_t = lambda a: torch.as_tensor(np.asarray(a, dtype=np.float32), device=device)  # noqa: E731
    return as_t(scaled_intrinsics(cam.K, downscale)), as_t(cam.c2w), cam.height // downscale, cam.width // downscale


def load_renderer(train_dir: Path, device: str = "auto"):
    """The trained model of ``train_dir`` ready to render: eval mode, the render spec's ``for_rendering`` (a
    view rendered twice, or by two stages, is the same image; training draws random quantiles, rendering
    must not)."""
    from dataclasses import replace

    from .train import load_model, resolve_device

    model = load_model(train_dir, str(resolve_device(device)))
    model.spec = replace(model.spec, render=model.spec.render.for_rendering())
    return model


_OBJECT_KEYS = ("rgb", "diffuse", "specular", "normal", "opacity", "depth")


def render_object_rays(model, origins, dirs, radii, chunk: int = 4096) -> dict[str, Any]:
    """Object render of rays ``(N, 3), (N, 3), (N,)`` (torch, the model's device): ``rgb``, ``diffuse``,
    ``specular``, ``normal`` ``(N, 3)``, ``opacity``, ray ``depth`` ``(N,)``. Rays that miss the model's
    bounding sphere (``spec.render.object_radius``) are zeros without being traced (the renderer gives them an
    empty interval: the same zeros, minus the cost)."""
    import torch

    from orca.sampling import ray_sphere_bounds

    n = origins.shape[0]
    out = {k: torch.zeros((n, 3) if k in ("rgb", "diffuse", "specular", "normal") else (n,), device=origins.device)
           for k in _OBJECT_KEYS}
    _, _, hit = ray_sphere_bounds(origins, dirs, model.spec.render.object_radius)
    index = torch.nonzero(hit).squeeze(-1)
    with torch.no_grad():
        for i in range(0, index.numel(), chunk):
            sl = index[i : i + chunk]
            r = model(origins[sl], dirs[sl], radii[sl])
            for key in _OBJECT_KEYS:
                out[key][sl] = getattr(r, key).detach().to(out[key].dtype)
    return out


def _image_rays(cam: Camera, downscale: int, device):
    from orca.rays import camera_rays, pixel_centers

    K, c2w, h, w = _camera_tensors(cam, downscale, device)
    origins, dirs, radii = camera_rays(pixel_centers(h, w, dtype=K.dtype, device=device).reshape(-1, 2), K, c2w)
    return origins, dirs, radii, c2w[:3, 2], h, w


def render_object_view(model, cam: Camera, downscale: int = 1) -> dict[str, np.ndarray]:
    """The object as ``cam`` sees it: ``rgb``, ``diffuse``, ``specular``, ``normal`` ``(H, W, 3)``, ``depth``
    ``(H, W)`` (+inf off the object), ``mask`` ``(H, W)`` bool, ``opacity`` ``(H, W)``."""
    device = next(model.parameters()).device
    origins, dirs, radii, axis, h, w = _image_rays(cam, downscale, device)
    rays = render_object_rays(model, origins, dirs, radii)
    rays["depth"] = rays["depth"] * (dirs * axis).sum(-1)  # ray distance -> z-depth
    r = {k: v.reshape(h, w, -1).squeeze(-1).cpu().numpy() for k, v in rays.items()}
    mask = r["opacity"] >= OPACITY_THRESHOLD
    normal = r["normal"] / np.linalg.norm(r["normal"], axis=-1, keepdims=True).clip(1e-8)
    # expected depth of a half-transparent pixel is not a surface; mark it like a miss
    depth = np.where(mask, r["depth"] / np.maximum(r["opacity"], 1e-8), np.inf)
    return {"rgb": r["rgb"], "diffuse": r["diffuse"], "specular": r["specular"],
            "normal": np.where(mask[..., None], normal, 0.0), "depth": depth, "mask": mask, "opacity": r["opacity"]}


def render_environment_view(model, cam: Camera, downscale: int = 1) -> dict[str, np.ndarray]:
    """The environment field alone from ``cam``: ``rgb`` ``(H, W, 3)`` and z-depth ``depth`` ``(H, W)``."""
    from orca.imaging import render_environment_image

    device = next(model.parameters()).device
    K, c2w, h, w = _camera_tensors(cam, downscale, device)
    r = render_environment_image(model, K, c2w, h, w)
    return {"rgb": r["rgb"].cpu().numpy(), "depth": r["depth"].cpu().numpy()}


def render_composite_view(model, cam: Camera, downscale: int = 1) -> np.ndarray:
    """What a camera would photograph: the object over the environment field, ``(H, W, 3)`` linear
    (``rgb + (1 - opacity) * environment``; the environment is traced only where the object lets it through)."""
    import torch

    device = next(model.parameters()).device
    origins, dirs, radii, _, h, w = _image_rays(cam, downscale, device)
    obj = render_object_rays(model, origins, dirs, radii)
    rgb = obj["rgb"].clone()
    through = torch.nonzero(obj["opacity"] < 1 - 1e-3).squeeze(-1)
    with torch.no_grad():
        for i in range(0, through.numel(), 8192):
            sl = through[i : i + 8192]
            env, _ = model.environment(origins[sl], dirs[sl], radii[sl])
            rgb[sl] += (1 - obj["opacity"][sl, None]) * env
    return rgb.reshape(h, w, 3).cpu().numpy()


def rendered_camera(cam: Camera, downscale: int, image: str | None = None) -> Camera:
    """``cam`` as rendered at 1/``downscale`` size: the size and intrinsics of the written images."""
    if downscale == 1:
        return cam.model_copy(update={"image": image})
    K = scaled_intrinsics(cam.K, downscale)
    return cam.model_copy(update={"image": image, "width": cam.width // downscale, "height": cam.height // downscale,
                                  "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]})


def write_views(folder: Path, name: str, images: dict[str, np.ndarray]) -> None:
    """``<name>_<key>.exr`` for every float image, ``_mask.png`` for the mask, ``_rgb.png`` to look at."""
    for key, image in images.items():
        if key == "mask":
            write_png(folder / f"{name}_mask.png", image.astype(np.uint8) * 255)
        elif key != "opacity":
            write_exr(folder / f"{name}_{key}.exr", image.astype(np.float32))
    write_png(folder / f"{name}_rgb.png", to_srgb8(images["rgb"]))


def run_render(
    train_dir: Path, cameras_path: Path, out_dir: Path, *, environment: bool = False, downscale: int = 1,
    device: str = "auto",
) -> Path:
    """Render every camera of ``cameras_path`` with the model of ``train_dir`` into ``out_dir`` (atomically)."""
    from ..log import progress

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
        save_cameras(tmp / "views.json", CameraSet(frame=cameras.frame, cameras=[
            rendered_camera(c, downscale, f"{c.name}_rgb.exr") for c in cameras.cameras]))
        write_manifest(tmp, stage="render", inputs={"model": Path(train_dir) / "model.pt", "cameras": cameras_path},
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
