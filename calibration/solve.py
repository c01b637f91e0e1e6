"""Intrinsics from detections: cv2.calibrateCamera, per-image reprojection errors, outlier images dropped.

Everything here is in OpenCV's pixel convention; :func:`calibration.result.calibration_doc` converts.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .detect import Detection

log = logging.getLogger("orca.calibration")


@dataclass(frozen=True)
class Solution:
    """Intrinsics (OpenCV convention) and what they explain."""

    K: np.ndarray  # (3, 3), OpenCV pixel convention
    dist: np.ndarray  # (5,) k1, k2, p1, p2, k3
    std: np.ndarray  # (9,) standard deviations of fx, fy, cx, cy, k1, k2, p1, p2, k3 (0 where fixed)
    rms_px: float  # over all corners of all images used
    per_image_rms_px: np.ndarray  # (M,)
    reprojected: list[np.ndarray]  # M x (N_i, 2)
    rvecs: list[np.ndarray]  # M x (3,) board-to-camera rotation (Rodrigues)
    tvecs: list[np.ndarray]  # M x (3,) board-to-camera translation, metres


def solve(detections: list[Detection], size: tuple[int, int], *, fit_k3: bool = False) -> Solution:
    """Calibrate one camera from M >= 3 views of a planar board. ``size``: (width, height) in pixels."""
    import cv2

    obj = [d.object_points.reshape(-1, 1, 3) for d in detections]
    img = [d.image_points.reshape(-1, 1, 2) for d in detections]
    # k3 is left out by default: a handful of board views cannot pin a sixth-order radial term (it trades
    # off against k1, k2 and wanders wildly outside the covered area), and COLMAP's OPENCV model has none.
    flags = 0 if fit_k3 else cv2.CALIB_FIX_K3
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs, std, _, _ = cv2.calibrateCameraExtended(
        obj, img, size, None, None, flags=flags, criteria=criteria
    )
    reprojected, per_image = [], []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, r, t, K, dist)
        p = p.reshape(-1, 2)
        reprojected.append(p)
        per_image.append(float(np.sqrt(np.mean(np.sum((p - i.reshape(-1, 2)) ** 2, axis=1)))))
    return Solution(
        K=np.asarray(K, np.float64),
        dist=np.asarray(dist, np.float64).ravel()[:5],
        std=np.asarray(std, np.float64).ravel()[:9],
        rms_px=float(rms),
        per_image_rms_px=np.array(per_image),
        reprojected=reprojected,
        rvecs=[np.asarray(r).ravel() for r in rvecs],
        tvecs=[np.asarray(t).ravel() for t in tvecs],
    )


def outliers(per_image_rms_px: np.ndarray, factor: float, floor_px: float) -> np.ndarray:
    """Indices of images whose RMS error exceeds both ``factor`` x the median and ``floor_px``.

    Such an image holds a misdetected corner or motion blur and drags every parameter; a fixed floor keeps a
    uniformly excellent set (median 0.1 px) from losing images to noise.
    """
    limit = max(factor * float(np.median(per_image_rms_px)), floor_px)
    return np.flatnonzero(per_image_rms_px > limit)
