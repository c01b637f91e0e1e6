"""The visual hull: voxels of the unit sphere carved by the views' masks, with votes (a few views, not one, must
see a voxel off the object), and its reprojection into a view."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..object_frame import pixels_of
from .parallel import MapViews, serial
from .views import Plane, SegmentOptions, View, pixel_rays, sphere_box


def voxel_centres(resolution: int) -> np.ndarray:
    """``(R, R, R, 3)`` float64: the centres of the ``resolution``^3 grid's voxels over [-1, 1]^3."""
    ax = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    return np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1)


def hull_grid(resolution: int, plane: Plane | None) -> tuple[np.ndarray, np.ndarray]:
    """Voxel centres ``(V, 3)`` of the ``resolution``^3 grid over [-1, 1]^3 that lie in the unit sphere and
    above the support plane or less than a voxel below it, and their flat indices ``(V,)`` into the grid. The layer
    under the plane is carved with the rest so that the votes just above the plane interpolate with carved ones,
    not with the outside's; :func:`stand_on_plane` then gives it its column's votes and :func:`in_hull` cuts the
    hull at the plane itself."""
    grid = voxel_centres(resolution).reshape(-1, 3)
    keep = np.einsum("ij,ij->i", grid, grid) < 1.0
    if plane is not None:
        keep &= plane.height(grid) > -2.0 / resolution
    index = np.nonzero(keep)[0]
    return grid[index].astype(np.float32), index


OUTSIDE_VOTES = 1.0e3  # the "background votes" of voxels outside the carved region


CARVE_GROUPS = 8  # fixed, not the worker count: the sums, and so the hull, do not depend on the machine


def _groups(n: int) -> list[range]:
    return [range(g, n, CARVE_GROUPS) for g in range(min(CARVE_GROUPS, n))]


def voxel_pixels(points: np.ndarray, views: Sequence[View], run_views: MapViews = serial) -> list[np.ndarray]:
    """Where each of ``points`` ``(M, 3)`` lands in each view: per view ``(M,)`` int32, the flat index of its pixel
    in the view's ``(H, W)`` image, -1 where the view does not see it. The carves of a run share the views and the
    grid, so they share this: projecting the million voxel centres was most of a carve's time (4.4 MB per view at
    the default 128^3 grid)."""
    parts = run_views(_project_views, [(points, [views[i] for i in g]) for g in _groups(len(views))], lambda: None)
    out: list[np.ndarray] = [np.empty(0, np.int32)] * len(views)
    for g, part in zip(_groups(len(views)), parts):
        for i, p in zip(g, part):
            out[i] = p
    return out


def _project_views(points: np.ndarray, views: Sequence[View]) -> list[np.ndarray]:
    out = []
    for v in views:
        inside, x, y = pixels_of(points, v.c2w, v.K, v.shape)
        flat = np.full(len(points), -1, np.int32)
        flat[inside] = y * v.shape[1] + x
        out.append(flat)
    return out


def carve(masks: Sequence[np.ndarray], pixels: Sequence[np.ndarray], index: np.ndarray, resolution: int,
          weights: Sequence[np.ndarray | None] | None = None, run_views: MapViews = serial) -> np.ndarray:
    """``(R, R, R)`` float32 background votes: for each voxel, in how many views that see it it lands off the
    object (:data:`OUTSIDE_VOTES` for voxels outside the region or seen by fewer than half the views). The hull
    is where the votes are below a small number: one view's mistake does not cut the object, while a voxel next
    to a thin object, off its silhouette in only the few views that look along the thin side, is still cut.
    ``pixels``: the region's voxels (flat grid indices ``index`` ``(M,)``) in each view, :func:`voxel_pixels`;
    ``weights``: per view, ``(H, W)`` float32 what a background vote from each pixel counts (None: 1 everywhere;
    less where the vote is doubtful). The views are counted in :data:`CARVE_GROUPS` groups by ``run_views``."""
    weights = weights if weights is not None else [None] * len(masks)
    parts = run_views(view_votes, [([pixels[i] for i in g], [masks[i] for i in g], [weights[i] for i in g])
                                   for g in _groups(len(masks))], lambda: None)
    seen = np.sum([p[0] for p in parts], axis=0)
    off = np.sum([p[1] for p in parts], axis=0, dtype=np.float32)
    votes = np.where(seen >= 0.5 * len(masks), off, OUTSIDE_VOTES).astype(np.float32)
    volume = np.full(resolution**3, OUTSIDE_VOTES, np.float32)
    volume[index] = votes
    return volume.reshape((resolution,) * 3)


def view_votes(pixels: Sequence[np.ndarray], masks: Sequence[np.ndarray], weights: Sequence[np.ndarray | None]
               ) -> tuple[np.ndarray, np.ndarray]:
    """For the voxels ``pixels`` places in each view (:func:`voxel_pixels`): in how many of the views each lands
    inside the image ``(M,)`` int32, and its background votes there ``(M,)`` float32 (see :func:`carve`)."""
    seen = np.zeros(len(pixels[0]), np.int32)
    off = np.zeros(len(pixels[0]), np.float32)
    for p, m, w in zip(pixels, masks, weights):
        inside = np.nonzero(p >= 0)[0]
        flat = p[inside]
        seen[inside] += 1
        vote = ~m.reshape(-1)[flat]
        off[inside] += vote if w is None else vote * w.reshape(-1)[flat]
    return seen, off


def stand_on_plane(volume: np.ndarray, plane: Plane | None, height: float) -> np.ndarray:
    """``(R, R, R)`` float32: the votes ``volume`` (as they are without a ``plane``) with every voxel less than
    ``height`` (at least a voxel) above the support ``plane`` given the fewest votes along its column up to that
    height (the normal's direction, sampled every half voxel): the hull stands on the plane wherever it comes
    that close to it. A glossy object's bottom rim mirrors the floor beside it, every view's colours give it to
    the floor, and the carved hull stops short of the plane by that rim (on the blowtorch's tank, a band along
    every view's bottom outline). The voxels less than a voxel below the plane (:func:`hull_grid`), which only
    the interpolation just above it reads (:func:`in_hull` cuts the hull at the plane), take their column's votes
    from the plane up, not their own: the carve of the space under the object, which no view sees, stops
    wherever the views' rays below the outline happen to pass, and the hull's bottom is its lowest layer's
    outline instead."""
    if plane is None:
        return volume
    res = volume.shape[0]
    voxel = 2.0 / res
    height = max(height, voxel)
    grid = voxel_centres(res)
    above = plane.height(grid)
    low = np.nonzero((above > -voxel) & (above < height) & (np.einsum("...i,...i->...", grid, grid) < 1.0))
    points, level = grid[low], above[low]
    out = volume.copy()
    votes = np.where(level >= 0.0, out[low], OUTSIDE_VOTES).astype(np.float32)
    step = voxel / 2.0
    for t in np.arange(step, float(height - level.min(initial=0.0)) + step, step):
        column = (t <= height - level) & (t >= -level)
        votes[column] = np.minimum(votes[column], _votes_at(volume, points[column] + t * plane.normal))
    out[low] = votes
    return out


def _votes_at(volume: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(M,)`` float32: the votes ``volume`` interpolated trilinearly at ``points`` ``(M, 3)`` (as :func:`in_hull`)."""
    from scipy.ndimage import map_coordinates

    res = volume.shape[0]
    idx = (points + 1.0) * (res / 2.0) - 0.5
    return map_coordinates(volume, idx.T, order=1, mode="constant", cval=OUTSIDE_VOTES).astype(np.float32)


def carve_votes(opts: SegmentOptions, views: int) -> float:
    """Background votes that cut a voxel: ``carve_share`` of the views, at least ``carve_votes``."""
    return max(opts.carve_votes, round(opts.carve_share * views))


def core_carve_votes(opts: SegmentOptions, views: int) -> float | None:
    """Background votes that cut a voxel from the tighter hull GrabCut's core comes from: ``core_carve_share`` of
    the views, at least ``core_carve_votes``; None where that hull is the hull itself (no fewer votes) or off."""
    if opts.core_carve_share is None:
        return None
    votes = max(opts.core_carve_votes, round(opts.core_carve_share * views))
    return votes if votes < carve_votes(opts, views) else None


def in_hull(volume: np.ndarray, points: np.ndarray, max_votes: float, plane: Plane | None = None) -> np.ndarray:
    """``(M,)`` bool: which of ``points`` ``(M, 3)`` lie in the hull ``volume < max_votes`` (``volume``: votes over
    the grid on [-1, 1]^3, interpolated trilinearly, so the outline is finer than the voxels) and, given the
    support ``plane``, on or above it."""
    inside = _votes_at(volume, points) < max_votes
    return inside & (plane.height(points) >= 0.0) if plane is not None else inside


# a sample is in the hull only if a hull voxel's centre lies less than 1 voxel from it along every axis, and its
# nearest centre is at most 0.5 away: 1.5 voxels, and a little for rounding
CLEARANCE_MARGIN = 1.5 + 1.0e-3


def hull_extent(volume: np.ndarray, max_votes: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The voxel index box ``(first (3,), last (3,))`` (inclusive; may reach one voxel past the grid) outside which
    :func:`in_hull` is false for certain: the hull's voxels one voxel further out (a trilinear value mixes the 8
    nearest centres, and is below ``max_votes`` only if one of them is). None when the hull is empty."""
    occupied = np.argwhere(volume < max_votes)
    if len(occupied) == 0:
        return None
    return occupied.min(0) - 1, occupied.max(0) + 1


def hull_depth(volume: np.ndarray, view: View, max_votes: float, plane: Plane | None = None) -> np.ndarray:
    """``(H, W)`` float32: the distance along each pixel's ray to where it enters the hull ``volume < max_votes``
    cut at the support ``plane`` (:func:`in_hull`; ``inf``: it misses), marching in steps of half a voxel through
    the unit sphere.

    A ray is sampled only inside the hull's box (:func:`hull_extent`), only until it enters, and it leaps over the
    samples its :func:`clearance` shows cannot be in the hull: the samples that decide and the answer are those
    of marching every ray through the whole sphere, at a fraction of the cost."""
    out = np.full(view.shape, np.inf, np.float32)
    box, extent = sphere_box(view), hull_extent(volume, max_votes)
    if box is None or extent is None:
        return out
    x0, y0, x1, y1 = box
    res = volume.shape[0]
    bounds = [(e + 0.5) * (2.0 / res) - 1.0 for e in extent]
    d = pixel_rays(view, box).reshape(-1, 3)
    o = view.c2w[:3, 3]
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = np.nonzero(disc > 0)[0]
    d, b, root = d[hit], b[hit], np.sqrt(disc[hit])
    t0, t1 = -b - root, -b + root
    steps = int(np.ceil(2.0 * res))  # the diameter (2) in half voxels (2 / res each)
    # each ray's samples k (at t0 + (t1 - t0) (k + 0.5) / steps) inside the box: slabs, axis by axis
    with np.errstate(divide="ignore", invalid="ignore"):
        near = (bounds[0][None] - o) / d
        far = (bounds[1][None] - o) / d
    enter = np.nanmax(np.minimum(near, far), axis=1)
    leave = np.nanmin(np.maximum(near, far), axis=1)
    scale = steps / (t1 - t0)
    k_first = np.maximum(np.ceil((enter - t0) * scale - 0.5), 0)
    k_last = np.minimum(np.floor((leave - t0) * scale - 0.5), steps - 1)
    step_voxels = np.abs(d).max(1) / scale * (res / 2.0)  # how far a step moves, in voxels along the longest axis
    lo, hi = np.maximum(extent[0], 0), np.minimum(extent[1], res - 1)  # the samples stay in the box
    free = clearance(volume[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1], max_votes)
    last = np.array(free.shape) - 1
    entry = np.full(len(d), np.inf, np.float32)
    rays = np.nonzero(k_first <= k_last)[0]
    k = k_first[rays]
    while len(rays):
        t = t0[rays] + (t1[rays] - t0[rays]) * ((k + 0.5) / steps)
        points = o + d[rays] * t[:, None]
        voxel = np.clip(np.rint((points + 1.0) * (res / 2.0) - 0.5).astype(np.int64) - lo, 0, last)
        # a trilinear sample mixes the centres less than a voxel from it (along every axis), and the point is
        # within half a voxel of its nearest centre: the next samples closer than this cannot be in the hull
        reach = free[voxel[:, 0], voxel[:, 1], voxel[:, 2]] - CLEARANCE_MARGIN
        close = reach <= 0
        inside = np.zeros(len(rays), bool)
        if close.any():
            inside[close] = in_hull(volume, points[close], max_votes, plane)
        entry[rays[inside]] = t[inside]
        k = k + np.where(close, 1, np.maximum(np.ceil(reach / step_voxels[rays]), 1))
        going = ~inside & (k <= k_last[rays])
        rays, k = rays[going], k[going]
    flat = np.full((y1 - y0) * (x1 - x0), np.inf, np.float32)
    flat[hit] = entry
    out[y0:y1, x0:x1] = flat.reshape(y1 - y0, x1 - x0)
    return out


def clearance(volume: np.ndarray, max_votes: float) -> np.ndarray:
    """``(X, Y, Z)`` float32: for each voxel of ``volume`` ``(X, Y, Z)``, its distance to the nearest voxel of the
    hull ``volume < max_votes`` in voxels along the longest axis (the chessboard distance, a lower bound of the
    straight one; 0 in the hull)."""
    from scipy.ndimage import distance_transform_cdt

    return distance_transform_cdt(volume >= max_votes, metric="chessboard").astype(np.float32)


def reproject(volume: np.ndarray, view: View, max_votes: float, plane: Plane | None = None) -> np.ndarray:
    """``(H, W)`` bool: pixels whose ray passes through the hull ``volume < max_votes`` cut at the support
    ``plane`` (:func:`hull_depth`)."""
    return np.isfinite(hull_depth(volume, view, max_votes, plane))
