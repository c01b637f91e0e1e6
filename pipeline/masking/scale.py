"""Between the photos' full size and the working size segmentation runs at: views reduced (area average), masks
brought back up with their outline snapped to the photo's edges."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ..errors import InputError
from .views import View

if TYPE_CHECKING:
    from ..results import DecodeArtifacts

# Raw pixels around a RAW photo's clipped highlight that segmentation treats as part of it. Decode flags only the
# saturated photosites (training's lower bounds), but the pixels beside them change with the viewpoint as the
# highlight does, and their colours are skewed by demosaicing: the photo-consistency tests and GrabCut's core
# kept this distance from them when decode itself grew its mask that far (the demo's masks: 0.956 median IoU
# with it, 0.936 without). 8/16-bit photos' masks are grown by decode as before.
HIGHLIGHT_MARGIN_RAW_PX = 2


def highlight_margin(entry: dict[str, Any]) -> int:
    """Pixels of the decoded photo (its ``decode.json`` record) to grow its clipped mask by:
    :data:`HIGHLIGHT_MARGIN_RAW_PX` raw pixels at the decoded size, for RAW photos."""
    if entry.get("format") != "raw":
        return 0
    downscale = max(entry["source_size"]) / max(entry["width"], entry["height"]) if entry.get("source_size") else 1.0
    return math.ceil(HIGHLIGHT_MARGIN_RAW_PX / max(downscale, 1.0))


def load_view(decoded: DecodeArtifacts, cam: Any, scale: float) -> View:
    """One photo at the working size (``scale`` of the camera's size): sRGB, clipped highlights (grown by
    :func:`highlight_margin`), intrinsics."""
    srgb = decoded.srgb(cam.name)
    if srgb.shape[:2] != (cam.height, cam.width):
        raise InputError(f"image {cam.name} is {srgb.shape[1]}x{srgb.shape[0]} but its camera says "
                         f"{cam.width}x{cam.height}", decoded.folder, fix="rerun poses on this decode folder")
    size = (max(1, round(cam.width * scale)), max(1, round(cam.height * scale)))
    clipped = decoded.clipped(cam.name)
    if reach := highlight_margin(decoded.entry(cam.name)):
        clipped = cv2.dilate(clipped.astype(np.uint8), np.ones((2 * reach + 1,) * 2, np.uint8)) > 0
    K = cam.K.copy()
    if scale != 1.0:
        srgb = cv2.resize(srgb, size, interpolation=cv2.INTER_AREA)
        clipped = cv2.resize(clipped.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
        K[0] *= size[0] / cam.width  # pixel (0, 0) is the image corner: every entry scales
        K[1] *= size[1] / cam.height
    return View(cam.name, np.ascontiguousarray(srgb), K, cam.c2w, clipped)


def full_size_mask(mask: np.ndarray, photo: np.ndarray) -> np.ndarray:
    """A working-size mask ``(h, w)`` -> ``(H, W)`` bool at the photo's size, its outline snapped to the photo's
    edges (guided filter of the upsampled mask, guide the photo, radius ~ the scale factor)."""
    H, W = photo.shape[:2]
    if mask.shape == (H, W):
        return mask
    soft = cv2.resize(mask.astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR)
    radius = max(1, round(W / mask.shape[1]))
    snapped = cv2.ximgproc.guidedFilter(photo.astype(np.float32) / 255.0, soft, radius, 1e-3)
    return snapped > 0.5


def reduce(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A full-size bool mask at the working ``shape`` (area average, then half)."""
    if mask.shape == shape:
        return mask
    return cv2.resize(mask.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA) > 0.5
