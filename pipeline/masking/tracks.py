"""Structure from motion's points as seeds: what each photo saw, and where in 3D it lies.

The poses stage triangulated thousands of features, and each point's track names the photos whose features made
it -- so in each of those photos the point was *visible* at its projection (no occlusion test is needed). Where a
point lies tells what that pixel shows:

- **on the floor** (within the plane's thickness, ``track_plane_tolerance`` of the points' median distance from
  the object's centre) or **far outside the sphere** the object lies in (``track_far`` radii: the sphere may
  still grow to hold an object reaching past it): the floor or the room, certain background;
- **clearly above the floor, inside the sphere** (more than twice the plane's thickness: a carpet's pile and
  waves lie within it): the object (a feature on its texture, a knob, a dark handle) or a reflection in it -- a
  convex mirror's virtual image lies behind its surface, inside the object -- certain object;
- anything else (just above the floor, below it, between the sphere and ``track_far``): no evidence.

The plane is fitted to the points by RANSAC (:func:`pipeline.object_frame.support_plane`, the poses stage's),
normal within 30 degrees of the cameras' up, and must cut the sphere (or nearly). Without one nothing inside the
sphere is labelled: the floor and the object cannot be told apart by position alone.

Why: colour alone loses a dark handle on a dark carpet shadow in every view from above, and the hull then
carves it away for good; a handful of features on it, seen from many sides, keep it. On the real blowtorch
(50 views with SfM's cameras) the masks' IoU against the photographers' rose from 0.63 to 0.73 with them. The
plane labels the points, and it is the floor cue's support plane where photo-consistency finds none (the
blowtorch's carpet; ``masks.support_plane_from``); in place of a plane photo-consistency found it is mixed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..object_frame import camera_up, pixels_of, plane_normal, support_plane
from ..sparse_depth import observation_pairs
from .views import Plane, View

FLOOR, OBJECT, UNKNOWN, OUTSIDE = 0, 1, 2, 3
LABELS = {"floor": FLOOR, "object": OBJECT, "no_evidence": UNKNOWN, "room": OUTSIDE}  # names for the report
PLANE_SEARCH_RADIUS = 3.0  # the plane is fitted to the points within this many sphere radii of the centre
MIN_TRACK_POINTS = 20  # fewer points than this: no evidence
OBJECT_CLEARANCE = 2.0  # an object point lies this many plane thicknesses above it (carpet pile lies within)
# The floor an object stands on touches its bounding sphere, but the sphere here is centred where the cameras
# aim, so the floor may lie a little below it: on the suite the standing objects' floors lay 0.42-1.01 radii
# below the centre, the floors under a floating object or a table 1.25-1.99.
BELOW_SPHERE = 0.1


@dataclass(frozen=True)
class Tracks:
    """Triangulated points and which views observed them."""

    xyz: np.ndarray  # (M, 3) in the views' frame
    seen: list[np.ndarray]  # per view: (K,) int indices into xyz of the points that view observed

    def framed(self, centre: np.ndarray, radius: float) -> Tracks:
        """The points in the frame where the sphere ``(centre, radius)`` is the unit sphere (as
        :func:`pipeline.masking.prior.in_sphere_frame` moves the views)."""
        return Tracks((self.xyz - centre) / radius, self.seen)


def tracks_for_views(xyz: np.ndarray, observers: Sequence[Sequence[str]], names: Sequence[str]) -> Tracks:
    """:class:`Tracks` from points ``(M, 3)`` and the names of the photos that observed each, for the views
    ``names`` (observers that are not among them are ignored)."""
    point, image = observation_pairs(observers, names)
    return Tracks(np.asarray(xyz, np.float64).reshape(-1, 3), [point[image == i] for i in range(len(names))])


def track_plane(tracks: Tracks, views: Sequence[View], tolerance: float, seed: int = 0) -> Plane | None:
    """The support plane fitted to the points by RANSAC, in the frame where the object lies in the unit sphere, or
    None: too few points near the object, no dominant plane along the cameras' up, or one that does not cut the
    sphere or come within ``BELOW_SPHERE`` of it (the object stands on what it touches; a floor under a table or
    under a floating object is not that).
    ``tolerance``: the plane's thickness as a share of the median distance of the fitted points from the origin;
    ``consistent_fraction``: the share of those points on it."""
    dist = np.linalg.norm(tracks.xyz, axis=1)
    near = tracks.xyz[dist < PLANE_SEARCH_RADIUS]
    if len(near) < MIN_TRACK_POINTS:
        return None
    up = camera_up(np.stack([v.c2w for v in views]))
    thickness = tolerance * float(np.median(np.linalg.norm(near, axis=1)))
    on = support_plane(near, up, thickness, np.random.default_rng(seed))
    if not on.any():
        return None
    flat = near[on]
    normal = plane_normal(flat, up)
    offset = float(normal @ flat.mean(0))
    if not -1.0 - BELOW_SPHERE < offset < 0.0:
        return None
    return Plane(normal, offset, float(on.mean()), thickness)


def label_points(tracks: Tracks, plane: Plane | None, far: float) -> np.ndarray:
    """``(M,)`` int8 label per point, in the frame where the object lies in the unit sphere: ``FLOOR``,
    ``OBJECT``, ``UNKNOWN`` or ``OUTSIDE`` (see the module doc). ``plane``: :func:`track_plane`'s; ``far``: the
    distance (sphere radii) beyond which a point is the room."""
    dist = np.linalg.norm(tracks.xyz, axis=1)
    labels = np.full(len(dist), UNKNOWN, np.int8)
    labels[dist >= far] = OUTSIDE
    if plane is None:
        return labels
    height = plane.height(tracks.xyz)
    labels[np.abs(height) < plane.thickness] = FLOOR
    labels[(height > OBJECT_CLEARANCE * plane.thickness) & (dist < 1.0)] = OBJECT
    return labels


def seed_maps(view: View, tracks: Tracks, seen: np.ndarray, labels: np.ndarray,
              radius_px: int) -> tuple[np.ndarray, np.ndarray]:
    """``(H, W)`` bool maps of one view: its observed object points and its observed background points (floor and
    outside the sphere), each a square of ``2 radius_px + 1`` pixels at the point's projection."""
    h, w = view.shape
    obj, bg = np.zeros((h, w), bool), np.zeros((h, w), bool)
    if len(seen) == 0:
        return obj, bg
    inside, x, y = pixels_of(tracks.xyz[seen], view.c2w, view.K, (h, w))
    kind = labels[seen][inside]
    square = np.ones((2 * radius_px + 1,) * 2, np.uint8)
    for out, chosen in ((obj, kind == OBJECT), (bg, (kind == FLOOR) | (kind == OUTSIDE))):
        out[y[chosen], x[chosen]] = True
        out[:] = cv2.dilate(out.view(np.uint8), square) > 0
    return obj, bg
