"""Colour, per view: OpenCV's GrabCut seeded by what the other cues know (certain background, the hull's core
as object, its band as uncertain)."""

from __future__ import annotations

import logging

import cv2
import numpy as np

from .views import disc

log = logging.getLogger("orca.masks")



GRABCUT_SEED = 0


def grabcut(image: np.ndarray, seeds: np.ndarray, iterations: int) -> np.ndarray:
    """``(H, W)`` bool object mask from OpenCV GrabCut on ``seeds`` (``cv2.GC_*`` labels), cropped to the
    seeds' uncertain region plus context so that the colour models are local and the run is fast. A seed map
    without certain object or any uncertain pixel is returned as is (GrabCut needs both classes)."""
    return grabcut_odds(image, seeds, iterations, odds=False)[0]


def grabcut_odds(image: np.ndarray, seeds: np.ndarray, iterations: int, odds: bool = True
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`grabcut`'s mask and, with ``odds``, ``(H, W)`` float32 the colour's log odds of background over object
    under the colour models GrabCut ended with (:func:`gmm_log_likelihood`): what the colour alone says of each
    pixel, before the smoothness term joins it to its neighbours. +inf where the seeds are certain (GrabCut did
    not decide them) and outside the crop; None when GrabCut did not run."""
    fg = (seeds == cv2.GC_FGD) | (seeds == cv2.GC_PR_FGD)
    unsure = (seeds == cv2.GC_PR_FGD) | (seeds == cv2.GC_PR_BGD)
    if not unsure.any() or not fg.any() or not ((seeds == cv2.GC_BGD) | (seeds == cv2.GC_PR_BGD)).any():
        return fg, None
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
        return fg, None
    finally:
        cv2.setNumThreads(threads)
    out = np.zeros((h, w), bool)
    out[y0:y1, x0:x1] = (crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)
    if not odds:
        return out, None
    pixels = bgr.reshape(-1, 3).astype(np.float64)
    local = (gmm_log_likelihood(bgd, pixels) - gmm_log_likelihood(fgd, pixels)).reshape(bgr.shape[:2])
    colour = np.full((h, w), np.inf, np.float32)
    colour[y0:y1, x0:x1] = local
    colour[~unsure] = np.inf
    return out, colour


GMM_COMPONENTS = 5  # OpenCV GrabCut's colour models: 5 Gaussians, stored as weights, means (3), covariances (3x3)
GMM_MIN_VARIANCE = 1e-3  # keeps a flat colour's covariance invertible (8-bit colour units squared)


def gmm_log_likelihood(model: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """``(N,)`` log density of ``pixels`` ``(N, 3)`` (BGR, 0-255) under an OpenCV GrabCut colour model ``(1, 65)``
    (as ``cv2.grabCut`` leaves it: 5 weights, then 5 means of 3, then 5 covariances of 3x3)."""
    k = GMM_COMPONENTS
    flat = model.ravel()
    weights, means, covs = flat[:k], flat[k:4 * k].reshape(k, 3), flat[4 * k:13 * k].reshape(k, 3, 3)
    # Summed in log space: a colour far from every component of both models (a clipped highlight against two
    # narrow models) would underflow both densities to 0 and read as odds 0, neither object nor room.
    terms = []
    for w, mu, cov in zip(weights, means, covs):
        if w <= 0:
            continue
        cov = cov + GMM_MIN_VARIANCE * np.eye(3)
        d = pixels - mu
        q = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d)
        terms.append(np.log(w) - 0.5 * (q + 3 * np.log(2 * np.pi) + np.log(np.linalg.det(cov))))
    return np.logaddexp.reduce(terms, axis=0) if terms else np.full(len(pixels), -np.inf)


def first_seeds(sphere: np.ndarray, background: np.ndarray, seed_radius: float,
                above_floor: np.ndarray | None = None, known_object: np.ndarray | None = None) -> np.ndarray:
    """GrabCut labels before any hull: certain background outside the sphere's image and on the floor,
    certain object in the central ``seed_radius`` of the sphere's image (the cameras converge on the object) and
    in ``known_object`` (sparse points on it), probable object out to 0.7, probable background beyond."""
    seeds = np.full(sphere.shape, cv2.GC_BGD, np.uint8)
    seeds[sphere < 1.0] = cv2.GC_PR_BGD
    seeds[sphere < 0.7] = cv2.GC_PR_FGD
    if above_floor is not None:
        seeds[above_floor & (sphere < 1.0)] = cv2.GC_PR_FGD
    seeds[background] = cv2.GC_BGD
    # The centre wins over floor evidence: a dark, flat object bottom matches a dark floor anywhere.
    seeds[sphere < seed_radius] = cv2.GC_FGD
    if known_object is not None:
        seeds[known_object & ~background] = cv2.GC_FGD
    return seeds


def hull_seeds(hull: np.ndarray, keep_out: np.ndarray | None, background: np.ndarray, floor: np.ndarray | None,
               erode_px: int, band_px: int, clipped: np.ndarray | None = None,
               known_object: np.ndarray | None = None, core_fraction: float = 0.0,
               core_hull: np.ndarray | None = None, contact: np.ndarray | None = None) -> np.ndarray:
    """GrabCut labels from the hull's reprojection: certain object in the hull's core -- eroded by ``erode_px``
    and farther from the outline than ``core_fraction`` of its deepest pixel's distance (but not in
    ``keep_out``, where the hull is known to be wrong) and on clipped highlights inside the hull (a glossy
    object's highlights are white like many backgrounds), probable object in the rest of the hull, probable
    background in a band around it, certain background beyond and in ``background`` and wherever the floor was
    seen -- except the floor inside the hull, which is only probable background: the bottom rim of a glossy object
    mirrors the floor next to it at grazing angles and passes the floor test. ``known_object`` (sparse points on the
    object) is certain object wherever it is not certain background. ``core_hull`` (a tighter hull's reprojection):
    the core is eroded from it instead, and the rest of ``hull`` is probable object. ``contact`` (where the hull
    meets the support plane) is certain object too, up to the hull's outline: the bottom rim of a glossy object
    mirrors the floor beside it, and colour alone gives it to the floor."""
    h8 = hull.astype(np.uint8)
    seeds = np.full(hull.shape, cv2.GC_BGD, np.uint8)
    seeds[cv2.dilate(h8, disc(band_px)) > 0] = cv2.GC_PR_BGD
    seeds[hull] = cv2.GC_PR_FGD
    if core_hull is not None:
        h8 = (core_hull & hull).astype(np.uint8)
    core = cv2.erode(h8, disc(erode_px)) > 0
    if core_fraction > 0:
        # A hull fattened by loose first masks (a wedge of carpet beside the object) is certain object only in
        # its deep core, so GrabCut can trim the rest by colour; forced, it would keep the wedge in every round.
        inside = cv2.distanceTransform(h8, cv2.DIST_L2, 5)
        core &= inside > core_fraction * float(inside.max(initial=0.0))
    if contact is not None:
        core |= contact & hull
    if keep_out is not None:
        core &= ~keep_out
    if clipped is not None:
        core |= clipped & hull
    seeds[core] = cv2.GC_FGD
    if floor is not None:
        seeds[floor & hull & ~core] = cv2.GC_PR_BGD
        seeds[floor & ~hull] = cv2.GC_BGD
    if known_object is not None:
        seeds[known_object] = cv2.GC_FGD
    seeds[background] = cv2.GC_BGD
    return seeds
