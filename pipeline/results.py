"""Load a stage's artifacts as Python objects, for notebooks and later stages.

    >>> from pipeline.results import load_decode
    >>> dec = load_decode("results/demo/decode")
    >>> dec.names[:3], dec.linear(dec.names[0]).shape
    >>> from pipeline.results import load_poses
    >>> poses = load_poses("results/demo/poses")
    >>> poses.cameras().c2w().shape, poses.report["registered"]
    >>> from pipeline.results import load_masks
    >>> masks = load_masks("results/demo/masks")
    >>> masks.mask("IMG_0001").mean(), masks.report["agreement"]["median"], masks.report["object_sphere"]
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .artifacts import read_stage_json, rerun_fix
from .cameras import CameraSet, load_cameras
from .colmap_model import model_folder
from .errors import InputError
from .imageio import read_exr, read_image
from .layout import (
    CAMERAS_JSON,
    DECODE,
    DECODE_JSON,
    IMAGE_KINDS,
    MANIFEST,
    MASKS,
    MASKS_REPORT,
    POSES,
    POSES_REPORT,
    SPARSE,
    mask_file,
)
from .signals import import_pycolmap


def _read_image_file(path: Path, reader: Any, written_by: Path, stage: str) -> np.ndarray:
    """``reader(path)``; a missing or damaged image is an InputError saying which stage to rerun."""
    try:
        return reader(path)
    except (OSError, ValueError) as e:
        what = "file not found" if isinstance(e, FileNotFoundError) else "not a readable image"
        raise InputError(what, path, rerun_fix(written_by, stage)) from e


@dataclass(frozen=True)
class DecodeArtifacts:
    """The decode stage's folder: ``decode.json`` plus per-image linear EXR, sRGB PNG and clipped mask."""

    folder: Path

    @cached_property
    def meta(self) -> dict[str, Any]:
        return read_stage_json(self.folder / DECODE_JSON, DECODE)

    @cached_property
    def manifest(self) -> dict[str, Any]:
        return read_stage_json(self.folder / MANIFEST, DECODE)

    @property
    def names(self) -> list[str]:
        return [im["name"] for im in self.meta["images"]]

    def entry(self, name: str) -> dict[str, Any]:
        """decode.json's record of one photo (its linear/srgb/clipped files, EXIF)."""
        for im in self.meta["images"]:
            if im["name"] == name:
                return im
        raise KeyError(f"{name!r} is not in {self.folder / DECODE_JSON}; known: {', '.join(self.names)}")

    def _image(self, name: str, kind: str, reader: Any) -> np.ndarray:
        return _read_image_file(self.folder / self.entry(name)[kind], reader, self.folder / DECODE_JSON, DECODE)

    def linear(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` float32 linear, exposure-normalized radiance."""
        return self._image(name, "linear", read_exr)

    def srgb(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` uint8 sRGB."""
        return self._image(name, "srgb", read_image)

    def clipped(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True where a highlight clipped."""
        return self._image(name, "clipped", read_image) > 127


def load_decode(folder: str | Path) -> DecodeArtifacts:
    """The decode folder, checked whole: a stage given a damaged one stops here, naming what is wrong, rather
    than at the first missing image it reaches (after minutes of work, with a traceback)."""
    folder = Path(folder)
    if not (folder / DECODE_JSON).is_file():
        raise InputError("not a decode artifact (no decode.json)", folder, "run `orca decode` on the capture first")
    decoded = DecodeArtifacts(folder)
    path = folder / DECODE_JSON
    meta, fix = decoded.meta, rerun_fix(path, DECODE)
    images = meta.get("images") if isinstance(meta, dict) else None
    entries_ok = isinstance(images, list) and all(
        isinstance(im, dict) and all(isinstance(im.get(k), str) for k in ("name", *IMAGE_KINDS)) for im in images)
    if not entries_ok or "size" not in meta:
        raise InputError("decode.json lacks the image list or size (every image needs its name, linear, srgb and "
                         "clipped files)", path, fix)
    missing = [im[k] for im in images for k in IMAGE_KINDS if not (folder / im[k]).is_file()]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise InputError(f"{len(missing)} of the image files decode.json lists are missing: {shown}", folder, fix)
    return decoded


@dataclass(frozen=True)
class PosesArtifacts:
    """The poses stage's folder: ``cameras.json`` (normalized frame), ``poses_report.json``, ``sparse/0/`` beside
    ``images/``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / POSES_REPORT, POSES)

    def cameras(self) -> CameraSet:
        """The cameras in the object-centred unit-sphere frame."""
        return load_cameras(self.folder / CAMERAS_JSON)

    def reconstruction(self) -> Any:
        """The COLMAP model (``pycolmap.Reconstruction``, COLMAP's frame; ``sparse/0``, or ``sparse`` as older
        poses stages wrote it); None for known cameras other than a COLMAP model."""
        if not (self.folder / SPARSE).is_dir():
            return None
        return import_pycolmap().Reconstruction(model_folder(self.folder / SPARSE))


def load_poses(folder: str | Path) -> PosesArtifacts:
    folder = Path(folder)
    if not (folder / CAMERAS_JSON).is_file():
        raise InputError("not a poses artifact (no cameras.json)", folder, "run `orca poses` on the capture first")
    return PosesArtifacts(folder)


@dataclass(frozen=True)
class MasksArtifacts:
    """The masks stage's folder: ``masks/<name>.png``, ``cameras.json`` (the object's tight sphere is the unit
    sphere), ``masks_report.json``, ``overlays/``, ``contact_sheet.jpg``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / MASKS_REPORT, MASKS)

    @property
    def names(self) -> list[str]:
        return [v["name"] for v in self.report["views"]]

    def mask(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True on the object."""
        path = self.folder / mask_file(name)
        if not path.is_file():
            raise KeyError(f"no mask {name!r} in {self.folder}; known: {', '.join(self.names[:10])}")
        return _read_image_file(path, read_image, self.folder / MASKS_REPORT, MASKS) > 127

    def cameras(self) -> CameraSet:
        """The cameras re-normalized to the object's tight sphere (see the report)."""
        return load_cameras(self.folder / CAMERAS_JSON)


def load_masks(folder: str | Path) -> MasksArtifacts:
    folder = Path(folder)
    if not (folder / MASKS_REPORT).is_file():
        raise InputError("not a masks artifact (no masks_report.json)", folder, "run `orca masks` on the capture first")
    return MasksArtifacts(folder)


# --------------------------------------------------------------------------------- the images of cameras.json


def image_folder(cameras: CameraSet, folder: Path, fallback: Path | None = None) -> Path:
    """The decode-style folder holding the images the cameras (of a cameras.json in ``folder``) point at
    (``<folder>/linear/<name>.exr``): the decode stage's, or the poses stage's ``undistorted/``. ``fallback``
    (a decode folder) serves cameras without image paths. Every later stage reads its images from here."""
    for cam in cameras.cameras:
        if cam.image:
            found = (folder / cam.image).resolve().parent.parent
            if (found / DECODE_JSON).is_file():
                return found
    if fallback is not None and (fallback / DECODE_JSON).is_file():
        return fallback
    raise InputError("cannot tell which decoded images the cameras belong to", folder / CAMERAS_JSON,
                     fix="pass --decode results/<capture>/decode")


def relocated(cameras: CameraSet, folder: Path, to: Path) -> CameraSet:
    """The cameras of a cameras.json in ``folder`` with image paths relative to ``to`` (where a new one goes)."""
    cams = []
    for c in cameras.cameras:
        image = c.image
        if image:
            image = os.path.relpath((folder / image).resolve(), to.resolve())
        cams.append(c.model_copy(update={"image": image}))
    return cameras.model_copy(update={"cameras": cams})
