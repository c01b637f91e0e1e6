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

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .artifacts import MANIFEST, read_json
from .errors import InputError
from .imageio import read_exr, read_image

DECODE_JSON = "decode.json"
IMAGE_FILES = ("linear", "srgb", "clipped")  # decode.json's per-image file entries


def read_stage_json(path: str | Path, stage: str | None = None) -> Any:
    """A JSON file a stage wrote. Missing or damaged (an interrupted copy, an edit gone wrong), it is an
    :class:`InputError` naming the file and the stage to rerun (:func:`rerun_fix`), not a traceback."""
    path = Path(path)
    try:
        return read_json(path)
    except FileNotFoundError as e:
        raise InputError("file not found", path, rerun_fix(path, stage)) from e
    except (OSError, ValueError) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise InputError(f"not valid JSON ({e})", path, rerun_fix(path, stage)) from e


def rerun_fix(path: Path, stage: str | None = None) -> str:
    """What to do about a damaged stage output: rerun the stage the manifest beside it names (or the one of
    the folder above: poses/undistorted/ is the poses stage's), else ``stage``. A file no stage wrote (a
    capture's own cameras.json) is the user's to correct."""
    stage = _writer(path) or stage
    if stage is None:
        return "correct the file"
    return f"rerun `orca {stage}` (or snakemake --forcerun {stage})"


def _writer(path: Path) -> str | None:
    for folder in (path.parent, path.parent.parent):
        try:
            return str(read_json(folder / MANIFEST)["stage"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None


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
        return read_stage_json(self.folder / DECODE_JSON, "decode")

    @cached_property
    def manifest(self) -> dict[str, Any]:
        return read_stage_json(self.folder / MANIFEST, "decode")

    @property
    def names(self) -> list[str]:
        return [im["name"] for im in self.meta["images"]]

    def _entry(self, name: str) -> dict[str, Any]:
        for im in self.meta["images"]:
            if im["name"] == name:
                return im
        raise KeyError(f"{name!r} is not in {self.folder / DECODE_JSON}; known: {', '.join(self.names)}")

    def _image(self, name: str, kind: str, reader: Any) -> np.ndarray:
        return _read_image_file(self.folder / self._entry(name)[kind], reader, self.folder / DECODE_JSON, "decode")

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
    meta, fix = decoded.meta, rerun_fix(path, "decode")
    images = meta.get("images") if isinstance(meta, dict) else None
    entries_ok = isinstance(images, list) and all(
        isinstance(im, dict) and all(isinstance(im.get(k), str) for k in ("name", *IMAGE_FILES)) for im in images)
    if not entries_ok or "size" not in meta:
        raise InputError("decode.json lacks the image list or size (every image needs its name, linear, srgb and "
                         "clipped files)", path, fix)
    missing = [im[k] for im in images for k in IMAGE_FILES if not (folder / im[k]).is_file()]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise InputError(f"{len(missing)} of the image files decode.json lists are missing: {shown}", folder, fix)
    return decoded


@dataclass(frozen=True)
class PosesArtifacts:
    """The poses stage's folder: ``cameras.json`` (normalized frame), ``poses_report.json``, ``sparse/``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / "poses_report.json", "poses")

    def cameras(self):
        """:class:`~pipeline.cameras.CameraSet` in the object-centred unit-sphere frame."""
        from .cameras import load_cameras

        return load_cameras(self.folder / "cameras.json")

    def reconstruction(self):
        """The COLMAP model (``pycolmap.Reconstruction``, COLMAP's frame); None for known cameras."""
        if not (self.folder / "sparse").is_dir():
            return None
        from .signals import import_pycolmap

        return import_pycolmap().Reconstruction(self.folder / "sparse")


def load_poses(folder: str | Path) -> PosesArtifacts:
    folder = Path(folder)
    if not (folder / "cameras.json").is_file():
        raise InputError("not a poses artifact (no cameras.json)", folder, "run `orca poses` on the capture first")
    return PosesArtifacts(folder)


@dataclass(frozen=True)
class MasksArtifacts:
    """The masks stage's folder: ``masks/<name>.png``, ``cameras.json`` (the object's tight sphere is the unit
    sphere), ``masks_report.json``, ``overlays/``, ``contact_sheet.jpg``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / "masks_report.json", "masks")

    @property
    def names(self) -> list[str]:
        return [v["name"] for v in self.report["views"]]

    def mask(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True on the object."""
        path = self.folder / "masks" / f"{name}.png"
        if not path.is_file():
            raise KeyError(f"no mask {name!r} in {self.folder}; known: {', '.join(self.names[:10])}")
        return _read_image_file(path, read_image, self.folder / "masks_report.json", "masks") > 127

    def cameras(self):
        """:class:`~pipeline.cameras.CameraSet` re-normalized to the object's tight sphere (see the report)."""
        from .cameras import load_cameras

        return load_cameras(self.folder / "cameras.json")


def load_masks(folder: str | Path) -> MasksArtifacts:
    folder = Path(folder)
    if not (folder / "masks_report.json").is_file():
        raise InputError("not a masks artifact (no masks_report.json)", folder, "run `orca masks` on the capture first")
    return MasksArtifacts(folder)
