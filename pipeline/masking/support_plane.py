"""The support plane the object stands on, found by photo-consistency: under the plane's homography a floor
pixel -- shadows included -- has the same colour in the neighbouring views, an object pixel does not."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import cv2
import numpy as np

from ..object_frame import camera_up
from .views import Plane, SegmentOptions, View, disc, plane_homography, sphere_distance

log = logging.getLogger("orca.masks")

CHANNEL_MEAN = np.full((1, 3), 1.0 / (3 * 255), np.float32)  # 8-bit RGB difference -> mean over channels, 0..1
# The support plane's search, in radii of the unit sphere: heights along the cameras' up from DEEPEST to SHALLOWEST
# below the centre COARSE apart, then FINE apart within one coarse step of the best; around the sparse points'
# plane, START_SPAN either side FINE apart (a floor is photo-consistent in a band a few hundredths wide); tilts by
# a pattern search from TILT_STEP_DEG, at most MAX_TILT_DEG from where it started.
DEEPEST, SHALLOWEST, COARSE, FINE, START_SPAN = -1.6, -0.02, 0.04, 0.01, 0.04
TILT_STEP_DEG, MAX_TILT_DEG, TILT_ROUNDS = 4.0, 10.0, 3


def exposure_gains(image: np.ndarray, warped: np.ndarray, seen: np.ndarray, min_pixels: int = 200,
                   stride: int = 4, limit: float = 8.0) -> np.ndarray:
    """``(3,)`` float32 per-channel gains that bring ``warped`` (another photo resampled into ``image``'s grid,
    both ``(h, w, 3)`` uint8) to ``image``'s exposure and white balance: the ratio of their medians over the
    pixels both see (``seen`` ``(h, w)`` bool; every ``stride``-th row and column). Photos of one capture often
    differ by stops (auto exposure, changed settings) and in tint (auto white balance); a ratio of medians is
    robust to the parts of the overlap that do not match. 1 where fewer than ``min_pixels`` are seen; clamped to
    ``[1/limit, limit]``."""
    pick = seen[::stride, ::stride]
    if np.count_nonzero(pick) < min_pixels:
        return np.ones(3, np.float32)
    a = np.median(image[::stride, ::stride][pick], axis=0)
    b = np.median(warped[::stride, ::stride][pick], axis=0)
    return np.clip((a + 1.0) / (b + 1.0), 1.0 / limit, limit).astype(np.float32)


def window_stats(grey: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """``(h, w)`` float32 grey -> its mean and variance over a ``window`` box around each pixel."""
    mean = cv2.blur(grey, (window, window))
    return mean, np.maximum(cv2.blur(grey * grey, (window, window)) - mean * mean, 0.0)


def zncc_cost(grey: np.ndarray, stats: tuple[np.ndarray, np.ndarray], warped: np.ndarray, window: int,
              min_std: float) -> np.ndarray:
    """``(h, w)`` float32: one minus the zero-mean normalized cross-correlation of ``grey`` (its
    :func:`window_stats` ``stats``) and ``warped`` (both ``(h, w)`` float32 grey, 0..255) over a ``window`` box,
    0 (same pattern) .. 2 (inverted); ``inf`` where either window is flatter than ``min_std`` grey levels (no
    pattern to compare: a plain floor matches at any height). Unlike a colour difference it ignores the photos'
    exposure, white balance and tone curve, and on a fine texture (a carpet's weave) it tells aligned from
    misaligned where a difference of colours is as large for both."""
    mean, var = stats
    w_mean, w_var = window_stats(warped, window)
    cov = cv2.blur(grey * warped, (window, window)) - mean * w_mean
    flat = np.minimum(var, w_var) < min_std * min_std
    cost = 1.0 - cov / np.sqrt(np.maximum(var * w_var, 1e-6))
    return np.where(flat, np.float32(np.inf), cost).astype(np.float32)


WINDOW = 5  # pixels: the box over which plane_cost compares a view with its neighbours


def plane_cost(view: View, others: Sequence[View], normal: np.ndarray, offset: float, rank: int,
               window: int = WINDOW, box: tuple[int, int, int, int] | None = None, min_views: int = 2,
               match_exposure: bool = False, zncc_min_std: float | None = None) -> np.ndarray:
    """``(h, w)`` float32 over ``box`` (default: the whole image): how badly the plane ``normal . x = offset``
    explains each pixel -- the ``rank``-th smallest (1-based) over the neighbours of the mean absolute sRGB
    difference (0..1) over a ``window`` box; each neighbour first brought to the view's exposure and white
    balance (:func:`exposure_gains`) when ``match_exposure``. With ``zncc_min_std`` the cost is instead
    :func:`zncc_cost` of the grey images (``inf`` on flat windows: no evidence).

    Only neighbours that see the plane's point count: it must land inside their image. With fewer such neighbours
    than ``rank`` the rank drops to their number; with fewer than ``min_views`` the cost is ``inf`` (no
    evidence)."""
    H_, W_ = view.shape
    x0, y0, x1, y1 = box if box is not None else (0, 0, W_, H_)
    size = (x1 - x0, y1 - y0)
    if len(others) == 0:
        return np.full((size[1], size[0]), np.inf, np.float32)
    shift = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])  # crop pixel -> image pixel
    img = np.ascontiguousarray(view.image[y0:y1, x0:x1])
    zncc = zncc_min_std is not None
    if zncc:
        grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)
        stats = window_stats(grey, window)
    erode = np.ones((window, window), np.uint8)
    costs, count = [], np.zeros((size[1], size[0]), np.uint8)
    for other in others:
        H = plane_homography(view, other, normal, offset) @ shift
        warped = cv2.cvtColor(cv2.warpPerspective(other.rgba, H, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                                  borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0)),
                              cv2.COLOR_RGBA2RGB)
        visible = np.ones(other.shape, np.uint8)
        seen = cv2.warpPerspective(visible, H, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        seen = cv2.erode(seen, erode) > 0  # the whole window must be seen
        if zncc:
            diff = zncc_cost(grey, stats, cv2.cvtColor(warped, cv2.COLOR_RGB2GRAY).astype(np.float32), window,
                             zncc_min_std)
        else:
            if match_exposure:  # in 8 bits, saturating: what the brighter photo would have clipped
                warped = cv2.multiply(warped, (*exposure_gains(img, warped, seen).tolist(), 0.0))
            diff = window_difference(img, warped, window)
        costs.append(np.where(seen, diff, np.float32(np.inf)))
        count += seen
    return ranked_cost(costs, count, rank, min_views)


def ranked_cost(costs: Sequence[np.ndarray], count: np.ndarray, rank: int, min_views: int) -> np.ndarray:
    """``(h, w)`` float32: each pixel's ``rank``-th smallest (1-based) of ``costs`` (one ``(h, w)`` per neighbour,
    ``inf`` where that neighbour does not see the pixel), the rank dropping to ``count`` (``(h, w)``: neighbours
    that see it) where fewer see it; ``inf`` where fewer than ``min(min_views, rank)`` do (no evidence)."""
    ordered = sorted_elementwise(costs)
    top = min(rank, len(costs))
    out = ordered[top - 1]
    for k in range(1, top):  # fewer neighbours see the pixel than the rank: the worst of those that do
        out = np.where(count == k, ordered[k - 1], out)
    return np.where(count >= min(min_views, rank), out, np.inf).astype(np.float32)


def window_difference(image: np.ndarray, warped: np.ndarray, window: int) -> np.ndarray:
    """``(h, w)`` float32: the mean absolute difference of two ``(h, w, 3)`` uint8 sRGB images over the channels and
    a ``window`` box, 0..1."""
    # |a - b| of 8-bit values is exact in 8 bits; the channel mean and the 0..1 scale in one transform
    return cv2.blur(cv2.transform(cv2.absdiff(warped, image).astype(np.float32), CHANNEL_MEAN), (window, window))


def sorted_elementwise(arrays: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``arrays`` (K of the same shape) sorted pixel by pixel: the k-th output holds each pixel's k-th smallest
    value. An odd-even transposition network of elementwise min/max -- for the few neighbours compared here
    (K <= 8) many times faster than numpy's sort along a stacked axis."""
    out = list(arrays)
    for step in range(len(out)):
        for i in range(step % 2, len(out) - 1, 2):
            out[i], out[i + 1] = np.minimum(out[i], out[i + 1]), np.maximum(out[i], out[i + 1])
    return out


def _tilted(normal: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """``normal`` rotated by small angles (radians) about two axes perpendicular to it."""
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    n = normal + ax * a + ay * b
    return n / np.linalg.norm(n)


def floor_measures(opts: SegmentOptions) -> tuple[str, ...]:
    """The measures ``opts.floor_measure`` names: ``"sad"``, ``"zncc"`` or both (a pixel any of them explains)."""
    return ("sad", "zncc") if opts.floor_measure == "both" else (opts.floor_measure,)


def floor_cost(view: View, others: Sequence[View], normal: np.ndarray, offset: float, opts: SegmentOptions,
               measure: str) -> np.ndarray:
    """:func:`plane_cost` by ``measure`` (``"sad"`` or ``"zncc"``), for the support plane and the floor."""
    if measure == "zncc":
        return plane_cost(view, others, normal, offset, opts.consistency_rank, window=opts.zncc_window,
                          zncc_min_std=opts.zncc_min_std)
    return plane_cost(view, others, normal, offset, opts.consistency_rank, match_exposure=opts.match_exposure)


def floor_thresholds(opts: SegmentOptions, measure: str) -> tuple[float, float, float]:
    """``(floor, margin, not_floor)`` thresholds on :func:`floor_cost` by ``measure``."""
    if measure == "zncc":
        return opts.zncc_floor_threshold, opts.zncc_floor_margin, opts.zncc_not_floor_threshold
    return opts.floor_threshold, opts.floor_margin, opts.not_floor_threshold


def find_support_plane(views: Sequence[View], nbrs: Sequence[Sequence[int]], opts: SegmentOptions,
                       start: Plane | None = None, samples: int = 6, min_fraction: float = 0.08) -> Plane | None:
    """The plane the object stands on, by photo-consistency (see the module doc), or None if no plane within
    ~10 degrees of the cameras' up or of ``start`` explains at least ``min_fraction`` of the pixels outside the
    unit sphere's image.

    Searched: offsets along the up vector from 1.6 below the centre to just below it (coarse, then fine) and, with
    ``start`` (the sparse points' plane), offsets near it along its normal; then from the better of the two, tilts
    of up to ~8 degrees (the cameras' mean up is off by the photographer's average tilt; the sparse points' plane
    is off by their noise). A real floor explains its pixels in a band of heights a few hundredths of a radius
    wide, and the cameras' up can be 10 degrees from it (a walk-around with more photos from one side): the start
    finds what a coarse search along the cameras' up misses."""
    up = camera_up(np.stack([v.c2w for v in views]))
    spread_out = np.unique(np.linspace(0, len(views) - 1, min(samples, len(views))).round().astype(int))
    regions = {int(i): sphere_distance(views[i]) >= 1.0 for i in spread_out}
    # a view the sphere's image fills (an object filling the frame) shows no pixel around the object to explain
    pick = [i for i in regions if regions[i].any()]
    if not pick:
        log.info("no support plane: the object's sphere fills the sampled views, leaving no pixels around it")
        return None

    def score(normal: np.ndarray, offset: float) -> float:
        fractions = []
        for i in pick:
            explained = np.zeros(views[i].shape, bool)
            for m in floor_measures(opts):
                cost = floor_cost(views[i], [views[j] for j in nbrs[i]], normal, offset, opts, m)
                explained |= cost < floor_thresholds(opts, m)[0]
            fractions.append(float(explained[regions[i]].mean()))
        return float(np.mean(fractions))

    def best_offset(normal: np.ndarray, offsets: np.ndarray) -> tuple[float, np.ndarray, float]:
        return max(((score(normal, float(d)), normal, float(d)) for d in offsets), key=lambda t: t[0])

    def around(offset: float, span: float) -> np.ndarray:
        return np.arange(offset - span, offset + span + FINE / 2, FINE)

    coarse = best_offset(up, np.arange(DEEPEST, SHALLOWEST, COARSE))
    best = max(coarse, best_offset(up, around(coarse[2], COARSE - FINE)), key=lambda t: t[0])
    if start is not None:
        best = max(best, best_offset(start.normal, around(start.offset, START_SPAN)), key=lambda t: t[0])
    origin = best[1]
    step = np.radians(TILT_STEP_DEG)
    for _ in range(TILT_ROUNDS):  # a small pattern search over the tilt, the offset re-fitted locally each time
        improved = False
        for ax, ay in ((step, 0), (-step, 0), (0, step), (0, -step)):
            n = _tilted(best[1], ax, ay)
            if np.degrees(np.arccos(np.clip(n @ origin, -1, 1))) > MAX_TILT_DEG:
                continue
            for d in (best[2] - FINE, best[2], best[2] + FINE):
                s = score(n, d)
                if s > best[0] + 1e-4:
                    best, improved = (s, n, d), True
        if not improved:
            step /= 2
    fraction, normal, offset = best
    if fraction < min_fraction:
        log.info("no support plane: the best plane explains %.0f %% of the pixels around the object "
                 "(needs %.0f %%)", 100 * fraction, 100 * min_fraction)
        return None
    return Plane(normal, float(offset), fraction)


def floor_evidence(view: View, others: Sequence[View], plane: Plane, outside: np.ndarray,
                   opts: SegmentOptions) -> tuple[np.ndarray, np.ndarray]:
    """``(floor, above)``, each ``(H, W)`` bool over the sphere's image (not ``outside``): pixels the support
    plane explains, and pixels it clearly does not (cost over ``not_floor_threshold``).

    A floor pixel must match at the plane's height *only*: the same plane moved ``floor_shift`` sphere radii down
    must explain it worse by ``floor_margin``. A flat patch matches under any homography -- a dark floating torus
    whose neighbours see more of the same torus where the plane puts its floor, a plain table -- and is no
    evidence either way. An opening drops isolated specks (chance matches on the object's flat patches)."""
    floor, above = np.zeros(view.shape, bool), None
    for m in floor_measures(opts):
        threshold, margin, not_floor = floor_thresholds(opts, m)
        cost = floor_cost(view, others, plane.normal, plane.offset, opts, m)
        found = (cost < threshold) & ~outside
        if opts.floor_shift > 0:
            for shift in (-opts.floor_shift, opts.floor_shift):
                found &= floor_cost(view, others, plane.normal, plane.offset + shift, opts, m) >= cost + margin
        floor |= cv2.morphologyEx(found.astype(np.uint8), cv2.MORPH_OPEN, disc(1)) > 0
        if above is None:  # the first measure's: with both, the colour difference's, as with it alone
            # ZNCC's inf is a flat window, no evidence; the colour difference's (too few neighbours see the pixel)
            # has always counted as off the plane
            above = cost > not_floor if m == "sad" else (cost > not_floor) & np.isfinite(cost)
    return floor, above & ~outside
