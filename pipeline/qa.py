"""The pictures a person checks the poses and masks stages by: the cameras around the object (matplotlib),
each mask's outline on its photo and a contact sheet of them all (OpenCV)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .cameras import CameraSet

# --------------------------------------------------------------------------------------------------- poses


def cameras_figure(path: Path, cameras: CameraSet, points: np.ndarray | None, colors: np.ndarray | None,
                   report: dict[str, Any], suspects: dict[str, np.ndarray] | None = None) -> None:
    """Top and side views of the cameras around the unit sphere (normalized frame), sparse points behind, the
    poses report's summary as the title; ``suspects``: name -> ``(3,)`` centre of each photo the pose checks
    doubt (kept or dropped), marked with a red cross and its name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c2w = cameras.c2w()
    centers, dirs = c2w[:, :3, 3], c2w[:, :3, 2]
    reach = 1.15 * max(float(np.abs(centers).max()), 1.0)
    arrow = 0.25 * float(np.median(np.linalg.norm(centers, axis=1)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6), constrained_layout=True)
    for ax, (i, j), title in zip(axes, [(0, 1), (0, 2)], ["top view (x, y)", "side view (x, z; z up)"]):
        if points is not None and len(points):
            sel = np.all(np.abs(points) < reach, axis=1)
            p, c = points[sel], (colors[sel] / 255.0 if colors is not None else "0.6")
            if len(p) > 4000:
                k = np.random.default_rng(0).choice(len(p), 4000, replace=False)
                p, c = p[k], (c[k] if not isinstance(c, str) else c)
            ax.scatter(p[:, i], p[:, j], s=1.5, c=c, alpha=0.5, linewidths=0)
        ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, color="tab:red", lw=1.5, label="object (unit sphere)"))
        ax.quiver(centers[:, i], centers[:, j], dirs[:, i] * arrow, dirs[:, j] * arrow, angles="xy",
                  scale_units="xy", scale=1, color="tab:blue", width=0.004)
        ax.scatter(centers[:, i], centers[:, j], s=18, color="tab:blue", zorder=3, label="cameras")
        if suspects:
            doubted = np.stack(list(suspects.values()))
            ax.scatter(doubted[:, i], doubted[:, j], s=60, marker="x", color="tab:red", zorder=4,
                       label="doubtful pose")
            for name, c in suspects.items():
                ax.annotate(name, c[[i, j]], fontsize=7, color="tab:red", xytext=(3, -9), textcoords="offset points")
        step = max(1, len(centers) // 12)
        for k in range(0, len(centers), step):
            ax.annotate(cameras.cameras[k].name, centers[k, [i, j]], fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    line = f"{report['registered']}/{report['total']} photos with cameras"
    if report["source"] == "sfm":
        line += (f"  |  reprojection {report['mean_reprojection_error_px']:.2f} px  |  track length "
                 f"{report['mean_track_length']:.1f}  |  {report['points3D']} points")
        if len(report.get("models", [])) > 1:
            line += f"  |  SfM split into {len(report['models'])} models"
    else:
        line += f"  |  known cameras: {Path(report['source']).name}"
    missing = [n for n in report["not_registered"] if n not in (suspects or {})]  # dropped: on the next line
    if missing:
        line += "\nno camera: " + ", ".join(missing[:12]) + (" ..." if len(missing) > 12 else "")
    if suspects:
        action = report.get("checks", {}).get("on_suspect", "warn")
        line += (f"\ndoubtful poses ({'dropped' if action == 'drop' else 'kept'}, see poses_report.json checks): "
                 + ", ".join(list(suspects)[:12]) + (" ..." if len(suspects) > 12 else ""))
    fig.suptitle(line, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------------------------------- masks


def write_jpeg(path: Path, rgb: np.ndarray, quality: int = 90) -> None:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise OSError(f"{path}: JPEG encoding failed")
    path.write_bytes(buf.tobytes())


def mask_overlay(photo: np.ndarray, mask: np.ndarray, hull: np.ndarray, user: bool, size: int) -> np.ndarray:
    """``(h, w, 3)`` uint8: the photo (longest side ``size``), the mask's outline (green; orange for a user's
    mask) and the visual hull's (magenta), the object slightly brightened."""
    import cv2

    H, W = photo.shape[:2]
    s = min(1.0, size / max(H, W))
    wh = (max(1, round(W * s)), max(1, round(H * s)))
    img = cv2.resize(photo, wh, interpolation=cv2.INTER_AREA) if s < 1 else photo.copy()
    m = cv2.resize(mask.astype(np.uint8), wh, interpolation=cv2.INTER_NEAREST) if s < 1 else mask.astype(np.uint8)
    h8 = cv2.resize(hull.astype(np.uint8), wh, interpolation=cv2.INTER_NEAREST)
    img = np.where(m[..., None] > 0, np.minimum(255, img.astype(np.int16) + 25), img).astype(np.uint8)
    thick = max(1, round(max(wh) / 400))
    contours, _ = cv2.findContours(h8, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (255, 0, 255), thick)
    contours, _ = cv2.findContours(m, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (255, 150, 0) if user else (0, 255, 0), thick)
    return img


def tile(overlay: np.ndarray, name: str, agreement: float, flagged: bool, width: int = 200) -> np.ndarray:
    """A contact-sheet tile: the overlay at ``width`` px with its name and hull IoU; red frame if flagged."""
    import cv2

    h, w = overlay.shape[:2]
    out = cv2.resize(overlay, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)
    label = f"{name}  {agreement:.2f}"
    cv2.rectangle(out, (0, 0), (width, 14), (0, 0, 0), -1)
    cv2.putText(out, label, (3, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
    if flagged:
        cv2.rectangle(out, (0, 0), (out.shape[1] - 1, out.shape[0] - 1), (255, 0, 0), 3)
    return out


def contact_sheet(tiles: list[np.ndarray]) -> np.ndarray:
    """The tiles in a grid (about 4:3), on black."""
    cols = max(1, int(np.ceil(np.sqrt(len(tiles) * 4 / 3))))
    rows = int(np.ceil(len(tiles) / cols))
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    sheet = np.zeros((rows * (th + 2), cols * (tw + 2), 3), np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        sheet[r * (th + 2): r * (th + 2) + t.shape[0], c * (tw + 2): c * (tw + 2) + t.shape[1]] = t
    return sheet
