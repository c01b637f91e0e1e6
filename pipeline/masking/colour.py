"""Colour odds: how much better the room right beside the hull explains a pixel's colour than the hull's deep core.

The last round forces the hull's whole core as object, so that a glossy rim mirroring the room -- lost by colour
in the few views that see it at the outline -- is kept. The same forcing keeps wedges of floor or wall that few
views see past (the blowtorch's carpet between its tank, burner and handle). The two differ in colour: the
wedge *is* the room beside it, while a mirror's rim shows a distorted room whose colours the rest of the mirror
shows as well. So a pixel GrabCut would take as certain object is left to it as probable background where its
colour is far more frequent in the certain background around the object than in the hull's deep core (its log
odds, from colour histograms of the two).
"""

from __future__ import annotations

import cv2
import numpy as np

from .views import disc


def colour_log_odds(image: np.ndarray, background: np.ndarray, object_: np.ndarray, bins: int) -> np.ndarray:
    """``(H, W)`` float32: per pixel, the natural log of p(colour | ``background``) / p(colour | ``object_``),
    each a histogram of ``bins`` per channel over the ``(H, W)`` bool region's pixels of the ``(H, W, 3)`` uint8
    ``image``, with one count added to every bin (a colour neither region shows has odds 1)."""
    q = image.astype(np.int32) * bins // 256
    index = (q[..., 0] * bins + q[..., 1]) * bins + q[..., 2]
    n = bins**3

    def density(region: np.ndarray) -> np.ndarray:
        counts = np.bincount(index[region], minlength=n).astype(np.float64) + 1.0
        return counts / counts.sum()

    return np.log(density(background) / density(object_)).astype(np.float32)[index]


def release_room_colours(image: np.ndarray, seeds: np.ndarray, deep_fraction: float, ring_px: int, bins: int,
                         log_odds: float, min_pixels: int, open_px: int = 0) -> np.ndarray:
    """GrabCut ``seeds`` (``(H, W)`` ``cv2.GC_*`` labels) with their certain object made probable background
    where it is coloured like the room: :func:`colour_log_odds` above ``log_odds``, the object being the certain
    object deeper inside the seeds' object (certain or probable) than ``deep_fraction`` of its deepest pixel's
    distance -- never released -- and the background the certain background within ``ring_px`` of it. With
    ``open_px``, only released pieces wider than a disc of that radius (a mirror's rim shows the room in a thin
    band). Unchanged where either sample has fewer than ``min_pixels``."""
    forced = seeds == cv2.GC_FGD
    obj = (forced | (seeds == cv2.GC_PR_FGD)).astype(np.uint8)
    inside = cv2.distanceTransform(obj, cv2.DIST_L2, 5)
    deep = forced & (inside > deep_fraction * float(inside.max(initial=0.0)))
    ring = (cv2.dilate(obj, disc(ring_px)) > 0) & (seeds == cv2.GC_BGD)
    if np.count_nonzero(deep) < min_pixels or np.count_nonzero(ring) < min_pixels:
        return seeds
    odds = colour_log_odds(image, ring, deep, bins)
    if open_px:  # a piece's odds on average over the disc: noise leaves holes that opening would widen
        odds = cv2.blur(odds, (2 * open_px + 1, 2 * open_px + 1))
    room = forced & ~deep & (odds > log_odds)
    if open_px:
        room = cv2.morphologyEx(room.astype(np.uint8), cv2.MORPH_OPEN, disc(open_px)) > 0
    out = seeds.copy()
    out[room] = cv2.GC_PR_BGD
    return out
