"""nerfstudio's ``transforms.json`` <-> :class:`~pipeline.cameras.CameraSet`, for interop.

nerfstudio (like instant-ngp and Blender's NeRF scenes) stores camera-to-world matrices in the OpenGL
convention (x right, y up, z backwards); ours is OpenCV's (x right, y down, z forward), so the camera's y and
z axes flip: ``c2w_opencv = c2w_opengl @ diag(1, -1, -1, 1)`` (its own inverse). Intrinsics ``fl_x, fl_y,
cx, cy, w, h`` sit at the top level when shared and in a frame when not; pixel coordinates follow COLMAP's
(centre of the top-left pixel at (0.5, 0.5)), as nerfstudio's COLMAP import copies them unchanged. Files
with only ``camera_angle_x`` (Blender/instant-ngp) get ``fl_x = w / (2 tan(camera_angle_x / 2))`` and a
centred principal point. Distortion (``k1, k2, k3, k4, p1, p2``) is returned separately: cameras.json is
pinhole, so distorted known cameras must be undistorted by the caller.

What nerfstudio's ``ns-train`` reads (:func:`nerfstudio_transforms`; its ``nerfstudio-data`` parser, checked by
``bench/nerfstudio_check.py``): ``file_path`` an 8-bit image PIL opens (the decode stage's ``srgb/*.png``, never the
linear EXR), ``mask_path`` a one-channel image of the same size whose 0 pixels are left out of training (our masks:
255 = object, so nerfstudio trains on the object alone), ``ply_file_path`` the sparse points (splatfacto's
starting Gaussians, else random) in the frame of the file's poses, and ``applied_transform``: the ``(3, 4)`` map
from the original frame (COLMAP's: ``frame.to_colmap`` inverted) to the file's, which nerfstudio composes into the
``dataparser_transform`` it saves, so its exports can go back to COLMAP's frame. It is a similarity (our frames are
scaled); ``applied_scale`` is not written because nerfstudio 1.1 multiplies the points by it but not the poses.
Paths are relative to the file's folder (nerfstudio joins them to it; ``..`` is allowed).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from .alignment import Similarity
from .artifacts import read_stage_json, write_json
from .cameras import Camera, CameraSet, as_matrix4, camera_problems
from .errors import InputError

FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])
INTRINSICS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
DISTORTION = ("k1", "k2", "p1", "p2", "k3", "k4")


def opengl_from_opencv(c2w: np.ndarray) -> np.ndarray:
    """``(..., 4, 4)`` OpenCV camera-to-world -> OpenGL/nerfstudio (and back: the map is its own inverse)."""
    return np.asarray(c2w, dtype=np.float64) @ FLIP_YZ


def to_transforms(cameras: CameraSet, image_paths: dict[str, str] | None = None) -> dict[str, Any]:
    """The nerfstudio ``transforms.json`` document of pinhole cameras (intrinsics shared when equal)."""
    cams = cameras.cameras
    intr = [{"fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy, "w": c.width, "h": c.height} for c in cams]
    shared = all(i == intr[0] for i in intr)
    doc: dict[str, Any] = {"camera_model": "OPENCV"}
    if shared and intr:
        doc.update(intr[0])
    frames = []
    for c, i in zip(cams, intr):
        path = (image_paths or {}).get(c.name, c.image) or c.name
        frame: dict[str, Any] = {"file_path": path, "transform_matrix": opengl_from_opencv(c.c2w).tolist()}
        if not shared:
            frame.update(i)
        frames.append(frame)
    doc["frames"] = frames
    return doc


def save_transforms(path: str | Path, cameras: CameraSet, image_paths: dict[str, str] | None = None) -> Path:
    return write_json(path, to_transforms(cameras, image_paths))


def applied_transform(cameras: CameraSet) -> np.ndarray:
    """``(3, 4)`` nerfstudio's ``applied_transform`` of ``cameras``: from the frame ``frame.to_colmap`` maps to
    (COLMAP's, or known cameras' own) to theirs; the identity when they record none."""
    to_colmap = cameras.frame.to_colmap
    if to_colmap is None:
        return np.eye(4)[:3]
    return Similarity.from_matrix(np.asarray(to_colmap, np.float64)).inverse().matrix[:3]


def from_colmap_frame(cameras: CameraSet, xyz: np.ndarray) -> np.ndarray:
    """Points ``(M, 3)`` in the frame ``cameras``' ``frame.to_colmap`` maps to, moved into theirs ``(M, 3)``."""
    m = applied_transform(cameras)
    return np.asarray(xyz, np.float64).reshape(-1, 3) @ m[:, :3].T + m[:, 3]


def in_colmap_frame(cameras: CameraSet) -> CameraSet:
    """The cameras moved into the frame their ``frame.to_colmap`` maps to (their own when they record none)."""
    if cameras.frame.to_colmap is None:
        return cameras
    to_colmap = Similarity.from_matrix(np.asarray(cameras.frame.to_colmap, np.float64))
    cams = [c.model_copy(update={"camera_to_world": to_colmap.apply_c2w(c.c2w).tolist()}) for c in cameras.cameras]
    return CameraSet(cameras=cams)


def nerfstudio_transforms(cameras: CameraSet, images: Mapping[str, str], masks: Mapping[str, str] | None = None,
                          points_file: str | None = None) -> dict[str, Any]:
    """The ``transforms.json`` document ``ns-train`` reads (see the module doc) of ``cameras``: ``images`` and
    ``masks`` map each camera's name to its 8-bit image and mask, ``points_file`` names the sparse points' PLY in
    the cameras' frame; paths relative to where the file goes."""
    doc = to_transforms(cameras, dict(images))
    if masks is not None:
        for frame, cam in zip(doc["frames"], cameras.cameras):
            frame["mask_path"] = masks[cam.name]
    doc["applied_transform"] = applied_transform(cameras).tolist()
    if points_file is not None:
        doc["ply_file_path"] = points_file
    return doc


@dataclass(frozen=True)
class KnownCameras:
    """Cameras read from a capture: pinhole parts as a :class:`CameraSet` (names = image stems), and
    distortion coefficients per camera name where the file gives non-zero ones."""

    cameras: CameraSet
    distortion: dict[str, dict[str, float]]


def load_transforms(path: str | Path) -> KnownCameras:
    """Read a nerfstudio/instant-ngp ``transforms.json``; camera names are the stems of ``file_path``."""
    path = Path(path)
    doc = read_stage_json(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), list) or not doc["frames"]:
        raise InputError("transforms.json has no 'frames' list", path,
                         fix="use nerfstudio's format: {'fl_x', 'fl_y', 'cx', 'cy', 'w', 'h', 'frames': [...]}")
    model = doc.get("camera_model", "OPENCV")
    if model not in ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE"):
        raise InputError(f"camera_model {model!r} is not supported (only OPENCV/pinhole cameras)", path)
    cameras, distortion = [], {}
    for k, frame in enumerate(doc["frames"]):
        merged = {**doc, **frame}
        where = f"frame {k} ({frame.get('file_path', '?')})"
        try:
            name = Path(str(frame["file_path"])).stem
            w, h = int(merged["w"]), int(merged["h"])
            if "fl_x" in merged:
                fx = float(merged["fl_x"])
                fy = float(merged.get("fl_y", fx))
            elif "camera_angle_x" in merged:
                fx = fy = 0.5 * w / np.tan(0.5 * float(merged["camera_angle_x"]))
            else:
                raise KeyError("fl_x or camera_angle_x")
            c2w = opengl_from_opencv(as_matrix4(frame["transform_matrix"], "transform_matrix"))
            cameras.append(Camera(name=name, image=str(frame["file_path"]), width=w, height=h, fx=fx, fy=fy,
                                  cx=float(merged.get("cx", w / 2)), cy=float(merged.get("cy", h / 2)),
                                  camera_to_world=c2w.tolist()))
        except KeyError as e:
            raise InputError(f"{where} lacks {e.args[0]}", path) from e
        except ValidationError as e:  # before ValueError, which it is: one line per problem, not pydantic's dump
            raise InputError(f"{where}: {'; '.join(camera_problems(e))}", path) from e
        except (TypeError, ValueError) as e:
            raise InputError(f"{where}: {e}", path) from e
        dist = {key: float(merged[key]) for key in DISTORTION if float(merged.get(key, 0.0) or 0.0) != 0.0}
        if dist:
            distortion[name] = dist
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise InputError("two frames have the same image name", path)
    return KnownCameras(CameraSet(cameras=cameras), distortion)
