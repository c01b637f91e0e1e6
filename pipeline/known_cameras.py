"""Known cameras instead of SfM: a capture's own ``cameras.json`` (our schema), ``transforms.json``
(nerfstudio/instant-ngp, OpenGL axes), ``poses_bounds.npy`` (LLFF, :mod:`pipeline.llff`) or COLMAP model
(``sparse/0/`` or nerfstudio's ``colmap/sparse/0/``, binary or text), from a turntable, a phone's AR session or
another SfM run. Cameras are matched to photos by file stem (LLFF's rows by ``all_image_names.txt``, or by the
photos' sorted order); their intrinsics are scaled to the decoded size, and a transforms.json's distortion
becomes the lens model (OPENCV, or FULL_OPENCV with k3/k4) that undistortion then removes. A COLMAP model keeps
its own lens models (SIMPLE_RADIAL, OPENCV, ...), as SfM's do, and its 3D points (sparse depth, the object's
support plane): it is restricted to the photos and scaled to their decoded size, 2D points included, and the
poses stage writes it as its own ``sparse/0``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .cameras import load_cameras
from .colmap_model import read_model, rescale
from .errors import InputError
from .layout import CAMERAS_JSON, NERFSTUDIO_MODEL, POSES_BOUNDS, SPARSE_MODEL, TRANSFORMS_JSON
from .llff import load_poses_bounds
from .object_frame import Posed
from .sfm import posed_from_reconstruction, stem_of, without_dropped
from .signals import import_pycolmap
from .transforms import load_transforms

if TYPE_CHECKING:
    import pycolmap  # noqa: TID251 - annotations only

log = logging.getLogger("orca.poses")

KNOWN_CAMERA_FILES = (CAMERAS_JSON, TRANSFORMS_JSON, POSES_BOUNDS)
KNOWN_COLMAP_MODELS = (SPARSE_MODEL, NERFSTUDIO_MODEL)  # folders
ASPECT_TOLERANCE = 0.01  # a camera whose x and y scale to the decoded photo differ more has another aspect ratio


def find_known_cameras(capture_dir: Path, known_poses: str) -> Path | None:
    """The capture's known-cameras file or COLMAP model folder, or None (none, or ``known_poses="ignore"``: SfM
    runs anyway).

    A ``poses_bounds.npy`` beside a COLMAP model is taken as made from it (LLFF's layout): the model is used.

    Raises:
        InputError: the capture has more than one of them.
    """
    found = [capture_dir / f for f in KNOWN_CAMERA_FILES if (capture_dir / f).is_file()]
    models = [capture_dir / m for m in KNOWN_COLMAP_MODELS if (capture_dir / m).is_dir()]
    if known_poses == "ignore" or not found + models:
        return None
    if models and capture_dir / POSES_BOUNDS in found:
        # LLFF's imgs2poses writes poses_bounds.npy from the sparse/0 beside it (every LLFF dataset ships both):
        # one source, and the model is the richer copy (lens model, 3D points)
        log.info("%s beside %s: the COLMAP model it was made from is used", POSES_BOUNDS,
                 models[0].relative_to(capture_dir))
        found.remove(capture_dir / POSES_BOUNDS)
    found += models
    if len(found) > 1:
        raise InputError(
            f"the capture has {' and '.join(str(p.relative_to(capture_dir)) for p in found)}: which cameras are "
            "right is ambiguous",
            capture_dir, fix="remove all but one of them (or set poses.known_poses=ignore to run SfM instead)",
        )
    return found[0]


def known_cameras(path: Path, names: list[str], width: int, height: int) -> tuple[Posed,
                                                                                   pycolmap.Reconstruction | None]:
    """The cameras of a known-cameras file or COLMAP model folder (:func:`find_known_cameras`) matched to the
    decoded photos, and the model restricted to them (None for a file)."""
    if path.is_dir():
        return posed_from_colmap(path, names, width, height)
    return posed_from_file(path, names, width, height), None


def posed_from_colmap(folder: Path, names: list[str], width: int, height: int) -> tuple[Posed,
                                                                                          pycolmap.Reconstruction]:
    """A COLMAP model's registered images matched to the decoded photos by name (the image name's stem, its
    folder and extension dropped), restricted to them and scaled to the decoded size; the photos' cameras
    (lens models as the model has them, its reliable 3D points) and the model.

    Raises:
        InputError: the model is unreadable, fewer than 2 photos have an image in it, or its cameras have
            another aspect ratio than the photos.
    """
    rec = read_model(folder, fix="give the COLMAP model's cameras, images and points3D (.bin or .txt) there, or "
                     "remove the folder (or set poses.known_poses=ignore) to run SfM")
    images = {stem_of(im.name): im for im in rec.images.values() if im.has_pose}
    matched, no_camera, unused = _matched(folder, names, sorted(images), "COLMAP model")
    without_dropped(rec, matched)
    for n in matched:
        cam = rec.cameras[images[n].camera_id]
        _check_aspect(folder, n, cam.width, cam.height, width, height)
    rescale(rec, width, height)
    stats = {"known_cameras": str(folder), "photos_without_camera": no_camera, "cameras_without_photo": unused}
    return posed_from_reconstruction(rec, names, stats), rec


def posed_from_file(path: Path, names: list[str], width: int, height: int) -> Posed:
    """Known cameras matched to the decoded photos by name, intrinsics scaled to the decoded size.

    Args:
        names: the decoded photos' names in the sorted order of their file names (decode's order), which is
            the order of an LLFF file's rows when no ``all_image_names.txt`` names them.
    """
    pycolmap = import_pycolmap()

    if path.name == TRANSFORMS_JSON:
        known = load_transforms(path)
        cams, distortion = known.cameras.by_name(), known.distortion
    elif path.name == POSES_BOUNDS:
        cams, distortion = load_poses_bounds(path, names).cameras.by_name(), {}
    else:
        cams, distortion = load_cameras(path).by_name(), {}
    matched, no_camera, unused = _matched(path, names, sorted(cams), "file")
    lens = []
    for n in matched:
        c = cams[n]
        sx, sy = _check_aspect(path, n, c.width, c.height, width, height)
        fx, fy, cx, cy = c.fx * sx, c.fy * sy, c.cx * sx, c.cy * sy
        d = distortion.get(n, {})
        if not d:
            lens.append(pycolmap.Camera(model="PINHOLE", width=width, height=height, params=[fx, fy, cx, cy]))
        elif set(d) <= {"k1", "k2", "p1", "p2"}:
            lens.append(pycolmap.Camera(model="OPENCV", width=width, height=height, params=[
                fx, fy, cx, cy, d.get("k1", 0.0), d.get("k2", 0.0), d.get("p1", 0.0), d.get("p2", 0.0)]))
        else:
            lens.append(pycolmap.Camera(model="FULL_OPENCV", width=width, height=height, params=[
                fx, fy, cx, cy, d.get("k1", 0.0), d.get("k2", 0.0), d.get("p1", 0.0), d.get("p2", 0.0),
                d.get("k3", 0.0), d.get("k4", 0.0), 0.0, 0.0]))
    c2w = np.stack([cams[n].c2w for n in matched])
    stats = {"known_cameras": str(path), "photos_without_camera": no_camera, "cameras_without_photo": unused}
    return Posed(matched, c2w, lens, None, None, stats)


def _matched(path: Path, names: list[str], known: list[str], what: str) -> tuple[list[str], list[str], list[str]]:
    """The photos with a known camera (in ``names``' order), those without (left out, a warning) and the known
    cameras of no photo (a warning).

    Raises:
        InputError: fewer than 2 photos have a camera.
    """
    has_camera = set(known)
    matched = [n for n in names if n in has_camera]
    no_camera = [n for n in names if n not in has_camera]
    unused = sorted(has_camera - set(names))
    if len(matched) < 2:
        raise InputError(
            f"only {len(matched)} of the {len(names)} photos have a camera in this {what} (cameras are matched to "
            f"photos by file name without extension or folder; its names {', '.join(known[:5])}, the photos "
            f"{', '.join(names[:5])})", path,
            fix="name the cameras after the photos (IMG_0001 for IMG_0001.dng), or remove it to run SfM",
        )
    if no_camera:
        log.warning("%s: %d photo(s) have no camera and are left out: %s", path, len(no_camera), ", ".join(no_camera))
    if unused:
        log.warning("%s: %d camera(s) match no photo: %s", path, len(unused), ", ".join(unused[:10]))
    return matched, no_camera, unused


def _check_aspect(path: Path, name: str, known_width: int, known_height: int, width: int,
                  height: int) -> tuple[float, float]:
    """The scale factors (x, y) from a known camera's image size to the decoded photo's.

    Raises:
        InputError: they differ (another aspect ratio).
    """
    sx, sy = width / known_width, height / known_height
    if abs(sx / sy - 1) > ASPECT_TOLERANCE:
        raise InputError(f"camera {name} is {known_width}x{known_height} but the decoded photo is {width}x{height} "
                         "(a different aspect ratio: rotated or cropped?)", path)
    return sx, sy
