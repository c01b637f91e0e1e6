"""The picture a person checks after a calibration (matplotlib, Agg): per-image errors, corner coverage of
the frame, and how far the lens distortion moves pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .detect import Detection
from .solve import Solution


def summary_figure(
    path: Path,
    names: list[str],
    detections: list[Detection],
    solution: Solution,
    size: tuple[int, int],
    rejected: dict[str, str],
    title: str,
) -> Path:
    """Write a 3-panel PNG. ``names``/``detections``: the M images used (same order as ``solution``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h = size
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.2), layout="constrained")
    fig.suptitle(title, fontsize=10)

    ax = axes[0]
    errs = solution.per_image_rms_px
    ax.bar(range(len(errs)), errs, color="tab:blue")
    ax.axhline(solution.rms_px, color="tab:red", ls="--", label=f"all corners: {solution.rms_px:.3f} px RMS")
    ax.set_xticks(range(len(errs)), names, rotation=90, fontsize=6 if len(errs) > 30 else 8)
    ax.set_ylabel("reprojection error, RMS (px)")
    ax.set_title(f"{len(errs)} images used, {len(rejected)} rejected")
    ax.legend(fontsize=8)

    ax = axes[1]
    pts = np.concatenate([d.image_points for d in detections]) + 0.5  # project convention for display
    res = np.concatenate([np.linalg.norm(p - d.image_points, axis=1) for p, d in zip(solution.reprojected, detections)])
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=res, s=6, cmap="viridis", vmin=0, vmax=max(float(res.max()), 1e-3))
    fig.colorbar(sc, ax=ax, label="corner reprojection error (px)")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_title("corners found (they should reach every part of the frame)", fontsize=9)

    ax = axes[2]
    xs, ys, shift = _distortion_shift(solution, w, h)
    cs = ax.contourf(xs, ys, shift, levels=12, cmap="magma")
    fig.colorbar(cs, ax=ax, label="pixel shift by the distortion (px)")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    k1, k2, p1, p2, k3 = solution.dist
    ax.set_title(f"distortion k1={k1:.3g} k2={k2:.3g} p1={p1:.2g} p2={p2:.2g} k3={k3:.2g}", fontsize=9)

    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _distortion_shift(solution: Solution, w: int, h: int, n: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|distorted - ideal| pixel positions on an (n, n) grid over the frame (OpenCV convention inside)."""
    import cv2

    xs, ys = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    ideal = np.stack([xs.ravel(), ys.ravel()], axis=1)
    K = solution.K
    x, y = (ideal[:, 0] - K[0, 2]) / K[0, 0], (ideal[:, 1] - K[1, 2]) / K[1, 1]
    normalized = np.stack([x, y, np.ones_like(x)], axis=1)  # rays of the ideal (undistorted) pixels
    projected, _ = cv2.projectPoints(normalized.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, solution.dist)
    shift = np.linalg.norm(projected.reshape(-1, 2) - ideal, axis=1).reshape(n, n)
    return xs + 0.5, ys + 0.5, shift
