"""Evaluation pictures: tile grids of ground truth beside prediction (matplotlib), and the exposure they are
shown with (depth colour scales: :mod:`pipeline.media`, shared with the export's pictures)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .media import depth_scale
from .metrics import PSNR_PEAK, tone_map

DISPLAY_PERCENTILE = 99.0
TILE_INCHES = 2.4


ERROR_GAIN = 4.0  # the held-out grid's error tiles: |render - photo| in sRGB, brightened


def percentile_peak(image: np.ndarray, mask: np.ndarray, percentile: float = DISPLAY_PERCENTILE) -> float:
    """The ``percentile`` of ``image`` ``(H, W[, C])`` over ``mask`` pixels (all channels): an automatic exposure
    for pictures. NaN for an empty mask or a non-positive value (a black image has no meaningful peak)."""
    values = image[np.asarray(mask, bool)]
    if values.size == 0:
        return float("nan")
    peak = float(np.percentile(values, percentile))
    return peak if peak > 0 else float("nan")


def display_peak(image: np.ndarray, mask: np.ndarray, fallback: float) -> float:
    """:func:`percentile_peak` of ``image`` over ``mask`` (the whole image if that is empty), else ``fallback``
    (else 1)."""
    p = percentile_peak(image, mask if mask.any() else np.ones(image.shape[:2], bool))
    return p if math.isfinite(p) else (fallback if math.isfinite(fallback) and fallback > 0 else 1.0)


def normals_rgb(normals: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` normals -> colours ``(n + 1) / 2`` in [0, 1]."""
    return np.clip(normals * 0.5 + 0.5, 0, 1)


def tile_figure(rows: int, columns: int, aspect: float):
    """A matplotlib figure of ``rows`` x ``columns`` tiles of height/width ``aspect``, without ticks:
    ``(figure, axes (rows, columns))``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(columns * TILE_INCHES, rows * TILE_INCHES * aspect + 0.4), dpi=110, layout="constrained")
    axes = fig.subplots(rows, columns, squeeze=False)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    return fig, axes


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
    fig, axes = tile_figure(len(rows), len(columns), h / w)
    for r, (name, pred, truth, figures) in enumerate(rows):
        peak = PSNR_PEAK
        spec_peak = display_peak(truth["specular"], truth["mask"], peak)
        tiles = [tone_map(truth["rgb"], peak), tone_map(pred["rgb"], peak), tone_map(truth["specular"], spec_peak),
                 tone_map(pred["specular"], spec_peak), normals_rgb(truth["normal"]), normals_rgb(pred["normal"])]
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
    tiles share one colour scale (:func:`pipeline.media.depth_scale` of every view's ground-truth depth), shown
    by a colour bar on each row; RGB is tone-mapped with the PSNR peak (as the camera would see it)."""
    columns = ["GT rgb", "predicted rgb", "GT depth", "predicted depth"]
    h, w = rows[0][1]["depth"].shape
    fig, axes = tile_figure(len(rows), len(columns), h / w)
    lo, hi = depth_scale([t["depth"] for _, _, t, _ in rows])
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


def held_out_grid(path: Path, rows: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray, dict]]) -> Path:
    """Rows (name, photo, render, object mask, figures) of photo | render | |error| of held-out photos, linear
    images tone-mapped with the PSNR peak (as the camera saw them), the object's outline marked on the error."""
    columns = ["held-out photo", "model's render", "error (x4)"]
    h, w = rows[0][1].shape[:2]
    fig, axes = tile_figure(len(rows), len(columns), h / w)
    for r, (name, photo, render, mask, figures) in enumerate(rows):
        shown_photo, shown_render = tone_map(photo, PSNR_PEAK), tone_map(render, PSNR_PEAK)
        error = np.clip(np.abs(shown_render - shown_photo) * ERROR_GAIN, 0, 1)
        for c, tile in enumerate((shown_photo, shown_render, error)):
            axes[r, c].imshow(tile, interpolation="nearest")
            if r == 0:
                axes[r, c].set_title(columns[c], fontsize=9)
        axes[r, 2].contour(mask, levels=[0.5], colors="yellow", linewidths=0.6)
        axes[r, 0].set_ylabel(_row_label(name, figures, (("psnr_srgb_object", "object {:.1f} dB"),
                                                         ("psnr_srgb_frame", "frame {:.1f} dB"))), fontsize=8)
    fig.savefig(path)
    return path
