"""Views at the working size and the geometry every cue shares: pixel rays, the unit sphere's image (the prior:
the cameras converge on the object, so a ray that misses the sphere is background), plane homographies, which
views to compare; the support plane's type and the method's knobs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import cv2
import numpy as np

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

    @cached_property
    def rgba(self) -> np.ndarray:
        """``(H, W, 4)`` uint8: :attr:`image` with an opaque alpha. OpenCV warps four channels several times faster
        than three (its vectorized path), and the photo-consistency sweeps warp neighbours thousands of times.
        Made once, on first use: make a new view (``dataclasses.replace``) rather than edit the image of one that
        a sweep has read."""
        return cv2.cvtColor(self.image, cv2.COLOR_RGB2RGBA)


@dataclass(frozen=True)
class Plane:
    """The support plane ``normal . x = offset`` (normal pointing up, unit), normalized frame."""

    normal: np.ndarray  # (3,)
    offset: float
    consistent_fraction: float  # share of the tested pixels (or sparse points, for tracks) the plane explains
    thickness: float = 0.0  # for sparse points: their distance from it that counts as on it

    def height(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` -> ``(...)`` signed height above the plane."""
        return points @ self.normal - self.offset

    def framed(self, centre: np.ndarray, radius: float) -> Plane:
        """The plane in the frame where the sphere ``(centre, radius)`` is the unit sphere at the origin
        (``x' = (x - centre) / radius``); thickness scaled alike."""
        return replace(self, offset=float((self.offset - self.normal @ centre) / radius),
                       thickness=self.thickness / radius)

    def unframed(self, centre: np.ndarray, radius: float) -> Plane:
        """The inverse of :meth:`framed`: from the sphere's frame back to the one ``centre`` is given in."""
        return replace(self, offset=float(radius * self.offset + self.normal @ centre),
                       thickness=self.thickness * radius)


@dataclass(frozen=True)
class SegmentOptions:
    """The method's knobs; those a user sets have :class:`pipeline.config.MasksConfig`'s names."""

    rounds: int = 3
    grabcut_iterations: int = 4
    hull_resolution: int = 128
    contact_height: float | None = 0.05
    stand_height: float = 0.0
    carve_votes: float = 3.0
    carve_share: float = 0.2
    core_carve_share: float | None = 0.15
    core_carve_votes: int = 6
    core_erode_px: int = 3
    core_fraction: float = 0.4
    final_core_fraction: float = 0.0
    core_colour_log_odds: float | None = 3.0
    colour_bins: int = 8
    colour_ring_px: int = 20
    colour_min_pixels: int = 50
    colour_open_px: int = 2
    trim_colour_log_odds: float | None = 1.5
    trim_capture_log_odds: float = 0.0
    trim_colour_bins: int = 16
    trim_core_px: int = 6
    trim_band_px: tuple[int, int] = (3, 18)
    trim_seen_through_votes: float = 0.75
    restore_colour_log_odds: float | None = 0.0
    restore_seen_through_votes: float = 3.25
    restore_piece_px: int = 1
    band_px: int = 4
    outline_reach_px: int = 2
    outline_contrast: float = 0.1
    outline_margin: float = 0.1
    outline_residual: float = 0.5
    neighbours: int = 6
    neighbour_max_deg: float = 60.0
    consistency_rank: int = 3
    floor_threshold: float = 0.03
    floor_shift: float = 0.3
    floor_margin: float = 0.03
    match_exposure: bool = False
    floor: bool = True
    not_floor_threshold: float = 0.12
    floor_measure: str = "sad"
    zncc_window: int = 7
    zncc_min_std: float = 2.0
    zncc_floor_threshold: float = 0.5
    zncc_floor_margin: float = 0.3
    zncc_not_floor_threshold: float = 0.8
    sweep: bool = True
    sweep_neighbours: int = 3
    sweep_rank: int = 2
    sweep_threshold: float = 0.04
    sweep_step_px: float = 1.0
    texture_threshold: float = 0.05
    occluder_reach_px: int = 6
    sweep_near: float = 0.25
    sweep_far: float = 4.0
    seed_radius: float = 0.3
    doubtful_vote: float = 0.5
    confirmed_vote: float = 3.0
    colour_vote_odds: float | None = 1.0
    colour_vote_thin_px: int = 3
    unexplained_vote: float = 1.0
    unexplained_max_rate: float = 0.4
    unexplained_retry_share: float = 0.4
    unexplained_reach_px: int = 2
    dark_level: int = 48
    final_reach_px: int = 1
    final_max_core_lost: float = 0.15
    front_sweep: bool = True
    front_step: float = 0.01
    front_margin: float = 0.1
    front_inset_px: int = 3
    front_min_px: int = 40
    front_corner: float = 1.0e-4
    front_column_share: float = 0.25
    front_surface_depth: float = 0.1
    front_surface_step: float = 0.02
    front_surface_margin: float = 0.02
    through_floor: bool = True
    through_threshold: float = 0.04
    through_min_px: int = 16
    through_reach_px: int = 20
    through_views: int = 40
    prior_growth: float = 1.5
    prior_max_growth: float = 3.0
    prior_touch_share: float = 0.1
    tracks: bool = True
    track_plane_tolerance: float = 0.02
    track_seed_px: int = 1
    track_far: float = 3.0
    support_plane_from: str = "photos_or_points"


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


def disc(r: int) -> np.ndarray:
    """A disc of radius ``r`` pixels, as a structuring element."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
