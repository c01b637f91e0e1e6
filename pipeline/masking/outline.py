"""Does a mask's outline follow the photo's edges? A check that needs no other view and no ground truth.

The masks stage's agreement check compares each mask with the visual hull of all of them, and masks that are
wrong the same way in every view agree with their hull: an object whose colours are its surroundings' loses a
part in every view, and the hull loses it too. What such masks cannot hide is where their outline runs: an
object's silhouette is an edge in the photo (the object against what lies behind it), while an outline that cuts
across the object, or through the floor beside it, runs along no edge at all.
"""

from __future__ import annotations

import cv2
import numpy as np

from .views import disc


def gradient_magnitude(image: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` uint8 sRGB -> ``(H, W)`` float32: the Sobel gradient's magnitude in CIELAB (a difference
    of colour as much as of brightness: a brass object on a red carpet may be as bright as the carpet)."""
    lab = cv2.cvtColor(image, cv2.COLOR_RGB2LAB).astype(np.float32)
    gx = cv2.Sobel(lab, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(lab, cv2.CV_32F, 0, 1, ksize=3)
    return np.sqrt((gx * gx + gy * gy).sum(-1))


def edge_support(image: np.ndarray, mask: np.ndarray, band_px: int, contrast: float) -> float | None:
    """The share of the outline of ``mask`` ``(H, W)`` bool that lies on an edge of ``image`` ``(H, W, 3)``
    uint8: outline pixels where the strongest gradient within a pixel is at least ``contrast`` times the median
    gradient in the band ``band_px`` wide on either side of the outline (the local texture's level: a carpet's
    weave is full of weak edges, a plain wall has none). None for an empty or full mask (no outline)."""
    m = mask.astype(np.uint8)
    if not m.any() or m.all():
        return None
    outline = cv2.dilate(m, disc(1)) != cv2.erode(m, disc(1))
    band = (cv2.dilate(m, disc(band_px)) != cv2.erode(m, disc(band_px))) & ~outline
    magnitude = gradient_magnitude(image)
    level = float(np.median(magnitude[band])) if band.any() else 0.0
    strongest = cv2.dilate(magnitude, np.ones((3, 3), np.uint8))[outline]
    # a level of zero (a flat render) would make any noise an edge: one grey level's step is the least that counts
    return float(np.mean(strongest >= contrast * max(level, 1.0)))
