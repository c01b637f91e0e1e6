"""Undistortion: photos taken through a real lens resampled to the pinhole camera of the same size and focal
length, which is what cameras.json describes and what training assumes.

When the lens model moves some pixel by more than a threshold, the decoded images (linear EXR, sRGB PNG,
clipped masks) are resampled with the same maps (bilinear; clipped masks nearest) into a folder in the
decode stage's layout. Pixels the lens did not see are black and marked clipped, so training ignores them.
The folder's ``decode.json`` records the lenses, so that images made for the original photos (a user's masks)
can follow the same maps (:func:`recorded_undistortion`).

Pixel convention: ours (COLMAP's) has pixel centres at +0.5, cv2.remap's at integers.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import imageio
from .artifacts import write_json
from .errors import InputError
from .layout import DECODE_JSON, IMAGE_KINDS
from .log import progress
from .signals import import_pycolmap

if TYPE_CHECKING:
    from .results import DecodeArtifacts

log = logging.getLogger("orca.poses")


@dataclass(frozen=True)
class UndistortMaps:
    """cv2.remap maps (OpenCV pixel convention) per distinct lens, and which lens each photo uses."""

    maps: list[tuple[np.ndarray, np.ndarray]]  # (map_x, map_y), each (H, W) float32
    lens_of: dict[str, int]
    max_shift_px: float
    lenses: list[dict[str, Any]]  # COLMAP model, size and parameters of each map's lens (recorded in decode.json)


def pinhole(camera: Any) -> np.ndarray:
    """``(3, 3)`` pinhole part of a COLMAP camera (what its undistorted image has)."""
    return np.array([[camera.focal_length_x, 0, camera.principal_point_x],
                     [0, camera.focal_length_y, camera.principal_point_y], [0, 0, 1]], np.float64)


def pinholes(cameras: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 3, 3)`` pinhole parts and ``(N, 2)`` (width, height) of N COLMAP cameras."""
    return (np.stack([pinhole(c) for c in cameras]),
            np.array([[c.width, c.height] for c in cameras], float))


def undistort_map(camera: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """Maps from the pinhole image (same size, same fx, fy, cx, cy) to the distorted one, and the largest
    pixel shift. Project pixel convention in, cv2.remap's (pixel centres at integers) out."""
    w, h = int(camera.width), int(camera.height)
    K = pinhole(camera)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    src = np.asarray(camera.img_from_cam(rays, check_cheirality=False)).reshape(h, w, 2)
    shift = float(np.nanmax(np.linalg.norm(src - np.stack([u, v], -1), axis=-1)))
    return (src[..., 0] - 0.5).astype(np.float32), (src[..., 1] - 0.5).astype(np.float32), shift


def lens_maps(cams: Sequence[Any]) -> tuple[list[tuple[np.ndarray, np.ndarray]], float]:
    """:func:`undistort_map` of each lens, and the largest shift among them (px)."""
    maps, worst = [], 0.0
    for c in cams:
        mx, my, shift = undistort_map(c)
        maps.append((mx, my))
        worst = max(worst, shift)
    return maps, worst


def undistortion(names: Sequence[str], lenses: Sequence[Any], threshold_px: float) -> tuple[UndistortMaps | None,
                                                                                             float]:
    """Maps for every distinct lens of the photos ``names`` (``lenses``: their COLMAP cameras), or None when no
    lens shifts a pixel by more than ``threshold_px``; and the largest shift."""
    keys: dict[tuple, int] = {}
    lens_of: dict[str, int] = {}
    cams = []
    for n, c in zip(names, lenses):
        key = (c.model_name, int(c.width), int(c.height), tuple(np.round(c.params, 12)))
        if key not in keys:
            keys[key] = len(cams)
            cams.append(c)
        lens_of[n] = keys[key]
    maps, worst = lens_maps(cams)
    if worst <= threshold_px:
        return None, worst
    log.info("lens distortion moves pixels by up to %.2f px: resampling the decoded images to pinhole", worst)
    record = [{"model": c.model_name, "width": int(c.width), "height": int(c.height),
               "params": [float(p) for p in c.params]} for c in cams]
    return UndistortMaps(maps, lens_of, worst, record), worst


def recorded_undistortion(decoded: DecodeArtifacts) -> UndistortMaps | None:
    """The undistortion the poses stage applied to an ``undistorted/`` folder (rebuilt from the lenses its
    ``decode.json`` records), so that images made for the original photos (a user's masks) follow it; None
    for a folder of photos as decoded."""
    pycolmap = import_pycolmap()
    record = decoded.meta.get("undistorted")
    if record is None:
        return None
    if "lenses" not in record:
        raise InputError("this undistorted folder does not record its lenses (made by an older version)",
                         decoded.folder / DECODE_JSON, fix="rerun `orca poses` (or snakemake --forcerun poses)")
    cams = [pycolmap.Camera(model=lens["model"], width=lens["width"], height=lens["height"], params=lens["params"])
            for lens in record["lenses"]]
    maps, worst = lens_maps(cams)
    return UndistortMaps(maps, dict(record["lens_of"]), worst, list(record["lenses"]))


def remap(img: np.ndarray, maps: tuple[np.ndarray, np.ndarray], nearest: bool = False,
          border: float = 0) -> np.ndarray:
    """``img`` resampled through ``maps`` (bilinear, or nearest), ``border`` outside the source image."""
    import cv2

    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(img, maps[0], maps[1], interp, borderMode=cv2.BORDER_CONSTANT, borderValue=border)


def undistort_mask(mask: np.ndarray, und: UndistortMaps, name: str) -> np.ndarray:
    """``(H, W)`` bool mask drawn on photo ``name`` -> the same mask on its undistorted (pinhole) image."""
    return remap(mask.astype(np.uint8), und.maps[und.lens_of[name]], nearest=True) > 0


def write_undistorted(decoded: DecodeArtifacts, names: Sequence[str], und: UndistortMaps, folder: Path) -> None:
    """The decoded images of ``names`` resampled to pinhole into ``folder``, in the decode stage's layout
    (``decode.json`` included, recording the lenses)."""
    for sub in IMAGE_KINDS:
        (folder / sub).mkdir(parents=True)
    with progress() as bar:
        task = bar.add_task("undistort", total=len(names))
        for n in names:
            maps = und.maps[und.lens_of[n]]
            entry = decoded.entry(n)
            imageio.write_exr(folder / entry["linear"], remap(decoded.linear(n), maps))
            imageio.write_png(folder / entry["srgb"], remap(decoded.srgb(n), maps))
            clipped = decoded.clipped(n).astype(np.uint8) * 255
            # Pixels the lens did not see count as clipped: training then ignores them.
            imageio.write_png(folder / entry["clipped"], remap(clipped, maps, nearest=True, border=255))
            bar.advance(task)
    meta = dict(decoded.meta)
    meta["images"] = [im for im in meta["images"] if im["name"] in set(names)]
    meta["undistorted"] = {
        "by": "poses stage", "max_shift_px": und.max_shift_px,
        "note": "decoded images resampled (bilinear) to the pinhole cameras of cameras.json; pixels outside the "
        "original photo are 0 and marked clipped",
        "lenses": und.lenses, "lens_of": {n: und.lens_of[n] for n in names},
    }
    write_json(folder / DECODE_JSON, meta)
