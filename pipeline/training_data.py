"""What training reads: decoded photos matched by name to their cameras and masks, as an ``orca.data.ImageSet``,
with the sparse depth of the surroundings when the poses stage's points are given."""

from __future__ import annotations

import logging
from collections.abc import Collection, Sequence
from pathlib import Path

import numpy as np

from .cameras import load_cameras
from .errors import InputError
from .layout import CAMERAS_JSON, MASKS_REPORT
from .mask_file import read_mask
from .results import load_decode, load_masks
from .sparse_depth import depth_observations, load_sparse_points

log = logging.getLogger("orca.train")


def held_out(names: Sequence[str], every: int) -> list[str]:
    """Every ``every``-th of ``names`` from the first (LLFF's convention), none for 0."""
    return list(names[::every]) if every else []


def learns_appearance(decode_dir: Path, names: Sequence[str], mode: bool | str) -> bool:
    """Whether training learns each photo's exposure and white balance (``train.appearance``): ``"auto"`` does
    unless every one of ``names`` was decoded from RAW (one white balance, exposure from EXIF)."""
    if mode != "auto":
        return bool(mode)
    decoded = load_decode(decode_dir)
    return any(decoded.entry(name).get("format") != "raw" for name in names)


def posed_names(decode_dir: Path, cameras_path: Path) -> list[str]:
    """The decoded images that have a camera in ``cameras_path``, in decode's order."""
    cams = load_cameras(cameras_path).by_name()
    return [n for n in load_decode(decode_dir).names if n in cams]


def support_plane(masks_dir: Path, cameras_path: Path) -> tuple[np.ndarray, float] | None:
    """The floor or table the object stands on, ``((3,) normal pointing up, offset)`` with ``normal . x =
    offset`` on it, in the frame of ``cameras_path``: the masks stage's plane when ``masks_dir`` is that stage's
    ``masks/`` folder and ``cameras_path`` its cameras.json; else (ground-truth or your own masks and cameras,
    no plane found) None."""
    stage = Path(masks_dir).parent
    if not (stage / MASKS_REPORT).is_file() or Path(cameras_path).resolve() != (stage / CAMERAS_JSON).resolve():
        return None
    plane = (load_masks(stage).report.get("support_plane") or {}).get("cameras_json")
    if plane is None:
        return None
    return np.asarray(plane["normal"], dtype=np.float64), float(plane["offset"])


def load_image_set(decode_dir: Path, cameras_path: Path, masks_dir: Path, points_dir: Path | None = None,
                   object_margin_px: int = 4, exclude: Collection[str] = ()):
    """Decoded images matched by name to cameras and masks, intrinsics scaled to the decoded size, and the
    sparse depth of the surroundings when ``points_dir`` (the poses stage's COLMAP model) is given; the images
    named in ``exclude`` (held out) left out.

    Returns:
        (``orca.data.ImageSet`` in float32 on the CPU, the image names).
    """
    import torch

    from orca.data import ImageSet

    decoded = load_decode(decode_dir)
    camera_set = load_cameras(cameras_path)
    cams = camera_set.by_name()
    missing = [n for n in decoded.names if n not in cams]
    if missing:
        log.warning("%d decoded image(s) have no camera in %s and are not used: %s",
                    len(missing), cameras_path, ", ".join(missing[:10]))
    excluded = set(exclude)
    names = [n for n in decoded.names if n in cams and n not in excluded]
    if len(names) < 2:
        raise InputError(
            f"only {len(names)} decoded image(s) have a camera (names must match the decoded file stems)",
            cameras_path, "run the poses stage on the same capture, or pass the capture's ground_truth/cameras.json",
        )
    images, masks, valid, Ks, c2ws = [], [], [], [], []
    for name in names:
        img = decoded.linear(name)
        h, w = img.shape[:2]
        cam = cams[name]
        sx, sy = w / cam.width, h / cam.height
        if abs(sx - sy) > 1e-3 * max(sx, sy):
            raise InputError(f"camera {name} is {cam.width}x{cam.height} but the decoded image is {w}x{h} "
                             "(different aspect ratio)", cameras_path)
        mask_path = masks_dir / f"{name}.png"
        if not mask_path.is_file():
            raise InputError(f"no mask for image {name}", mask_path, "run the masks stage, or add the missing mask")
        m = read_mask(mask_path, (w, h))
        K = cam.K.copy()
        K[0] *= sx
        K[1] *= sy
        images.append(img[..., :3])
        masks.append(m)
        valid.append(~decoded.clipped(name))
        Ks.append(K)
        c2ws.append(cam.c2w)
    if not any(m.any() for m in masks):
        raise InputError("every mask is empty", masks_dir, "check the masks stage output (the object was not found)")
    t = lambda a, dt=torch.float32: torch.from_numpy(np.stack(a)).to(dt)  # noqa: E731
    depth = None
    if points_dir is not None:
        depth = _sparse_depth(points_dir, camera_set, names, np.stack(Ks), np.stack(c2ws), np.stack(masks),
                              object_margin_px)
    return ImageSet(t(images), t(masks, torch.bool), t(valid, torch.bool), t(Ks), t(c2ws), depth=depth), names


def _sparse_depth(points_dir: Path, cameras, names: list[str], K: np.ndarray, c2w: np.ndarray, masks: np.ndarray,
                  object_margin_px: int):
    """``orca.data.SparseDepth`` from the poses stage's points (see pipeline.sparse_depth)."""
    import torch

    from orca.data import SparseDepth

    points = load_sparse_points(points_dir, cameras)
    obs = depth_observations(points, names, K, c2w, masks, object_margin_px)
    log.info("sparse depth: %d of %d points of the surroundings (%d dropped: seen on or next to the object), "
             "%d pixels, median distance %.2f", obs.points_used, len(points.xyz), obs.points_on_object,
             len(obs.distance), float(np.median(obs.distance)) if len(obs.distance) else float("nan"))
    if not len(obs.distance):
        log.warning("no sparse point of the surroundings projects into the photos off the object (%s): training "
                    "goes on without sparse depth", points_dir)
    return SparseDepth(torch.from_numpy(obs.image), torch.from_numpy(obs.uv).float(),
                       torch.from_numpy(obs.distance).float())
