"""A trained model's views of ``cameras.json`` cameras, as numpy images, and the files they are written to.

Rendering is deterministic (:func:`load_renderer`: evenly spaced instead of random sample quantiles), so a
view rendered twice is the same image. Object rays that miss the model's bounding sphere are not traced:
the renderer gives them an empty interval anyway, and on a photo the object fills a fraction of the frame.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from .cameras import Camera, scaled_intrinsics
from .imageio import to_srgb8, write_exr, write_png
from .model_io import load_model, resolve_device

OPACITY_THRESHOLD = 0.5  # the object mask, like the ground truth's coverage >= 0.5


def _camera_tensors(cam: Camera, downscale: int, device):
    import torch

    as_t = lambda a: torch.as_tensor(np.asarray(a, dtype=np.float32), device=device)  # noqa: E731
    return as_t(scaled_intrinsics(cam.K, downscale)), as_t(cam.c2w), cam.height // downscale, cam.width // downscale


def load_renderer(train_dir: Path, device: str = "auto"):
    """The trained model of ``train_dir`` ready to render: eval mode, the render spec's ``for_rendering`` (a
    view rendered twice, or by two stages, is the same image; training draws random quantiles, rendering
    must not)."""
    model = load_model(train_dir, str(resolve_device(device)))
    model.spec = replace(model.spec, render=model.spec.render.for_rendering())
    return model


def render_object_view(model, cam: Camera, downscale: int = 1) -> dict[str, np.ndarray]:
    """The object as ``cam`` sees it: ``rgb``, ``diffuse``, ``specular``, ``normal`` ``(H, W, 3)``, ``depth``
    ``(H, W)`` (+inf off the object), ``mask`` ``(H, W)`` bool, ``opacity`` ``(H, W)``."""
    from orca.imaging import render_object_image

    K, c2w, h, w = _camera_tensors(cam, downscale, next(model.parameters()).device)
    r = {k: v.cpu().numpy() for k, v in render_object_image(model, K, c2w, h, w, skip_misses=True).items()}
    mask = r["opacity"] >= OPACITY_THRESHOLD
    normal = r["normal"] / np.linalg.norm(r["normal"], axis=-1, keepdims=True).clip(1e-8)
    # expected depth of a half-transparent pixel is not a surface; mark it like a miss
    depth = np.where(mask, r["depth"] / np.maximum(r["opacity"], 1e-8), np.inf)
    return {"rgb": r["rgb"], "diffuse": r["diffuse"], "specular": r["specular"],
            "normal": np.where(mask[..., None], normal, 0.0), "depth": depth, "mask": mask, "opacity": r["opacity"]}


def render_environment_view(model, cam: Camera, downscale: int = 1) -> dict[str, np.ndarray]:
    """The environment field alone from ``cam``: ``rgb`` ``(H, W, 3)`` and z-depth ``depth`` ``(H, W)``."""
    from orca.imaging import render_environment_image

    K, c2w, h, w = _camera_tensors(cam, downscale, next(model.parameters()).device)
    r = render_environment_image(model, K, c2w, h, w)
    return {"rgb": r["rgb"].cpu().numpy(), "depth": r["depth"].cpu().numpy()}


def render_composite_view(model, cam: Camera, downscale: int = 1) -> np.ndarray:
    """What a camera would photograph: the object over the environment field, ``(H, W, 3)`` linear."""
    from orca.imaging import render_composite_image

    K, c2w, h, w = _camera_tensors(cam, downscale, next(model.parameters()).device)
    return render_composite_image(model, K, c2w, h, w).cpu().numpy()


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
