"""The sphere prior, re-estimated from the views: a sphere that really contains the object.

The poses stage's sphere is a guess when it had no masks and no sparse points on a plane (the "framing": a
sphere at the cameras' convergence that fills ``poses.object_window`` of the frame). An elongated object that is
not centred in the photos, or one framed larger than that window, reaches past it -- and everything outside the
sphere's image is certain background, so the masks cut the object (the real blowtorch walk-around: the
reference masks' visual hull has twice the framing sphere's radius, and 30 % of the object lay outside it).

So the masks are probed first: cheap masks (the sphere prior and one round of carving, no floor or sweeps) in the
frame where the current sphere is the unit sphere. Where they reach the sphere's outline in more than
``prior_touch_share`` of the views the object is cut by the sphere: the sphere is re-centred on the probe's hull
and grown by ``prior_growth``, and probed again (at most ``prior_max_growth`` times the first radius). A sphere
that is larger than the object costs the method little (more background, coarser voxels); one that is too small
loses the object for certain.

Spheres here are ``(centre (3,), radius)`` in the frame of the views given (the poses stage's).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..object_frame import sphere_from_masks
from .views import SegmentOptions, View, sphere_distance

log = logging.getLogger("orca.masks")

# The sphere's outline: its image's pixels at most this far from the edge of that image. In pixels, not a share of the
# radius: a mask cut by the sphere stops a few pixels short of it (GrabCut's outline keeps clear of the certain
# background beyond), however large the sphere's image. A textured torus on a poster floor that the sphere cut stopped
# 3-6 px short in most views and was never found cut (a rim of 3 % of the radius); no other capture's masks come
# within 8 px of an outline that does not cut its object.
RIM_PX = 6
RIM_MAX_SHARE = 0.1  # but at most this share of the sphere image's radius: in a thumbnail 6 px is most of the sphere
RIM_COVERED = 0.02  # a mask touches the outline when it covers this share of the outline's pixels
PROBE_EXTENT = 1.0  # the probe's hull is carved in the unit sphere's cube


@dataclass(frozen=True)
class PriorSphere:
    """The sphere segmentation works in, and how it was found."""

    centre: np.ndarray  # (3,) frame of the views given
    radius: float
    probes: list[dict[str, float]]  # per probe: its radius and centre, views touching the outline


def in_sphere_frame(view: View, centre: np.ndarray, radius: float) -> View:
    """``view`` with its camera in the frame where the sphere ``(centre, radius)`` is the unit sphere at the
    origin (a translation and a uniform scale: the image and intrinsics are unchanged)."""
    c2w = view.c2w.copy()
    c2w[:3, 3] = (c2w[:3, 3] - centre) / radius
    return replace(view, c2w=c2w)


def outline_rim(distance: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: the pixels of the unit sphere's image within :data:`RIM_PX` of its outline (at most
    :data:`RIM_MAX_SHARE` of the image's radius, its deepest pixel's depth); ``distance``: :func:`sphere_distance`.
    Where the image cuts the sphere's image off, its edge is not the outline."""
    inside = (distance < 1.0).astype(np.uint8)
    depth = cv2.distanceTransform(np.pad(inside, 1, mode="edge"), cv2.DIST_L2, cv2.DIST_MASK_5)[1:-1, 1:-1]
    return (inside > 0) & (depth <= min(RIM_PX, RIM_MAX_SHARE * float(depth.max(initial=0.0))))


def touches_outline(mask: np.ndarray, distance: np.ndarray) -> bool:
    """Whether ``mask`` ``(H, W)`` reaches the unit sphere's outline (:func:`outline_rim`); ``distance``:
    :func:`sphere_distance`."""
    rim = outline_rim(distance)
    return np.count_nonzero(mask & rim) > RIM_COVERED * max(1, np.count_nonzero(rim))


def touching_views(masks: Sequence[np.ndarray], views: Sequence[View]) -> int:
    """How many of the ``masks`` reach the unit sphere's outline in their view (views in the sphere's frame)."""
    return sum(touches_outline(m, sphere_distance(v)) for m, v in zip(masks, views))


def grown(masks: Sequence[np.ndarray], views: Sequence[View], growth: float) -> tuple[np.ndarray, float]:
    """The next sphere, in the frame of ``views`` (where the current sphere is the unit sphere): centred on the
    bounding sphere of the ``masks``' visual hull (cut by the current sphere, it leans towards where the object
    goes on), radius ``growth`` (the origin when the hull is empty)."""
    c2w = np.stack([v.c2w for v in views])
    K = np.stack([v.K for v in views])
    hull = sphere_from_masks(masks, c2w, K, np.zeros(3), PROBE_EXTENT)
    centre = np.zeros(3) if hull is None else np.asarray(hull[0], float)
    return centre, float(growth)


def probe_options(opts: SegmentOptions) -> SegmentOptions:
    """The cheap segmentation a probe runs: the sphere prior and one round of carving, no floor, no sweeps, no
    colour trim (a probe asks how far the object reaches; trimmed there too, the sphere moved and the blowtorch's
    every sixth photo scored 0.842 / 0.728, median / worst view, against 0.878 / 0.763 trimmed in the final masks
    alone and 0.836 / 0.750 with no trim), no outline to the pixel (a pixel more or less says nothing of that)."""
    return replace(opts, rounds=1, floor=False, sweep=False, front_sweep=False, through_floor=False,
                   trim_colour_log_odds=None, outline_reach_px=0)


def framed_options(opts: SegmentOptions, radius: float) -> SegmentOptions:
    """``opts`` for views framed by a sphere of ``radius`` (in units of the first sphere): the disc taken as
    certain object keeps the size it has in the first sphere, where the cameras converge. A sphere grows because
    the object reaches past it somewhere, not because its core is wider: grown with it, the disc takes in the
    background between an object's parts (a real blowtorch's handle and tank)."""
    return replace(opts, seed_radius=opts.seed_radius / radius)


def outgrown(prior: PriorSphere, masks: Sequence[np.ndarray], framed: Sequence[View], opts: SegmentOptions,
             by: str = "probe") -> tuple[PriorSphere, PriorSphere | None]:
    """Whether ``masks`` (of the views ``framed`` in ``prior``'s frame, where it is the unit sphere) outgrow the
    sphere: ``prior`` with their record added to its probes, and the grown sphere to segment in again (None when
    they reach its outline in at most ``prior_touch_share`` of the views, or it may not grow further). ``by``:
    what made the masks, for the record."""
    touching = touching_views(masks, framed)
    probes = [*prior.probes, {"radius": prior.radius, "centre": prior.centre.tolist(), "touching_views": touching,
                              "by": by}]
    log.info("sphere prior radius %.2f: the %s's masks reach its outline in %d of %d views", prior.radius, by,
             touching, len(framed))
    recorded = replace(prior, probes=probes)
    if touching <= opts.prior_touch_share * len(framed) or prior.radius >= opts.prior_max_growth:
        return recorded, None
    step, factor = grown(masks, framed, min(opts.prior_growth, opts.prior_max_growth / prior.radius))
    return recorded, PriorSphere(prior.centre + prior.radius * step, prior.radius * factor, probes)


def find_prior_sphere(views: Sequence[View], opts: SegmentOptions,
                      segment: Callable[[Sequence[View], SegmentOptions, np.ndarray, float], list[np.ndarray]]
                      ) -> PriorSphere:
    """The sphere (frame of ``views``) that contains the object: the unit sphere, grown while the probe's masks
    reach its outline (see the module doc). ``segment``: views in the sphere's frame, options, the sphere's
    centre and radius in the frame of ``views`` -> masks (the driver)."""
    prior: PriorSphere | None = PriorSphere(np.zeros(3), 1.0, [])
    cheap = probe_options(opts)
    while prior is not None:
        framed = [in_sphere_frame(v, prior.centre, prior.radius) for v in views]
        masks = segment(framed, framed_options(cheap, prior.radius), prior.centre, prior.radius)
        found, prior = outgrown(prior, masks, framed, opts)
    return found
