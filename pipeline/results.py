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


@dataclass(frozen=True)
class DecodeArtifacts:
    """The decode stage's folder: ``decode.json`` plus per-image linear EXR, sRGB PNG and clipped mask."""

    folder: Path

    @cached_property
    def meta(self) -> dict[str, Any]:
        return read_json(self.folder / "decode.json")

    @cached_property
    def manifest(self) -> dict[str, Any]:
        return read_json(self.folder / MANIFEST)

    @property
    def names(self) -> list[str]:
        return [im["name"] for im in self.meta["images"]]

    def _entry(self, name: str) -> dict[str, Any]:
        for im in self.meta["images"]:
            if im["name"] == name:
                return im
        raise KeyError(f"{name!r} is not in {self.folder / 'decode.json'}; known: {', '.join(self.names)}")

    def linear(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` float32 linear, exposure-normalized radiance."""
        return read_exr(self.folder / self._entry(name)["linear"])

    def srgb(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` uint8 sRGB."""
        return read_image(self.folder / self._entry(name)["srgb"])

    def clipped(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True where a highlight clipped."""
        return read_image(self.folder / self._entry(name)["clipped"]) > 127


def load_decode(folder: str | Path) -> DecodeArtifacts:
    folder = Path(folder)
    if not (folder / "decode.json").is_file():
        raise InputError("not a decode artifact (no decode.json)", folder, "run `orca decode` on the capture first")
    return DecodeArtifacts(folder)


@dataclass(frozen=True)
class PosesArtifacts:
    """The poses stage's folder: ``cameras.json`` (normalized frame), ``poses_report.json``, ``sparse/``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_json(self.folder / "poses_report.json")

    def cameras(self):
        """:class:`~pipeline.cameras.CameraSet` in the object-centred unit-sphere frame."""
        from .cameras import load_cameras

        return load_cameras(self.folder / "cameras.json")

    def reconstruction(self):
        """The COLMAP model (``pycolmap.Reconstruction``, COLMAP's frame); None for known cameras."""
        if not (self.folder / "sparse").is_dir():
            return None
        import pycolmap

        return pycolmap.Reconstruction(self.folder / "sparse")


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
        return read_json(self.folder / "masks_report.json")

    @property
    def names(self) -> list[str]:
        return [v["name"] for v in self.report["views"]]

    def mask(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True on the object."""
        path = self.folder / "masks" / f"{name}.png"
        if not path.is_file():
            raise KeyError(f"no mask {name!r} in {self.folder}; known: {', '.join(self.names[:10])}")
        return read_image(path) > 127

    def cameras(self):
        """:class:`~pipeline.cameras.CameraSet` re-normalized to the object's tight sphere (see the report)."""
        from .cameras import load_cameras

        return load_cameras(self.folder / "cameras.json")


def load_masks(folder: str | Path) -> MasksArtifacts:
    folder = Path(folder)
    if not (folder / "masks_report.json").is_file():
        raise InputError("not a masks artifact (no masks_report.json)", folder, "run `orca masks` on the capture first")
    return MasksArtifacts(folder)
