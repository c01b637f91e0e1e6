"""The evaluate stage: a trained model against a synthetic capture's ground truth (``orca evaluate``).

Object views (the capture's cameras, ``ground_truth/cameras.json``) are rendered from the model and compared
with the ground truth: normal mean angular error, mask IoU, PSNR/SSIM of the combined (rgb), diffuse and
specular images, and z-depth errors. Environment views (``ground_truth/environment/``: virtual cameras at and
near the object centre, rendered with the object removed) are rendered from the environment field alone and
compared in RGB (PSNR/SSIM) and z-depth (AbsRel/RMSE), over all pixels and over *prop pixels* (those whose
ground-truth 3-D point lies on one of the scene's props: the close-by objects that make the field 5D).

Definitions (every figure is per view; a mean is the mean over views of the per-view figures, NaN-free):

- Units: ground-truth radiance x ``scene.json["radiance_to_decoded"]["factor"]`` = decoded units, the units
  the model was trained in. Depth in ground-truth world units.
- Object region (PSNR, SSIM, depth): the ground truth's *interior* object pixels, where diffuse + specular =
  linear holds: coverage 255 (``ground_truth/coverage/``), eroded by the optics blur's 3-sigma radius
  (``scene.json["ground_truth"]["optics_blur_px"]``). Silhouette pixels mix object and room and are left out.
  Without ``coverage/`` the object mask eroded by :data:`FALLBACK_ERODE_PX` pixels is used. The JSON says which.
- Normal MAE: over ground-truth mask pixels with a non-zero ground-truth normal; the predicted normal (an
  opacity-weighted sum) is normalized; where the model sees nothing (zero normal) the error counts as 90 deg.
- Mask IoU: predicted opacity > 0.5 against the ground-truth mask.
- PSNR peak: one fixed value, :data:`PSNR_PEAK` = 1 decoded unit, the white level of the capture's reference
  exposure (the brightest value its photos, the model's training data, can hold). The same for every view,
  component and method, so figures compare across all of them. (A per-view 99th percentile of the ground
  truth was tried: on the demo it lands on the ceiling light's highlight, 2.4 on object views whose 95th
  percentile is 0.15, and 25 on the environment view of the ceiling, moving PSNR by > 20 dB between views.)
- ``psnr_*``: ``10 log10(peak^2 / MSE)`` on linear radiance clipped to [0, peak], what the sensor records
  (the photos clip there too, so a light source's true radiance above it was never observable), over the
  region's pixels and channels. ``psnr_srgb_*``: the same on the tone-mapped images below with
  peak 1, i.e. on what the camera would show (highlights clipped): the figure to set beside the paper's,
  whose images are LDR. MSE is floored so PSNR is capped at :data:`PSNR_CAP_DB` (identical images).
- Tone mapping (SSIM, sRGB PSNR, pictures): ``srgb(clip(x / peak, 0, 1))``.
- SSIM (kornia, 11x11 Gaussian window, sigma 1.5): on tone-mapped images, the mean of the SSIM map over the
  region's pixels and channels; outside the region the prediction is replaced by the ground truth so that
  background in the window does not count.
- Depth: AbsRel ``mean(|d - d_gt| / d_gt)`` and RMSE over pixels with finite ground-truth depth (and, for
  object views, inside the region); prop pixels: ground-truth points within :data:`PROP_MARGIN` of a prop.
- ``downscale`` k renders at ``(H // k, W // k)`` with the intrinsics scaled (pixel centres map to the centres
  of k x k blocks) and reduces the ground truth over each block: radiance by the mean; masks by the mean
  >= 0.5; interior, finite depth and non-zero normals only where the whole block is (depth then the block's
  mean, normals the normalized block mean).
- Frames: the model's world frame maps to the ground truth's by a 4x4 similarity ``to_ground_truth``:
  cameras are moved into the model frame to render, predicted depths scaled and normals rotated back. The
  similarity is fitted (Umeyama, :func:`pipeline.alignment.compare_poses`) on the centres of the cameras the
  model was trained with (``--cameras``, e.g. ``results/<capture>/poses/cameras.json``; default: the cameras
  the train manifest records) matched by name to the ground truth's. Identity (to rounding) when training used
  the ground-truth cameras.
- Poses: after that alignment, per camera the rotation error (deg) and the centre error, in ground-truth
  units and in % of the orbit radius (the ground-truth cameras' median distance from the object centre).
  Ground-truth cameras the result lacks (photos SfM did not register) are listed, not counted.
- Mesh (``--mesh``, e.g. ``results/<capture>/mesh/mesh.ply``): moved into the ground-truth frame and compared
  with ``ground_truth/object.ply`` by open3d (``TriangleMesh.compute_metrics``, :data:`MESH_SAMPLES` points
  sampled on each surface, distances to the other surface by ray casting): Chamfer distance (the sum of the
  two mean distances), Hausdorff distance and F-score at 1/2/5 % of the object radius; distances also as a
  fraction of the object radius (``scene.json`` object.radius).

Writes ``OUT/`` atomically: ``evaluate.json`` (every figure per view and the means, what was compared,
timing), ``object_grid.png`` and ``environment_grid.png`` (ground truth beside prediction), the predicted
images at the rendered size in decoded units and the ground-truth frame (``<view>_rgb|diffuse|specular|normal|
depth.exr``, the normal as rendered: opacity-weighted, not normalized; ``<view>_mask.png``, opacity > 0.5;
``env_<view>_rgb|depth.exr``) and ``manifest.json``.

``orca evaluate RESULTS`` also takes a capture's results folder (``results/<capture>/``): its ``train/``,
``poses/cameras.json`` and ``mesh/mesh.ply`` are then used where they exist.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, file_sha256, read_json, write_json, write_manifest
from ..cameras import Camera, CameraSet, load_cameras, scaled_intrinsics
from ..errors import InputError
from ..provenance import FORCE_HELP, common_capture
from .render import render_environment_view, render_object_view, write_views

log = logging.getLogger("orca.evaluate")

EVALUATE_JSON = "evaluate.json"
PSNR_CAP_DB = 100.0
PSNR_PEAK = 1.0  # decoded units: the white level of the reference exposure (see the module doc)
DISPLAY_PERCENTILE = 99.0
SSIM_WINDOW = 11
PROP_MARGIN = 0.05
FALLBACK_ERODE_PX = 2
GRID_OBJECT_VIEWS = 4
MESH_SAMPLES = 100_000
FSCORE_RADII = (0.01, 0.02, 0.05)  # object radii

OBJECT_METRICS = (
    "normal_mae_deg", "mask_iou",
    "psnr_rgb", "psnr_srgb_rgb", "ssim_rgb",
    "psnr_diffuse", "psnr_srgb_diffuse", "ssim_diffuse",
    "psnr_specular", "psnr_srgb_specular", "ssim_specular",
    "depth_absrel", "depth_rmse",
)
ENVIRONMENT_METRICS = (
    "psnr", "psnr_srgb", "ssim", "psnr_all", "psnr_srgb_all", "ssim_all",
    "depth_absrel", "depth_rmse", "prop_depth_absrel", "prop_depth_rmse",
)


# ---------------------------------------------------------------------------------------------- metrics


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


def percentile_peak(gt: np.ndarray, mask: np.ndarray, percentile: float = DISPLAY_PERCENTILE) -> float:
    """The ``percentile`` of ``gt`` ``(H, W[, C])`` over ``mask`` pixels (all channels): an automatic exposure
    for pictures. NaN for an empty mask or a non-positive value (a black image has no meaningful peak)."""
    values = gt[np.asarray(mask, bool)]
    if values.size == 0:
        return float("nan")
    peak = float(np.percentile(values, percentile))
    return peak if peak > 0 else float("nan")


def masked_psnr(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray, peak: float = PSNR_PEAK) -> float:
    """PSNR in dB of ``pred`` against ``gt`` (``(H, W[, C])``, linear) over the ``mask`` ``(H, W)`` pixels and
    all channels: ``10 log10(peak^2 / MSE)``, capped at :data:`PSNR_CAP_DB`. NaN for an empty mask or a
    non-finite peak."""
    sel = np.asarray(mask, bool)
    if not sel.any() or not math.isfinite(peak) or peak <= 0:
        return float("nan")
    mse = float(np.mean((pred[sel].astype(np.float64) - gt[sel].astype(np.float64)) ** 2))
    mse = max(mse, peak**2 * 10 ** (-PSNR_CAP_DB / 10))
    return float(10 * np.log10(peak**2 / mse))


def masked_psnr_linear(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray, peak: float = PSNR_PEAK) -> float:
    """:func:`masked_psnr` of linear radiance clipped to the sensor's range [0, ``peak``]."""
    return masked_psnr(np.clip(pred, 0, peak), np.clip(gt, 0, peak), mask, peak)


def tone_map(linear: np.ndarray, peak: float = PSNR_PEAK) -> np.ndarray:
    """Linear radiance -> sRGB in [0, 1], ``peak`` mapped to white."""
    from ..imageio import linear_to_srgb

    return linear_to_srgb(np.asarray(linear, np.float32) / np.float32(peak))


def masked_psnr_srgb(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray, peak: float = PSNR_PEAK) -> float:
    """PSNR of the tone-mapped images (:func:`tone_map` with ``peak``; the PSNR's own peak is then 1) over
    the ``mask`` pixels: the error a viewer sees, highlights above ``peak`` clipped."""
    return masked_psnr(tone_map(pred, peak), tone_map(gt, peak), mask, 1.0)


def masked_ssim(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray, peak: float = PSNR_PEAK,
                window: int = SSIM_WINDOW) -> float:
    """Mean SSIM over the ``mask`` ``(H, W)`` pixels of ``pred`` and ``gt`` ``(H, W, 3)`` linear radiance,
    both tone-mapped with :func:`tone_map` (``peak`` -> white). Outside the mask ``pred`` is replaced by
    ``gt``. The window shrinks (odd) for images smaller than it. NaN for an empty mask or a bad peak."""
    import kornia
    import torch

    sel = np.asarray(mask, bool)
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


def mask_iou(pred: np.ndarray, gt: np.ndarray) -> float:
    """Intersection over union of two boolean ``(H, W)`` masks; 1 when both are empty."""
    pred, gt = np.asarray(pred, bool), np.asarray(gt, bool)
    union = int((pred | gt).sum())
    return float((pred & gt).sum() / union) if union else 1.0


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


# ------------------------------------------------------------------------------------------------ props


@dataclass(frozen=True)
class Prop:
    """A scene prop from ``scene.json``: ``box`` (``size`` = half extents before the yaw about z), ``sphere``
    (``size`` = radius x 3) or ``cylinder`` (``size`` = (radius, radius, height), axis along z through
    ``centre``)."""

    name: str
    kind: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw_deg: float = 0.0

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Prop:
        if d.get("kind") not in ("box", "sphere", "cylinder"):
            raise ValueError(f"prop {d.get('name')!r}: unknown kind {d.get('kind')!r}")
        return cls(str(d.get("name", "")), d["kind"], tuple(map(float, d["centre"])), tuple(map(float, d["size"])),
                   float(d.get("yaw_deg", 0.0)))

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """``(..., 3)`` world points -> ``(...)`` bool: inside the prop or within ``margin`` of it (for a box,
        within ``margin`` of each face plane: the box grown by ``margin``)."""
        p = np.asarray(points, np.float64) - np.asarray(self.centre)
        sx, sy, sz = self.size
        if self.kind == "sphere":
            return np.linalg.norm(p, axis=-1) <= sx + margin
        if self.kind == "cylinder":
            return (np.hypot(p[..., 0], p[..., 1]) <= sx + margin) & (np.abs(p[..., 2]) <= sz / 2 + margin)
        a = np.deg2rad(self.yaw_deg)  # local = R_z(yaw)^T (p - centre)
        lx = np.cos(a) * p[..., 0] + np.sin(a) * p[..., 1]
        ly = -np.sin(a) * p[..., 0] + np.cos(a) * p[..., 1]
        return (np.abs(lx) <= sx + margin) & (np.abs(ly) <= sy + margin) & (np.abs(p[..., 2]) <= sz + margin)


def points_in_props(points: np.ndarray, props: Sequence[Prop], margin: float = PROP_MARGIN) -> np.ndarray:
    """``(..., 3)`` points -> ``(...)`` bool: within ``margin`` of any prop (non-finite points: False)."""
    points = np.asarray(points, np.float64)
    inside = np.zeros(points.shape[:-1], bool)
    finite = np.isfinite(points).all(-1)
    safe = np.where(finite[..., None], points, 0.0)
    for prop in props:
        inside |= prop.contains(safe, margin)
    return inside & finite


def points_from_depth(depth: np.ndarray, K: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World points ``(H, W, 3)`` of a z-depth map ``(H, W)`` seen by a pinhole ``K`` ``(3, 3)`` with OpenCV
    camera-to-world ``c2w`` ``(4, 4)``; pixel centres at (i + 0.5). Non-finite depth gives non-finite points."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    z = depth.astype(np.float64)
    with np.errstate(invalid="ignore"):
        cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)
        return cam @ c2w[:3, :3].T + c2w[:3, 3]


# ------------------------------------------------------------------------------------------ resampling


def _blocks(a: np.ndarray, k: int) -> np.ndarray:
    """``(H, W, ...)`` -> ``(H // k, k, W // k, k, ...)``, cropping the remainder."""
    h, w = a.shape[0] // k, a.shape[1] // k
    return a[: h * k, : w * k].reshape(h, k, w, k, *a.shape[2:])


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """k x k area average of ``(H, W[, C])``."""
    return a if k == 1 else _blocks(np.asarray(a, np.float32), k).mean((1, 3))


def block_all(a: np.ndarray, k: int) -> np.ndarray:
    """``(H, W)`` bool -> True where the whole k x k block is True."""
    return np.asarray(a, bool) if k == 1 else _blocks(np.asarray(a, bool), k).all((1, 3))


def downscale_depth(depth: np.ndarray, k: int) -> np.ndarray:
    """Block mean of a z-depth map where the whole block is finite, else +inf."""
    if k == 1:
        return depth
    finite = block_all(np.isfinite(depth), k)
    mean = block_mean(np.where(np.isfinite(depth), depth, 0.0), k)
    return np.where(finite, mean, np.inf).astype(np.float32)


def downscale_normals(normals: np.ndarray, k: int) -> np.ndarray:
    """Normalized block mean of ``(H, W, 3)`` unit normals where the whole block has normals, else 0."""
    if k == 1:
        return normals
    valid = block_all(np.linalg.norm(normals, axis=-1) > 1e-6, k)
    mean = block_mean(normals, k)
    mean /= np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-12)
    return np.where(valid[..., None], mean, 0.0).astype(np.float32)


# ------------------------------------------------------------------------------------------------ frames


@dataclass(frozen=True)
class Alignment:
    """The similarity ``to_ground_truth`` (4x4, model world -> ground-truth world: x_gt = s R x_model + t)."""

    matrix: np.ndarray

    @classmethod
    def identity(cls) -> Alignment:
        return cls(np.eye(4))

    @classmethod
    def from_matrix(cls, m: np.ndarray | None) -> Alignment:
        if m is None:
            return cls.identity()
        m = np.asarray(m, np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all() or not np.allclose(m[3], [0, 0, 0, 1]):
            raise InputError(f"to_ground_truth must be a finite 4x4 similarity with last row 0 0 0 1, got {m.shape}")
        det = np.linalg.det(m[:3, :3])
        if det <= 0:
            raise InputError("to_ground_truth is a reflection or degenerate (det <= 0)")
        r = m[:3, :3] / np.cbrt(det)
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-5):
            raise InputError("to_ground_truth is not a similarity (its 3x3 part is not a scaled rotation)")
        return cls(m)

    @property
    def scale(self) -> float:
        return float(np.cbrt(np.linalg.det(self.matrix[:3, :3])))

    @property
    def rotation(self) -> np.ndarray:
        return self.matrix[:3, :3] / self.scale

    def camera_to_model(self, c2w: np.ndarray) -> np.ndarray:
        """A ground-truth camera-to-world ``(4, 4)`` -> the same camera in the model's frame (rigid)."""
        r, s, t = self.rotation, self.scale, self.matrix[:3, 3]
        out = np.eye(4)
        out[:3, :3] = r.T @ c2w[:3, :3]
        out[:3, 3] = r.T @ (c2w[:3, 3] - t) / s
        return out

    def depth_to_ground_truth(self, depth: np.ndarray) -> np.ndarray:
        return depth * self.scale

    def normals_to_ground_truth(self, normals: np.ndarray) -> np.ndarray:
        return normals @ self.rotation.T

    def points_to_ground_truth(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` model-frame points -> ground-truth frame."""
        return self.scale * np.asarray(points) @ self.rotation.T + self.matrix[:3, 3]


def align_cameras(result: CameraSet, truth: CameraSet, centre: np.ndarray | None = None,
                  result_path: Path | None = None) -> tuple[Alignment, dict[str, Any]]:
    """The similarity result frame -> ground-truth frame fitted on the centres of the cameras both hold
    (matched by name), and the pose errors left after it (see the module doc).

    Args:
        centre: the object centre in the ground-truth frame (the orbit radius is measured from it);
            default: the mean of the ground-truth camera centres.
    Returns:
        the alignment and a JSON-ready report: ``summary`` (medians, means, maxima; centre errors also in %
        of the orbit radius), ``per_camera``, ``missing`` (ground-truth cameras the result lacks).
    """
    from ..alignment import compare_poses

    ours, theirs = result.by_name(), truth.by_name()
    common = [n for n in theirs if n in ours]
    missing = [n for n in theirs if n not in ours]
    if len(common) < 3:
        raise InputError(f"only {len(common)} camera name(s) in common with the ground truth; aligning the frames "
                         "needs 3 or more", result_path,
                         "pass the cameras.json the model was trained with (the poses stage's), whose names are the "
                         "photos' names")
    est = np.stack([ours[n].c2w for n in common])
    ref = np.stack([theirs[n].c2w for n in common])
    try:
        errors = compare_poses(est, ref)
    except ValueError as e:
        raise InputError(f"cannot align the cameras to the ground truth: {e}", result_path) from e
    centres = np.stack([c.center for c in truth.cameras])
    centre = centres.mean(0) if centre is None else np.asarray(centre, np.float64)
    orbit = float(np.median(np.linalg.norm(centres - centre, axis=1)))
    summary = errors.summary(scale=orbit)
    summary = {k: v for k, v in summary.items() if not k.endswith("_fraction")}
    summary.update(center_median_percent=100 * float(np.median(errors.center)) / orbit,
                   center_max_percent=100 * float(errors.center.max()) / orbit, orbit_radius=orbit,
                   cameras=len(common), missing=len(missing), scale=errors.similarity.scale)
    report = {
        "summary": summary,
        "per_camera": {n: {"rotation_deg": float(r), "center": float(c), "center_percent": 100 * float(c) / orbit}
                       for n, r, c in zip(common, errors.rotation_deg, errors.center, strict=True)},
        "missing": missing, "to_ground_truth": errors.similarity.matrix.tolist(),
        "method": "Umeyama similarity on camera centres (result -> ground truth), then per-camera errors",
    }
    return Alignment.from_matrix(errors.similarity.matrix), report


# ------------------------------------------------------------------------------------------ ground truth


@dataclass(frozen=True)
class GroundTruth:
    """A synthetic capture's ``ground_truth/`` folder (written by ``orca synth``)."""

    folder: Path

    def path(self, *parts: str, required: bool = True, fix: str | None = None) -> Path:
        p = self.folder.joinpath(*parts)
        if required and not p.exists():
            raise InputError("missing ground-truth file", p, fix or "regenerate the capture with `orca synth`")
        return p

    @cached_property
    def cameras(self) -> CameraSet:
        return load_cameras(self.path("cameras.json"))

    @cached_property
    def scene(self) -> dict[str, Any]:
        from ..results import read_stage_json

        return read_stage_json(self.path("scene.json"), "synth")

    @property
    def factor(self) -> float:
        """Decoded-image units per ground-truth radiance unit."""
        try:
            return float(self.scene["radiance_to_decoded"]["factor"])
        except (KeyError, TypeError, ValueError) as e:
            raise InputError("scene.json has no radiance_to_decoded.factor", self.folder / "scene.json",
                             "regenerate the capture with a current `orca synth`") from e

    @cached_property
    def props(self) -> list[Prop]:
        try:
            return [Prop.from_json(p) for p in self.scene.get("props", [])]
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"bad props entry: {e}", self.folder / "scene.json") from e

    @property
    def object_centre(self) -> np.ndarray | None:
        centre = self.scene.get("object", {}).get("centre") if self.scene_path.is_file() else None
        return np.asarray(centre, np.float64) if centre is not None else None

    @property
    def object_radius(self) -> float:
        radius = self.scene.get("object", {}).get("radius") if self.scene_path.is_file() else None
        return float(radius) if radius is not None else 1.0

    @property
    def scene_path(self) -> Path:
        return self.folder / "scene.json"

    def object_mesh(self) -> Path:
        name = self.scene.get("object", {}).get("mesh", "object.ply") if self.scene_path.is_file() else "object.ply"
        return self.path(name, fix="the ground truth has no object mesh: drop --mesh, or regenerate the capture "
                                   "with `orca synth`")

    @property
    def optics_blur_px(self) -> float:
        return float(self.scene.get("ground_truth", {}).get("optics_blur_px", 0.0))

    @property
    def has_environment(self) -> bool:
        return (self.folder / "environment" / "cameras.json").is_file()

    @cached_property
    def environment_cameras(self) -> CameraSet:
        return load_cameras(self.path("environment", "cameras.json",
                                      fix="pass --no-environment, or regenerate the capture with `orca synth`"))

    def exr(self, *parts: str) -> np.ndarray:
        from ..imageio import read_exr

        return read_exr(self.path(*parts))

    def mask(self, name: str) -> np.ndarray:
        from ..imageio import read_image

        m = read_image(self.path("masks", f"{name}.png"))
        m = m[..., 0] if m.ndim == 3 else m
        return m > (np.iinfo(m.dtype).max // 2 if m.dtype.kind == "u" else 0.5)

    def region(self, name: str, mask: np.ndarray) -> tuple[np.ndarray, str]:
        """The object pixels where radiance is compared and how they were chosen (see the module doc)."""
        cov_path = self.folder / "coverage" / f"{name}.png"
        if cov_path.is_file():
            from ..imageio import read_image
            from ..synth.render import interior_mask

            cov = read_image(cov_path)
            cov = (cov[..., 0] if cov.ndim == 3 else cov).astype(np.float32) / np.iinfo(cov.dtype).max
            return interior_mask(cov, self.optics_blur_px) & mask, \
                f"interior: coverage 255 eroded by 3 x optics blur sigma ({self.optics_blur_px} px)"
        import cv2

        size = 2 * FALLBACK_ERODE_PX + 1
        eroded = cv2.erode(mask.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
        return eroded, f"mask eroded by {FALLBACK_ERODE_PX} px (no coverage/ in the ground truth)"


def resolve_ground_truth(path: Path) -> GroundTruth:
    """A ``ground_truth/`` folder, or a capture folder holding one."""
    path = Path(path)
    if not (path / "cameras.json").is_file() and (path / "ground_truth" / "cameras.json").is_file():
        path = path / "ground_truth"
    if not path.is_dir():
        raise InputError("ground-truth folder not found", path, "pass a synthetic capture's ground_truth/ folder")
    if not (path / "cameras.json").is_file():
        raise InputError("not a ground-truth folder (no cameras.json)", path,
                         "pass the ground_truth/ folder of a capture made by `orca synth`")
    return GroundTruth(path)


def select_views(names: Sequence[str], views: int | Sequence[str] | None) -> list[str]:
    """``None``: every view; an int N: N evenly spaced views (first and last included); names: those."""
    names = list(names)
    if views is None:
        return names
    if isinstance(views, int):
        if views < 1:
            raise InputError(f"--views must be at least 1, got {views}")
        if views >= len(names):
            return names
        idx = np.round(np.linspace(0, len(names) - 1, views)).astype(int)
        return [names[i] for i in dict.fromkeys(idx.tolist())]
    unknown = [v for v in views if v not in names]
    if unknown:
        raise InputError(f"unknown view(s) {', '.join(unknown)}; the ground truth has {', '.join(names[:8])}"
                         + (" ..." if len(names) > 8 else ""))
    return list(views)


# -------------------------------------------------------------------------------------------- rendering


def _in_model_frame(cam: Camera, align: Alignment) -> Camera:
    return cam.model_copy(update={"camera_to_world": align.camera_to_model(cam.c2w).tolist()})


def render_object(model, cam: Camera, downscale: int, align: Alignment) -> dict[str, np.ndarray]:
    """Render a ground-truth camera from the model, in ground-truth units and frame (see
    :func:`pipeline.stages.render.render_object_view`)."""
    r = render_object_view(model, _in_model_frame(cam, align), downscale)
    r["normal"] = align.normals_to_ground_truth(r["normal"]).astype(np.float32)
    r["depth"] = align.depth_to_ground_truth(r["depth"]).astype(np.float32)
    return r


def render_environment(model, cam: Camera, downscale: int, align: Alignment) -> dict[str, np.ndarray]:
    """Render the environment field alone from a ground-truth camera: ``rgb`` ``(h, w, 3)``, ``depth``."""
    r = render_environment_view(model, _in_model_frame(cam, align), downscale)
    r["depth"] = align.depth_to_ground_truth(r["depth"]).astype(np.float32)
    return r


# ------------------------------------------------------------------------------------------- evaluation


def _nanmean(values: list[float]) -> float:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _means(per_view: dict[str, dict[str, Any]], keys: Sequence[str]) -> dict[str, float]:
    return {k: _nanmean([v[k] for v in per_view.values()]) for k in keys}


def _check_size(image: np.ndarray, cam: Camera, path: Path) -> None:
    if image.shape[:2] != (cam.height, cam.width):
        raise InputError(f"image is {image.shape[1]}x{image.shape[0]} but camera {cam.name} is "
                         f"{cam.width}x{cam.height}", path, "regenerate the capture with `orca synth`")


def evaluate_object_view(model, gt: GroundTruth, cam: Camera, downscale: int = 1,
                         align: Alignment | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray],
                                                                  dict[str, np.ndarray]]:
    """One object view: (figures, prediction, ground truth at the rendered size, decoded units)."""
    align = align or Alignment.identity()
    k, n = downscale, cam.name
    f = gt.factor
    linear = gt.exr("linear", f"{n}.exr")
    _check_size(linear, cam, gt.folder / "linear" / f"{n}.exr")
    mask_full = gt.mask(n)
    region_full, region_how = gt.region(n, mask_full)
    truth = {
        "rgb": block_mean(linear[..., :3] * f, k),
        "diffuse": block_mean(gt.exr("diffuse", f"{n}.exr")[..., :3] * f, k),
        "specular": block_mean(gt.exr("specular", f"{n}.exr")[..., :3] * f, k),
        "normal": downscale_normals(gt.exr("normals", f"{n}.exr")[..., :3], k),
        "depth": downscale_depth(gt.exr("depth", f"{n}.exr"), k),
        "mask": block_mean(mask_full.astype(np.float32), k) >= 0.5 if k > 1 else mask_full,
        "region": block_all(region_full, k),
    }
    pred = render_object(model, cam, k, align)
    region, mask = truth["region"], truth["mask"]
    figures: dict[str, Any] = {
        "normal_mae_deg": normal_angular_error(pred["normal"], truth["normal"], mask),
        "mask_iou": mask_iou(pred["mask"], mask),
    }
    for part in ("rgb", "diffuse", "specular"):
        figures[f"psnr_{part}"] = masked_psnr_linear(pred[part], truth[part], region)
        figures[f"psnr_srgb_{part}"] = masked_psnr_srgb(pred[part], truth[part], region)
        figures[f"ssim_{part}"] = masked_ssim(pred[part], truth[part], region)
    depth = depth_errors(pred["depth"], truth["depth"], region)
    figures.update(depth_absrel=depth["absrel"], depth_rmse=depth["rmse"],
                   pixels={"mask": int(mask.sum()), "region": int(region.sum()), "depth": depth["pixels"]},
                   region=region_how)
    return figures, pred, truth


def evaluate_environment_view(model, gt: GroundTruth, cam: Camera, downscale: int = 1,
                              align: Alignment | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray],
                                                                       dict[str, np.ndarray]]:
    """One environment view: (figures, prediction, ground truth at the rendered size, decoded units)."""
    align = align or Alignment.identity()
    k, n = downscale, cam.name
    rgb = gt.exr("environment", "rgb", f"{n}.exr")
    _check_size(rgb, cam, gt.folder / "environment" / "rgb" / f"{n}.exr")
    truth = {"rgb": block_mean(rgb[..., :3] * gt.factor, k),
             "depth": downscale_depth(gt.exr("environment", "depth", f"{n}.exr"), k)}
    pred = render_environment(model, cam, k, align)
    finite = np.isfinite(truth["depth"])
    everywhere = np.ones_like(finite)
    props = points_in_props(points_from_depth(truth["depth"], scaled_intrinsics(cam.K, k), cam.c2w), gt.props)
    depth, prop_depth = depth_errors(pred["depth"], truth["depth"]), depth_errors(pred["depth"], truth["depth"], props)
    figures = {
        "psnr": masked_psnr_linear(pred["rgb"], truth["rgb"], finite),
        "psnr_srgb": masked_psnr_srgb(pred["rgb"], truth["rgb"], finite),
        "ssim": masked_ssim(pred["rgb"], truth["rgb"], finite),
        "psnr_all": masked_psnr_linear(pred["rgb"], truth["rgb"], everywhere),
        "psnr_srgb_all": masked_psnr_srgb(pred["rgb"], truth["rgb"], everywhere),
        "ssim_all": masked_ssim(pred["rgb"], truth["rgb"], everywhere),
        "depth_absrel": depth["absrel"], "depth_rmse": depth["rmse"],
        "prop_depth_absrel": prop_depth["absrel"], "prop_depth_rmse": prop_depth["rmse"],
        "pixels": {"all": int(finite.size), "finite_depth": int(finite.sum()), "props": prop_depth["pixels"]},
    }
    truth["props"] = props
    return figures, pred, truth


def evaluate_object(model, gt_dir: Path, views: int | Sequence[str] | None = None, downscale: int = 1, *,
                    to_ground_truth: np.ndarray | None = None, save_dir: Path | None = None) -> dict[str, Any]:
    """Render the ground truth's object views from ``model`` and compare (see the module doc).

    Args:
        views: None (every view), N (N evenly spaced views) or a list of view names.
        to_ground_truth: 4x4 similarity model frame -> ground-truth frame (default identity).
        save_dir: where to write the predicted images and ``object_grid.png`` (nothing written when None).
    Returns:
        ``{"views", "downscale", "region", "per_view": {name: figures}, "mean": {metric: value},
        "seconds_per_view"}``.
    """
    from ..log import progress

    if downscale < 1:
        raise InputError(f"--downscale must be at least 1, got {downscale}")
    gt = resolve_ground_truth(gt_dir)
    align = Alignment.from_matrix(to_ground_truth)
    cams = gt.cameras.by_name()
    names = select_views(list(cams), views)
    grid_names = set(select_views(names, GRID_OBJECT_VIEWS))
    per_view: dict[str, dict[str, Any]] = {}
    rows: list[tuple[str, dict[str, np.ndarray], dict[str, np.ndarray], dict[str, Any]]] = []
    t0 = time.time()
    with progress() as bar:
        task = bar.add_task("evaluate object views", total=len(names))
        for name in names:
            figures, pred, truth = evaluate_object_view(model, gt, cams[name], downscale, align)
            per_view[name] = figures
            if figures["pixels"]["region"] == 0:
                log.warning("view %s: no object region pixels at downscale %d; its radiance figures are NaN",
                            name, downscale)
            if save_dir is not None:
                write_views(save_dir, name, pred)
                if name in grid_names:
                    rows.append((name, pred, truth, figures))
            bar.advance(task)
    seconds = time.time() - t0
    if save_dir is not None and rows:
        object_grid(save_dir / "object_grid.png", rows)
    return {
        "views": names, "downscale": downscale,
        "region": next(iter(per_view.values()))["region"] if per_view else None,
        "per_view": per_view, "mean": _means(per_view, OBJECT_METRICS),
        "seconds_per_view": seconds / max(len(names), 1),
    }


def evaluate_environment(model, gt_dir: Path, views: int | Sequence[str] | None = None, downscale: int = 1, *,
                         to_ground_truth: np.ndarray | None = None, save_dir: Path | None = None) -> dict[str, Any]:
    """Render the ground truth's environment views from the model's environment field and compare.

    Same arguments and result layout as :func:`evaluate_object` (grid: ``environment_grid.png``).
    """
    from ..log import progress

    if downscale < 1:
        raise InputError(f"--downscale must be at least 1, got {downscale}")
    gt = resolve_ground_truth(gt_dir)
    if not gt.has_environment:
        raise InputError("the ground truth has no environment views", gt.folder / "environment" / "cameras.json",
                         "pass --no-environment (or environment=False), or regenerate the capture with `orca synth`")
    align = Alignment.from_matrix(to_ground_truth)
    cams = gt.environment_cameras.by_name()
    names = select_views(list(cams), views)
    per_view: dict[str, dict[str, Any]] = {}
    rows = []
    t0 = time.time()
    with progress() as bar:
        task = bar.add_task("evaluate environment views", total=len(names))
        for name in names:
            figures, pred, truth = evaluate_environment_view(model, gt, cams[name], downscale, align)
            per_view[name] = figures
            if save_dir is not None:
                write_views(save_dir, f"env_{name}", pred)
                rows.append((name, pred, truth, figures))
            bar.advance(task)
    seconds = time.time() - t0
    if save_dir is not None and rows:
        environment_grid(save_dir / "environment_grid.png", rows)
    return {"views": names, "downscale": downscale, "prop_margin": PROP_MARGIN, "per_view": per_view,
            "mean": _means(per_view, ENVIRONMENT_METRICS), "seconds_per_view": seconds / max(len(names), 1)}


# ------------------------------------------------------------------------------------------------- mesh


def evaluate_mesh(mesh_path: Path, gt: GroundTruth, align: Alignment | None = None,
                  samples: int = MESH_SAMPLES) -> dict[str, Any]:
    """A result mesh (model frame) against the ground truth's object mesh, in the ground-truth frame (see the
    module doc). Distances in ground-truth units and, ``*_fraction``, in object radii."""
    import open3d as o3d

    align = align or Alignment.identity()
    mesh_path = Path(mesh_path)
    if not mesh_path.is_file():
        raise InputError("mesh not found", mesh_path, "run `orca mesh` first, or drop --mesh")
    ours = o3d.io.read_triangle_mesh(str(mesh_path))
    if len(ours.triangles) == 0:
        raise InputError("the mesh has no triangles", mesh_path, "check mesh_report.json beside it")
    theirs_path = gt.object_mesh()
    theirs = o3d.io.read_triangle_mesh(str(theirs_path))
    if len(theirs.triangles) == 0:
        raise InputError("the ground-truth mesh has no triangles", theirs_path)
    ours.transform(align.matrix)
    radius = gt.object_radius
    o3d.utility.random.seed(0)  # the surface samples: the same figures on every run
    params = o3d.t.geometry.MetricParameters(fscore_radius=[f * radius for f in FSCORE_RADII],
                                             n_sampled_points=samples)
    metrics = o3d.t.geometry.Metric
    values = o3d.t.geometry.TriangleMesh.from_legacy(ours).compute_metrics(
        o3d.t.geometry.TriangleMesh.from_legacy(theirs),
        [metrics.ChamferDistance, metrics.HausdorffDistance, metrics.FScore], params).numpy().astype(float)
    chamfer, hausdorff, fscores = float(values[0]), float(values[1]), values[2:]
    return {
        "mesh": str(mesh_path), "ground_truth_mesh": str(theirs_path), "object_radius": radius,
        "chamfer": chamfer, "chamfer_fraction": chamfer / radius,
        "hausdorff": hausdorff, "hausdorff_fraction": hausdorff / radius,
        **{f"fscore_{round(100 * f)}pct": float(v) / 100 for f, v in zip(FSCORE_RADII, fscores, strict=True)},
        "samples": samples, "vertices": len(ours.vertices), "triangles": len(ours.triangles),
        "definition": "open3d compute_metrics: Chamfer = mean distance of sampled points of each mesh to the "
                      "other mesh, summed over both directions; F-score in [0, 1] at the given fraction of the "
                      "object radius",
    }


# ---------------------------------------------------------------------------------------------- pictures


def _figure(rows: int, columns: int, aspect: float):
    from matplotlib.figure import Figure

    tile = 2.4
    fig = Figure(figsize=(columns * tile, rows * tile * aspect + 0.4), dpi=110, layout="constrained")
    axes = fig.subplots(rows, columns, squeeze=False)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    return fig, axes


def _display_peak(image: np.ndarray, mask: np.ndarray, fallback: float) -> float:
    """The 99th percentile of ``image`` over ``mask`` (the whole image if that is empty), else ``fallback``."""
    p = percentile_peak(image, mask if mask.any() else np.ones(image.shape[:2], bool))
    return p if math.isfinite(p) else (fallback if math.isfinite(fallback) and fallback > 0 else 1.0)


def _normals_rgb(n: np.ndarray) -> np.ndarray:
    return np.clip(n * 0.5 + 0.5, 0, 1)


def _row_label(name: str, figures: dict[str, Any], keys: Sequence[tuple[str, str]]) -> str:
    parts = [fmt.format(figures[k]) for k, fmt in keys
             if isinstance(figures.get(k), float) and math.isfinite(figures[k])]
    return "\n".join([name, *parts])


def object_grid(path: Path, rows: Sequence[tuple[str, dict, dict, dict]]) -> Path:
    """Rows (name, prediction, truth, figures) of GT combined | predicted | GT specular | predicted specular |
    GT normals | predicted normals. Combined radiance is tone-mapped with the PSNR peak (as the camera saw
    it); specular, much dimmer, with the 99th percentile of the ground-truth specular over the object mask
    (the same for truth and prediction)."""
    columns = ["GT combined", "predicted", "GT specular", "pred. specular", "GT normals", "pred. normals"]
    h, w = rows[0][1]["opacity"].shape
    fig, axes = _figure(len(rows), len(columns), h / w)
    for r, (name, pred, truth, figures) in enumerate(rows):
        peak = PSNR_PEAK
        spec_peak = _display_peak(truth["specular"], truth["mask"], peak)
        tiles = [tone_map(truth["rgb"], peak), tone_map(pred["rgb"], peak), tone_map(truth["specular"], spec_peak),
                 tone_map(pred["specular"], spec_peak), _normals_rgb(truth["normal"]), _normals_rgb(pred["normal"])]
        for c, tile in enumerate(tiles):
            axes[r, c].imshow(tile, interpolation="nearest")
            if r == 0:
                axes[r, c].set_title(columns[c], fontsize=9)
        label = _row_label(name, figures, (("psnr_srgb_rgb", "sRGB PSNR {:.1f} dB"),
                                           ("psnr_srgb_specular", "spec. {:.1f} dB"),
                                           ("normal_mae_deg", "normals {:.1f}°")))
        axes[r, 0].set_ylabel(label, fontsize=8)
    fig.savefig(path)
    return path


def environment_grid(path: Path, rows: Sequence[tuple[str, dict, dict, dict]]) -> Path:
    """Rows (name, prediction, truth, figures) of GT rgb | predicted rgb | GT depth | predicted depth. All depth
    tiles share one colour scale (1st-99th percentile of every view's finite ground-truth depth), shown by a
    colour bar on each row; RGB is tone-mapped with the PSNR peak (as the camera would see it)."""
    columns = ["GT rgb", "predicted rgb", "GT depth", "predicted depth"]
    h, w = rows[0][1]["depth"].shape
    fig, axes = _figure(len(rows), len(columns), h / w)
    finite = np.concatenate([t["depth"][np.isfinite(t["depth"])] for _, _, t, _ in rows])
    lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
    hi = hi if hi > lo else lo + 1.0
    for r, (name, pred, truth, figures) in enumerate(rows):
        axes[r, 0].imshow(tone_map(truth["rgb"]), interpolation="nearest")
        axes[r, 1].imshow(tone_map(pred["rgb"]), interpolation="nearest")
        gt_depth = np.where(np.isfinite(truth["depth"]), truth["depth"], np.nan)
        axes[r, 2].imshow(gt_depth, cmap="turbo", vmin=lo, vmax=hi, interpolation="nearest")
        im = axes[r, 3].imshow(pred["depth"], cmap="turbo", vmin=lo, vmax=hi, interpolation="nearest")
        fig.colorbar(im, ax=axes[r, 3], fraction=0.046, pad=0.02)
        label = _row_label(name, figures, (("psnr_srgb_all", "sRGB PSNR {:.1f} dB"), ("depth_absrel", "AbsRel {:.2f}")))
        axes[r, 0].set_ylabel(label, fontsize=8)
        if r == 0:
            for c, title in enumerate(columns):
                axes[r, c].set_title(title, fontsize=9)
    fig.savefig(path)
    return path


# ----------------------------------------------------------------------------------------------- report


def _json_safe(value: Any) -> Any:
    """NaN/inf -> None (strict JSON), recursively."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return None
    return value


_PARTS = {"rgb": "combined", "diffuse": "diffuse", "specular": "specular"}
_LABELS = {
    "normal_mae_deg": ("normal MAE", "deg", "lower"), "mask_iou": ("mask IoU", "", "higher"),
    **{f"psnr_{k}": (f"PSNR {v} (linear)", "dB", "higher") for k, v in _PARTS.items()},
    **{f"psnr_srgb_{k}": (f"PSNR {v} (sRGB)", "dB", "higher") for k, v in _PARTS.items()},
    **{f"ssim_{k}": (f"SSIM {v}", "", "higher") for k, v in _PARTS.items()},
    "depth_absrel": ("depth AbsRel", "", "lower"), "depth_rmse": ("depth RMSE", "units", "lower"),
    "psnr": ("PSNR linear (finite depth)", "dB", "higher"), "psnr_srgb": ("PSNR sRGB (finite depth)", "dB", "higher"),
    "ssim": ("SSIM (finite depth)", "", "higher"), "psnr_all": ("PSNR linear (all pixels)", "dB", "higher"),
    "psnr_srgb_all": ("PSNR sRGB (all pixels)", "dB", "higher"), "ssim_all": ("SSIM (all pixels)", "", "higher"),
    "prop_depth_absrel": ("prop depth AbsRel", "", "lower"), "prop_depth_rmse": ("prop depth RMSE", "units", "lower"),
}


def print_table(results: dict[str, Any]) -> None:
    """The means as a rich table on the terminal (stderr, beside the logs)."""
    from rich.table import Table

    from ..log import console

    for part, title in (("object", "object views"), ("environment", "environment views")):
        res = results.get(part)
        if not res:
            continue
        table = Table(title=f"{title}: mean of {len(res['views'])}, 1/{res['downscale']} size")
        table.add_column("metric")
        table.add_column("mean", justify="right")
        table.add_column("unit")
        table.add_column("better")
        for key, value in res["mean"].items():
            label, unit, better = _LABELS.get(key, (key, "", ""))
            text = "—" if value is None or not math.isfinite(value) else f"{value:.4g}"
            table.add_row(label, text, unit, better)
        console.print(table)
    poses = results.get("poses")
    if poses:
        s = poses["summary"]
        table = Table(title=f"poses: {s['cameras']} cameras aligned by a similarity on their centres"
                            + (f" ({s['missing']} missing)" if s["missing"] else ""))
        for column in ("metric", "median", "max", "unit"):
            table.add_column(column, justify="left" if column in ("metric", "unit") else "right")
        table.add_row("rotation error", f"{s['rotation_deg_median']:.3g}", f"{s['rotation_deg_max']:.3g}", "deg")
        table.add_row("centre error", f"{s['center_median_percent']:.3g}", f"{s['center_max_percent']:.3g}",
                      "% of orbit radius")
        console.print(table)
    mesh = results.get("mesh")
    if mesh:
        table = Table(title=f"mesh vs ground truth ({mesh['samples']} samples per surface)")
        for column in ("metric", "value", "unit"):
            table.add_column(column, justify="right" if column == "value" else "left")
        table.add_row("Chamfer", f"{mesh['chamfer_fraction']:.4g}", "object radii (lower is better)")
        table.add_row("Hausdorff", f"{mesh['hausdorff_fraction']:.4g}", "object radii")
        for f in FSCORE_RADII:
            key = f"fscore_{round(100 * f)}pct"
            table.add_row(f"F-score at {100 * f:g} %", f"{mesh[key]:.4g}", "(higher is better)")
        console.print(table)


def _recorded_cameras(train_dir: Path) -> Path | None:
    """The cameras.json the train manifest records, if it is reachable from here."""
    try:
        path = Path(read_json(train_dir / "manifest.json")["inputs"]["cameras"]["path"])
    except (OSError, KeyError, TypeError, ValueError):
        return None
    return path if path.is_file() else None


def _trained_on(train_dir: Path, cameras_path: Path) -> bool | None:
    """Whether the train stage's manifest records these very cameras (None when it cannot tell)."""
    try:
        recorded = read_json(train_dir / "manifest.json")["inputs"]["cameras"]["sha256"]
    except (OSError, KeyError, TypeError, ValueError):
        return None
    return recorded == file_sha256(cameras_path)


def run_evaluate(
    train_dir: Path,
    gt_dir: Path,
    out_dir: Path,
    *,
    views: int | Sequence[str] | None = None,
    downscale: int = 1,
    object: bool = True,  # the name of the CLI's --no-object (shadows the builtin here only)
    environment: bool = True,
    to_ground_truth: np.ndarray | None = None,
    cameras: Path | None = None,
    mesh: Path | None = None,
    device: str = "auto",
    force: bool = False,
) -> dict[str, Any]:
    """Evaluate a train folder against a ground-truth folder and write ``out_dir`` atomically.

    Args:
        views: object views: None (all), N evenly spaced, or names. Environment views: always all.
        downscale: render (and compare) k times smaller, for both object and environment views.
        to_ground_truth: 4x4 similarity model frame -> ground-truth frame; default: fitted on the centres of
            ``cameras`` (below), else identity.
        cameras: the cameras.json the model was trained with (its frame is the model's); default: the one the
            train manifest records. Gives the alignment and the pose errors.
        mesh: a mesh of the model (``orca mesh``'s mesh.ply, model frame) to compare with ``object.ply``.
    Returns:
        The content of ``evaluate.json`` (NaN written as null).
    """
    from .render import load_renderer
    from .train import FINAL_WEIGHTS

    started = time.time()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    if not object and not environment:
        raise InputError("nothing to evaluate: both the object and the environment views are switched off",
                         fix="drop --no-object or --no-environment")
    weights = train_dir / FINAL_WEIGHTS
    if not weights.is_file():
        raise InputError("no trained model here", weights, "run `orca train` first (it writes model.pt when done)")
    gt = resolve_ground_truth(gt_dir)
    if environment and not gt.has_environment:
        raise InputError("the ground truth has no environment views", gt.folder / "environment" / "cameras.json",
                         "pass --no-environment, or regenerate the capture with `orca synth`")
    if mesh is not None and not Path(mesh).is_file():
        raise InputError("mesh not found", mesh, "run `orca mesh` first, or drop --mesh")
    trained_on_gt = _trained_on(train_dir, gt.folder / "cameras.json")
    cameras = Path(cameras) if cameras is not None else _recorded_cameras(train_dir)
    capture = common_capture([train_dir, gt.folder, cameras, mesh], force=force)
    poses: dict[str, Any] | None = None
    if cameras is not None:
        fitted, poses = align_cameras(load_cameras(cameras), gt.cameras, gt.object_centre, cameras)
        poses["cameras"] = str(cameras)
        log.info("poses: %d cameras of %s aligned to the ground truth: rotation error median %.3g deg, centre "
                 "error median %.3g %% of the orbit radius", poses["summary"]["cameras"], cameras,
                 poses["summary"]["rotation_deg_median"], poses["summary"]["center_median_percent"])
    align = Alignment.from_matrix(to_ground_truth if to_ground_truth is not None or cameras is None else
                                  fitted.matrix)
    if trained_on_gt is False and to_ground_truth is None and cameras is None:
        log.warning("the model was trained with other cameras than %s; without them (--cameras) its frame may "
                    "differ from the ground truth's and the figures will be meaningless", gt.folder / "cameras.json")
    model = load_renderer(train_dir, device)
    log.info("evaluate: %s against %s (downscale %d)", train_dir, gt.folder, downscale)
    results: dict[str, Any] = {
        "train": str(train_dir), "ground_truth": str(gt.folder), "downscale": downscale,
        "to_ground_truth": align.matrix.tolist(),
        "alignment": "given" if to_ground_truth is not None else (
            "fitted on camera centres" if cameras is not None else "identity (no cameras to fit on)"),
        "trained_with_ground_truth_cameras": trained_on_gt,
        "radiance_to_decoded": gt.factor,
        "definitions": {
            "psnr_peak": f"{PSNR_PEAK:g} decoded unit (the white level of the reference exposure) for every view "
                         f"and component; PSNR capped at {PSNR_CAP_DB:g} dB",
            "psnr": "linear radiance (decoded units), unclipped, over the region's pixels and channels",
            "psnr_srgb": "the same on srgb(clip(x / peak, 0, 1)) images with peak 1 (highlights clipped)",
            "ssim": f"kornia SSIM ({SSIM_WINDOW}x{SSIM_WINDOW} Gaussian, sigma 1.5) on srgb(clip(x / peak, 0, 1)), "
                    "mean over the region; prediction replaced by the ground truth outside it",
            "object_region": "ground-truth interior pixels (coverage 255 eroded by the optics blur's 3 sigma), "
                             f"or the mask eroded by {FALLBACK_ERODE_PX} px without coverage/",
            "prop_pixels": f"ground-truth points within {PROP_MARGIN} of a scene.json prop",
            "means": "mean over views of the per-view figures, ignoring views where a figure is undefined",
        },
    }
    if poses is not None:
        results["poses"] = poses
    with atomic_dir(out_dir, "evaluate", [train_dir, gt.folder, *(p for p in (cameras, mesh) if p)]) as tmp:
        if mesh is not None:
            results["mesh"] = evaluate_mesh(Path(mesh), gt, align)
        if object:
            results["object"] = evaluate_object(model, gt.folder, views, downscale, to_ground_truth=align.matrix,
                                                save_dir=tmp)
        if environment:
            results["environment"] = evaluate_environment(model, gt.folder, None, downscale,
                                                          to_ground_truth=align.matrix, save_dir=tmp)
        results["seconds"] = round(time.time() - started, 2)
        results["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        results = _json_safe(results)
        write_json(tmp / EVALUATE_JSON, results)
        inputs = {"model": weights, "cameras": gt.folder / "cameras.json", "scene": gt.folder / "scene.json"}
        if cameras is not None:
            inputs["result_cameras"] = cameras
        if mesh is not None:
            inputs["mesh"] = Path(mesh)
        write_manifest(tmp, stage="evaluate", inputs=inputs, started=started,
                       config={"views": results.get("object", {}).get("views"), "downscale": downscale,
                               "object": object, "environment": environment}, capture=capture)
    print_table(results)
    log.info("evaluate: wrote %s in %.1f s", out_dir, time.time() - started)
    return results


# ------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth
        every object view and every environment view at full resolution (slow on a CPU)
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth --views 4 --downscale 2
        4 evenly spaced object views at half resolution: a quick look
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth --no-environment

Writes <out>/evaluate.json (per view and means), object_grid.png, environment_grid.png and the predicted
images (EXR). The definitions of the region, the PSNR peak and SSIM are in evaluate.json and in
pipeline/stages/evaluate.py.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "evaluate", help="trained model vs a synthetic capture's ground truth -> figures + comparison pictures",
        description="Compare a trained model with ground truth: normals, mask, diffuse/specular/combined "
        "PSNR/SSIM on object views; RGB and depth of environment views (all pixels and prop pixels).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("train_dir", type=Path, metavar="RESULTS",
                   help="train stage folder (holds model.pt), or a capture's results folder holding train/")
    p.add_argument("--ground-truth", type=Path, required=True, help="a synthetic capture's ground_truth/ folder")
    p.add_argument("--cameras", type=Path, default=None,
                   help="the cameras.json the model was trained with (e.g. results/<capture>/poses/cameras.json): "
                        "aligns its frame to the ground truth's and reports pose errors (default: RESULTS/poses/"
                        "cameras.json, else the cameras the train manifest records)")
    p.add_argument("--mesh", type=Path, default=None,
                   help="the model's mesh.ply (orca mesh) to compare with ground_truth/object.ply (default: "
                        "RESULTS/mesh/mesh.ply when RESULTS is a results folder)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: evaluate/ beside TRAIN_DIR)")
    p.add_argument("--views", type=int, default=None, metavar="N",
                   help="evaluate N evenly spaced object views (default: every view)")
    p.add_argument("--downscale", type=int, default=1, metavar="K", help="render and compare K times smaller")
    p.add_argument("--no-object", action="store_true", help="skip the object views")
    p.add_argument("--no-environment", action="store_true", help="skip the environment views")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto", help="where to render")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=main)


def resolve_results(path: Path) -> tuple[Path, Path | None, Path | None]:
    """``(train_dir, cameras, mesh)`` of a train folder (no cameras or mesh implied), or of a capture's results
    folder (``train/``, ``poses/cameras.json`` and ``mesh/mesh.ply`` where they exist)."""
    path = Path(path)
    if (path / "model.pt").is_file() or not (path / "train" / "model.pt").is_file():
        return path, None, None

    def found(p: Path) -> Path | None:
        return p if p.is_file() else None

    return path / "train", found(path / "poses" / "cameras.json"), found(path / "mesh" / "mesh.ply")


def main(args: argparse.Namespace) -> dict[str, Any]:
    train_dir, cameras, mesh = resolve_results(args.train_dir)
    out = args.out if args.out is not None else train_dir.parent / "evaluate"
    return run_evaluate(train_dir, args.ground_truth, out, views=args.views, downscale=args.downscale,
                        object=not args.no_object, environment=not args.no_environment,
                        cameras=args.cameras or cameras, mesh=args.mesh or mesh, device=args.device,
                        force=args.force)
