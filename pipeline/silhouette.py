"""Automatic object masks from a calibrated orbit, without learned weights (the masks stage's method).

Three cues, each cheap and each weak alone, made to agree:

1. **Where the cameras converge.** After ``poses`` the object lies inside the unit sphere of the normalized
   frame. Pixels whose ray misses the sphere are background, in every view, for certain.
2. **The support plane explains the floor.** The object stands on a table or floor. Under the plane's
   homography a floor pixel -- shadows included, they do not move with the viewpoint -- has the same colour in
   the neighbouring views, while an object pixel lands on unrelated content (it is not on the plane) and a
   glossy one changes with the viewpoint anyway. The plane is found by sweeping its height (normal: the
   cameras' mean up, then a small tilt search) for the most consistent pixels; photo-consistency with it marks
   floor pixels as background. Without this the contact shadow, dark like many glossy objects, is segmented
   as object in every view, and the visual hull grows a skirt down to the floor that no view from above can
   carve away.
3. **Colour, per view (GrabCut).** OpenCV's GrabCut (colour GMMs + contrast-sensitive graph cut) inside the
   projected sphere, seeded by what is known: cues 1 and 2 as certain background, the current visual hull's
   reprojection as probable object, its eroded core as object.

They are made to agree by **visual-hull carving**: a voxel of the unit sphere is cut when ``carve_share`` of
the views (at least ``carve_votes``) see it off the object: a few, not one, so that a view that misses a piece
does not cut it out of every other view; not many, because next to a thin part only the few views looking
along it can see the gap. A background vote counts fully where evidence confirms it (outside the sphere, the
floor, the depth sweep) or where the pixel is not dark; a dark pixel's vote that nothing confirms counts
``weak_weight`` (0.5): the dark bottom of a glossy object on its dark contact shadow is lost by colour in every
view from above, and only the few views that see it against a lit background say otherwise. The hull,
reprojected into every view, seeds the next round of GrabCut; a few rounds settle. The hull knows nothing of
occlusion: where a prop stands between a camera and the object it covers the prop, and its core would force the
prop into that view's mask. So, from the second round, planes parallel to the support plane are swept between
each camera and the hull (:func:`front_evidence`): textured pixels -- texture in two directions, an edge
alone matches at any depth -- that such a plane explains in the neighbours, in blobs, whose column down to the
floor stays out of the hull (a prop stands beside the object; a chance match on the object's own texture has
the object under it), are a prop's top in front of the object, and the image of those columns in front of the
hull is its side: certain background, and the core is not forced next to them. And where fewer than
``carve_share`` of the views see through the object -- a hole, the space under a lifted side -- the hull fills
it; those views' pixels inside the hull's image that the support plane explains in *any* other view (one
suffices: the views that see through are few and on every side), textured in two directions, in blobs, are the
floor seen through the hull (:func:`floor_through_hull`): certain background, and the core is not forced within
``through_reach_px`` of them (they are textured specks of a larger hole; GrabCut decides the rest by colour).
The final mask of a view is
the last hull's reprojection within ``final_reach_px`` (1) of that view's last GrabCut mask, less certain
background: the hull keeps what one view's colours lose inside the object (a glossy rim mirroring the
background, a dark bottom), the view's own colours trim the hull's overhang at the outline (the hull is
larger than the object wherever fewer than ``carve_share`` of the views see past it) and cut the pieces of the
hull hidden by a prop in front (GrabCut gives them to the prop).

Failure cases (documented in the README): an object not standing on a visible textured plane (hanging,
held, on a textureless table: cue 2 finds nothing and the contact shadow may stay in the masks); an
object whose colours are those of its surroundings *and* which is seen against them everywhere; fewer than
~8 views around the object (the hull then barely constrains anything); a loose unit sphere from ``poses``
that includes large props (they are carved only where views disagree; the sweep in front of the hull finds
props that stand on the floor with a textured top: not a prop hanging over the object, nor a round one's side
beyond its top's outline); holes through the object and the space under an overhang that fewer than
``carve_share`` of the views see through, where what shows through is not a textured floor (the hull fills
them, and inside the hull colour alone does not separate a glossy object from what it mirrors); thin parts
below the voxel size.

Arrays: images ``(H, W, 3)`` uint8 sRGB at the working size; masks ``(H, W)`` bool; cameras OpenCV
camera-to-world ``(4, 4)`` and pinhole ``K`` ``(3, 3)`` at the working size (pixel (0, 0) is the image
corner, so scaling an image by ``s`` scales every entry of ``K``'s first two rows by ``s``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from .metrics import iou
from .object_frame import camera_up, pixels_of

log = logging.getLogger("orca.masks")

# cv2's pixel centres are at integers, ours at +0.5 (COLMAP's convention): ours = cv2 + 0.5.
_TO_OURS = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
_TO_CV2 = np.linalg.inv(_TO_OURS)


@dataclass
class View:
    """One photo at the working size."""

    name: str
    image: np.ndarray  # (H, W, 3) uint8 sRGB
    K: np.ndarray  # (3, 3)
    c2w: np.ndarray  # (4, 4)
    clipped: np.ndarray | None = None  # (H, W) bool: highlight-clipped pixels (decode stage)

    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape[0], self.image.shape[1]


@dataclass(frozen=True)
class Plane:
    """The support plane ``normal . x = offset`` (normal pointing up, unit), normalized frame."""

    normal: np.ndarray  # (3,)
    offset: float
    consistent_fraction: float  # share of the tested pixels the plane explains

    def height(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` -> ``(...)`` signed height above the plane."""
        return points @ self.normal - self.offset


@dataclass(frozen=True)
class SegmentOptions:
    """The method's knobs (the stage fills them from :class:`pipeline.config.MasksConfig`)."""

    rounds: int = 3
    grabcut_iterations: int = 4
    hull_resolution: int = 128
    carve_votes: float = 3.0
    carve_share: float = 0.2
    votes_relax: float = 0.0
    floor_visibility: bool = False
    occluder_min_height: float = 0.1
    core_erode_px: int = 3
    band_px: int = 4
    neighbours: int = 6
    neighbour_max_deg: float = 60.0
    consistency_rank: int = 3
    floor_threshold: float = 0.03
    floor: bool = True
    not_floor_threshold: float = 0.12
    occluders: bool = True
    occluder_neighbours: int = 3
    occluder_rank: int = 2
    occluder_threshold: float = 0.04
    texture_threshold: float = 0.05
    occluder_reach_px: int = 6
    sweep_far: float = 4.0
    seed_radius: float = 0.3
    weak_weight: float = 0.5
    dark_level: int = 48
    final_reach_px: int = 1
    front_sweep: bool = True
    front_step: float = 0.01
    front_margin: float = 0.1
    front_inset_px: int = 3
    front_min_px: int = 40
    front_corner: float = 1.0e-4
    front_column_share: float = 0.25
    through_floor: bool = True
    through_threshold: float = 0.04
    through_min_px: int = 16
    through_reach_px: int = 20
    through_views: int = 40


@dataclass
class Segmentation:
    """What :func:`segment` found, at the working size."""

    masks: list[np.ndarray]  # per view (H, W) bool: the final masks
    colour_masks: list[np.ndarray]  # per view: the last round's GrabCut result
    hull_masks: list[np.ndarray]  # per view: the last visual hull's reprojection
    floor_masks: list[np.ndarray | None]  # per view: pixels explained by the support plane (None: no plane)
    swept_masks: list[np.ndarray | None]  # per view: pixels a surface outside the sphere explains (None: no sweep)
    plane: Plane | None
    volume: np.ndarray  # (R, R, R) float32 background votes over [-1, 1]^3 (see carve)
    rounds: list[dict[str, float]] = field(default_factory=list)  # per round: agreement of GrabCut and hull


# ------------------------------------------------------------------------------------------------ geometry


def pixel_rays(view: View, box: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Unit world directions of pixel centres, ``(h, w, 3)`` over ``box = (x0, y0, x1, y1)`` (default: all)."""
    h, w = view.shape
    x0, y0, x1, y1 = box if box is not None else (0, 0, w, h)
    u, v = np.meshgrid(np.arange(x0, x1) + 0.5, np.arange(y0, y1) + 0.5)
    K = view.K
    cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    d = cam @ view.c2w[:3, :3].T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def sphere_distance(view: View, radius: float = 1.0) -> np.ndarray:
    """``(H, W)`` distance of each pixel's ray from the origin, in units of ``radius`` (< 1: the ray hits the
    sphere). Rays pointing away from the sphere get ``inf``."""
    o = view.c2w[:3, 3]
    d = pixel_rays(view)
    t = -(d @ o)
    dist = np.sqrt(np.maximum(o @ o - t * t, 0.0)) / radius
    return np.where(t > 0, dist, np.inf).astype(np.float32)


def sphere_box(view: View, margin: float = 0.0, radius: float = 1.0) -> tuple[int, int, int, int] | None:
    """Pixel box ``(x0, y0, x1, y1)`` holding the sphere's image grown by ``margin`` (a fraction of its size),
    clipped to the image; None if the sphere is not in view."""
    inside = sphere_distance(view, radius) < 1.0
    ys, xs = np.nonzero(inside)
    if len(xs) == 0:
        return None
    h, w = view.shape
    mx = int(np.ceil(margin * (xs.max() - xs.min() + 1))) + 1
    my = int(np.ceil(margin * (ys.max() - ys.min() + 1))) + 1
    return max(0, xs.min() - mx), max(0, ys.min() - my), min(w, xs.max() + mx + 1), min(h, ys.max() + my + 1)


def plane_homography(src: View, dst: View, normal: np.ndarray, offset: float) -> np.ndarray:
    """``(3, 3)`` homography taking ``src``'s pixels (cv2 convention) to ``dst``'s through the world plane
    ``normal . x = offset``: what :func:`cv2.warpPerspective` with ``WARP_INVERSE_MAP`` needs to pull ``dst``'s
    image into ``src``'s pixel grid."""
    R_s, o_s = src.c2w[:3, :3], src.c2w[:3, 3]
    n_cam = R_s.T @ normal  # the plane in src's camera frame: n_cam . X = depth_offset
    depth_offset = offset - normal @ o_s
    rel = np.linalg.inv(dst.c2w) @ src.c2w  # src camera -> dst camera
    H = dst.K @ (rel[:3, :3] + np.outer(rel[:3, 3], n_cam) / depth_offset) @ np.linalg.inv(src.K)
    return _TO_CV2 @ H @ _TO_OURS


def neighbours(views: Sequence[View], count: int, max_deg: float, min_deg: float = 2.0) -> list[list[int]]:
    """For each view, up to ``count`` other views whose direction from the object centre is within
    ``max_deg`` (nearest first, but at least ``min_deg`` away: a photo taken twice from one spot adds nothing)."""
    centres = np.stack([v.c2w[:3, 3] for v in views])
    dirs = centres / np.linalg.norm(centres, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1.0, 1.0)))
    out = []
    for i in range(len(views)):
        order = [j for j in np.argsort(angles[i]) if j != i and min_deg <= angles[i, j] <= max_deg]
        out.append(order[:count])
    return out


def spread(views: Sequence[View], count: int) -> list[list[int]]:
    """For each view, up to ``count`` of the other views spread around the object: all of them when there are
    that few, else greedily the one whose direction from the object centre is farthest from those already taken
    (the first: the farthest from the view itself). Tests that need views on every side, not the nearest, cost
    ``count`` per view instead of all of them."""
    centres = np.stack([v.c2w[:3, 3] for v in views])
    dirs = centres / np.linalg.norm(centres, axis=1, keepdims=True)
    out = []
    for i in range(len(views)):
        others = [j for j in range(len(views)) if j != i]
        if len(others) <= count:
            out.append(others)
            continue
        nearest = dirs[others] @ dirs[i]  # cosine to the nearest taken direction, for each candidate
        taken: list[int] = []
        for _ in range(count):
            k = int(np.argmin(nearest))
            taken.append(others[k])
            nearest = np.maximum(nearest, dirs[others] @ dirs[others[k]])
        out.append(sorted(taken))
    return out


# ------------------------------------------------------------------------------------ the support plane


def plane_cost(view: View, others: Sequence[View], normal: np.ndarray, offset: float, rank: int,
               window: int = 5, box: tuple[int, int, int, int] | None = None,
               hidden: Sequence[np.ndarray | None] | None = None, min_views: int = 2) -> np.ndarray:
    """``(h, w)`` float32 over ``box`` (default: the whole image): how badly the plane ``normal . x = offset``
    explains each pixel -- the ``rank``-th smallest (1-based) over the neighbours of the mean absolute sRGB
    difference (0..1) over a ``window`` box.

    Only neighbours that see the plane's point count: it must land inside their image and, when ``hidden`` gives
    a neighbour's ``(H, W)`` bool mask of what hides the background there (the object's hull), outside it. With
    fewer such neighbours than ``rank`` the rank drops to their number; with fewer than ``min_views`` the cost is
    ``inf`` (no evidence)."""
    H_, W_ = view.shape
    x0, y0, x1, y1 = box if box is not None else (0, 0, W_, H_)
    size = (x1 - x0, y1 - y0)
    shift = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])  # crop pixel -> image pixel
    img = view.image[y0:y1, x0:x1].astype(np.float32) / 255.0
    costs = np.full((len(others), size[1], size[0]), np.inf, np.float32)
    for k, other in enumerate(others):
        H = plane_homography(view, other, normal, offset) @ shift
        warped = cv2.warpPerspective(other.image, H, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
        visible = np.ones(other.shape, np.uint8)
        if hidden is not None and hidden[k] is not None:
            visible[hidden[k]] = 0
        seen = cv2.warpPerspective(visible, H, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        seen = cv2.erode(seen, np.ones((window, window), np.uint8))  # the whole window must be seen
        diff = cv2.blur(np.abs(warped.astype(np.float32) / 255.0 - img).mean(-1), (window, window))
        costs[k] = np.where(seen > 0, diff, np.inf)
    count = np.isfinite(costs).sum(0)
    if len(others) == 0:
        return np.full((size[1], size[0]), np.inf, np.float32)
    costs.sort(axis=0)
    pick = np.clip(np.minimum(rank, count) - 1, 0, len(others) - 1)
    out = np.take_along_axis(costs, pick[None], axis=0)[0]
    return np.where(count >= min(min_views, rank), out, np.inf).astype(np.float32)


def outside_cost(view: View, others: Sequence[View], rank: int, step_px: float = 1.0, near: float = 0.25,
                 far: float = 4.0) -> tuple[np.ndarray, tuple[int, int, int, int]] | None:
    """How well something *outside* the unit sphere -- a prop in front of it, a wall or prop behind it --
    explains each pixel of the sphere's image: the best ``rank``-th neighbour cost of :func:`plane_cost` over
    fronto-parallel planes at depths from ``near`` to ``far`` times the camera's distance from the centre,
    skipping depths inside the sphere along that pixel's ray (and a margin of 2 % of the distance around it).
    Static background is consistent at its depth; the object, inside the sphere, is not, and a glossy object
    is not even at its own depth. Planes are spaced by ``step_px`` of disparity in the widest-baseline
    neighbour.

    Returns:
        (``(h, w)`` float32 cost over the box, ``box``), or None when the sphere is not in view.
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
    for inv in np.linspace(1.0 / z_near, 1.0 / z_far, count):
        z = 1.0 / inv
        valid = (z < entry) | (z > exit_)
        if not valid.any():
            continue
        cost = plane_cost(view, others, axis, float(axis @ o) + z, rank, box=box)
        np.minimum(best, np.where(valid, cost, np.inf), out=best)
    return best, box


def _tilted(normal: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """``normal`` rotated by small angles (radians) about two axes perpendicular to it."""
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    n = normal + ax * a + ay * b
    return n / np.linalg.norm(n)


def find_support_plane(views: Sequence[View], nbrs: Sequence[Sequence[int]], opts: SegmentOptions,
                       samples: int = 6, min_fraction: float = 0.08) -> Plane | None:
    """The plane the object stands on, by photo-consistency (see the module doc), or None if no plane
    perpendicular to the cameras' up within ~10 degrees explains at least ``min_fraction`` of the pixels
    outside the unit sphere's image.

    Searched: offsets along the up vector from 1.6 below the centre to just below it (coarse, then fine), then
    tilts of up to ~8 degrees (the cameras' mean up is off by the photographer's average tilt)."""
    up = camera_up(np.stack([v.c2w for v in views]))
    pick = np.unique(np.linspace(0, len(views) - 1, min(samples, len(views))).round().astype(int))
    regions = {int(i): sphere_distance(views[i]) >= 1.0 for i in pick}

    def score(normal: np.ndarray, offset: float) -> float:
        fractions = []
        for i in pick:
            others = [views[j] for j in nbrs[i]]
            cost = plane_cost(views[i], others, normal, offset, opts.consistency_rank)
            fractions.append(float((cost[regions[int(i)]] < opts.floor_threshold).mean()))
        return float(np.mean(fractions))

    offsets = np.arange(-1.6, -0.02, 0.04)
    scores = [score(up, d) for d in offsets]
    best_d = float(offsets[int(np.argmax(scores))])
    for d in np.arange(best_d - 0.04, best_d + 0.0401, 0.01):
        s = score(up, d)
        if s > max(scores):
            scores.append(s)
            best_d = float(d)
    best = (max(scores), up, best_d)
    step = np.radians(4.0)
    for _ in range(3):  # a small pattern search over the tilt, the offset re-fitted locally each time
        improved = False
        for ax, ay in ((step, 0), (-step, 0), (0, step), (0, -step)):
            n = _tilted(best[1], ax, ay)
            if np.degrees(np.arccos(np.clip(n @ up, -1, 1))) > 10.0:
                continue
            for d in (best[2] - 0.01, best[2], best[2] + 0.01):
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


# ------------------------------------------------------------------------------------- the visual hull


def hull_grid(resolution: int, plane: Plane | None) -> tuple[np.ndarray, np.ndarray]:
    """Voxel centres ``(V, 3)`` of the ``resolution``^3 grid over [-1, 1]^3 that lie in the unit sphere and
    above the support plane, and their flat indices ``(V,)`` into the grid."""
    ax = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    grid = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    keep = np.einsum("ij,ij->i", grid, grid) < 1.0
    if plane is not None:
        keep &= plane.height(grid) > 0.0
    index = np.nonzero(keep)[0]
    return grid[index].astype(np.float32), index


OUTSIDE_VOTES = 1.0e3  # the "background votes" of voxels outside the carved region


def carve(masks: Sequence[np.ndarray], views: Sequence[View], points: np.ndarray, index: np.ndarray,
          resolution: int, weights: Sequence[np.ndarray | None] | None = None) -> np.ndarray:
    """``(R, R, R)`` float32 background votes: for each voxel, in how many views that see it it lands off the
    object (:data:`OUTSIDE_VOTES` for voxels outside the region or seen by fewer than half the views). The hull
    is where the votes are below a small number: one view's mistake does not cut the object, while a voxel next
    to a thin object, off its silhouette in only the few views that look along the thin side, is still cut.
    ``weights``: per view, ``(H, W)`` float32 what a background vote from each pixel counts (None: 1 everywhere;
    less where the vote is doubtful)."""
    seen = np.zeros(len(points), np.int32)
    off = np.zeros(len(points), np.float32)
    for i, (m, v) in enumerate(zip(masks, views)):
        inside, x, y = pixels_of(points, v.c2w, v.K, m.shape)
        seen[inside] += 1
        vote = ~m[y, x]
        off[inside] += vote if weights is None or weights[i] is None else vote * weights[i][y, x]
    votes = np.where(seen >= 0.5 * len(views), off, OUTSIDE_VOTES).astype(np.float32)
    volume = np.full(resolution**3, OUTSIDE_VOTES, np.float32)
    volume[index] = votes
    return volume.reshape((resolution,) * 3)


def _heights(plane: Plane, resolution: int) -> np.ndarray:
    """``(R, R, R)`` height above ``plane`` of the voxel centres of the grid over [-1, 1]^3."""
    ax = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
    return (x * plane.normal[0] + y * plane.normal[1] + z * plane.normal[2] - plane.offset).astype(np.float32)


def carve_votes(opts: SegmentOptions, views: int) -> float:
    """Background votes that cut a voxel: ``carve_share`` of the views, at least ``carve_votes``."""
    return max(opts.carve_votes, round(opts.carve_share * views))


def in_hull(volume: np.ndarray, points: np.ndarray, max_votes: float) -> np.ndarray:
    """``(M,)`` bool: which of ``points`` ``(M, 3)`` lie in the hull ``volume < max_votes`` (``volume``: votes over
    the grid on [-1, 1]^3, interpolated trilinearly, so the outline is finer than the voxels)."""
    from scipy.ndimage import map_coordinates

    res = volume.shape[0]
    idx = (points + 1.0) * (res / 2.0) - 0.5
    return map_coordinates(volume, idx.T, order=1, mode="constant", cval=OUTSIDE_VOTES) < max_votes


def hull_depth(volume: np.ndarray, view: View, max_votes: float) -> np.ndarray:
    """``(H, W)`` float32: the distance along each pixel's ray to where it enters the hull ``volume < max_votes``
    (:func:`in_hull`; ``inf``: it misses), marching in steps of half a voxel through the unit sphere."""
    out = np.full(view.shape, np.inf, np.float32)
    box = sphere_box(view)
    if box is None:
        return out
    x0, y0, x1, y1 = box
    d = pixel_rays(view, box).reshape(-1, 3)
    o = view.c2w[:3, 3]
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = np.nonzero(disc > 0)[0]
    d, b, root = d[hit], b[hit], np.sqrt(disc[hit])
    t0, t1 = -b - root, -b + root
    steps = int(np.ceil(2.0 * volume.shape[0]))  # the diameter (2) in half voxels (2 / res each)
    entry = np.full(len(d), np.inf, np.float32)
    for k in range(steps):
        t = t0 + (t1 - t0) * ((k + 0.5) / steps)
        np.minimum(entry, np.where(in_hull(volume, o + d * t[:, None], max_votes), t, np.inf), out=entry)
    flat = np.full((y1 - y0) * (x1 - x0), np.inf, np.float32)
    flat[hit] = entry
    out[y0:y1, x0:x1] = flat.reshape(y1 - y0, x1 - x0)
    return out


def reproject(volume: np.ndarray, view: View, max_votes: float) -> np.ndarray:
    """``(H, W)`` bool: pixels whose ray passes through the hull ``volume < max_votes`` (:func:`hull_depth`)."""
    return np.isfinite(hull_depth(volume, view, max_votes))


# ------------------------------------------------------------------------------------- per-view colour


GRABCUT_SEED = 0


def grabcut(image: np.ndarray, seeds: np.ndarray, iterations: int) -> np.ndarray:
    """``(H, W)`` bool object mask from OpenCV GrabCut on ``seeds`` (``cv2.GC_*`` labels), cropped to the
    seeds' uncertain region plus context so that the colour models are local and the run is fast. A seed map
    without certain object or any uncertain pixel is returned as is (GrabCut needs both classes)."""
    fg = (seeds == cv2.GC_FGD) | (seeds == cv2.GC_PR_FGD)
    unsure = (seeds == cv2.GC_PR_FGD) | (seeds == cv2.GC_PR_BGD)
    if not unsure.any() or not fg.any() or not ((seeds == cv2.GC_BGD) | (seeds == cv2.GC_PR_BGD)).any():
        return fg
    ys, xs = np.nonzero(unsure | (seeds == cv2.GC_FGD))
    h, w = seeds.shape
    m = max(8, int(0.25 * max(xs.max() - xs.min(), ys.max() - ys.min())))
    x0, y0 = max(0, xs.min() - m), max(0, ys.min() - m)
    x1, y1 = min(w, xs.max() + m + 1), min(h, ys.max() + m + 1)
    crop = np.ascontiguousarray(seeds[y0:y1, x0:x1])
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    bgr = np.ascontiguousarray(image[y0:y1, x0:x1, ::-1])
    # Repeatable masks: the colour models start from k-means on OpenCV's global random state, and the threaded
    # parts add their own noise (each a few pixels per view; with neither, two runs of the demo's 32 views on
    # the same evidence gave identical masks, where they differed by ~0.01 IoU before). Not bit-exact: a
    # process's first call can still differ by a pixel or two (measured on a small synthetic image).
    threads = cv2.getNumThreads()
    cv2.setRNGSeed(GRABCUT_SEED)
    cv2.setNumThreads(1)
    try:
        cv2.grabCut(bgr, crop, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    except cv2.error as e:  # a degenerate colour model (e.g. a single colour): keep the seeds
        log.debug("GrabCut failed (%s); seeds kept", e)
        return fg
    finally:
        cv2.setNumThreads(threads)
    out = np.zeros((h, w), bool)
    out[y0:y1, x0:x1] = (crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)
    return out


def _disc(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def first_seeds(sphere: np.ndarray, background: np.ndarray, seed_radius: float,
                above_floor: np.ndarray | None = None) -> np.ndarray:
    """GrabCut labels before any hull: certain background outside the sphere's image and on the floor,
    certain object in the central ``seed_radius`` of the sphere's image (the cameras converge on the object),
    probable object out to 0.7, probable background beyond."""
    seeds = np.full(sphere.shape, cv2.GC_BGD, np.uint8)
    seeds[sphere < 1.0] = cv2.GC_PR_BGD
    seeds[sphere < 0.7] = cv2.GC_PR_FGD
    if above_floor is not None:
        seeds[above_floor & (sphere < 1.0)] = cv2.GC_PR_FGD
    seeds[background] = cv2.GC_BGD
    # The centre wins over floor evidence: a dark, flat object bottom matches a dark floor anywhere.
    seeds[sphere < seed_radius] = cv2.GC_FGD
    return seeds


def hull_seeds(hull: np.ndarray, keep_out: np.ndarray | None, background: np.ndarray, floor: np.ndarray | None,
               erode_px: int, band_px: int, clipped: np.ndarray | None = None) -> np.ndarray:
    """GrabCut labels from the hull's reprojection: certain object in the hull's eroded core (but not in
    ``keep_out``, where the hull is known to be wrong) and on clipped highlights inside the hull (a glossy
    object's highlights are white like many backgrounds), probable object in the rest of the hull, probable
    background in a band around it, certain background beyond and in ``background`` and wherever the floor was
    seen -- except the floor inside the hull, which is only probable background: the bottom rim of a glossy object
    mirrors the floor next to it at grazing angles and passes the floor test."""
    h8 = hull.astype(np.uint8)
    seeds = np.full(hull.shape, cv2.GC_BGD, np.uint8)
    seeds[cv2.dilate(h8, _disc(band_px)) > 0] = cv2.GC_PR_BGD
    seeds[hull] = cv2.GC_PR_FGD
    core = cv2.erode(h8, _disc(erode_px)) > 0
    if keep_out is not None:
        core &= ~keep_out
    if clipped is not None:
        core |= clipped & hull
    seeds[core] = cv2.GC_FGD
    if floor is not None:
        seeds[floor & hull & ~core] = cv2.GC_PR_BGD
        seeds[floor & ~hull] = cv2.GC_BGD
    seeds[background] = cv2.GC_BGD
    return seeds


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


def occluder_evidence(view: View, others: Sequence[View], opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: textured, unclipped pixels of the sphere's image that a surface outside the sphere
    explains (:func:`outside_cost`): a prop in front of the object, the room behind it."""
    found = outside_cost(view, others, opts.occluder_rank, far=opts.sweep_far)
    if found is None:
        return np.zeros(view.shape, bool)
    cost, box = found
    return _matched(view, cost, box, opts.occluder_threshold, opts)


def _matched(view: View, cost: np.ndarray, box: tuple[int, int, int, int], threshold: float,
             opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: the pixels of ``box`` whose sweep ``cost`` is under ``threshold``, textured and away from
    clipped highlights (a highlight's outline can match at a wrong depth; it is never evidence)."""
    x0, y0, x1, y1 = box
    out = np.zeros(view.shape, bool)
    textured = local_contrast(view.image[y0:y1, x0:x1]) > opts.texture_threshold
    out[y0:y1, x0:x1] = (cost < threshold) & textured
    if view.clipped is not None:
        out &= ~(cv2.dilate(view.clipped.astype(np.uint8), _disc(2)) > 0)
    return out


def front_cost(view: View, others: Sequence[View], plane: Plane, entry: np.ndarray, box: tuple[int, int, int, int],
               rank: int, step: float, margin: float) -> tuple[np.ndarray, np.ndarray]:
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
            cost = np.where(valid, plane_cost(view, others, plane.normal, offset, rank, box=box), np.inf)
            better = cost < best
            best[better] = cost[better]
            best_height[better] = height
    return best, best_height


def _inner(hull: np.ndarray, opts: SegmentOptions) -> np.ndarray:
    """Well inside the hull's image: at its outline a window mixes the object with what is behind it."""
    return cv2.erode(hull.astype(np.uint8), _disc(opts.front_inset_px)) > 0


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
    between the camera and the hull (:func:`front_cost`; ``depth``: :func:`hull_depth`), in blobs, whose column
    down to the support plane stays out of the hull ``volume < max_votes`` (:func:`column_in_hull`): a prop stands
    on the floor beside the object, while a chance match on the object's own texture floats in front of it with
    the object under it. Its sides: the image of those columns in front of the hull
    (:func:`column_image`), which planes parallel to the floor do not fit."""
    box = sphere_box(view)
    if box is None or not others:
        return np.zeros(view.shape, bool)
    x0, y0, x1, y1 = box
    entry = np.where(_inner(np.isfinite(depth), opts), depth, -np.inf)[y0:y1, x0:x1]
    cost, heights = front_cost(view, others, plane, entry, box, opts.occluder_rank, opts.front_step, opts.front_margin)
    tops = _blobs_of_corners(view, _matched(view, cost, box, opts.occluder_threshold, opts), opts.front_min_px, opts)
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
    return cv2.morphologyEx(out.astype(np.uint8), cv2.MORPH_CLOSE, _disc(1)) > 0


def floor_through_hull(view: View, others: Sequence[View], plane: Plane, hull: np.ndarray,
                       opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: pixels well inside the hull's reprojection ``hull`` that the support plane explains in at
    least one of ``others`` (other views, on every side: :func:`spread`), textured in two directions
    (:func:`corner_strength`), in blobs:
    the floor seen through a hole in the object or under an overhang, which the hull fills because fewer than
    ``carve_share`` of the views see through it. One view suffices: the few that see through are on every side.
    The object's own matches -- a glossy bottom mirrors the floor next to it -- are flat or edges, and specks."""
    cost = plane_cost(view, others, plane.normal, plane.offset, 1)
    whole = (0, 0, view.shape[1], view.shape[0])
    found = _matched(view, cost, whole, opts.through_threshold, opts) & _inner(hull, opts)
    return _blobs_of_corners(view, found, opts.through_min_px, opts)


def _floor_from_cost(cost: np.ndarray, outside: np.ndarray, opts: SegmentOptions) -> np.ndarray:
    """Pixels of the sphere's image the support plane explains; an opening drops isolated specks (chance
    matches on the object's flat patches)."""
    floor = ((cost < opts.floor_threshold) & ~outside).astype(np.uint8)
    return cv2.morphologyEx(floor, cv2.MORPH_OPEN, _disc(1)) > 0


def floor_evidence(view: View, others: Sequence[View], plane: Plane, outside: np.ndarray, opts: SegmentOptions,
                   hidden: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """``(H, W)`` bool: floor pixels inside the sphere's image (:func:`plane_cost` under the threshold)."""
    cost = plane_cost(view, others, plane.normal, plane.offset, opts.consistency_rank, hidden=hidden)
    return _floor_from_cost(cost, outside, opts)


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
    touched = np.unique(labels[(cv2.dilate(swept.astype(np.uint8), _disc(2)) > 0) & candidates])
    return np.isin(labels, touched[touched > 0])


# -------------------------------------------------------------------------------------------- the driver


def _released(occluded: np.ndarray | None, front: np.ndarray | None, through: np.ndarray | None,
              opts: SegmentOptions) -> np.ndarray | None:
    """``(H, W)`` bool where the hull's core is not forced as object (None: nowhere). The hull knows nothing of
    occlusion: not near a prop seen in front (within ``occluder_reach_px``). Where the floor shows through the
    hull the hull is wrong, and the floor found there is a few textured specks of a larger hole: not within
    ``through_reach_px`` of them, so that GrabCut decides the rest of the hole by colour."""
    out = None
    for found, reach in ((occluded, opts.occluder_reach_px), (front, opts.occluder_reach_px),
                         (through, opts.through_reach_px)):
        if found is not None and found.any():
            near = cv2.dilate(found.astype(np.uint8), _disc(reach)) > 0
            out = near if out is None else out | near
    return out


def vote_weights(views: Sequence[View], backgrounds: Sequence[np.ndarray], floors: Sequence[np.ndarray | None],
                 fixed: dict[int, np.ndarray], opts: SegmentOptions) -> list[np.ndarray | None]:
    """Per view, ``(H, W)`` float32 what a background vote counts in :func:`carve` (None: 1 everywhere).
    ``weak_weight`` on dark pixels (brightest channel <= ``dark_level``) that no evidence confirms as background
    (outside the sphere, swept, floor): a dark object bottom and its dark contact shadow look alike, and views
    from above lose the bottom by colour."""
    out: list[np.ndarray | None] = []
    for i, v in enumerate(views):
        if i in fixed:
            out.append(None)
            continue
        weight = np.ones(v.shape, np.float32)
        sure = backgrounds[i] | (v.image.max(-1) > opts.dark_level)
        if floors[i] is not None:
            sure = sure | floors[i]
        weight[~sure] = opts.weak_weight
        out.append(weight)
    return out


@dataclass
class Evidence:
    """What :func:`gather_evidence` found before any hull (per view, at the working size)."""

    plane: Plane | None
    spheres: list[np.ndarray]  # (H, W) float32: distance of each pixel's ray from the centre (< 1: in the sphere)
    floors: list[np.ndarray | None]  # pixels the support plane explains
    above: list[np.ndarray | None]  # pixels the support plane clearly does not explain
    backgrounds: list[np.ndarray]  # certain background: outside the sphere's image, or swept
    occluded: list[np.ndarray | None]  # pixels a surface outside the sphere explains
    masks: list[np.ndarray]  # the first GrabCut masks (the user's where fixed)


def gather_evidence(views: Sequence[View], opts: SegmentOptions, fixed: dict[int, np.ndarray] | None = None,
                    step: Callable[[str], None] = lambda label: None) -> Evidence:
    """The support plane, floor and swept evidence per view, and the first masks from the sphere prior."""
    fixed = fixed or {}
    nbrs = neighbours(views, opts.neighbours, opts.neighbour_max_deg)
    plane = find_support_plane(views, nbrs, opts) if opts.floor else None
    step("support plane")
    if plane is not None:
        log.info("support plane %.3f below the centre, tilt %.1f deg from the cameras' up, explains %.0f %% of the "
                 "pixels around the object", -plane.offset,
                 np.degrees(np.arccos(np.clip(plane.normal @ camera_up(np.stack([v.c2w for v in views])), -1, 1))),
                 100 * plane.consistent_fraction)

    spheres = [sphere_distance(v) for v in views]
    floors: list[np.ndarray | None] = []
    above: list[np.ndarray | None] = []
    backgrounds = []
    occluded: list[np.ndarray | None] = []
    near = neighbours(views, opts.occluder_neighbours, opts.neighbour_max_deg) if opts.occluders else None
    for i, v in enumerate(views):
        outside = spheres[i] >= 1.0
        if near is not None:
            occluded.append(occluder_evidence(v, [views[j] for j in near[i]], opts))
        else:
            occluded.append(None)
        if plane is not None:
            cost = plane_cost(v, [views[j] for j in nbrs[i]], plane.normal, plane.offset, opts.consistency_rank)
            floors.append(_floor_from_cost(cost, outside, opts))
            above.append((cost > opts.not_floor_threshold) & ~outside)
        else:
            floors.append(None)
            above.append(None)
        backgrounds.append(outside)
        if occluded[i] is not None:
            backgrounds[i] = backgrounds[i] | occluded[i]
        step("floor")

    masks = []
    for i, v in enumerate(views):
        if i in fixed:
            masks.append(fixed[i])
        else:
            certain = backgrounds[i] if floors[i] is None else backgrounds[i] | floors[i]
            masks.append(grabcut(v.image, first_seeds(spheres[i], certain, opts.seed_radius, above[i]),
                                 opts.grabcut_iterations))
        step("segment")
    return Evidence(plane, spheres, floors, above, backgrounds, occluded, masks)


def segment(views: Sequence[View], opts: SegmentOptions, fixed: dict[int, np.ndarray] | None = None,
            on_step: Callable[[str], None] | None = None) -> Segmentation:
    """Object masks for every view (see the module doc).

    Args:
        views: the photos at the working size, cameras in the normalized frame.
        fixed: view index -> ``(H, W)`` bool mask the user gave: kept as is, and it votes in every carve.
        on_step: called with a short label after each unit of work (progress bars).
    """
    step = on_step or (lambda label: None)
    evidence = gather_evidence(views, opts, fixed, step)
    return refine(views, opts, evidence, fixed, step)


def _log_found(r: int, what: str, views: Sequence[View], found: Sequence[np.ndarray | None]) -> None:
    names = [v.name for v, f in zip(views, found) if f is not None and f.any()]
    if names:
        log.info("round %d: %s in %d view(s): %s", r + 1, what, len(names), ", ".join(names))


def refine(views: Sequence[View], opts: SegmentOptions, evidence: Evidence, fixed: dict[int, np.ndarray] | None = None,
           step: Callable[[str], None] = lambda label: None) -> Segmentation:
    """Rounds of carving and GrabCut from the ``evidence``, then the final masks (see the module doc)."""
    fixed = fixed or {}
    n = len(views)
    plane, spheres, backgrounds, occluded = evidence.plane, evidence.spheres, evidence.backgrounds, evidence.occluded
    floors = list(evidence.floors)
    masks = list(evidence.masks)
    nbrs = neighbours(views, opts.neighbours, opts.neighbour_max_deg)
    near = neighbours(views, opts.occluder_neighbours, opts.neighbour_max_deg)
    around = spread(views, opts.through_views)
    points, index = hull_grid(opts.hull_resolution, plane)
    rounds: list[dict[str, float]] = []
    hulls: list[np.ndarray] = []
    volume = np.full((opts.hull_resolution,) * 3, OUTSIDE_VOTES, np.float32)
    through: list[np.ndarray | None] = [None] * n
    fronts: list[np.ndarray | None] = [None] * n
    for r in range(opts.rounds):
        weights = vote_weights(views, backgrounds, floors, fixed, opts)
        volume = carve(masks, views, points, index, opts.hull_resolution, weights)
        # Generous early, strict at the end: the first masks (from the sphere prior alone) miss pieces that
        # later rounds, seeded by a hull that kept them, can find again.
        votes = carve_votes(opts, n) + opts.votes_relax * (opts.rounds - 1 - r)
        depths = [hull_depth(volume, v, votes - 0.5) for v in views]
        hulls = [np.isfinite(d) for d in depths]
        step("carve")
        if r > 0:
            for i, v in enumerate(views):
                if plane is not None and i not in fixed and opts.front_sweep:
                    # Props in front of the object inside the sphere, found anew against each round's hull (not the
                    # first round's: the sphere prior's masks make a hull too loose to have much in front of it).
                    fronts[i] = front_evidence(v, [views[j] for j in near[i]], plane, depths[i], volume, votes - 0.5,
                                               opts)
                if plane is not None and i not in fixed and opts.through_floor:
                    through[i] = floor_through_hull(v, [views[j] for j in around[i]], plane, hulls[i], opts)
                step("evidence against the hull")
            _log_found(r, "a prop in front of the hull", views, fronts)
            _log_found(r, "the floor seen through the hull", views, through)
        # Both are certain background: no mask keeps them, and the floor confirms the view's votes in the next carve.
        backgrounds = [np.logical_or.reduce([e for e in (b, t, f) if e is not None])
                       for b, t, f in zip(evidence.backgrounds, through, fronts)]
        if plane is not None and opts.floor_visibility:
            # Again, now that the hull tells which neighbours see each floor point: the shadowed floor under an
            # overhang is hidden from most neighbours, and they must not vote against it. Only the hull's part
            # clearly above the floor hides anything: its skirt down to the floor -- what this is to remove --
            # would otherwise hide the very floor that carves it.
            lifted = volume.copy()
            lifted[~(_heights(plane, lifted.shape[0]) > opts.occluder_min_height)] = OUTSIDE_VOTES
            grown = [cv2.dilate(reproject(lifted, v, votes - 0.5).astype(np.uint8), _disc(2)) > 0 for v in views]
            floors = [floor_evidence(v, [views[j] for j in nbrs[i]], plane, spheres[i] >= 1.0, opts,
                                     [grown[j] for j in nbrs[i]]) for i, v in enumerate(views)]
        new = []
        for i, v in enumerate(views):
            if i in fixed:
                new.append(fixed[i])
            else:
                seeds = hull_seeds(hulls[i], _released(occluded[i], fronts[i], through[i], opts), backgrounds[i],
                                   floors[i], opts.core_erode_px, opts.band_px, v.clipped)
                new.append(grabcut(v.image, seeds, opts.grabcut_iterations))
            step("segment")
        agreement = [iou(a, b) for a, b in zip(new, hulls)]
        change = [iou(a, b) for a, b in zip(new, masks)]
        rounds.append({"agreement_median": float(np.median(agreement)), "agreement_min": float(np.min(agreement)),
                       "change_median": float(np.median(change))})
        log.info("round %d: GrabCut vs hull IoU median %.3f (worst %.3f); masks changed by %.3f IoU", r + 1,
                 rounds[-1]["agreement_median"], rounds[-1]["agreement_min"], 1 - rounds[-1]["change_median"])
        masks = new
    # The final masks: the hull's reprojection -- the views agree on it, and it keeps what one view's colours
    # lose (a glossy rim mirroring the background, a dark bottom on its dark shadow) -- less what this view
    # knows the hull cannot: certain background (outside the sphere, swept) and, where a prop in front was
    # seen, the pieces GrabCut gave to that prop.
    final = []
    for i, (m, h) in enumerate(zip(masks, hulls)):
        if i not in fixed:
            if opts.final_reach_px >= 0:
                near = cv2.dilate(m.astype(np.uint8), _disc(opts.final_reach_px)) > 0 if opts.final_reach_px else m
                m = h & near & ~backgrounds[i]
            else:
                m = h & ~backgrounds[i] & ~occluded_region(h, m, occluded[i])
        final.append(m)
    return Segmentation(final, masks, hulls, floors, occluded, plane, volume, rounds)
