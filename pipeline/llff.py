"""LLFF's ``poses_bounds.npy`` (the NeRF LLFF and real-360 datasets, COLMAP's poses via LLFF's ``imgs2poses``)
<-> :class:`~pipeline.cameras.CameraSet`, for known cameras and interop.

An ``(N, 17)`` array, one row per photo in the sorted order of the photos' file names: a 3x5 matrix
``[R | t | h w f]`` flattened row-major, then the scene's near and far depth bounds (unused here, kept by the
writer). ``[R | t]`` is camera-to-world with the rotation's columns the camera's (down, right, back) axes;
``h, w, f`` are the photos' size and focal length in pixels at the size the poses were made for, the principal
point the image centre. Ours is OpenCV's (x right, y down, z forward): x = LLFF's column 1, y = column 0,
z = minus column 2, so ``R_opencv = R_llff @ LLFF_TO_OPENCV`` (a proper rotation and its own inverse).

The rows carry no names. A dataset that publishes only some of its photos ships ``all_image_names.txt`` (one
file name per line, in the rows' order) naming every row; without it the rows are the capture's photos.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from .artifacts import atomic_path
from .cameras import Camera, CameraSet, camera_problems
from .errors import InputError
from .layout import LLFF_IMAGE_NAMES

LLFF_TO_OPENCV = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
ROW = 17  # 3x5 pose-and-hwf matrix, near, far
CENTRED_RTOL = 1e-9  # the writer's test that a camera is LLFF's (one focal length, centred principal point)


@dataclass(frozen=True)
class PosesBounds:
    """A ``poses_bounds.npy`` read: cameras named after their photos (file stems), at the file's image size,
    and each row's ``(near, far)`` as ``(N, 2)``."""

    cameras: CameraSet
    near_far: np.ndarray


def to_poses_bounds(cameras: CameraSet, near_far: np.ndarray) -> np.ndarray:
    """``(N, 17)`` rows of ``cameras`` (in their order) with their ``(N, 2)`` depth bounds.

    Raises:
        ValueError: a camera LLFF cannot hold (``fx != fy``, or the principal point off the image centre).
    """
    near_far = np.asarray(near_far, dtype=np.float64)
    if near_far.shape != (len(cameras), 2):
        raise ValueError(f"expected ({len(cameras)}, 2) near/far bounds, got {near_far.shape}")
    rows = []
    for c in cameras.cameras:
        centred = np.isclose([c.cx, c.cy], [c.width / 2, c.height / 2], rtol=CENTRED_RTOL, atol=0).all()
        if not (centred and np.isclose(c.fx, c.fy, rtol=CENTRED_RTOL, atol=0)):
            raise ValueError(f"camera {c.name}: LLFF holds one focal length and a centred principal point, got "
                             f"fx {c.fx}, fy {c.fy}, principal point ({c.cx}, {c.cy}) in {c.width}x{c.height}")
        pose = np.concatenate([c.c2w[:3, :3] @ LLFF_TO_OPENCV, c.c2w[:3, 3:],
                               [[c.height], [c.width], [c.fx]]], axis=1)
        rows.append(pose.reshape(-1))
    return np.concatenate([np.stack(rows), near_far], axis=1)


def save_poses_bounds(path: str | Path, cameras: CameraSet, near_far: np.ndarray,
                      image_names: Sequence[str] | None = None) -> Path:
    """Write ``poses_bounds.npy`` (see :func:`to_poses_bounds`), and ``image_names`` (one file name per row)
    as ``all_image_names.txt`` beside it when given."""
    path = Path(path)
    rows = to_poses_bounds(cameras, near_far)
    if image_names is not None:
        if len(image_names) != len(rows):
            raise ValueError(f"{len(image_names)} image names for {len(rows)} cameras")
        with atomic_path(path.parent / LLFF_IMAGE_NAMES) as tmp:
            tmp.write_text("".join(f"{n}\n" for n in image_names), encoding="utf-8")
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.save(f, rows)
    return path


def _row_names(path: Path, rows: np.ndarray, photos: Sequence[str]) -> list[str]:
    """The names (file stems) of ``path``'s rows: ``all_image_names.txt`` beside it when there is one, else
    ``photos``.

    Raises:
        InputError: the names and the rows differ in number, or two rows have one name.
    """
    listed = path.parent / LLFF_IMAGE_NAMES
    if listed.is_file():
        names = [Path(line.strip()).stem for line in listed.read_text(encoding="utf-8").splitlines() if line.strip()]
        if len(names) != len(rows):
            raise InputError(f"{listed.name} names {len(names)} images but {path.name} has {len(rows)} rows", listed,
                             fix=f"list the file name of every row of {path.name}, one per line, in the rows' order")
    else:
        names = list(photos)
        if len(names) != len(rows):
            raise InputError(
                f"{path.name} has {len(rows)} rows but the capture has {len(names)} photos; without "
                f"{LLFF_IMAGE_NAMES} the rows are the photos in the sorted order of their file names", path,
                fix=f"add {LLFF_IMAGE_NAMES} beside it (the file name of every row, one per line, sorted), or put "
                "exactly the photos the poses were made from in the capture")
    repeated = sorted(n for n, count in Counter(names).items() if count > 1)
    if repeated:
        raise InputError(f"two rows have the same image name: {', '.join(repeated[:5])}",
                         listed if listed.is_file() else path)
    return names


def load_poses_bounds(path: str | Path, photos: Sequence[str]) -> PosesBounds:
    """Read ``poses_bounds.npy`` as OpenCV cameras, named by ``all_image_names.txt`` beside it when there is
    one, else by ``photos`` (the capture's photos' names in the sorted order of their file names).

    Raises:
        InputError: an unreadable file or a bad row (naming it); names and rows that differ in number.
    """
    path = Path(path)
    rows = _read_rows(path)
    names = _row_names(path, rows, photos)
    cameras = []
    for k, (name, row) in enumerate(zip(names, rows)):
        pose = row[:15].reshape(3, 5)
        h, w, f = (float(v) for v in pose[:, 4])
        h, w = round(h), round(w)
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = pose[:, :3] @ LLFF_TO_OPENCV, pose[:, 3]
        try:
            cameras.append(Camera(name=name, width=w, height=h, fx=f, fy=f, cx=w / 2, cy=h / 2,
                                  camera_to_world=c2w.tolist()))
        except ValidationError as e:
            raise InputError(f"row {k} ({name}): {'; '.join(camera_problems(e))}", path) from e
    return PosesBounds(CameraSet(cameras=cameras), rows[:, 15:].copy())


def _read_rows(path: Path) -> np.ndarray:
    """``(N, 17)`` float64 rows of a ``poses_bounds.npy``, checked for shape and finiteness."""
    try:
        rows = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise InputError(f"not a readable .npy array ({e})", path,
                         fix="save LLFF poses with numpy.save as an (N, 17) float array") from e
    if not np.issubdtype(rows.dtype, np.number) or rows.ndim != 2 or rows.shape[1] != ROW or not len(rows):
        raise InputError(f"expected an (N, {ROW}) array (a 3x5 [R | t | h w f] and near, far per row), got "
                         f"{rows.dtype} {rows.shape}", path)
    if not np.isfinite(rows).all():
        raise InputError(f"row {int(np.argwhere(~np.isfinite(rows))[0, 0])} holds NaN or infinity", path)
    return rows.astype(np.float64)
