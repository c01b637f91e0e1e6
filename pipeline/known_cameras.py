"""Known cameras instead of SfM: a capture's own ``cameras.json`` (our schema), ``transforms.json``
(nerfstudio/instant-ngp, OpenGL axes) or ``poses_bounds.npy`` (LLFF, :mod:`pipeline.llff`), from a turntable,
a phone's AR session or another SfM run. Cameras are matched to photos by file stem (LLFF's rows by
``all_image_names.txt``, or by the photos' sorted order); their intrinsics are scaled to the decoded size, and
a transforms.json's distortion becomes the lens model (OPENCV, or FULL_OPENCV with k3/k4) that undistortion
then removes.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .cameras import load_cameras
from .errors import InputError
from .layout import CAMERAS_JSON, POSES_BOUNDS, TRANSFORMS_JSON
from .llff import load_poses_bounds
from .object_frame import Posed
from .signals import import_pycolmap
from .transforms import load_transforms

log = logging.getLogger("orca.poses")

KNOWN_CAMERA_FILES = (CAMERAS_JSON, TRANSFORMS_JSON, POSES_BOUNDS)


def find_known_cameras(capture_dir: Path, known_poses: str) -> Path | None:
    """The capture's known-cameras file, or None (none, or ``known_poses="ignore"``: SfM runs anyway).

    Raises:
        InputError: the capture has more than one of the files.
    """
    found = [capture_dir / f for f in KNOWN_CAMERA_FILES if (capture_dir / f).is_file()]
    if known_poses == "ignore" or not found:
        return None
    if len(found) > 1:
        raise InputError(
            f"the capture has {' and '.join(p.name for p in found)}: which cameras are right is ambiguous",
            capture_dir, fix="remove all but one of them (or set poses.known_poses=ignore to run SfM instead)",
        )
    return found[0]


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
    matched = [n for n in names if n in cams]
    no_camera = [n for n in names if n not in cams]
    unused = sorted(set(cams) - set(names))
    if len(matched) < 2:
        raise InputError(
            f"only {len(matched)} of the {len(names)} photos have a camera in this file (cameras are matched to "
            f"photos by file name without extension; the file names {', '.join(sorted(cams)[:5])}, the photos "
            f"{', '.join(names[:5])})", path,
            fix="name the cameras after the photos (IMG_0001 for IMG_0001.dng), or remove the file to run SfM",
        )
    if no_camera:
        log.warning("%s: %d photo(s) have no camera and are left out: %s", path, len(no_camera), ", ".join(no_camera))
    if unused:
        log.warning("%s: %d camera(s) match no photo: %s", path, len(unused), ", ".join(unused[:10]))
    lens = []
    for n in matched:
        c = cams[n]
        sx, sy = width / c.width, height / c.height
        if abs(sx / sy - 1) > 0.01:
            raise InputError(f"camera {n} is {c.width}x{c.height} but the decoded photo is {width}x{height} "
                             "(a different aspect ratio: rotated or cropped?)", path)
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
