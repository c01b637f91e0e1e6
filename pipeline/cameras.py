"""``cameras.json``: the one camera file every stage reads (schema in DESIGN.md).

OpenCV convention (x right, y down, z forward), camera-to-world 4x4, pinhole intrinsics; pixel (0, 0) is
the top-left corner of the image, so the centre of the top-left pixel is (0.5, 0.5).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .artifacts import read_stage_json, rerun_fix, write_json
from .errors import InputError, validation_problem

Matrix4 = list[list[float]]


def as_matrix4(m: Any, name: str | None = None) -> np.ndarray:
    """``m`` (4 lists of 4 numbers) as a ``(4, 4)`` float64 array; a ValueError says what is wrong with it
    (its shape, a value that is not a number, NaN or infinity), prefixed by ``name`` when given."""
    prefix = f"{name}: " if name else ""
    rows = [len(r) if isinstance(r, (list, tuple)) else None for r in m] if isinstance(m, (list, tuple)) else None
    if rows is None or rows != [4, 4, 4, 4]:
        raise ValueError(f"{prefix}expected a 4x4 matrix (4 rows of 4 numbers), got {_rows(m, rows)}")
    try:
        a = np.asarray(m, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{prefix}expected numbers, got {m!r:.80}") from e
    bad = np.argwhere(~np.isfinite(a))
    if len(bad):
        r, c = bad[0]
        raise ValueError(f"{prefix}expected finite numbers, got {a[r, c]} in row {r + 1}, column {c + 1}")
    return a


def _rows(m: Any, rows: list[int | None] | None) -> str:
    if rows is None:
        return f"{type(m).__name__} {m!r:.40}"
    if any(n is None for n in rows):
        return f"a list of {len(rows)} values, not of rows"
    lengths = sorted(set(rows))
    return f"{len(rows)} row{'s' if len(rows) != 1 else ''} of {'/'.join(map(str, lengths))} numbers"


def _check_4x4(m: Matrix4 | None, *, rigid: bool) -> Matrix4 | None:
    if m is None:
        return None
    a = as_matrix4(m)
    if not np.allclose(a[3], [0, 0, 0, 1], atol=1e-9):
        raise ValueError("last row of a 4x4 transform must be [0, 0, 0, 1]")
    r = a[:3, :3]
    scale = np.cbrt(np.linalg.det(r))
    if scale <= 0:
        raise ValueError("transform is a reflection or degenerate (det <= 0)")
    tol = 1e-4
    if not np.allclose(r.T @ r, scale**2 * np.eye(3), atol=tol * max(1.0, scale**2)):
        raise ValueError("rotation part is not orthogonal")
    if rigid and abs(scale - 1) > tol:
        raise ValueError(f"camera_to_world must be rigid (scale 1), got scale {scale:.6f}")
    return a.tolist()


class Camera(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str
    image: str | None = None
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    fx: float = Field(gt=0)
    fy: float = Field(gt=0)
    cx: float
    cy: float
    camera_to_world: Matrix4

    @field_validator("camera_to_world")
    @classmethod
    def _rigid(cls, v: Matrix4) -> Matrix4:
        return _check_4x4(v, rigid=True)

    @property
    def K(self) -> np.ndarray:
        """``(3, 3)`` intrinsic matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    @property
    def c2w(self) -> np.ndarray:
        """``(4, 4)`` camera-to-world matrix."""
        return np.asarray(self.camera_to_world, dtype=np.float64)

    @property
    def center(self) -> np.ndarray:
        """``(3,)`` camera centre in world coordinates."""
        return self.c2w[:3, 3].copy()


class Frame(BaseModel):
    model_config = ConfigDict(extra="forbid")

    convention: str = "opencv"
    to_colmap: Matrix4 | None = None

    @field_validator("convention")
    @classmethod
    def _opencv(cls, v: str) -> str:
        if v != "opencv":
            raise ValueError(f"only the 'opencv' convention is supported, got {v!r}")
        return v

    @field_validator("to_colmap")
    @classmethod
    def _similarity(cls, v: Matrix4 | None) -> Matrix4 | None:
        return _check_4x4(v, rigid=False)


class CameraSet(BaseModel):
    model_config = ConfigDict(extra="forbid")

    frame: Frame = Field(default_factory=Frame)
    cameras: list[Camera]

    def __len__(self) -> int:
        return len(self.cameras)

    def by_name(self) -> dict[str, Camera]:
        return {c.name: c for c in self.cameras}

    def K(self) -> np.ndarray:
        """``(N, 3, 3)`` intrinsics."""
        return np.stack([c.K for c in self.cameras])

    def c2w(self) -> np.ndarray:
        """``(N, 4, 4)`` camera-to-world matrices."""
        return np.stack([c.c2w for c in self.cameras])


def load_cameras(path: str | Path) -> CameraSet:
    """Read and validate a ``cameras.json``; errors name the file, each problem and the stage to rerun."""
    path = Path(path)
    if not path.is_file():
        raise InputError("camera file not found", path, "run the poses stage or pass an existing cameras.json")
    doc = read_stage_json(path)
    try:
        return CameraSet.model_validate(doc)
    except ValidationError as e:
        lines = camera_problems(e, doc)
        message = f"invalid camera file: {lines[0]}" if len(lines) == 1 else "invalid camera file:\n" + "\n".join(
            f"  {line}" for line in lines)
        raise InputError(message, path, rerun_fix(path)) from e


def camera_problems(error: ValidationError, doc: Any = None) -> list[str]:
    """One line per problem of a camera file, each naming its camera. A problem many cameras share (a key the
    file's writer never wrote) is one line saying which cameras, not one per camera."""
    grouped: dict[tuple[str, str], list[str]] = {}
    for item in error.errors():
        loc = item["loc"]
        if len(loc) > 1 and loc[0] == "cameras" and isinstance(loc[1], int):
            key, camera = ".".join(map(str, loc[2:])) or "the entry", _camera_label(doc, loc[1])
        else:
            key, camera = ".".join(map(str, loc)) or "the file", ""
        grouped.setdefault((key, validation_problem(item)), []).append(camera)
    lines = []
    for (key, what), cameras in grouped.items():
        named = [c for c in cameras if c]
        if len(named) == 1:
            lines.append(f"camera {named[0]}: {key}: {what}")
        elif named:
            shown = ", ".join(named[:5]) + (", ..." if len(named) > 5 else "")
            lines.append(f"{len(named)} cameras ({shown}): {key}: {what}")
        else:
            lines.append(f"{key}: {what}")
    return lines


def _camera_label(doc: Any, index: int) -> str:
    """The camera's name where the file gives one, else its index in the list ([0] first)."""
    try:
        name = doc["cameras"][index]["name"]
    except (KeyError, IndexError, TypeError):
        name = None
    return str(name) if isinstance(name, str) and name else f"[{index}]"


def save_cameras(path: str | Path, cameras: CameraSet) -> Path:
    return write_json(path, cameras.model_dump(mode="json"))


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """``(4, 4)`` OpenCV camera-to-world looking from ``eye`` at ``target`` (image up ~ ``up``, default +z)."""
    if up is None:
        up = np.array([0.0, 0.0, 1.0])
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking along `up`: any perpendicular will do
        x = np.cross(z, np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, eye
    return m


def scaled_intrinsics(K: np.ndarray, k: int) -> np.ndarray:
    """Intrinsics of an image rendered k times smaller (pixel (0, 0) stays the top-left corner)."""
    K = np.array(K, np.float64)
    K[:2] /= k
    return K


def intrinsics_from_fov(width: int, height: int, fov_x_deg: float) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of a centred pinhole with horizontal field of view ``fov_x_deg``, square pixels."""
    fx = 0.5 * width / np.tan(np.deg2rad(fov_x_deg) / 2)
    return float(fx), float(fx), width / 2.0, height / 2.0


def select_views(names: Sequence[str], views: int | Sequence[str] | None) -> list[str]:
    """``None``: every view; an int N: N evenly spaced views (first and last included); names: those."""
    names = list(names)
    if views is None:
        return names
    if isinstance(views, int):
        if views < 1:
            raise InputError(f"--views must be at least 1, got {views}")
        if views >= len(names):
            return names
        idx = np.round(np.linspace(0, len(names) - 1, views)).astype(int)
        return [names[i] for i in dict.fromkeys(idx.tolist())]
    unknown = [v for v in views if v not in names]
    if unknown:
        raise InputError(f"unknown view(s) {', '.join(unknown)}; the ground truth has {', '.join(names[:8])}"
                         + (" ..." if len(names) > 8 else ""))
    return list(views)
