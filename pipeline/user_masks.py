"""A user's object masks (``CAPTURE/masks/`` or ``--user-masks``): one image per photo, named like the photo
(``IMG_0001.png`` for ``IMG_0001.dng``), white (non-zero) = object, in any encoding :mod:`pipeline.mask_file`
reads. Files whose name matches no photo, two files for one photo, and (nearly) empty masks are refused with
the files named; masks of photos SfM did not register are skipped. Drawn on the photos, they follow the poses
stage's undistortion into the pixel grid training reads.
"""

from __future__ import annotations

import logging
from collections.abc import Collection
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .mask_file import read_mask
from .undistort import UndistortMaps, undistort_mask

log = logging.getLogger("orca.masks")

MASK_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".webp")


def find_user_masks(folder: Path, names: list[str], no_camera: Collection[str] = ()) -> dict[str, Path]:
    """``name -> file`` for the mask images in ``folder`` (see the module doc); every file must match a photo.

    Args:
        names: the photos with a camera.
        no_camera: photos that exist but got no camera (SfM did not register them): their masks are skipped
            with a log line, as the photos are.

    Raises:
        InputError: a file that matches no photo (listing them and a few photo names), two files for one photo.
    """
    if not folder.is_dir():
        raise InputError("user masks folder not found", folder, fix="pass a folder of <photo name>.png masks")
    known, dropped = set(names), set(no_camera)
    photos = known | dropped
    found: dict[str, Path] = {}
    unmatched: list[str] = []
    skipped: list[str] = []
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or not path.is_file():
            continue
        if path.suffix.lower() not in MASK_SUFFIXES:
            log.warning("%s: not a mask image (%s); skipped", path, ", ".join(MASK_SUFFIXES))
            continue
        stem = path.stem
        if stem not in photos and Path(stem).stem in photos:  # IMG_0001.jpg.png (COLMAP's naming)
            stem = Path(stem).stem
        if stem in dropped:
            skipped.append(path.name)
            continue
        if stem not in known:
            unmatched.append(path.name)
            continue
        if stem in found:
            raise InputError(f"two masks for photo {stem}: {found[stem].name} and {path.name}", folder,
                             fix="keep one of them")
        found[stem] = path
    if unmatched:
        sample = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
        raise InputError(
            f"{len(unmatched)} mask file(s) match no photo: {', '.join(unmatched[:10])}"
            + (" ..." if len(unmatched) > 10 else "") + f" (photos: {sample})",
            folder, fix="name each mask like its photo (IMG_0001.png for IMG_0001.dng), or remove the extra files",
        )
    if skipped:
        log.info("%d user mask(s) skipped: their photos have no camera (the poses stage did not register them): %s",
                 len(skipped), ", ".join(skipped[:10]) + (" ..." if len(skipped) > 10 else ""))
    return found


def user_mask(path: Path, cam: Any, undistortion: UndistortMaps | None) -> np.ndarray:
    """A user's mask for camera ``cam``, in the pixel grid of the images the cameras point at: resampled
    like the photo when the poses stage undistorted it."""
    m = read_mask(path, (cam.width, cam.height))
    return undistort_mask(m, undistortion, cam.name) if undistortion is not None else m


def refuse_empty(areas: dict[str, float], files: dict[str, Path], min_fraction: float) -> None:
    """Stop on user masks with (almost) no object, naming the files: one empty view carves the object out of the
    visual hull (the object sphere then falls back to the poses stage's loose one), and a set of empty masks has
    no object at all. ``areas``: each user-masked view's object fraction of its image.

    Raises:
        InputError: every user mask is empty; some cover less than ``min_fraction``.
    """
    def listing(views: list[str]) -> str:
        return ", ".join(files[n].name for n in views[:10]) + (" ..." if len(views) > 10 else "")

    folder = next(iter(files.values())).parent if files else None
    if areas and not any(areas.values()):
        raise InputError(f"every user mask is empty (no object pixel): {listing(list(areas))}", folder,
                         fix="draw the object white (non-zero) on black, or remove the folder for automatic masks")
    small = [n for n, a in areas.items() if a < min_fraction]
    if small:
        raise InputError(
            f"{len(small)} user mask(s) empty or nearly (object under {min_fraction:g} of the image): "
            f"{listing(small)}", folder,
            fix="draw the object white on them, or delete those files (their views then get automatic masks); if "
            "the object is really out of those photos, set masks.user_mask_min_fraction=0",
        )
