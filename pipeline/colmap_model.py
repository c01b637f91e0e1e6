"""COLMAP models in and out: a user's model read (as known cameras), ours written where other tools look.

Layout: COLMAP's mapper writes one model per folder of ``sparse/`` (``sparse/0``, ``sparse/1``, ...); 3D Gaussian
splatting, gsplat and nerfstudio's colmap dataparser read ``sparse/0`` beside an ``images/`` folder that holds each
image under the name ``images.bin`` gives it. The poses stage writes that (:func:`write_dataset`), 8-bit PNGs in
``images/``; readers here take ``sparse/`` or ``sparse/0`` alike (:func:`model_folder`).

Cameras: those of ``cameras.json``, PINHOLE, with the 2D points moved to where the pinhole camera sees them
(:func:`to_pinhole`): what COLMAP's image_undistorter gives (ours keeps the photos' size and focal length,
:mod:`pipeline.undistort`), and what 3D Gaussian splatting requires. ``images/`` then holds the undistorted
photos, or the photos as decoded where the lens moves no pixel by more than ``poses.undistort_threshold_px``
(which cameras.json treats as pinhole too).

Pixel convention: COLMAP's, (0, 0) the top-left corner of the image, so scaling an image scales its points.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError
from .layout import COLMAP_IMAGES, SPARSE_MODEL
from .signals import import_pycolmap

if TYPE_CHECKING:
    import pycolmap  # noqa: TID251 - annotations only

log = logging.getLogger("orca.poses")

MODEL_FILES = ("cameras", "images", "points3D")  # what every COLMAP model has (newer ones add rigs, frames)
MODEL_FORMATS = (".bin", ".txt")
FIRST_MODEL = "0"  # the folder in sparse/ that COLMAP's mapper gives its largest model


def model_files(folder: Path) -> list[Path]:
    """The model files in ``folder`` (cameras, images, points3D; binary or text)."""
    return [folder / f"{f}{ext}" for ext in MODEL_FORMATS for f in MODEL_FILES if (folder / f"{f}{ext}").is_file()]


def model_folder(folder: Path) -> Path:
    """``folder`` when it holds a model's files, else its ``0/`` when that does (``sparse/`` as COLMAP's mapper and
    the poses stage write it, or ``sparse/`` holding the model as older poses stages wrote it)."""
    folder = Path(folder)
    return folder / FIRST_MODEL if not model_files(folder) and model_files(folder / FIRST_MODEL) else folder


def read_model(folder: Path, fix: str) -> pycolmap.Reconstruction:
    """The COLMAP model in ``folder`` (binary or text).

    Raises:
        InputError: no model there, or one pycolmap cannot read; ``fix`` says what to do.
    """
    pycolmap = import_pycolmap()

    if not model_files(folder):
        raise InputError(f"no COLMAP model here (no {', '.join(f + '.bin' for f in MODEL_FILES)} or .txt)", folder,
                         fix=fix)
    try:
        return pycolmap.Reconstruction(str(folder))
    except Exception as e:  # noqa: BLE001 - pycolmap raises ValueError or RuntimeError for unreadable models
        raise InputError(f"cannot read the COLMAP model: {e}", folder, fix=fix) from e


def model_points(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """The 3D points of the COLMAP model in ``folder`` (or its ``0/``), in its frame: ``xyz`` ``(M, 3)`` and their
    colours ``(M, 3)`` uint8."""
    rec = read_model(model_folder(folder), fix="rerun the poses stage")
    points = list(rec.points3D.values())
    xyz = np.array([p.xyz for p in points], np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in points], np.uint8).reshape(-1, 3)
    return xyz, rgb


def rescale(rec: pycolmap.Reconstruction, width: int, height: int) -> None:
    """Every camera of ``rec``'s registered images scaled to ``width`` x ``height`` (focal lengths, principal
    point), and their images' 2D points with them; reprojection errors recomputed. Changes ``rec`` in place."""
    images = [rec.images[i] for i in rec.reg_image_ids()]
    scale = {}
    for cid in {im.camera_id for im in images}:
        cam = rec.cameras[cid]
        scale[cid] = np.array([width / cam.width, height / cam.height])
        cam.rescale(width, height)
    for im in images:
        if np.any(scale[im.camera_id] != 1):
            for p in im.points2D:
                p.xy = p.xy * scale[im.camera_id]
    rec.update_point_3d_errors()


def to_pinhole(rec: pycolmap.Reconstruction) -> None:
    """Every camera of ``rec``'s registered images made PINHOLE with its own focal lengths and principal point
    (the undistorted photos' camera, :func:`pipeline.undistort.pinhole`), and their images' 2D points moved
    where the undistorted photos show them. Changes ``rec`` in place."""
    images = [rec.images[i] for i in rec.reg_image_ids()]
    for cid in {im.camera_id for im in images}:
        cam = rec.cameras[cid]
        if cam.model_name == "PINHOLE":
            continue
        fx, fy, cx, cy = cam.focal_length_x, cam.focal_length_y, cam.principal_point_x, cam.principal_point_y
        for im in (im for im in images if im.camera_id == cid):
            if im.num_points2D():
                xy = np.array([p.xy for p in im.points2D], np.float64)
                ray = np.asarray(cam.cam_from_img(xy))
                for p, (u, v) in zip(im.points2D, ray):
                    p.xy = np.array([fx * u + cx, fy * v + cy])
        cam.model = "PINHOLE"
        cam.params = [fx, fy, cx, cy]
    rec.update_point_3d_errors()


def write_dataset(rec: pycolmap.Reconstruction, folder: Path, images: Mapping[str, Path]) -> None:
    """``rec`` with PINHOLE cameras (:func:`to_pinhole`) as ``folder/sparse/0`` (binary) beside ``folder/images/``:
    each registered image renamed to the file name of its photo's 8-bit pinhole image in ``images`` (by photo
    name: the image name's stem), which is linked there (copied where the file system cannot link). ``rec``
    itself is not changed."""
    from .sfm import stem_of

    rec = import_pycolmap().Reconstruction(rec)
    to_pinhole(rec)
    (folder / SPARSE_MODEL).mkdir(parents=True)
    (folder / COLMAP_IMAGES).mkdir()
    for i in rec.reg_image_ids():
        image = rec.images[i]
        source = Path(images[stem_of(image.name)])
        image.name = source.name
        _link_or_copy(source, folder / COLMAP_IMAGES / source.name)
    rec.write(folder / SPARSE_MODEL)


def _link_or_copy(source: Path, target: Path) -> None:
    # A hard link costs no space and stays right when the source is replaced: stages replace folders, never files.
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)
