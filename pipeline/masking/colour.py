"""Colour odds: how much better the room right beside the hull explains a pixel's colour than the hull's deep core.

The last round forces the hull's whole core as object, so that a glossy rim mirroring the room -- lost by colour
in the few views that see it at the outline -- is kept. The same forcing keeps wedges of floor or wall that few
views see past (the blowtorch's carpet between its tank, burner and handle). The two differ in colour: the
wedge *is* the room beside it, while a mirror's rim shows a distorted room whose colours the rest of the mirror
shows as well. So a pixel GrabCut would take as certain object is left to it as probable background where its
colour is far more frequent in the certain background around the object than in the hull's deep core (its log
odds, from colour histograms of the two).

The same odds trim the final masks where some view sees through the hull (:func:`trim_room_colours`): a gap
shows what the view shows beside the object, and the object's colours, pooled over the whole capture, are not
that. And they decide the converse (:func:`restore_object_colours`): a piece of the hull that no more than a few
views see past, which a view's colours gave to the room although its colour is no likelier there than on the
object (a white mug's shadowed side on its dark shadow), goes back to the object.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from .views import disc


def colour_index(image: np.ndarray, bins: int) -> np.ndarray:
    """``(H, W)`` int32: each pixel's colour histogram bin, ``bins`` per channel of the ``(H, W, 3)`` uint8
    ``image``."""
    q = image.astype(np.int32) * bins // 256
    return (q[..., 0] * bins + q[..., 1]) * bins + q[..., 2]


def log_odds_table(background: np.ndarray, object_: np.ndarray) -> np.ndarray:
    """``(B,)`` float32: per bin, the natural log of p(bin | background) / p(bin | object), from the two
    ``(B,)`` histograms' counts with one count added to every bin (a colour neither shows has odds 1)."""
    b, o = background.astype(np.float64) + 1.0, object_.astype(np.float64) + 1.0
    return np.log((b / b.sum()) / (o / o.sum())).astype(np.float32)


def colour_log_odds(image: np.ndarray, background: np.ndarray, object_: np.ndarray, bins: int) -> np.ndarray:
    """``(H, W)`` float32: per pixel, the natural log of p(colour | ``background``) / p(colour | ``object_``),
    each a histogram of ``bins`` per channel over the ``(H, W)`` bool region's pixels of the ``(H, W, 3)`` uint8
    ``image``, with one count added to every bin (a colour neither region shows has odds 1)."""
    index = colour_index(image, bins)
    n = bins**3
    return log_odds_table(np.bincount(index[background], minlength=n),
                          np.bincount(index[object_], minlength=n))[index]


def room_pieces(odds: np.ndarray, region: np.ndarray, log_odds: float, open_px: int) -> np.ndarray:
    """``(H, W)`` bool: the pixels of the ``(H, W)`` bool ``region`` whose ``(H, W)`` float32 colour ``odds``
    (:func:`colour_log_odds`) are above ``log_odds``; with ``open_px``, the odds averaged over a disc of that
    radius and only pieces wider than it (a mirror's rim shows the room in a thin band)."""
    if open_px:  # a piece's odds on average over the disc: noise leaves holes that opening would widen
        odds = cv2.blur(odds, (2 * open_px + 1, 2 * open_px + 1))
    room = region & (odds > log_odds)
    if open_px:
        room = cv2.morphologyEx(room.astype(np.uint8), cv2.MORPH_OPEN, disc(open_px)) > 0
    return room


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
    room = room_pieces(colour_log_odds(image, ring, deep, bins), forced & ~deep, log_odds, open_px)
    out = seeds.copy()
    out[room] = cv2.GC_PR_BGD
    return out


def mask_samples(mask: np.ndarray, core_px: int, band_px: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``(H, W)`` bool each: the object's sample, ``mask`` eroded by ``core_px``, and the room's, the ring from
    ``band_px[0]`` to ``band_px[1]`` pixels outside it."""
    m = mask.astype(np.uint8)
    core = cv2.erode(m, disc(core_px)) > 0 if core_px else mask
    band = (cv2.dilate(m, disc(band_px[1])) > 0) & ~(cv2.dilate(m, disc(band_px[0])) > 0)
    return core, band


def trim_room_colours(images: Sequence[np.ndarray], masks: Sequence[np.ndarray],
                      trimmable: Sequence[np.ndarray | None], bins: int, log_odds: float, capture_log_odds: float,
                      open_px: int, core_px: int, band_px: tuple[int, int], min_pixels: int) -> list[np.ndarray]:
    """The ``(H, W)`` bool ``masks`` of the ``(H, W, 3)`` uint8 ``images`` less the pieces coloured like the room
    within each view's ``(H, W)`` bool ``trimmable`` region (None: the view is left as it is), wider than a disc of
    ``open_px``. The object's colours are pooled over all views (every mask eroded by ``core_px``), and a piece
    goes where its colour (:func:`log_odds_table`, ``bins`` per channel, averaged over that disc) is

    * ``log_odds`` likelier in this view's room, the ring ``band_px`` outside its mask (:func:`mask_samples`),
      than on the object: a gap shows what lies behind the object in this view, and that is what this view shows
      beside it -- the blowtorch's low views see a white cabinet through the gap between handle and tank, a colour
      the rest of the capture, which sees the carpet around the object, rarely shows beside it;
    * and ``capture_log_odds`` likelier in the room around every view's mask than on the object: a part coloured
      like the room behind it in one view (a dark burner against dark wood in an underexposed photo) has the
      object's colours over the whole capture.

    A mirror shows the room too, over its core as well, and a glossy rim in a band (thin, or in no gap the views
    see through: the caller's ``trimmable``). A view whose ring has fewer than ``min_pixels`` uses the pooled ring;
    unchanged where either pooled sample has fewer."""
    indices = [colour_index(im, bins) for im in images]
    tables = room_odds_tables(indices, masks, bins, core_px, band_px, min_pixels)
    if tables is None:
        return list(masks)
    views, capture = tables
    out = []
    for index, mask, where, view in zip(indices, masks, trimmable, views):
        if where is None:
            out.append(mask)
            continue
        region = mask & where
        room_like = (room_pieces(view[index], region, log_odds, open_px)
                     & room_pieces(capture[index], region, capture_log_odds, open_px))
        out.append(mask & ~room_like)
    return out


def room_odds_tables(indices: Sequence[np.ndarray], masks: Sequence[np.ndarray], bins: int, core_px: int,
                     band_px: tuple[int, int], min_pixels: int,
                     unsure: Sequence[np.ndarray | None] | None = None
                     ) -> tuple[list[np.ndarray], np.ndarray] | None:
    """Per view, the ``(B,)`` :func:`log_odds_table` of the ring ``band_px`` outside its ``(H, W)`` bool mask (less
    the view's ``unsure`` pixels, where given) against the object's colours pooled over every view (each mask
    eroded by ``core_px``; :func:`mask_samples`), from the views' ``(H, W)`` colour ``indices``
    (:func:`colour_index`, ``bins`` per channel); and the capture's table, every view's ring pooled, which a view
    whose ring has fewer than ``min_pixels`` takes as its own. None when either pooled sample has fewer."""
    n = bins**3
    rooms, obj = [], np.zeros(n, np.int64)
    for k, (index, mask) in enumerate(zip(indices, masks)):
        core, band = mask_samples(mask, core_px, band_px)
        if unsure is not None and unsure[k] is not None:
            band = band & ~unsure[k]
        obj += np.bincount(index[core], minlength=n)
        rooms.append(np.bincount(index[band], minlength=n))
    room = np.sum(rooms, axis=0)
    if obj.sum() < min_pixels or room.sum() < min_pixels:
        return None
    capture = log_odds_table(room, obj)
    return [log_odds_table(own, obj) if own.sum() >= min_pixels else capture for own in rooms], capture


def restore_object_colours(images: Sequence[np.ndarray], masks: Sequence[np.ndarray],
                           restorable: Sequence[np.ndarray | None], bins: int, log_odds: float, piece_px: int,
                           blur_px: int, core_px: int, band_px: tuple[int, int], min_pixels: int
                           ) -> list[np.ndarray]:
    """The ``(H, W)`` bool ``masks`` of the ``(H, W, 3)`` uint8 ``images`` with the pieces of each view's ``(H, W)``
    bool ``restorable`` region (None: none) wider than a disc of ``piece_px`` added back where their colour is
    not ``log_odds`` likelier in the view's room than on the object (:func:`room_odds_tables`, the odds averaged
    over a square of ``2 blur_px + 1`` pixels; the room's sample leaves the restorable pixels out, which lie
    beside the mask and are what is in question): the colours that lost them say nothing either way. The room's
    colours stay out: a gap the hull kept shows the room behind, and the view's colours were right to take it."""
    indices = [colour_index(im, bins) for im in images]
    tables = room_odds_tables(indices, masks, bins, core_px, band_px, min_pixels, restorable)
    if tables is None:
        return list(masks)
    out = []
    for index, mask, where, view in zip(indices, masks, restorable, tables[0]):
        if where is None:
            out.append(mask)
            continue
        pieces = cv2.morphologyEx(where.astype(np.uint8), cv2.MORPH_OPEN, disc(piece_px)) > 0 if piece_px else where
        odds = cv2.blur(view[index], (2 * blur_px + 1, 2 * blur_px + 1)) if blur_px else view[index]
        out.append(mask | (pieces & (odds < log_odds)))
    return out
