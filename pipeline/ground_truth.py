"""A synthetic capture's ``ground_truth/`` folder (written by ``orca synth``), read view by view at the size a
model renders it: radiance in decoded units (the units the model was trained in), reduced over k x k blocks
by :mod:`pipeline.downscale`.

The folder holds ``cameras.json``, ``scene.json`` (the radiance-to-decoded factor, the object's centre,
radius and mesh, the props, the optics blur), per object view ``linear/``, ``diffuse/``, ``specular/``,
``normals/``, ``depth/`` (EXR), ``masks/`` and ``coverage/`` (PNG), ``object.ply``, and ``environment/``
(``cameras.json``, ``rgb/``, ``depth/``: virtual cameras near the object centre, the object removed).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .cameras import Camera, CameraSet, load_cameras, scaled_intrinsics
from .downscale import block_all, block_mean, downscale_depth, downscale_mask, downscale_normals
from .errors import InputError
from .imageio import read_exr, read_image
from .layout import CAMERAS_JSON, GROUND_TRUTH, SCENE_JSON
from .props import Prop, points_from_depth, points_in_props
from .results import read_stage_json
from .synth.render import interior_mask

FALLBACK_ERODE_PX = 2  # the object region without coverage/: the mask eroded by this many pixels


@dataclass(frozen=True)
class GroundTruth:
    """A synthetic capture's ``ground_truth/`` folder."""

    folder: Path

    def path(self, *parts: str, required: bool = True, fix: str | None = None) -> Path:
        p = self.folder.joinpath(*parts)
        if required and not p.exists():
            raise InputError("missing ground-truth file", p, fix or "regenerate the capture with `orca synth`")
        return p

    @cached_property
    def cameras(self) -> CameraSet:
        return load_cameras(self.path(CAMERAS_JSON))

    @cached_property
    def scene(self) -> dict[str, Any]:
        return read_stage_json(self.path(SCENE_JSON), "synth")

    @property
    def factor(self) -> float:
        """Decoded-image units per ground-truth radiance unit."""
        try:
            return float(self.scene["radiance_to_decoded"]["factor"])
        except (KeyError, TypeError, ValueError) as e:
            raise InputError("scene.json has no radiance_to_decoded.factor", self.folder / SCENE_JSON,
                             "regenerate the capture with a current `orca synth`") from e

    @cached_property
    def props(self) -> list[Prop]:
        try:
            return [Prop.from_json(p) for p in self.scene.get("props", [])]
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"bad props entry: {e}", self.folder / SCENE_JSON) from e

    @property
    def object_centre(self) -> np.ndarray | None:
        centre = self.scene.get("object", {}).get("centre") if self.scene_path.is_file() else None
        return np.asarray(centre, np.float64) if centre is not None else None

    @property
    def object_radius(self) -> float:
        radius = self.scene.get("object", {}).get("radius") if self.scene_path.is_file() else None
        return float(radius) if radius is not None else 1.0

    @property
    def scene_path(self) -> Path:
        return self.folder / SCENE_JSON

    def object_mesh(self) -> Path:
        name = self.scene.get("object", {}).get("mesh", "object.ply") if self.scene_path.is_file() else "object.ply"
        return self.path(name, fix="the ground truth has no object mesh: drop --mesh, or regenerate the capture "
                                   "with `orca synth`")

    @property
    def optics_blur_px(self) -> float:
        return float(self.scene.get("ground_truth", {}).get("optics_blur_px", 0.0))

    @property
    def has_environment(self) -> bool:
        return (self.folder / "environment" / CAMERAS_JSON).is_file()

    @cached_property
    def environment_cameras(self) -> CameraSet:
        return load_cameras(self.path("environment", CAMERAS_JSON,
                                      fix="pass --no-environment, or regenerate the capture with `orca synth`"))

    def exr(self, *parts: str) -> np.ndarray:
        return read_exr(self.path(*parts))

    def mask(self, name: str) -> np.ndarray:
        m = read_image(self.path("masks", f"{name}.png"))
        m = m[..., 0] if m.ndim == 3 else m
        return m > (np.iinfo(m.dtype).max // 2 if m.dtype.kind == "u" else 0.5)

    def region(self, name: str, mask: np.ndarray) -> tuple[np.ndarray, str]:
        """The object pixels where radiance is compared, and how they were chosen: the interior, where
        diffuse + specular = linear holds (coverage 255 eroded by the optics blur's 3-sigma radius; silhouette
        pixels mix object and room), else the mask eroded by :data:`FALLBACK_ERODE_PX`."""
        cov_path = self.folder / "coverage" / f"{name}.png"
        if cov_path.is_file():
            cov = read_image(cov_path)
            cov = (cov[..., 0] if cov.ndim == 3 else cov).astype(np.float32) / np.iinfo(cov.dtype).max
            return interior_mask(cov, self.optics_blur_px) & mask, \
                f"interior: coverage 255 eroded by 3 x optics blur sigma ({self.optics_blur_px} px)"
        import cv2

        size = 2 * FALLBACK_ERODE_PX + 1
        eroded = cv2.erode(mask.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
        return eroded, f"mask eroded by {FALLBACK_ERODE_PX} px (no coverage/ in the ground truth)"

    def object_view(self, cam: Camera, k: int = 1) -> tuple[dict[str, np.ndarray], str]:
        """One object view at ``(H // k, W // k)``: ``rgb``, ``diffuse``, ``specular`` ``(h, w, 3)`` (decoded
        units), ``normal`` ``(h, w, 3)``, ``depth``, ``mask`` and ``region`` ``(h, w)``; and how the region was
        chosen (:meth:`region`, kept only where the whole block is region)."""
        n, f = cam.name, self.factor
        linear = self.exr("linear", f"{n}.exr")
        _check_size(linear, cam, self.folder / "linear" / f"{n}.exr")
        mask = self.mask(n)
        region, how = self.region(n, mask)
        return {
            "rgb": block_mean(linear[..., :3] * f, k),
            "diffuse": block_mean(self.exr("diffuse", f"{n}.exr")[..., :3] * f, k),
            "specular": block_mean(self.exr("specular", f"{n}.exr")[..., :3] * f, k),
            "normal": downscale_normals(self.exr("normals", f"{n}.exr")[..., :3], k),
            "depth": downscale_depth(self.exr("depth", f"{n}.exr"), k),
            "mask": downscale_mask(mask, k),
            "region": block_all(region, k),
        }, how

    def environment_view(self, cam: Camera, k: int = 1) -> dict[str, np.ndarray]:
        """One environment view at ``(H // k, W // k)``: ``rgb`` ``(h, w, 3)`` (decoded units), ``depth`` and
        ``props`` ``(h, w)``: the pixels whose 3-D point lies on a prop (:func:`pipeline.props.points_in_props`)."""
        rgb = self.exr("environment", "rgb", f"{cam.name}.exr")
        _check_size(rgb, cam, self.folder / "environment" / "rgb" / f"{cam.name}.exr")
        depth = downscale_depth(self.exr("environment", "depth", f"{cam.name}.exr"), k)
        return {"rgb": block_mean(rgb[..., :3] * self.factor, k), "depth": depth,
                "props": points_in_props(points_from_depth(depth, scaled_intrinsics(cam.K, k), cam.c2w), self.props)}


def _check_size(image: np.ndarray, cam: Camera, path: Path) -> None:
    if image.shape[:2] != (cam.height, cam.width):
        raise InputError(f"image is {image.shape[1]}x{image.shape[0]} but camera {cam.name} is "
                         f"{cam.width}x{cam.height}", path, "regenerate the capture with `orca synth`")


def resolve_ground_truth(path: Path) -> GroundTruth:
    """A ``ground_truth/`` folder, or a capture folder holding one."""
    path = Path(path)
    if not (path / CAMERAS_JSON).is_file() and (path / GROUND_TRUTH / CAMERAS_JSON).is_file():
        path = path / GROUND_TRUTH
    if not path.is_dir():
        raise InputError("ground-truth folder not found", path, "pass a synthetic capture's ground_truth/ folder")
    if not (path / CAMERAS_JSON).is_file():
        raise InputError("not a ground-truth folder (no cameras.json)", path,
                         "pass the ground_truth/ folder of a capture made by `orca synth`")
    return GroundTruth(path)
