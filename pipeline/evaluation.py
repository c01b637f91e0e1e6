"""What ``orca evaluate`` measures: the figures of one view from a prediction and the ground truth at the same
size (:func:`object_figures`, :func:`environment_figures`), their means over views, and their definitions
(:data:`DEFINITIONS`, the one text of them: written into every ``evaluate.json``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .ground_truth import FALLBACK_ERODE_PX
from .metrics import (
    FSCORE_RADII,
    MESH_SAMPLES,
    PSNR_CAP_DB,
    PSNR_PEAK,
    SSIM_WINDOW,
    depth_errors,
    iou,
    matching_gains,
    normal_angular_error,
    psnr_linear,
    psnr_srgb,
    ssim,
)
from .props import PROP_MARGIN

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

_PARTS = {"rgb": "combined", "diffuse": "diffuse", "specular": "specular"}
LABELS = {  # metric -> (label, unit, which way is better)
    "normal_mae_deg": ("normal MAE", "deg", "lower"), "mask_iou": ("mask IoU", "", "higher"),
    **{f"psnr_{k}": (f"PSNR {v} (linear)", "dB", "higher") for k, v in _PARTS.items()},
    **{f"psnr_srgb_{k}": (f"PSNR {v} (sRGB)", "dB", "higher") for k, v in _PARTS.items()},
    **{f"ssim_{k}": (f"SSIM {v}", "", "higher") for k, v in _PARTS.items()},
    "depth_absrel": ("depth AbsRel", "", "lower"), "depth_rmse": ("depth RMSE", "units", "lower"),
    "psnr": ("PSNR linear (finite depth)", "dB", "higher"), "psnr_srgb": ("PSNR sRGB (finite depth)", "dB", "higher"),
    "ssim": ("SSIM (finite depth)", "", "higher"), "psnr_all": ("PSNR linear (all pixels)", "dB", "higher"),
    "psnr_srgb_all": ("PSNR sRGB (all pixels)", "dB", "higher"), "ssim_all": ("SSIM (all pixels)", "", "higher"),
    "prop_depth_absrel": ("prop depth AbsRel", "", "lower"), "prop_depth_rmse": ("prop depth RMSE", "units", "lower"),
    "psnr_srgb_object": ("PSNR object (sRGB)", "dB", "higher"), "ssim_object": ("SSIM object", "", "higher"),
    "psnr_srgb_frame": ("PSNR whole frame (sRGB)", "dB", "higher"), "ssim_frame": ("SSIM whole frame", "", "higher"),
    "psnr_srgb_object_matched": ("PSNR object, gains matched (sRGB)", "dB", "higher"),
    "psnr_srgb_frame_matched": ("PSNR whole frame, gains matched (sRGB)", "dB", "higher"),
}

DEFINITIONS = {
    "means": "every figure is per view; a mean is the mean over views of the per-view figures, ignoring views "
             "where a figure is undefined (NaN, written as null)",
    "units": "ground-truth radiance x scene.json radiance_to_decoded.factor = decoded units, the units the model "
             "was trained in; depth in ground-truth world units",
    "object_region": "ground-truth interior pixels, where diffuse + specular = linear holds: coverage 255 eroded by "
                     "the optics blur's 3 sigma (scene.json ground_truth.optics_blur_px); silhouette pixels mix "
                     f"object and room and are left out. Without coverage/: the mask eroded by {FALLBACK_ERODE_PX} "
                     "px. PSNR, SSIM and depth of object views are over this region",
    "normal_mae_deg": "mean angle over ground-truth mask pixels with a non-zero ground-truth normal; the predicted "
                      "normal (an opacity-weighted sum) is normalized; where it is zero the error counts as 90 deg",
    "mask_iou": "predicted opacity > 0.5 against the ground-truth mask",
    "psnr_peak": f"{PSNR_PEAK:g} decoded unit (the white level of the reference exposure: the brightest value the "
                 "photos, the model's training data, can hold) for every view, component and method; PSNR capped "
                 f"at {PSNR_CAP_DB:g} dB (MSE floored: identical images)",
    "psnr": "10 log10(peak^2 / MSE) on linear radiance (decoded units) clipped to [0, peak], what the sensor "
            "records, over the region's pixels and channels",
    "psnr_srgb": "the same on srgb(clip(x / peak, 0, 1)) images with peak 1 (highlights clipped): what the camera "
                 "would show, the figure to set beside LDR results",
    "ssim": f"kornia SSIM ({SSIM_WINDOW}x{SSIM_WINDOW} Gaussian, sigma 1.5) on srgb(clip(x / peak, 0, 1)), mean of "
            "the SSIM map over the region's pixels and channels; prediction replaced by the ground truth outside "
            "the region so that background in the window does not count",
    "depth": "z-depth AbsRel mean(|d - d_gt| / d_gt) and RMSE over pixels with finite ground-truth depth (object "
             "views: inside the region)",
    "environment": "environment views (object removed) rendered from the environment field alone; figures over "
                   "pixels with finite ground-truth depth, over all pixels (*_all) and over prop pixels (prop_*)",
    "prop_pixels": f"ground-truth points within {PROP_MARGIN} of a scene.json prop",
    "downscale": "k renders at (H // k, W // k) with the intrinsics scaled (pixel centres map to the centres of "
                 "k x k blocks); the ground truth is reduced over each block: radiance by the mean, the mask by "
                 "the mean >= 0.5, region, finite depth and non-zero normals only where the whole block is (depth "
                 "then the block's mean, normals the normalized block mean)",
    "frames": "the model's world frame maps to the ground truth's by the similarity to_ground_truth: cameras are "
              "moved into the model frame to render, predicted depths scaled and normals rotated back. Fitted "
              "(Umeyama) on the centres of the cameras the model was trained with, matched by name to the ground "
              "truth's; identity (to rounding) when training used the ground-truth cameras",
    "poses": "after that alignment, per camera the rotation error (deg) and the centre error, in ground-truth "
             "units and in % of the orbit radius (the ground-truth cameras' median distance from the object "
             "centre); ground-truth cameras the result lacks are listed, not counted",
    "held_out": "photos the model was not trained on (train.holdout_every) against its render of their cameras "
                "(the object over the environment field), in decoded units: sRGB PSNR and SSIM as above over the "
                "object (the masks stage's mask) and over the whole frame, highlight-clipped pixels left out; "
                "*_matched: the same PSNRs after the render is scaled by the gain per colour channel that best maps it "
                "onto the photo over the frame (least squares, linear): the photo's own exposure and white balance, "
                "which a model trained on other photos cannot know (train.appearance)",
    "mesh": "the mesh moved into the ground-truth frame against ground_truth/object.ply by open3d compute_metrics: "
            f"{MESH_SAMPLES} points sampled on each surface, distances to the other surface by ray casting; "
            "Chamfer = the sum of the two mean distances, Hausdorff distance, F-score in [0, 1] at "
            f"{', '.join(f'{100 * f:g}' for f in FSCORE_RADII)} % of the object radius; distances also in object "
            "radii (scene.json object.radius)",
}


def object_figures(pred: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> dict[str, Any]:
    """One object view's :data:`OBJECT_METRICS` and pixel counts, from a prediction (``rgb``, ``diffuse``,
    ``specular``, ``normal``, ``depth``, ``mask``) and the ground truth at the same size
    (:meth:`pipeline.ground_truth.GroundTruth.object_view`), both in decoded units and the ground-truth frame."""
    region, mask = truth["region"], truth["mask"]
    figures: dict[str, Any] = {
        "normal_mae_deg": normal_angular_error(pred["normal"], truth["normal"], mask),
        "mask_iou": iou(pred["mask"], mask),
    }
    for part in ("rgb", "diffuse", "specular"):
        figures[f"psnr_{part}"] = psnr_linear(pred[part], truth[part], region)
        figures[f"psnr_srgb_{part}"] = psnr_srgb(pred[part], truth[part], region)
        figures[f"ssim_{part}"] = ssim(pred[part], truth[part], region)
    depth = depth_errors(pred["depth"], truth["depth"], region)
    figures.update(depth_absrel=depth["absrel"], depth_rmse=depth["rmse"],
                   pixels={"mask": int(mask.sum()), "region": int(region.sum()), "depth": depth["pixels"]})
    return figures


def environment_figures(pred: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> dict[str, Any]:
    """One environment view's :data:`ENVIRONMENT_METRICS` and pixel counts, from a prediction (``rgb``,
    ``depth``) and the ground truth at the same size (:meth:`pipeline.ground_truth.GroundTruth.environment_view`)."""
    finite = np.isfinite(truth["depth"])
    everywhere = np.ones_like(finite)
    depth = depth_errors(pred["depth"], truth["depth"])
    prop_depth = depth_errors(pred["depth"], truth["depth"], truth["props"])
    return {
        "psnr": psnr_linear(pred["rgb"], truth["rgb"], finite),
        "psnr_srgb": psnr_srgb(pred["rgb"], truth["rgb"], finite),
        "ssim": ssim(pred["rgb"], truth["rgb"], finite),
        "psnr_all": psnr_linear(pred["rgb"], truth["rgb"], everywhere),
        "psnr_srgb_all": psnr_srgb(pred["rgb"], truth["rgb"], everywhere),
        "ssim_all": ssim(pred["rgb"], truth["rgb"], everywhere),
        "depth_absrel": depth["absrel"], "depth_rmse": depth["rmse"],
        "prop_depth_absrel": prop_depth["absrel"], "prop_depth_rmse": prop_depth["rmse"],
        "pixels": {"all": int(finite.size), "finite_depth": int(finite.sum()), "props": prop_depth["pixels"]},
    }


def means(per_view: dict[str, dict[str, Any]], keys: Sequence[str]) -> dict[str, float]:
    """The mean over views of each figure in ``keys``, ignoring views where it is undefined (NaN or None)."""
    def mean(values: list[Any]) -> float:
        finite = [v for v in values if v is not None and math.isfinite(v)]
        return float(np.mean(finite)) if finite else float("nan")

    return {k: mean([v[k] for v in per_view.values()]) for k in keys}


def json_safe(value: Any) -> Any:
    """NaN/inf -> None (strict JSON), recursively."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return None
    return value


def metric_rows(means: dict[str, Any]) -> list[tuple[str, Any, str, str]]:
    """``(label, value, unit, which way is better)`` of each figure of ``means``, in their order."""
    rows = []
    for key, value in means.items():
        label, unit, better = LABELS.get(key, (key, "", ""))
        rows.append((label, value, unit, better))
    return rows


def summary_tables(results: dict[str, Any]) -> list[Any]:
    """The means, pose and mesh errors of an ``evaluate.json`` as rich tables, for a terminal."""
    from rich.table import Table

    tables = []
    for part, title in (("object", "object views"), ("environment", "environment views"),
                        ("held_out", "held-out photos")):
        res = results.get(part)
        if not res:
            continue
        table = Table(title=f"{title}: mean of {len(res['views'])}, 1/{res['downscale']} size")
        for column in ("metric", "mean", "unit", "better"):
            table.add_column(column, justify="right" if column == "mean" else "left")
        for label, value, unit, better in metric_rows(res["mean"]):
            table.add_row(label, "—" if value is None or not math.isfinite(value) else f"{value:.4g}", unit, better)
        tables.append(table)
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
        tables.append(table)
    mesh = results.get("mesh")
    if mesh:
        table = Table(title=f"mesh vs ground truth ({mesh['samples']} samples per surface)")
        for column in ("metric", "value", "unit"):
            table.add_column(column, justify="right" if column == "value" else "left")
        table.add_row("Chamfer", f"{mesh['chamfer_fraction']:.4g}", "object radii (lower is better)")
        table.add_row("Hausdorff", f"{mesh['hausdorff_fraction']:.4g}", "object radii")
        for f in FSCORE_RADII:
            table.add_row(f"F-score at {100 * f:g} %", f"{mesh[f'fscore_{round(100 * f)}pct']:.4g}",
                          "(higher is better)")
        tables.append(table)
    return tables


HELD_OUT_METRICS = ("psnr_srgb_object", "ssim_object", "psnr_srgb_frame", "ssim_frame", "psnr_srgb_object_matched",
                    "psnr_srgb_frame_matched")


def held_out_figures(render: np.ndarray, photo: np.ndarray, mask: np.ndarray, valid: np.ndarray) -> dict[str, Any]:
    """A held-out photo ``(H, W, 3)`` (linear, decoded units) against the model's render of its camera ``render``
    (the object over the environment field): sRGB PSNR (:func:`pipeline.metrics.psnr_srgb`) and SSIM over the
    object (``mask`` ``(H, W)``, the masks stage's) and over the whole frame, highlight-clipped pixels (``valid``
    false) left out of both: the photo does not record them."""
    obj, frame = mask & valid, valid
    gains = matching_gains(render[frame], photo[frame])
    matched = render * gains
    return {"psnr_srgb_object": psnr_srgb(render, photo, obj), "ssim_object": ssim(render, photo, obj),
            "psnr_srgb_frame": psnr_srgb(render, photo, frame), "ssim_frame": ssim(render, photo, frame),
            "psnr_srgb_object_matched": psnr_srgb(matched, photo, obj),
            "psnr_srgb_frame_matched": psnr_srgb(matched, photo, frame), "gains": gains.tolist(),
            "pixels": {"object": int(obj.sum()), "frame": int(frame.sum())}}
