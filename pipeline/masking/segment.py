"""The driver: the evidence before any hull, then rounds of carving and GrabCut, then the final masks."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import cv2
import numpy as np

from ..config import MasksConfig
from ..metrics import iou
from ..object_frame import camera_up
from .colour import release_room_colours, restore_object_colours, trim_room_colours
from .grabcut import first_seeds, grabcut, grabcut_odds, hull_seeds
from .hull import (
    OUTSIDE_VOTES,
    carve,
    carve_votes,
    core_carve_votes,
    hull_depth,
    hull_grid,
    reproject,
    stand_on_plane,
    voxel_pixels,
)
from .outline import snap_outline
from .parallel import MapViews, serial
from .support_plane import find_support_plane, floor_evidence
from .sweeps import floor_through_hull, front_evidence, occluded_region, occluder_evidence
from .tracks import LABELS, Tracks, label_points, seed_maps, track_plane
from .views import Plane, SegmentOptions, View, disc, neighbours, pixel_rays, sphere_distance, spread

log = logging.getLogger("orca.masks")


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
    track_labels: dict[str, int] | None = None  # the sparse points per label (None: no points)
    unexplained_beside: dict[str, Any] | None = None  # refine_checked's check (None: not made)


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
            near = cv2.dilate(found.astype(np.uint8), disc(reach)) > 0
            out = near if out is None else out | near
    return out


def vote_weights(views: Sequence[View], backgrounds: Sequence[np.ndarray], floors: Sequence[np.ndarray | None],
                 fixed: dict[int, np.ndarray], opts: SegmentOptions,
                 unexplained: Sequence[np.ndarray | None] | None = None,
                 confirmed: Sequence[np.ndarray | None] | None = None,
                 colour_odds: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray | None]:
    """Per view, ``(H, W)`` float32 what a background vote counts in :func:`carve` (None: 1 everywhere).
    ``doubtful_vote`` on dark pixels (brightest channel <= ``dark_level``) that no evidence confirms as background
    (outside the sphere, swept, floor): a dark object bottom and its dark contact shadow look alike, and views
    from above lose the bottom by colour. ``confirmed_vote`` on the ``confirmed`` pixels (a surface behind the
    sphere explains them: the ray passes the object empty; None: nowhere). At most ``unexplained_vote`` on the
    ``unexplained`` pixels (:func:`unexplained_pixels`; None: nowhere)."""
    out: list[np.ndarray | None] = []
    for i, v in enumerate(views):
        if i in fixed:
            out.append(None)
            continue
        weight = np.ones(v.shape, np.float32)
        sure = backgrounds[i] | (v.image.max(-1) > opts.dark_level)
        if floors[i] is not None:
            sure = sure | floors[i]
        weight[~sure] = opts.doubtful_vote
        if confirmed is not None and confirmed[i] is not None:
            weight[confirmed[i]] = opts.confirmed_vote
        if unexplained is not None and unexplained[i] is not None:
            weight[unexplained[i]] = np.minimum(weight[unexplained[i]], opts.unexplained_vote)
        if opts.colour_vote_odds is not None and colour_odds is not None and colour_odds[i] is not None:
            weight *= np.clip(colour_odds[i] / opts.colour_vote_odds, 0.0, 1.0)
        out.append(weight)
    return out


def unexplained_pixels(views: Sequence[View], evidence: Evidence, opts: SegmentOptions
                       ) -> list[np.ndarray | None] | None:
    """Per view, ``(H, W)`` bool: pixels in the sphere's image, brighter than ``dark_level``, that no background
    explains -- the support plane clearly does not, no surface outside the sphere does (textured: a flat patch is
    explained by anything) -- so something inside the sphere is seen there: the object, or a prop standing in
    it. A mirror-like part reflects the room and GrabCut gives it to the background in every view, but no
    background surface explains a reflection. None without a support plane (no ``above`` evidence), or when the
    capture's background is not explained well enough for this to mean anything: the median view's likely
    background (in the sphere's image, outside the first masks) is unexplained in more than
    ``unexplained_max_rate`` of its pixels (a real carpet's weave matches no plane by colour)."""
    if all(a is None for a in evidence.above):
        return None
    out, rates = [], []
    for view, above, background, floor, sphere, first in zip(views, evidence.above, evidence.backgrounds,
                                                              evidence.floors, evidence.spheres, evidence.masks):
        if above is None:
            out.append(None)
            continue
        # not dark: a contact shadow on a support the plane does not explain (a table when the plane found is the
        # floor under it) is as unexplained as a reflection
        found = above & ~background & (~floor if floor is not None else True) & (view.image.max(-1) > opts.dark_level)
        likely_background = (sphere < 1.0) & ~background & ~first
        rates.append(np.count_nonzero(found & likely_background) / max(1, np.count_nonzero(likely_background)))
        out.append(found)
    rate = float(np.median(rates))
    if rate > opts.unexplained_max_rate:
        log.info("the background is unexplained in %.0f %% of its pixels (median view): no object evidence from "
                 "unexplained pixels", 100 * rate)
        return None
    return out


def unexplained_beside(masks: Sequence[np.ndarray], unexplained: Sequence[np.ndarray | None],
                       spheres: Sequence[np.ndarray], reach_px: int) -> list[float | None]:
    """Per view, the unexplained pixels (:func:`unexplained_pixels`) outside the mask ``(H, W)`` bool and in the
    sphere's image, in pieces that touch the mask (within ``reach_px``; 1: adjacent), as a share of the mask's
    area (None: no evidence in that view, or an empty mask). A part the masks lose leaves such pixels beside
    them; the room's own unexplained specks mostly lie apart from the object."""
    out: list[float | None] = []
    for mask, found, sphere in zip(masks, unexplained, spheres):
        area = np.count_nonzero(mask)
        if found is None or area == 0:
            out.append(None)
            continue
        outside = (found & ~mask & (sphere < 1.0)).astype(np.uint8)
        _, pieces = cv2.connectedComponents(outside, connectivity=8)
        near = cv2.dilate(mask.astype(np.uint8), disc(reach_px)) > 0
        touching = np.unique(pieces[near & (pieces > 0)])
        out.append(np.count_nonzero(np.isin(pieces, touching)) / area)  # labels > 0 only: 0 is not a piece
    return out


def view_evidence(view: View, near: Sequence[View] | None, nbrs: Sequence[View], plane: Plane | None,
                  outside: np.ndarray, opts: SegmentOptions
                  ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """One view's ``(occluded, beyond, floor, above)`` (:func:`.sweeps.occluder_evidence` against the sweep's
    neighbours ``near``, None: no sweep; :func:`.support_plane.floor_evidence` against ``nbrs``, None: no
    ``plane``)."""
    occluded, beyond = occluder_evidence(view, near, opts) if near is not None else (None, None)
    if plane is None:
        return occluded, beyond, None, None
    floor, not_floor = floor_evidence(view, nbrs, plane, outside, opts)
    return occluded, beyond, floor, not_floor


def view_masks(run_views: MapViews, fn: Callable[..., Any], tasks: Sequence[tuple[Any, ...]],
               fixed: dict[int, Any], step: Callable[[str], None]) -> list[Any]:
    """Every view's ``(H, W)`` bool mask (or what ``fn`` returns with it): ``fixed``'s where given (the user's),
    else ``fn(*task)`` by ``run_views`` with the next of ``tasks`` (one per view not fixed, in order); a
    "segment" step per view."""
    made = iter(run_views(fn, tasks, lambda: step("segment")))
    masks = [fixed[i] if i in fixed else next(made) for i in range(len(tasks) + len(fixed))]
    for _ in fixed:
        step("segment")
    return masks


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
    objects: list[np.ndarray | None]  # pixels where the view observed a sparse point on the object
    track_labels: dict[str, int] | None = None  # the sparse points per label (None: no points)
    beyond: list[np.ndarray | None] | None = None  # pixels a surface behind the sphere explains (None: no sweep)


def gather_evidence(views: Sequence[View], opts: SegmentOptions, fixed: dict[int, np.ndarray] | None = None,
                    step: Callable[[str], None] = lambda label: None, tracks: Tracks | None = None,
                    run_views: MapViews = serial) -> Evidence:
    """The support plane, floor, swept and sparse-point evidence per view, and the first masks from the sphere
    prior (each view's by ``run_views``)."""
    fixed = fixed or {}
    nbrs = neighbours(views, opts.neighbours, opts.neighbour_max_deg)
    use_tracks = tracks is not None and opts.tracks
    sparse_plane = track_plane(tracks, views, opts.track_plane_tolerance) if use_tracks else None
    labels = label_points(tracks, sparse_plane, opts.track_far) if use_tracks else None
    plane = None
    if opts.floor:
        if opts.support_plane_from != "points" or sparse_plane is None:
            plane = find_support_plane(views, nbrs, opts, start=sparse_plane)
        if plane is None and opts.support_plane_from != "photos":
            plane = sparse_plane
    step("support plane")
    if plane is not None:
        log.info("support plane %.3f below the centre, tilt %.1f deg from the cameras' up, %s", -plane.offset,
                 np.degrees(np.arccos(np.clip(plane.normal @ camera_up(np.stack([v.c2w for v in views])), -1, 1))),
                 f"fitted to {100 * plane.consistent_fraction:.0f} % of the sparse points near the object"
                 if plane.thickness else
                 f"explains {100 * plane.consistent_fraction:.0f} % of the pixels around the object")

    spheres = [sphere_distance(v) for v in views]
    outsides, objects = [], []
    for i, v in enumerate(views):
        outside = spheres[i] >= 1.0
        if labels is not None:
            seen_object, seen_background = seed_maps(v, tracks, tracks.seen[i], labels, opts.track_seed_px)
            objects.append(seen_object)
            outside = outside | seen_background
        else:
            objects.append(None)
        outsides.append(outside)
    near = neighbours(views, opts.sweep_neighbours, opts.neighbour_max_deg) if opts.sweep else None
    found = run_views(view_evidence, [(v, [views[j] for j in near[i]] if near is not None else None,
                                       [views[j] for j in nbrs[i]], plane, outsides[i], opts)
                                      for i, v in enumerate(views)], lambda: step("floor"))
    occluded, beyond, floors, above = ([f[k] for f in found] for k in range(4))
    backgrounds = [o if swept is None else o | swept for o, swept in zip(outsides, occluded)]

    certain = [b if f is None else b | f for b, f in zip(backgrounds, floors)]
    masks = view_masks(run_views, grabcut, [(v.image, first_seeds(spheres[i], certain[i], opts.seed_radius, above[i],
                                                                   objects[i]), opts.grabcut_iterations)
                                            for i, v in enumerate(views) if i not in fixed], fixed, step)
    counts = None if labels is None else {name: int((labels == value).sum()) for name, value in LABELS.items()}
    return Evidence(plane, spheres, floors, above, backgrounds, occluded, masks, objects, counts, beyond)


def segment(views: Sequence[View], opts: SegmentOptions, fixed: dict[int, np.ndarray] | None = None,
            on_step: Callable[[str], None] | None = None, tracks: Tracks | None = None,
            on_retry: Callable[[], None] = lambda: None, run_views: MapViews = serial) -> Segmentation:
    """Object masks for every view (see the module doc).

    Args:
        views: the photos at the working size, cameras in the normalized frame.
        fixed: view index -> ``(H, W)`` bool mask the user gave: kept as is, and it votes in every carve.
        on_step: called with a short label after each unit of work (progress bars).
        tracks: the poses stage's sparse points in the views' frame and which views observed them (seeds: see
            :mod:`.tracks`), or None.
        on_retry: called before the rounds run again (:func:`refine_checked`), e.g. to rewind a progress bar.
        run_views: runs each view's work (:mod:`.parallel`).
    """
    step = on_step or (lambda label: None)
    evidence = gather_evidence(views, opts, fixed, step, tracks, run_views)
    return refine_checked(views, opts, evidence, fixed, step, on_retry, run_views)


def refine_checked(views: Sequence[View], opts: SegmentOptions, evidence: Evidence,
                   fixed: dict[int, np.ndarray] | None = None,
                   step: Callable[[str], None] = lambda label: None,
                   on_retry: Callable[[], None] = lambda: None, run_views: MapViews = serial) -> Segmentation:
    """:func:`refine`, then a check for a part lost alike in every view: when the masks leave out, in the median
    view, unexplained pixels touching them (:func:`unexplained_beside`) of more than ``unexplained_retry_share``
    of their area, the rounds run again with ``unexplained_vote`` 0. The hull agrees with masks that are all wrong
    the same way (a vase's mirror-like neck, or paint coloured like the posters around it, given to the room in
    every view), but no background surface explains what they left out. The second masks are kept only if they
    explain it: at most ``unexplained_retry_share`` left beside them. Otherwise the unexplained pixels were not a
    part lost alike but something wider the support plane does not explain (a table top when the plane found is
    the floor under it), and counting them as the object's only grows the masks into it: the first masks stay.
    The check needs the support plane's evidence and a capture whose background is mostly explained
    (``unexplained_max_rate``)."""
    fixed = fixed or {}
    seg = refine(views, opts, evidence, fixed, step, run_views)
    if opts.unexplained_vote < 1.0 or opts.unexplained_retry_share <= 0:
        return seg
    unexplained = unexplained_pixels(views, evidence, opts)
    if unexplained is None:
        return seg
    auto = [i for i in range(len(views)) if i not in fixed]

    def median_share(masks: Sequence[np.ndarray]) -> float | None:
        shares = unexplained_beside([masks[i] for i in auto], [unexplained[i] for i in auto],
                                    [evidence.spheres[i] for i in auto], opts.unexplained_reach_px)
        known = [s for s in shares if s is not None]
        return float(np.median(known)) if known else None

    before = median_share(seg.masks)
    seg.unexplained_beside = {"median": before, "threshold": opts.unexplained_retry_share, "retried": False}
    if before is None or before <= opts.unexplained_retry_share:
        return seg
    log.warning("the masks leave out unexplained pixels beside them of %.0f %% of their area (median view): a part "
                "lost in every view; segmenting again with their background votes not counted", 100 * before)
    on_retry()
    again = refine(views, replace(opts, unexplained_vote=0.0), evidence, fixed, step, run_views)
    after = median_share(again.masks)
    kept = after is not None and after <= opts.unexplained_retry_share
    check = {"median": before, "threshold": opts.unexplained_retry_share, "retried": True, "median_after": after,
             "kept": "second" if kept else "first"}
    if kept:
        log.info("segmented again: unexplained pixels beside the masks %.0f %% of their area (median view)",
                 100 * after)
        again.unexplained_beside = check
        return again
    log.warning("segmented again, the masks still leave out unexplained pixels beside them of %s of their area "
                "(median view): not a part lost alike in every view but something wider that no background "
                "explains (a table under the object when the support plane found is the floor); the first masks "
                "are kept",
                "?" if after is None else f"{100 * after:.0f} %")
    seg.unexplained_beside = check
    return seg


def probe_masks(tracks: Tracks | None, fixed: dict[int, np.ndarray] | None = None, run_views: MapViews = serial
                ) -> Callable[[Sequence[View], SegmentOptions, np.ndarray, float], list[np.ndarray]]:
    """The driver :func:`.prior.find_prior_sphere` probes with: :func:`segment` on views framed by the sphere
    ``(centre, radius)``, the sparse points ``tracks`` (frame of the unframed views, or None) framed the same way."""
    def probe(views: Sequence[View], opts: SegmentOptions, centre: np.ndarray, radius: float) -> list[np.ndarray]:
        return segment(views, opts, fixed=fixed, tracks=tracks.framed(centre, radius) if tracks is not None else None,
                       run_views=run_views).masks
    return probe


def segment_options(config: MasksConfig) -> SegmentOptions:
    """The method's knobs a user sets, from the masks config section's fields of the same names."""
    return SegmentOptions(**{f.name: getattr(config, f.name) for f in fields(SegmentOptions)
                             if f.name in type(config).model_fields})


def _log_found(r: int, what: str, views: Sequence[View], found: Sequence[np.ndarray | None]) -> None:
    names = [v.name for v, f in zip(views, found) if f is not None and f.any()]
    if names:
        log.info("round %d: %s in %d view(s): %s", r + 1, what, len(names), ", ".join(names))


def core_lost(colour: np.ndarray, hull: np.ndarray, erode_px: int) -> float:
    """The share of the hull's core (``hull`` ``(H, W)`` bool eroded by ``erode_px``) that the mask ``colour``
    leaves out. Unlike their IoU it ignores the band along the outline, where the hull overhangs the object by a
    pixel or two -- a large share of a small object's area."""
    core = cv2.erode(hull.astype(np.uint8), disc(erode_px)) > 0
    n = np.count_nonzero(core)
    return float(np.count_nonzero(core & ~colour) / n) if n else 0.0


def final_mask(colour: np.ndarray, hull: np.ndarray, background: np.ndarray, occluded: np.ndarray | None,
               opts: SegmentOptions) -> np.ndarray:
    """``(H, W)`` bool: a view's final mask from its last GrabCut mask ``colour`` and the hull's reprojection
    ``hull``. The hull -- the views agree on it, and it keeps what one view's colours lose (a glossy rim mirroring
    the background, a dark bottom on its dark shadow) -- within ``final_reach_px`` of ``colour`` (the view's
    colours trim the hull's overhang at the outline), less what this view knows the hull cannot: certain
    ``background`` and, with ``final_reach_px`` -1, the pieces GrabCut gave to a prop in front (``occluded``).
    Where ``colour`` lost more than ``final_max_core_lost`` of the hull's core (:func:`core_lost`) the view's
    colours failed (a shadowed side lost to a dark floor): the hull less certain background."""
    if core_lost(colour, hull, opts.core_erode_px) > opts.final_max_core_lost:
        return hull & ~background
    if opts.final_reach_px >= 0:
        near = cv2.dilate(colour.astype(np.uint8), disc(opts.final_reach_px)) > 0 if opts.final_reach_px else colour
        return hull & near & ~background
    return hull & ~background & ~occluded_region(hull, colour, occluded)


def hull_evidence(view: View, volume: np.ndarray, max_votes: float, near: Sequence[View], around: Sequence[View],
                  plane: Plane | None, opts: SegmentOptions, core_votes: float | None = None,
                  contact_height: float | None = None, props: bool = True
                  ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """One view's ``(depth, front, through, core, contact)``: where its rays enter the hull ``volume < max_votes``
    cut at the support ``plane`` (:func:`.hull.hull_depth`), and, given the plane and ``props``, a prop in front
    of the hull (:func:`.sweeps.front_evidence` against ``near``) and the floor seen through it
    (:func:`.sweeps.floor_through_hull` against ``around``), the tighter hull ``volume < core_votes``
    reprojected (:func:`.hull.reproject`), and the hull's contact with the plane up to ``contact_height``
    (:func:`contact_band`, less the dark pixels: a contact shadow is dark, a glossy rim mirroring the floor is not),
    each None when not looked for."""
    core = reproject(volume, view, core_votes, plane) if core_votes is not None else None
    depth = hull_depth(volume, view, max_votes, plane)
    front = through = contact = None
    if plane is not None and contact_height is not None:
        contact = contact_band(view, depth, plane, contact_height) & (view.image.max(-1) > opts.dark_level)
    if plane is not None and props and opts.front_sweep:
        front = front_evidence(view, near, plane, depth, volume, max_votes, opts)
    if plane is not None and props and opts.through_floor:
        through = floor_through_hull(view, around, plane, np.isfinite(depth), opts)
    return depth, front, through, core, contact


def contact_band(view: View, depth: np.ndarray, plane: Plane, height: float) -> np.ndarray:
    """``(H, W)`` bool: pixels whose ray enters the hull (``depth``, :func:`.hull.hull_depth`) at most ``height``
    (sphere radii) above the support ``plane``: where the object meets what it stands on."""
    hit = np.isfinite(depth)
    rays = pixel_rays(view)
    points = view.c2w[:3, 3] + rays * np.where(hit, depth, 0.0)[..., None]
    return hit & (plane.height(points) < height)


def round_mask(image: np.ndarray, hull: np.ndarray, released: np.ndarray | None, background: np.ndarray,
               floor: np.ndarray | None, clipped: np.ndarray | None, objects: np.ndarray | None, core_fraction: float,
               opts: SegmentOptions, core_hull: np.ndarray | None = None, contact: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """One view's GrabCut mask ``(H, W)`` bool in a round: seeded by the hull's reprojection ``hull``
    (:func:`.grabcut.hull_seeds`: its core -- or ``core_hull``'s, a tighter hull's reprojection -- and the hull's
    ``contact`` band with the support plane forced as object but where ``released``), the forced core's pixels
    coloured like the room beside the object released (:func:`.colour.release_room_colours`); with
    ``colour_vote_odds``, also its colour odds on the thin pieces it cut off the hull (:func:`thin_cut_odds`; else
    None)."""
    seeds = hull_seeds(hull, released, background, floor, opts.core_erode_px, opts.band_px, clipped, objects,
                       core_fraction, core_hull, contact)
    if opts.core_colour_log_odds is not None:
        seeds = release_room_colours(image, seeds, opts.core_fraction, opts.colour_ring_px, opts.colour_bins,
                                     opts.core_colour_log_odds, opts.colour_min_pixels, opts.colour_open_px)
    mask, odds = grabcut_odds(image, seeds, opts.grabcut_iterations, odds=opts.colour_vote_odds is not None)
    return mask, thin_cut_odds(hull, mask, odds, opts.colour_vote_thin_px) if odds is not None else None


def thin_cut_odds(hull: np.ndarray, mask: np.ndarray, odds: np.ndarray, thin_px: int) -> np.ndarray:
    """``(H, W)`` float32: the colour ``odds`` (:func:`.grabcut.grabcut_odds`) on the pieces the GrabCut ``mask``
    cut off the ``hull`` (both ``(H, W)`` bool) that a disc of ``thin_px`` does not fit in, +inf on the wider ones
    (0: on every piece). A thin piece is a part GrabCut's smoothness joined to the background; a wide one a gap
    of room the hull kept, which the object's colour model, learned from that hull, also holds."""
    if thin_px <= 0:
        return odds
    cut = (hull & ~mask).astype(np.uint8)
    wide = cv2.morphologyEx(cut, cv2.MORPH_OPEN, disc(thin_px)) > 0
    return np.where(wide, np.float32(np.inf), odds)


def firm_hull(volume: np.ndarray, views: Sequence[View], fixed: dict[int, np.ndarray], max_votes: float,
              plane: Plane | None, run_views: MapViews) -> list[np.ndarray | None]:
    """Per view, ``(H, W)`` bool: the pixels whose ray crosses a voxel of ``volume`` with fewer than ``max_votes``
    background votes (:func:`.hull.reproject`), where hardly any view sees past the hull; None for the ``fixed``
    views (the user's masks are kept as they are)."""
    auto = [i for i in range(len(views)) if i not in fixed]
    found = dict(zip(auto, run_views(reproject, [(volume, views[i], max_votes, plane) for i in auto], lambda: None)))
    return [found.get(i) for i in range(len(views))]


def refine(views: Sequence[View], opts: SegmentOptions, evidence: Evidence, fixed: dict[int, np.ndarray] | None = None,
           step: Callable[[str], None] = lambda label: None, run_views: MapViews = serial) -> Segmentation:
    """Rounds of carving and GrabCut from the ``evidence``, then the final masks (see the module doc); each view's
    work by ``run_views``."""
    fixed = fixed or {}
    n = len(views)
    plane, backgrounds, occluded = evidence.plane, evidence.backgrounds, evidence.occluded
    floors = list(evidence.floors)
    masks = list(evidence.masks)
    near = neighbours(views, opts.sweep_neighbours, opts.neighbour_max_deg)
    around = spread(views, opts.through_views)
    unexplained = unexplained_pixels(views, evidence, opts) if opts.unexplained_vote < 1.0 else None
    points, index = hull_grid(opts.hull_resolution, plane)
    pixels = voxel_pixels(points, views, run_views)
    rounds: list[dict[str, float]] = []
    hulls: list[np.ndarray] = []
    volume = np.full((opts.hull_resolution,) * 3, OUTSIDE_VOTES, np.float32)
    through: list[np.ndarray | None] = [None] * n
    fronts: list[np.ndarray | None] = [None] * n
    odds: list[np.ndarray | None] | None = None
    for r in range(opts.rounds):
        weights = vote_weights(views, backgrounds, floors, fixed, opts, unexplained, evidence.beyond, odds)
        volume = stand_on_plane(carve(masks, pixels, index, opts.hull_resolution, weights, run_views), plane,
                                opts.stand_height)
        votes = carve_votes(opts, n)
        core_votes = core_carve_votes(opts, n)
        core_max = None if core_votes is None else core_votes - 0.5
        contact_height = opts.contact_height if r == opts.rounds - 1 else None  # only the last round forces it
        step("carve")
        # Props in front of the object inside the sphere are found anew against each round's hull, from the second
        # (the sphere prior's masks make a hull too loose to have much in front of it).
        found = run_views(hull_evidence, [(v, volume, votes - 0.5, [views[j] for j in near[i]],
                                           [views[j] for j in around[i]], plane, opts,
                                           core_max if i not in fixed else None, contact_height,
                                           r > 0 and i not in fixed)
                                          for i, v in enumerate(views)],
                          (lambda: step("evidence against the hull")) if r > 0 else (lambda: None))
        hulls = [np.isfinite(f[0]) for f in found]
        cores = [f[3] for f in found]
        contacts = [f[4] for f in found]
        if r > 0:
            fronts = [f[1] for f in found]
            through = [f[2] for f in found]
            _log_found(r, "a prop in front of the hull", views, fronts)
            _log_found(r, "the floor seen through the hull", views, through)
        # Both are certain background: no mask keeps them, and the floor confirms the view's votes in the next carve.
        backgrounds = [np.logical_or.reduce([e for e in (b, t, f) if e is not None])
                       for b, t, f in zip(evidence.backgrounds, through, fronts)]
        # Before the last round only the hull's deep core is certain object: colour trims the wedges of room that
        # loose first masks leave in the hull, and the next carve removes them (they are off the object in many
        # views). The last round forces the whole core again: a glossy rim that mirrors the room is lost by colour
        # only in the few views that see it at the outline, so the hull kept it, and these masks keep it too. The
        # core is cut from a tighter hull (core_carve_share): a wedge that fewer views than carve_share see past,
        # but a good many do, is left to colour rather than forced in every round.
        # The last round also forces where the hull meets the support plane (contacts): a glossy bottom rim mirrors
        # the floor beside it, and the 3 px rim the core leaves to colour would go to the floor in every view.
        core = opts.core_fraction if r < opts.rounds - 1 else opts.final_core_fraction
        tasks = [(v.image, hulls[i], _released(occluded[i], fronts[i], through[i], opts), backgrounds[i], floors[i],
                  v.clipped, evidence.objects[i], core, opts, cores[i], contacts[i])
                 for i, v in enumerate(views) if i not in fixed]
        made = view_masks(run_views, round_mask, tasks, {i: (m, None) for i, m in fixed.items()}, step)
        new, odds = [m for m, _ in made], [o for _, o in made]
        agreement = [iou(a, b) for a, b in zip(new, hulls)]
        change = [iou(a, b) for a, b in zip(new, masks)]
        rounds.append({"agreement_median": float(np.median(agreement)), "agreement_min": float(np.min(agreement)),
                       "change_median": float(np.median(change))})
        log.info("round %d: GrabCut vs hull IoU median %.3f (worst %.3f); masks changed by %.3f IoU", r + 1,
                 rounds[-1]["agreement_median"], rounds[-1]["agreement_min"], 1 - rounds[-1]["change_median"])
        masks = new
    final, failed = [], []
    for i, (m, h) in enumerate(zip(masks, hulls)):
        if i not in fixed:
            if core_lost(m, h, opts.core_erode_px) > opts.final_max_core_lost:
                failed.append(views[i].name)
            m = final_mask(m, h, backgrounds[i], occluded[i], opts)
        final.append(m)
    if failed:
        log.info("GrabCut left out more than %.0f %% of the hull's core in %d view(s), their masks are the hull's: "
                 "%s", 100 * opts.final_max_core_lost, len(failed), ", ".join(failed))
    if opts.trim_colour_log_odds is not None:
        # Only where some view sees past every voxel of the ray's way through the hull: a gap between the object's
        # parts that too few views see through to carve. A glossy rim showing the room is solid object to every
        # view that sees it inside its outline (unrestricted, a dark glossy blob in a poster room lost its rims:
        # worst view 0.962 -> 0.874).
        firm = firm_hull(volume, views, fixed, opts.trim_seen_through_votes, plane, run_views)
        trimmable = [None if f is None else h & ~f for h, f in zip(hulls, firm)]
        final = trim_room_colours([v.image for v in views], final, trimmable, opts.trim_colour_bins,
                                  opts.trim_colour_log_odds, opts.trim_capture_log_odds, opts.colour_open_px,
                                  opts.trim_core_px, opts.trim_band_px, opts.colour_min_pixels)
    if opts.restore_colour_log_odds is not None:
        # The converse: a piece of the hull that hardly any view sees past, which this view's colours gave to the
        # room although they say nothing either way (a white mug's shadowed side on its dark shadow), is the object
        # the views agree on. A gap few views see through keeps the room's colours, and stays out.
        firm = firm_hull(volume, views, fixed, opts.restore_seen_through_votes, plane, run_views)
        restorable = [None if f is None else h & f & ~m & ~b for h, f, m, b in zip(hulls, firm, final, backgrounds)]
        final = restore_object_colours([v.image for v in views], final, restorable, opts.trim_colour_bins,
                                       opts.restore_colour_log_odds, opts.restore_piece_px, opts.colour_open_px,
                                       opts.trim_core_px, opts.trim_band_px, opts.colour_min_pixels)
    if opts.outline_reach_px > 0:
        final = [m if i in fixed else snap_outline(views[i].image, m, opts.outline_reach_px, opts.outline_contrast,
                                                   opts.outline_margin, opts.outline_residual, backgrounds[i])
                 for i, m in enumerate(final)]
    return Segmentation(final, masks, hulls, floors, occluded, plane, volume, rounds, evidence.track_labels)
