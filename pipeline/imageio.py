"""Image files: linear HDR as OpenEXR (the ``openexr`` package), 8/16-bit as PNG (OpenCV), sRGB transfer.

Arrays are ``(H, W, C)`` float32 for EXR and ``(H, W, C)`` uint8/uint16 for PNG, RGB channel order
(OpenCV's BGR is hidden here), or ``(H, W)`` for single-channel images.
"""

from __future__ import annotations

import errno
from pathlib import Path

import cv2
import numpy as np
import OpenEXR

from .artifacts import atomic_path

_RGB = ("R", "G", "B")
_RGBA = ("R", "G", "B", "A")


def write_exr(path: str | Path, image: np.ndarray, *, half: bool = False) -> Path:
    """Write ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` floats as an EXR (ZIP compression).

    Single-channel images are stored as channel ``Y`` (depth, masks); 3/4 channels as R, G, B(, A).
    """
    path = Path(path)
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    dtype = np.float16 if half else np.float32
    image = np.ascontiguousarray(image.astype(dtype))
    if image.ndim == 2:
        channels = {"Y": image}
    elif image.ndim == 3 and image.shape[2] in (3, 4):
        names = _RGB if image.shape[2] == 3 else _RGBA
        channels = {n: np.ascontiguousarray(image[..., i]) for i, n in enumerate(names)}
    else:
        raise ValueError(f"write_exr: expected (H, W), (H, W, 3) or (H, W, 4), got {image.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
    return path


def read_exr(path: str | Path) -> np.ndarray:
    """Read an EXR as float32: ``(H, W)`` for one channel, ``(H, W, 3|4)`` for RGB(A).

    A missing file is a FileNotFoundError and a damaged one a ValueError naming it, as :func:`read_image`'s
    (OpenEXR reports both as a RuntimeError)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = {n: c.pixels for n, c in f.channels().items()}
    except (RuntimeError, ValueError) as e:  # a truncated file: ValueError
        raise ValueError(f"{path}: not a readable EXR image ({e})") from e
    names = list(channels)
    if all(n in names for n in _RGB):
        order = _RGBA if "A" in names else _RGB
        return np.stack([channels[n].astype(np.float32) for n in order], axis=-1)
    if len(names) == 1:
        return channels[names[0]].astype(np.float32)
    raise ValueError(f"{path}: unsupported EXR channels {names}")


def png_bytes(image: np.ndarray) -> bytes:
    """uint8/uint16 ``(H, W)`` or RGB(A) ``(H, W, 3|4)`` encoded as a PNG file."""
    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG: expected uint8 or uint16, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write uint8/uint16 ``(H, W)`` or RGB(A) ``(H, W, 3|4)`` as PNG, atomically."""
    path = Path(path)
    data = png_bytes(image)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def read_image(path: str | Path) -> np.ndarray:
    """Read a PNG/JPEG/TIFF as stored (uint8/uint16), RGB(A) order; EXIF orientation is NOT applied
    (photos go through :mod:`pipeline.raw`, which applies it)."""
    path = Path(path)
    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH) if data.size else None
    if image is None:
        raise ValueError(f"{path}: not a readable image")
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
    return image


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Inverse sRGB transfer (IEC 61966-2-1) on values in [0, 1]."""
    x = np.asarray(x, dtype=np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """sRGB transfer on linear values; clipped to [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


def to_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear float image -> 8-bit sRGB for display and feature matching."""
    return np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)
