"""Plane sweeps that find what is not the object: a surface outside the unit sphere (props in front, the room
behind), a prop standing in front of the object inside the sphere (planes parallel to the floor between the
camera and the hull), and the floor seen through the hull (holes, overhangs)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ..object_frame import pixels_of, project
from .hull import in_hull
from .support_plane import WINDOW, plane_cost, ranked_cost, window_difference
from .views import Plane, SegmentOptions, View, disc, pixel_rays, sphere_box


def outside_cost(view: View, others: Sequence[View], rank: int, step_px: float, near: float, far: float,
                 match_exposure: bool = False) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]] | None:
    """How well something *outside* the unit sphere -- a prop in front of it, a wall or prop behind it --
    explains each pixel of the sphere's image: the best ``rank``-th neighbour cost of :func:`plane_cost` over
    fronto-parallel planes at depths from ``near`` to ``far`` times the camera's distance from the centre,
    skipping depths inside the sphere along that pixel's ray (and a margin of 2 % of the distance around it).
    Static background is consistent at its depth; the object, inside the sphere, is not, and a glossy object
    is not even at its own depth. Planes are spaced by ``step_px`` of disparity in the widest-baseline
    neighbour.

    Returns:
        (``(h, w)`` float32 cost over the box, the same over the planes behind the sphere alone, ``box``), or None
        when the sphere is not in view.
    """
    box = sphere_box(view)
    if box is None or not others:
        return None
    o, axis = view.c2w[:3, 3], view.c2w[:3, 2]
    d = pixel_rays(view, box)
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    root = np.sqrt(np.maximum(disc, 0.0))
    cos = d @ axis  # z-depth = t * cos
    dist = float(np.linalg.norm(o))
    margin = 0.02 * dist
    entry = np.where(disc > 0, (-b - root) * cos - margin, np.inf)
    exit_ = np.where(disc > 0, (-b + root) * cos + margin, -np.inf)
    z_near, z_far = near * dist, far * dist
    baseline = max(float(np.linalg.norm(other.c2w[:3, 3] - o)) for other in others)
    count = int(np.ceil(view.K[0, 0] * baseline * (1.0 / z_near - 1.0 / z_far) / step_px)) + 1
    best = np.full(entry.shape, np.inf, np.float32)
    beyond = np.full(entry.shape, np.inf, np.float32)
    for inv in np.linspace(1.0 / z_near, 1.0 / z_far, count):
        z = 1.0 / inv
        behind = z > exit_
        valid = (z < entry) | behind
        if not valid.any():
            continue
        cost = plane_cost(view, others, axis, float(axis @ o) + z, rank, box=box, match_exposure=match_exposure)
        np.minimum(best, np.where(valid, cost, np.inf), out=best)
        np.minimum(beyond, np.where(behind, cost, np.inf), out=beyond)
    return best, beyond, box


def local_contrast(image: np.ndarray, window: int = 5) -> np.ndarray:
    """``(H, W)`` float32: the standard deviation of the sRGB values (0..1) over a ``window`` box, averaged over
    the channels. Photo-consistency says nothing about flat patches: they match anywhere nearby."""
    g = image.astype(np.float32) / 255.0
    mu = cv2.blur(g, (window, window))
    return np.sqrt(np.maximum(cv2.blur(g * g, (window, window)) - mu * mu, 0.0)).mean(-1)


def corner_strength(image: np.ndarray, window: int = 5) -> np.ndarray:
    """``(H, W)`` float32: the smaller eigenvalue of the structure tensor of the grey image (0..1, Sobel gradients
    per pixel) over a ``window`` box. Large only where the texture varies in two directions: an edge alone (the
    outline of a light's reflection) matches all along itself, so a plane sweep places it at any depth."""
    g = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    a, b, c = (cv2.blur(x, (window, window)) for x in (gx * gx, gx * gy, gy * gy))
    return (a + c) / 2.0 - np.sqrt(((a - c) / 2.0) ** 2 + b * b)


def occluder_evidence(view: View, others: Sequence[View], opts: SegmentOptions) -> tuple[np.ndarray, np.ndarray]:
    """``(H, W)`` bool twice: textured, unclipped pixels of the sphere's image that a surface outside the sphere
    explains (:func:`outside_cost`) -- a prop in front of the object, the room behind it -- and those a surface
    behind the sphere explains with every pixel of their comparison window: their rays pass the whole sphere,
    object and all, empty. A window that straddles a thin part (a mug's handle) matches the room behind it, so
    its centre alone may be the part's."""
    found = outside_cost(view, others, opts.sweep_rank, opts.sweep_step_px, opts.sweep_near, opts.sweep_far,
                         match_exposure=opts.match_exposure)
    if found is None:
        return np.zeros(view.shape, bool), np.zeros(view.shape, bool)
    cost, beyond, box = found
    whole_window = cv2.erode((beyond < opts.sweep_threshold).astype(np.uint8), np.ones((WINDOW, WINDOW), np.uint8))
    usable = _usable(view, box, opts)
    return _in_box(view, cost < opts.sweep_threshold, box) & usable, _in_box(view, whole_window > 0, box) & usable


def _matched(view: View, cost: np.ndarray, box: tuple[int, int, int, int], threshold: float,
             opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: the pixels of ``box`` whose sweep ``cost`` is under ``threshold`` and :func:`_usable`."""
    return _in_box(view, cost < threshold, box) & _usable(view, box, opts)


def _in_box(view: View, inside: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """``(H, W)`` bool: ``inside`` (``(h, w)`` bool over ``box``) placed in the view, False elsewhere."""
    x0, y0, x1, y1 = box
    out = np.zeros(view.shape, bool)
    out[y0:y1, x0:x1] = inside
    return out


def _usable(view: View, box: tuple[int, int, int, int], opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: the pixels of ``box`` that are textured and away from clipped highlights (a highlight's
    outline can match at a wrong depth; it is never evidence)."""
    x0, y0, x1, y1 = box
    out = _in_box(view, local_contrast(view.image[y0:y1, x0:x1]) > opts.texture_threshold, box)
    if view.clipped is not None:
        out &= ~(cv2.dilate(view.clipped.astype(np.uint8), disc(2)) > 0)
    return out


def front_cost(view: View, others: Sequence[View], plane: Plane, entry: np.ndarray, box: tuple[int, int, int, int],
               rank: int, step: float, margin: float, match_exposure: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(h, w)`` float32 over ``box``: how well something *inside* the unit sphere but in front of the object's
    hull explains each pixel -- the best :func:`plane_cost` over planes parallel to the support plane (a prop's
    top), from ``step`` above it to the top of the sphere, ``step`` apart, counting only where the pixel's ray
    meets the plane more than ``margin`` before it enters the hull (``entry``, :func:`hull_depth`): the object is
    never in front of its hull, a prop the loose sphere holds can be. And ``(h, w)`` float32 the best plane's
    height above the support plane (NaN: none counted)."""
    o = view.c2w[:3, 3]
    facing = pixel_rays(view, box) @ plane.normal
    best = np.full(entry.shape, np.inf, np.float32)
    best_height = np.full(entry.shape, np.nan, np.float32)
    for height in np.arange(step, 1.0 - plane.offset, step):
        offset = plane.offset + height
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset - plane.normal @ o) / facing
        valid = (t > 0) & (t < entry - margin)
        if valid.any():
            cost = np.where(valid, plane_cost(view, others, plane.normal, offset, rank, box=box,
                                              match_exposure=match_exposure), np.inf)
            better = cost < best
            best[better] = cost[better]
            best_height[better] = height
    return best, best_height


def depth_cost(view: View, others: Sequence[View], depth: np.ndarray, box: tuple[int, int, int, int], rank: int,
               window: int = 5, min_views: int = 2) -> np.ndarray:
    """``(h, w)`` float32 over ``box``: how badly the points at distance ``depth`` (``(h, w)`` along each pixel's
    ray; ``inf``: none) explain each pixel -- as :func:`~.support_plane.plane_cost`, with a depth per pixel
    instead of a plane: each neighbour sampled where it sees the point (bilinear), the mean absolute sRGB
    difference over a ``window`` box, the ``rank``-th smallest over the neighbours that see the whole window;
    ``inf`` where no depth is given or fewer than ``min_views`` see it."""
    x0, y0, x1, y1 = box
    h, w = y1 - y0, x1 - x0
    img = np.ascontiguousarray(view.image[y0:y1, x0:x1])
    given = np.isfinite(depth)
    points = view.c2w[:3, 3] + pixel_rays(view, box) * np.where(given, depth, 0.0)[..., None]
    erode = np.ones((window, window), np.uint8)
    costs, count = [], np.zeros((h, w), np.uint8)
    for other in others:
        uv, z = project(points.reshape(-1, 3), other.c2w[None], other.K[None])
        # pixel centres at +0.5 (pixel_rays), cv2.remap's at integers
        mx, my = (uv[0, :, k].reshape(h, w) - 0.5 for k in (0, 1))
        oh, ow = other.shape
        inside = given & (z[0].reshape(h, w) > 1e-6) & (mx >= 0) & (my >= 0) & (mx <= ow - 1) & (my <= oh - 1)
        mx, my = np.where(inside, mx, -1.0).astype(np.float32), np.where(inside, my, -1.0).astype(np.float32)
        warped = cv2.remap(other.image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        seen = cv2.erode(inside.astype(np.uint8), erode) > 0  # the whole window must be seen
        costs.append(np.where(seen, window_difference(img, warped, window), np.float32(np.inf)))
        count += seen
    if not costs:
        return np.full((h, w), np.inf, np.float32)
    return ranked_cost(costs, count, rank, min_views)


def surface_cost(view: View, others: Sequence[View], entry: np.ndarray, box: tuple[int, int, int, int], rank: int,
                 depth: float, step: float) -> np.ndarray:
    """``(h, w)`` float32 over ``box``: how well the object's own surface explains each pixel -- the best
    :func:`depth_cost` from where the ray enters the hull (``entry``, ``(h, w)``; ``inf``: it misses) to ``depth``
    behind it, ``step`` apart (the hull overhangs the object: its surface lies at or behind the entry). ``inf``
    off the hull or where too few neighbours see it."""
    best = np.full(entry.shape, np.inf, np.float32)
    for behind in np.arange(0.0, depth + 1e-9, step):
        np.minimum(best, depth_cost(view, others, entry + behind, box, rank), out=best)
    return best


def _inner(hull: np.ndarray, opts: SegmentOptions) -> np.ndarray:
    """Well inside the hull's image: at its outline a window mixes the object with what is behind it."""
    return cv2.erode(hull.astype(np.uint8), disc(opts.front_inset_px)) > 0


def _blobs_of_corners(view: View, found: np.ndarray, min_px: int, opts: SegmentOptions) -> np.ndarray:
    """``found`` where the texture varies in two directions (:func:`corner_strength`), without its connected pieces
    smaller than ``min_px``: a surface matches in blobs, the object's own chance matches (corners of a reflection)
    in specks."""
    found = (found & (corner_strength(view.image) > opts.front_corner)).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(found, connectivity=8)
    big = np.nonzero(stats[:, cv2.CC_STAT_AREA] >= min_px)[0]
    return np.isin(labels, big[big > 0])


def front_evidence(view: View, others: Sequence[View], plane: Plane, depth: np.ndarray, volume: np.ndarray,
                   max_votes: float, opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: a prop between the camera and the object, inside the sphere -- which the depth sweep outside
    the sphere cannot see and the hull, knowing nothing of occlusion, covers.

    Its top: textured, unclipped pixels of the sphere's image that a plane parallel to the support plane explains
    between the camera and the hull (:func:`front_cost`; ``depth``: :func:`hull_depth`) clearly better than the
    object's own surface behind it does (:func:`surface_cost`, by ``front_surface_margin``: on a plain, noisy
    object -- a grey mug in shadow -- the best of a hundred planes in front matches the noise by chance about as
    well as the surface, a real prop's top far better than the object hidden behind it), in blobs, whose column
    down to the support plane stays out of the hull ``volume < max_votes`` (:func:`column_in_hull`): a prop stands
    on the floor beside the object, while a chance match on the object's own texture floats in front of it with
    the object under it. Its sides: the image of those columns in front of the hull
    (:func:`column_image`), which planes parallel to the floor do not fit."""
    box = sphere_box(view)
    if box is None or not others:
        return np.zeros(view.shape, bool)
    x0, y0, x1, y1 = box
    entry = np.where(_inner(np.isfinite(depth), opts), depth, -np.inf)[y0:y1, x0:x1]
    cost, heights = front_cost(view, others, plane, entry, box, opts.sweep_rank, opts.front_step, opts.front_margin,
                               opts.match_exposure)
    surface = surface_cost(view, others, np.where(np.isfinite(entry), entry, np.inf), box, opts.sweep_rank,
                           opts.front_surface_depth, opts.front_surface_step)
    cost = np.where(cost + opts.front_surface_margin < surface, cost, np.inf)
    tops = _blobs_of_corners(view, _matched(view, cost, box, opts.sweep_threshold, opts), opts.front_min_px, opts)
    ys, xs = np.nonzero(tops[y0:y1, x0:x1])
    if len(ys) == 0:
        return tops
    points = plane_points(view.c2w[:3, 3], pixel_rays(view, box)[ys, xs], plane, heights[ys, xs])
    standing = np.zeros(view.shape, bool)
    keep = column_in_hull(points, plane, volume, max_votes, opts.front_step) <= opts.front_column_share
    standing[ys[keep] + y0, xs[keep] + x0] = True
    tops = _blobs_of_corners(view, standing, opts.front_min_px, opts)
    if not tops.any():
        return tops
    return tops | column_image(view, points[tops[ys + y0, xs + x0]], plane, depth, opts.front_step, opts.front_margin)


def plane_points(origin: np.ndarray, rays: np.ndarray, plane: Plane, heights: np.ndarray) -> np.ndarray:
    """``(M, 3)``: where ``rays`` ``(M, 3)`` from ``origin`` ``(3,)`` meet the planes ``heights`` ``(M,)`` above the
    support plane."""
    t = (plane.offset + heights - plane.normal @ origin) / (rays @ plane.normal)
    return origin + rays * t[:, None]


def column_in_hull(points: np.ndarray, plane: Plane, volume: np.ndarray, max_votes: float, step: float) -> np.ndarray:
    """``(M,)``: the share of each point's column down to the support plane (sampled ``step`` apart) that lies in
    the hull ``volume < max_votes`` (:func:`in_hull`; ``points`` ``(M, 3)`` above the plane)."""
    height = plane.height(points)
    inside = np.zeros(len(points))
    count = np.zeros(len(points))
    for s in np.arange(0.0, float(height.max(initial=0.0)), step):
        below = s <= height
        inside[below] += in_hull(volume, points[below] - s * plane.normal, max_votes)
        count[below] += 1
    return inside / np.maximum(count, 1)


def column_image(view: View, points: np.ndarray, plane: Plane, depth: np.ndarray, step: float,
                 margin: float) -> np.ndarray:
    """``(H, W)`` bool: the image of the columns under ``points`` ``(M, 3)`` down to the support plane (sampled
    ``step`` apart) where they are more than ``margin`` in front of the hull (``depth``, :func:`hull_depth`): a
    box's or a can's side stands under its top."""
    out = np.zeros(view.shape, bool)
    if len(points) == 0:
        return out
    height = plane.height(points)
    o = view.c2w[:3, 3]
    for s in np.arange(0.0, float(height.max()), step):
        p = points[s <= height] - s * plane.normal
        seen, x, y = pixels_of(p, view.c2w, view.K, view.shape)
        front = np.linalg.norm(p[seen] - o, axis=-1) < depth[y, x] - margin
        out[y[front], x[front]] = True
    return cv2.morphologyEx(out.astype(np.uint8), cv2.MORPH_CLOSE, disc(1)) > 0


def floor_through_hull(view: View, others: Sequence[View], plane: Plane, hull: np.ndarray,
                       opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: pixels well inside the hull's reprojection ``hull`` that the support plane explains in at
    least one of ``others`` (other views, on every side: :func:`spread`), textured in two directions
    (:func:`corner_strength`), in blobs:
    the floor seen through a hole in the object or under an overhang, which the hull fills because fewer than
    ``carve_share`` of the views see through it. One view suffices: the few that see through are on every side.
    The object's own matches -- a glossy bottom mirrors the floor next to it -- are flat or edges, and specks."""
    cost = plane_cost(view, others, plane.normal, plane.offset, 1, match_exposure=opts.match_exposure)
    whole = (0, 0, view.shape[1], view.shape[0])
    found = _matched(view, cost, whole, opts.through_threshold, opts) & _inner(hull, opts)
    return _blobs_of_corners(view, found, opts.through_min_px, opts)


def occluded_region(hull: np.ndarray, colour: np.ndarray, swept: np.ndarray | None) -> np.ndarray:
    """``(H, W)`` bool: the parts of the hull's reprojection that GrabCut (``colour``) gave to the background
    and that touch (within 2 px) pixels a surface outside the sphere explains (``swept``): a prop in front of
    the object, which the hull, knowing nothing of occlusion, covers."""
    from scipy.ndimage import label

    out = np.zeros(hull.shape, bool)
    if swept is None or not swept.any():
        return out
    candidates = hull & ~colour
    labels, count = label(candidates)
    if count == 0:
        return out
    touched = np.unique(labels[(cv2.dilate(swept.astype(np.uint8), disc(2)) > 0) & candidates])
    return np.isin(labels, touched[touched > 0])
