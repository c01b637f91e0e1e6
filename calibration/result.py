"""``calibration.json``: the intrinsics a calibration produces, and :func:`load_calibration` to read them.

Pixel convention: the project's (COLMAP's): (0, 0) is the top-left **corner** of the image, the top-left
pixel's centre is (0.5, 0.5). OpenCV's functions put that centre at (0, 0), so

    cx = cx_opencv + 0.5,   cy = cy_opencv + 0.5        (fx, fy and the distortion are the same)

:meth:`Calibration.opencv_camera_matrix` gives the matrix to hand to ``cv2.undistort`` & co.; COLMAP and
pycolmap take ``fx, fy, cx, cy`` as stored. A hand-written file may say ``"pixel_convention": "opencv"``;
the loader then converts, so a :class:`Calibration` is always in the project's convention.

Distortion: OpenCV's Brown-Conrady coefficients in OpenCV's order ``[k1, k2, p1, p2, k3]``. By default
``k3`` is fixed at 0 and the model is COLMAP's ``OPENCV`` (fx, fy, cx, cy, k1, k2, p1, p2); calibrated with
``k3`` it is ``FULL_OPENCV`` (k4..k6 = 0).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.errors import InputError

CALIBRATION_JSON = "calibration.json"
SCHEMA_VERSION = 1
PIXEL_CONVENTION = "colmap"  # top-left pixel centre at (0.5, 0.5)


class Calibration(BaseModel):
    """One camera's intrinsics at ``width`` x ``height``, project pixel convention. Other keys of
    calibration.json (per-image errors, the board, ...) are reports for people and are not loaded."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    model: Literal["OPENCV", "FULL_OPENCV"] = "OPENCV"
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    fx: float = Field(gt=0)
    fy: float = Field(gt=0)
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)  # k1, k2, p1, p2, k3
    rms_reprojection_px: float | None = None
    images_used: int | None = None

    def camera_matrix(self) -> np.ndarray:
        """(3, 3) K in the project's pixel convention."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], np.float64)

    def opencv_camera_matrix(self) -> np.ndarray:
        """(3, 3) K in OpenCV's pixel convention (for cv2.undistort, cv2.projectPoints, ...)."""
        K = self.camera_matrix()
        K[:2, 2] -= 0.5
        return K

    def dist_coeffs(self) -> np.ndarray:
        """(5,) float64 ``[k1, k2, p1, p2, k3]`` for OpenCV."""
        return np.array(self.dist, np.float64)

    def colmap_params(self) -> tuple[str, list[float]]:
        """(COLMAP model name, its parameter list), e.g. for ``pycolmap.Camera(model=..., params=...)``."""
        k1, k2, p1, p2, k3 = self.dist
        base = [self.fx, self.fy, self.cx, self.cy, k1, k2, p1, p2]
        if self.model == "OPENCV":
            return "OPENCV", base
        return "FULL_OPENCV", base + [k3, 0.0, 0.0, 0.0]

    def scaled_to(self, width: int, height: int) -> Calibration:
        """The same camera at another resolution (e.g. photos decoded with ``downscale``).

        Pixel edges scale, so with (0, 0) at the image corner every coordinate scales by the size ratio.
        A different aspect ratio (a rotated or cropped image) is an error, not a guess.
        """
        sx, sy = width / self.width, height / self.height
        if abs(sx / sy - 1) > 0.01:
            raise InputError(
                f"the calibration is for {self.width}x{self.height} images but these are {width}x{height} "
                "(a different aspect ratio: rotated or cropped?)",
                fix="calibrate with photos of the same orientation and aspect ratio as the capture",
            )
        return self.model_copy(
            update={"width": width, "height": height, "fx": self.fx * sx, "fy": self.fy * sy,
                    "cx": self.cx * sx, "cy": self.cy * sy}
        )


def calibration_doc(calibration: Calibration, **report: Any) -> dict[str, Any]:
    """The calibration.json document: the intrinsics first, then ``report`` (per_image, board, ...)."""
    doc: dict[str, Any] = {"schema": SCHEMA_VERSION, **calibration.model_dump(mode="json")}
    doc["pixel_convention"] = PIXEL_CONVENTION
    doc.update(report)
    return doc


def load_calibration(path: str | Path) -> Calibration:
    """Read ``calibration.json`` (or the folder holding it) -> :class:`Calibration`, project pixel convention.

    Raises :class:`~pipeline.errors.InputError` naming the file when it is missing or does not validate.
    """
    path = Path(path)
    if path.is_dir():
        path = path / CALIBRATION_JSON
    if not path.is_file():
        raise InputError("calibration file not found", path, fix="run `orca calibrate PHOTOS --out FOLDER` first")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e}", path, fix="rerun `orca calibrate`") from e
    if not isinstance(doc, dict):
        raise InputError("a calibration file must hold a JSON object", path)
    schema = doc.get("schema", SCHEMA_VERSION)
    if schema != SCHEMA_VERSION:
        raise InputError(f"calibration schema {schema} is not supported (this reader: {SCHEMA_VERSION})", path)
    convention = doc.get("pixel_convention", PIXEL_CONVENTION)
    if convention not in ("colmap", "opencv"):
        raise InputError(f"unknown pixel_convention {convention!r}", path, fix="use 'colmap' or 'opencv'")
    try:
        cal = Calibration.model_validate(doc)
    except ValidationError as e:
        problems = "; ".join(f"{'.'.join(map(str, err['loc']))}: {err['msg']}" for err in e.errors())
        raise InputError(f"invalid calibration: {problems}", path, fix="rerun `orca calibrate`") from e
    if convention == "opencv":
        cal = cal.model_copy(update={"cx": cal.cx + 0.5, "cy": cal.cy + 0.5})
    return cal
