"""How well a poses stage's cameras agree at the object: the blowtorch's reference masks carved into a visual
hull with those cameras and reprojected into every photo.

    python bench/pose_consistency.py RUN/results/poses                      # one run's cameras
    python bench/pose_consistency.py A/poses B/poses --common               # several, on the photos all have

A camera a fraction of a degree off cuts the hull in every other photo, so the reprojected hull's IoU with each
photo's own mask falls with the cameras' disagreement, whatever the masks stage would make of them: it separates
"the poses are off" from "the masks method is off". The masks are the photographers' (resampled like the photos
when the poses stage undistorted them); the hull is a grid over ``--extent`` times the normalized frame's unit
sphere (the object's), a voxel kept when no photo sees it off its mask. Pose agreement with the reference
cameras (:func:`bench.blowtorch.pose_agreement`) is printed beside it.

Prints a line per run and appends a JSON line to bench/results/pose_consistency.jsonl.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.blowtorch import (  # noqa: E402
    DATASET,
    append_record,
    commit,
    machine,
    pose_agreement,
    reference_cameras,
    reference_mask,
)
from pipeline.layout import UNDISTORTED, USER_MASKS  # noqa: E402
from pipeline.results import load_decode, load_poses  # noqa: E402
from pipeline.undistort import recorded_undistortion  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "pose_consistency.jsonl"
SPLAT_FRACTION = 0.75  # a surface voxel's splat radius, as a share of its projected size (no gaps between them)


def project(K: np.ndarray, w2c: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(M, 2)`` and depths ``(M,)`` of points ``X`` ``(M, 3)``."""
    cam = X @ w2c[:3, :3].T + w2c[:3, 3]
    uv = cam @ K.T
    return uv[:, :2] / np.maximum(uv[:, 2:], 1e-9), cam[:, 2]


def hull_ious(K: np.ndarray, w2c: np.ndarray, masks: list[np.ndarray], extent: float, n: int) -> np.ndarray:
    """``(N,)`` IoU of each photo's mask with the reprojection of the hull all the masks carve."""
    h, w = masks[0].shape
    axis = np.linspace(-extent, extent, n)
    voxel = axis[1] - axis[0]
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    seen_off = np.zeros(len(grid), bool)
    for k, m, mask in zip(K, w2c, masks):
        uv, z = project(k, m, grid)
        u, v = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        inside = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        seen_off[inside] |= ~mask[v[inside], u[inside]]
    solid = ndimage.binary_opening(~seen_off.reshape(n, n, n))
    surface = grid[(solid & ~ndimage.binary_erosion(solid)).reshape(-1)]
    ious = []
    for k, m, mask in zip(K, w2c, masks):
        uv, z = project(k, m, surface)
        radius = int(np.ceil(SPLAT_FRACTION * k[0, 0] * voxel / z.min()))
        u, v = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
        hit = (u >= 0) & (u < w) & (v >= 0) & (v < h)
        image = np.zeros((h, w), np.uint8)
        image[v[hit], u[hit]] = 1
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        image = ndimage.binary_fill_holes(cv2.dilate(image, disc)).astype(np.uint8)
        # the splats reach half a voxel past the silhouette: take it back
        image = cv2.erode(image, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (radius + 1, radius + 1))) > 0
        ious.append((image & mask).sum() / max((image | mask).sum(), 1))
    return np.array(ious)


def consistency(poses: Path, names: list[str] | None, extent: float, n: int) -> dict:
    """The hull IoUs and the pose agreement of the poses folder ``poses`` on ``names`` (default: all its photos)."""
    cameras = load_poses(poses).cameras()
    by_name = cameras.by_name()
    names = sorted(by_name) if names is None else names
    undistorted = poses / UNDISTORTED
    undistortion = recorded_undistortion(load_decode(undistorted)) if undistorted.is_dir() else None
    size = (by_name[names[0]].width, by_name[names[0]].height)
    masks = [reference_mask(DATASET / USER_MASKS / f"{name}.png", size, undistortion) for name in names]
    K = np.stack([by_name[name].K for name in names])
    w2c = np.linalg.inv(np.stack([by_name[name].c2w for name in names]))
    ious = hull_ious(K, w2c, masks, extent, n)
    agreement = pose_agreement(cameras.model_copy(update={"cameras": [by_name[x] for x in names]}),
                               reference_cameras())
    return {"poses": str(poses), "photos": len(names), "hull_iou_median": float(np.median(ious)),
            "hull_iou_worst": float(ious.min()), "worst_photo": names[int(ious.argmin())],
            **{k: v for k, v in agreement.items() if k != "per_camera"}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("poses", type=Path, nargs="+", help="poses stage folders of blowtorch runs")
    parser.add_argument("--common", action="store_true", help="score every run on the photos all of them have")
    parser.add_argument("--extent", type=float, default=2.2,
                        help="the grid's half side, in object radii (the poses stage's sphere is a loose bound)")
    parser.add_argument("--grid", type=int, default=220, help="voxels along each side")
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--note", default="", help="what the runs are, recorded with them")
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args()

    names = None
    if args.common:
        sets = [set(load_poses(p).cameras().by_name()) for p in args.poses]
        names = sorted(set.intersection(*sets))
    runs = []
    for poses in args.poses:
        run = consistency(poses, names, args.extent, args.grid)
        runs.append(run)
        print(f"{poses}: {run['photos']} photos, hull IoU median {run['hull_iou_median']:.3f} worst "
              f"{run['hull_iou_worst']:.3f} ({run['worst_photo']}); rotation {run['rotation_deg_median']:.2f} deg "
              f"median, centre {100 * run['center_median_fraction']:.2f} % from the reference", flush=True)
    if not args.no_record:
        record = {"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": machine(), "commit": commit(),
                  "grid": args.grid, "extent": args.extent, "note": args.note, "runs": runs}
        append_record(args.results, record)


if __name__ == "__main__":
    main()
