"""Image, depth, normal, mask and mesh metrics: the one definition of each, for evaluation, tests and benchmarks.

Images are linear radiance ``(H, W[, C])``; a ``mask`` ``(H, W)`` selects the pixels compared (all channels
of each). ``peak`` is the white level: 1 decoded unit, the brightest value the capture's reference exposure
records. What ``orca evaluate`` computes with these is defined in :data:`pipeline.evaluation.DEFINITIONS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .imageio import linear_to_srgb

# One peak for every view, component and method, so figures compare across them. A per-view percentile of the
# ground truth lands on highlights (the demo's ceiling light: 2.4 on object views whose 95th percentile is 0.15,
# 25 on the environment view of the ceiling) and moves PSNR by more than 20 dB between views.
PSNR_PEAK = 1.0
PSNR_CAP_DB = 100.0  # identical images: MSE is floored there
SSIM_WINDOW = 11
FSCORE_RADII = (0.01, 0.02, 0.05)  # fractions of the object radius
MESH_SAMPLES = 100_000


def _selection(image: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    return np.ones(image.shape[:2], bool) if mask is None else np.asarray(mask, bool)


def psnr(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, peak: float = PSNR_PEAK) -> float:
    """PSNR in dB of ``pred`` against ``gt`` over the ``mask`` pixels (default: all) and all channels:
    ``10 log10(peak^2 / MSE)``, capped at :data:`PSNR_CAP_DB`. NaN for an empty mask or a non-finite peak."""
    sel = _selection(gt, mask)
    if not sel.any() or not math.isfinite(peak) or peak <= 0:
        return float("nan")
    mse = float(np.mean((pred[sel].astype(np.float64) - gt[sel].astype(np.float64)) ** 2))
    mse = max(mse, peak**2 * 10 ** (-PSNR_CAP_DB / 10))
    return float(10 * np.log10(peak**2 / mse))


def psnr_linear(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, peak: float = PSNR_PEAK) -> float:
    """:func:`psnr` of linear radiance clipped to the sensor's range [0, ``peak``]: a light source's radiance
    above the white level was never recorded, so it is not an error to miss it."""
    return psnr(np.clip(pred, 0, peak), np.clip(gt, 0, peak), mask, peak)


def tone_map(linear: np.ndarray, peak: float = PSNR_PEAK) -> np.ndarray:
    """Linear radiance -> sRGB in [0, 1], ``peak`` mapped to white: ``srgb(clip(x / peak, 0, 1))``."""
    return linear_to_srgb(np.asarray(linear, np.float32) / np.float32(peak))


def psnr_srgb(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, peak: float = PSNR_PEAK) -> float:
    """PSNR of the tone-mapped images (:func:`tone_map` with ``peak``; the PSNR's own peak is then 1) over
    the ``mask`` pixels: the error a viewer sees, highlights above ``peak`` clipped."""
    return psnr(tone_map(pred, peak), tone_map(gt, peak), mask, 1.0)


def matching_gains(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The gain per channel ``(3,)`` that best maps ``pred`` onto ``target`` (both ``(M, 3)``, linear) in the
    least-squares sense; 1 for a channel ``pred`` is black in."""
    num = (pred * target).sum(axis=0, dtype=np.float64)
    den = np.square(pred).sum(axis=0, dtype=np.float64)
    return np.where(den > 0, num / np.maximum(den, np.finfo(np.float64).tiny), 1.0).astype(np.float32)


def ssim(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, peak: float = PSNR_PEAK,
         window: int = SSIM_WINDOW) -> float:
    """Mean SSIM (kornia, Gaussian window, sigma 1.5) over the ``mask`` pixels of ``pred`` and ``gt``
    ``(H, W, 3)`` linear radiance, both tone-mapped with :func:`tone_map`. Outside the mask ``pred`` is replaced
    by ``gt``, so that what the window sees there does not count. The window shrinks (odd) for images smaller
    than it. NaN for an empty mask or a bad peak."""
    import kornia
    import torch

    sel = _selection(gt, mask)
    if not sel.any() or not math.isfinite(peak) or peak <= 0:
        return float("nan")
    h, w = sel.shape
    window = min(window, 2 * min(h, w) - 1)  # 'same' padding reflects window // 2 pixels: needs < H, W
    if window < 3:
        return float("nan")
    a = tone_map(np.where(sel[..., None], pred, gt), peak)
    b = tone_map(gt, peak)
    a_t, b_t = (torch.from_numpy(np.ascontiguousarray(x)).permute(2, 0, 1)[None] for x in (a, b))
    ssim_map = kornia.metrics.ssim(a_t, b_t, window, max_val=1.0)[0].permute(1, 2, 0).numpy()
    return float(ssim_map[sel].mean())


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean ``(H, W)`` masks; 1 when both are empty."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = int(np.count_nonzero(a | b))
    return float(np.count_nonzero(a & b)) / union if union else 1.0


def normal_angular_error(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> float:
    """Mean angle in degrees between normals ``(H, W, 3)`` over ``mask`` ``(H, W)`` pixels whose ``gt`` is
    non-zero. ``pred`` need not be unit length (it is normalized); a zero ``pred`` counts as 90 deg.
    ``gt`` is normalized too. NaN when no pixel qualifies."""
    gt_norm = np.linalg.norm(gt, axis=-1)
    sel = np.asarray(mask, bool) & (gt_norm > 1e-6)
    if not sel.any():
        return float("nan")
    p = pred[sel].astype(np.float64)
    g = gt[sel].astype(np.float64) / gt_norm[sel][:, None]
    p_norm = np.linalg.norm(p, axis=-1)
    p = p / np.maximum(p_norm, 1e-12)[:, None]
    cos = np.clip((p * g).sum(-1), -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)).mean())


def depth_errors(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """``absrel`` = mean(|d - d_gt| / d_gt) and ``rmse`` of depth maps ``(H, W)`` over pixels with a finite,
    positive ``gt`` (and ``mask``, when given); ``pixels`` counts them. NaN figures when there are none."""
    sel = np.isfinite(gt) & (gt > 0)
    if mask is not None:
        sel &= np.asarray(mask, bool)
    n = int(sel.sum())
    if n == 0:
        return {"absrel": float("nan"), "rmse": float("nan"), "pixels": 0}
    d, g = pred[sel].astype(np.float64), gt[sel].astype(np.float64)
    return {"absrel": float(np.mean(np.abs(d - g) / g)), "rmse": float(np.sqrt(np.mean((d - g) ** 2))), "pixels": n}


def mesh_errors(mesh_path: Path, truth_path: Path, radius: float, to_truth: np.ndarray | None = None,
                samples: int = MESH_SAMPLES, fscore_radii: Sequence[float] = FSCORE_RADII) -> dict[str, Any]:
    """A mesh against a true mesh by open3d (``TriangleMesh.compute_metrics``: ``samples`` points on each
    surface, distances to the other surface by ray casting), the mesh first moved by the 4x4 ``to_truth``.
    Chamfer (the sum of the two mean distances) and Hausdorff distances in the true mesh's units and,
    ``*_fraction``, in ``radius``; F-scores in [0, 1] at ``fscore_radii`` x ``radius``."""
    import open3d as o3d

    ours = o3d.io.read_triangle_mesh(str(mesh_path))
    if len(ours.triangles) == 0:
        raise InputError("the mesh has no triangles", mesh_path, "check mesh_report.json beside it")
    theirs = o3d.io.read_triangle_mesh(str(truth_path))
    if len(theirs.triangles) == 0:
        raise InputError("the ground-truth mesh has no triangles", truth_path)
    if to_truth is not None:
        ours.transform(to_truth)
    o3d.utility.random.seed(0)  # the surface samples: the same figures on every run
    params = o3d.t.geometry.MetricParameters(fscore_radius=[f * radius for f in fscore_radii],
                                             n_sampled_points=samples)
    metrics = o3d.t.geometry.Metric
    values = o3d.t.geometry.TriangleMesh.from_legacy(ours).compute_metrics(
        o3d.t.geometry.TriangleMesh.from_legacy(theirs),
        [metrics.ChamferDistance, metrics.HausdorffDistance, metrics.FScore], params).numpy().astype(float)
    chamfer, hausdorff, fscores = float(values[0]), float(values[1]), values[2:]
    return {
        "mesh": str(mesh_path), "ground_truth_mesh": str(truth_path), "object_radius": radius,
        "chamfer": chamfer, "chamfer_fraction": chamfer / radius,
        "hausdorff": hausdorff, "hausdorff_fraction": hausdorff / radius,
        **{f"fscore_{round(100 * f)}pct": float(v) / 100 for f, v in zip(fscore_radii, fscores, strict=True)},
        "samples": samples, "vertices": len(ours.vertices), "triangles": len(ours.triangles),
    }
