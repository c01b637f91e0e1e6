"""Sparse depth of the surroundings: the poses stage's structure-from-motion points, in the training cameras'
frame, projected into the photos that saw them, off the object.

The room is what the photos see around a glossy object, and structure from motion triangulated thousands of
its points (walls, floor, props) to a fraction of a pixel. Training uses them to tell the environment field
where the rays through them end (``orca.losses.sparse_depth_loss``): without it the field is free to put a
wall at whatever depth explains one photo's pixels best, and floaters before the lenses do exactly that.
Points that any of their photos see on or next to the object are dropped: features there are the object's
texture or, worse, reflections, which triangulate to places where nothing is.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .alignment import fit_similarity
from .cameras import CameraSet
from .errors import InputError
from .object_frame import project

log = logging.getLogger("orca.sparse_depth")


@dataclass(frozen=True)
class SparsePoints:
    """``M`` triangulated points and the photos (names without extension) whose features made each."""

    xyz: np.ndarray  # (M, 3) in the frame of the cameras they were loaded for
    observers: list[list[str]]
    ids: list[int] | None = None  # COLMAP's point3D ids, when loaded from a model


def load_sparse_points(sparse_dir: Path, cameras: CameraSet, min_track: int = 3) -> SparsePoints:
    """The points of a COLMAP model (the poses stage's ``sparse/``, which holds it as ``0/``; or a model's own
    folder) seen in at least ``min_track`` photos, moved into the frame of ``cameras``: through its
    ``frame.to_colmap`` when it records one (the poses and masks stages' cameras), else by the similarity between
    the model's camera centres and theirs (known or ground-truth cameras of the same photos)."""
    from .colmap_model import model_folder
    from .sfm import stem_of
    from .signals import import_pycolmap

    pycolmap = import_pycolmap()

    sparse_dir = model_folder(Path(sparse_dir))
    if not (sparse_dir / "points3D.bin").is_file() and not (sparse_dir / "points3D.txt").is_file():
        raise InputError("no COLMAP points3D here", sparse_dir, "pass the poses stage's sparse/ folder")
    try:
        rec = pycolmap.Reconstruction(str(sparse_dir))
    except Exception as e:  # noqa: BLE001 - pycolmap raises plain RuntimeErrors for unreadable models
        raise InputError(f"cannot read the COLMAP model: {e}", sparse_dir, "rerun the poses stage") from e
    names = {image_id: stem_of(image.name) for image_id, image in rec.images.items()}
    if cameras.frame.to_colmap is not None:
        from_colmap = np.linalg.inv(np.asarray(cameras.frame.to_colmap, dtype=np.float64))
    else:
        centres = {names[i]: image.projection_center() for i, image in rec.images.items() if image.has_pose}
        from_colmap = frame_from_centres(centres, cameras, sparse_dir)
    xyz, observers, ids = [], [], []
    for point_id, point in rec.points3D.items():
        if point.track.length() >= min_track:
            ids.append(int(point_id))
            xyz.append(point.xyz)
            observers.append(sorted({names[e.image_id] for e in point.track.elements}))
    points = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    points = points @ from_colmap[:3, :3].T + from_colmap[:3, 3]
    return SparsePoints(points, observers, ids)


# A model whose camera centres fit the given ones worse than this (RMS, as a share of the centres' spread) is
# of other photos or another scene; SfM of the same photos fits to ~0.1 %.
CENTRE_FIT_TOLERANCE = 0.01


def frame_from_centres(centres: dict[str, np.ndarray], cameras: CameraSet, sparse_dir: Path) -> np.ndarray:
    """``(4, 4)`` similarity from the model's frame to the cameras', fitted on the centres of the photos both
    have."""
    given = cameras.by_name()
    common = sorted(set(centres) & set(given))
    if len(common) < 3:
        raise InputError(f"the COLMAP model shares {len(common)} photo(s) with the cameras (3 needed to place its "
                         "points in their frame)", sparse_dir, "pass the poses stage's model of the same capture")
    src = np.stack([centres[n] for n in common])
    dst = np.stack([given[n].center for n in common])
    fit = fit_similarity(src, dst)
    rms = float(np.sqrt(((fit.apply(src) - dst) ** 2).sum(-1).mean()))
    spread = float(np.sqrt(((dst - dst.mean(0)) ** 2).sum(-1).mean()))
    if rms > CENTRE_FIT_TOLERANCE * spread:
        raise InputError(f"the COLMAP model's cameras do not fit the given ones (centre RMS {rms / spread:.1%} of "
                         "their spread after a similarity)", sparse_dir, "pass the model of the same photos")
    log.info("sparse points placed by a similarity fitted on %d camera centres (RMS %.2g of their spread)",
             len(common), rms / spread)
    return fit.matrix


@dataclass(frozen=True)
class DepthObservations:
    """``P`` pixels whose rays end at known distances."""

    image: np.ndarray  # (P,) int64 index into the image list
    uv: np.ndarray  # (P, 2) pixel coordinates (COLMAP convention: (0, 0) is the top-left corner)
    distance: np.ndarray  # (P,) from the camera centre
    points_used: int
    points_on_object: int


def observation_pairs(observers: Sequence[Sequence[str]], names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Every (point, photo that saw it) pair, in the order of the points: ``(P,)`` int64 point indices and
    ``(P,)`` int64 indices into ``names`` (observers not among ``names`` are left out)."""
    index = {n: i for i, n in enumerate(names)}
    pairs = [(k, index[name]) for k, seen_by in enumerate(observers) for name in seen_by if name in index]
    if not pairs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    point, image = (np.asarray(a, np.int64) for a in zip(*pairs))
    return point, image


def depth_observations(
    points: SparsePoints, names: Sequence[str], K: np.ndarray, c2w: np.ndarray, masks: np.ndarray,
    object_margin_px: int,
) -> DepthObservations:
    """Project each point into the photos that saw it; drop points that land within ``object_margin_px`` of
    the object's mask in any of them.

    Args:
        names: ``N`` image names; K ``(N, 3, 3)``, c2w ``(N, 4, 4)``, masks ``(N, H, W)`` bool, as trained on.
    """
    _, h, w = masks.shape
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * object_margin_px + 1,) * 2)
    point, image = observation_pairs(points.observers, names)
    uv = np.zeros((len(point), 2))
    seen = np.zeros(len(point), bool)  # in front of the camera and inside its photo
    near = np.zeros(len(point), bool)
    for i in np.unique(image):
        sel = np.nonzero(image == i)[0]
        pix, z = project(points.xyz[point[sel]], c2w[i][None], K[i][None])
        col, row = np.floor(pix[0]).astype(np.int64).T
        inside = (z[0] > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        near_object = cv2.dilate(masks[i].astype(np.uint8), kernel) > 0
        uv[sel], seen[sel] = pix[0], inside
        near[sel[inside]] = near_object[row[inside], col[inside]]
    on_object = np.zeros(len(points.xyz), bool)
    on_object[point[near]] = True
    keep = seen & ~on_object[point]
    distance = np.linalg.norm(points.xyz[point[keep]] - c2w[image[keep], :3, 3], axis=-1)
    return DepthObservations(image[keep], uv[keep], distance, int(np.unique(point[keep]).size),
                             int(on_object.sum()))


# The farthest points are the first to be outliers (a bad match triangulated near infinity): the bound is taken
# at this quantile of the distances.
FAR_QUANTILE = 0.999


def far_bound(distance: np.ndarray, factor: float) -> float:
    """How far environment samples need to reach: ``factor`` times the farthest a photo saw a point (its
    :data:`FAR_QUANTILE`), as LLFF bounds each image's depth range by its points. Without a bound the field
    puts what no point pins down (a ceiling only the reflections see) at whatever depth the samples reach."""
    if not len(distance):
        raise ValueError("no sparse depth to bound")
    return float(factor * np.quantile(distance, FAR_QUANTILE))
