"""Between the photos' full size and the working size segmentation runs at: views reduced (area average), masks
brought back up with their outline snapped to the photo's edges."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ..errors import InputError
from .grabcut import grabcut
from .views import View, disc

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


@dataclass(frozen=True)
class EdgeSnap:
    """How a working-size mask's outline is moved onto the photo's edges at full size (:func:`snap_to_edges`;
    the ``masks.snap_*`` settings)."""

    band_px: float  # working pixels either side of the outline (0: off)
    iterations: int  # GrabCut's own iterations
    min_edge_gain: float  # the snapped outline's median image gradient over the upsampled one's, at least
    min_core: float  # the share of the mask farther than the band from its outline, at least


def edge_snap(config: Any) -> EdgeSnap:
    """The :class:`EdgeSnap` of a masks configuration's ``snap_*`` settings (``pipeline.config.MasksConfig``)."""
    return EdgeSnap(config.snap_band_px, config.snap_iterations, config.snap_min_edge_gain, config.snap_min_core)


def full_size_mask(mask: np.ndarray, photo: np.ndarray, snap: EdgeSnap | None = None) -> tuple[np.ndarray, bool]:
    """A working-size mask ``(h, w)`` -> ``(H, W)`` bool at the photo's size, its outline snapped to the photo's
    edges: a guided filter of the upsampled mask (guide the photo, radius ~ the scale factor), then
    :func:`snap_to_edges` within ``snap.band_px`` working pixels. Returns the mask and whether the snap was kept."""
    H, W = photo.shape[:2]
    if mask.shape == (H, W):
        return mask, False
    soft = cv2.resize(mask.astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR)
    radius = max(1, round(W / mask.shape[1]))
    guided = cv2.ximgproc.guidedFilter(photo.astype(np.float32) / 255.0, soft, radius, 1e-3) > 0.5
    if snap is None:
        return guided, False
    return snap_to_edges(guided, photo, round(snap.band_px * W / mask.shape[1]), snap)


def snap_to_edges(mask: np.ndarray, photo: np.ndarray, band_px: int, snap: EdgeSnap) -> tuple[np.ndarray, bool]:
    """``mask`` ``(H, W)`` bool with its outline moved onto the edges of ``photo`` ``(H, W, 3)`` uint8 within
    ``band_px`` pixels of where it is, or ``mask`` itself where that does not find better edges.

    Segmentation runs at the working size, and an outline brought up from there follows the photo's edges only to
    a working pixel (on the blowtorch's 1060x707 photos from 480 px, its median image gradient was half the
    reference masks'). GrabCut at the photo's size decides the band: the mask eroded by ``band_px`` is certain
    object, the mask grown by it the most the object may reach. The result is kept only where it puts the outline
    on clearly stronger edges (``snap.min_edge_gain``): a glossy rim that mirrors the room has its strongest edge
    inside the object, and GrabCut would cut the rim off. Nor where the band is more than a thin margin of the
    mask (``snap.min_core``): a small or thin object's colour model is then mostly band, and the cut can take
    whole parts of it.

    Returns:
        The mask and whether the snap was kept.
    """
    if band_px < 1 or not mask.any():
        return mask, False
    m = mask.astype(np.uint8)
    core = cv2.erode(m, disc(band_px)) > 0
    if np.count_nonzero(core) < snap.min_core * np.count_nonzero(mask):
        return mask, False
    seeds = np.full(mask.shape, cv2.GC_BGD, np.uint8)
    seeds[cv2.dilate(m, disc(band_px)) > 0] = cv2.GC_PR_BGD
    seeds[mask] = cv2.GC_PR_FGD
    seeds[core] = cv2.GC_FGD
    snapped = grabcut(photo, seeds, snap.iterations)
    gradient = image_gradient(photo)
    if outline_gradient(snapped, gradient) < snap.min_edge_gain * outline_gradient(mask, gradient):
        return mask, False
    return snapped, True


def image_gradient(photo: np.ndarray) -> np.ndarray:
    """``(H, W)`` float32 gradient magnitude (Sobel) of ``photo`` ``(H, W, 3)`` uint8's grey."""
    grey = cv2.cvtColor(photo, cv2.COLOR_RGB2GRAY).astype(np.float32)
    return np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))


def outline_gradient(mask: np.ndarray, gradient: np.ndarray) -> float:
    """The median of ``gradient`` ``(H, W)`` over the outline of ``mask`` ``(H, W)`` bool (its pixels with a
    neighbour outside it); 0 for an empty mask."""
    m = mask.astype(np.uint8)
    outline = (m - cv2.erode(m, disc(1))) > 0
    return float(np.median(gradient[outline])) if outline.any() else 0.0


def reduce(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A full-size bool mask at the working ``shape`` (area average, then half)."""
    if mask.shape == shape:
        return mask
    return cv2.resize(mask.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA) > 0.5
