"""Mask files: what the poses and masks stages (a user's masks) and training (``--masks``) read, by one rule,
so a file one of them refuses another does not silently stretch or misread.

Any common encoding is read: 8/16-bit grey 0/255 (or 0/65535), 0/1, RGB, or an alpha channel (a cut-out PNG:
the alpha is the mask when it is not constant); white (above half the encoding's full scale) is the object.
A mask at another resolution with the photo's aspect ratio was drawn on the original photo while decode
downscaled it (or the reverse): it is resized. Another aspect ratio means a rotated or cropped mask, or
another photo's: it is refused, naming the file.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .errors import InputError

log = logging.getLogger("orca.masks")


def mask_at_photo_size(mask: np.ndarray, size: tuple[int, int], path: Path) -> np.ndarray:
    """``(h, w)`` mask as read from ``path`` -> the same mask at the photo's ``size`` (width, height).

    Returns:
        ``mask`` itself when it has the photo's size; otherwise resized (area average), float32 on the same
        value scale as ``mask`` (threshold it as the original).

    Raises:
        InputError: the aspect ratios differ by more than a pixel.
    """
    import cv2

    width, height = size
    h, w = mask.shape
    if (w, h) == (width, height):
        return mask
    if abs(w * height - h * width) > max(w, h, width, height):  # aspect ratios differ by more than a pixel
        raise InputError(
            f"mask is {w}x{h} but its photo is {width}x{height} (another aspect ratio: rotated, cropped, or "
            "the mask of another photo?)", path,
            fix=f"save the mask at {width}x{height} (or at the original photo's size), not rotated or cropped",
        )
    log.info("%s: %dx%d mask resized to the photo's %dx%d", path.name, w, h, width, height)
    return cv2.resize(mask.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA)


def read_mask(path: Path, size: tuple[int, int]) -> np.ndarray:
    """``(H, W)`` bool (True = object) from a mask file of any common encoding, at ``size`` (width, height).

    Raises:
        InputError: unreadable, or an aspect ratio unlike the photo's (rotated, cropped, another photo).
    """
    from .imageio import read_image

    try:
        m = read_image(path)
    except (ValueError, OSError) as e:
        raise InputError("not a readable image", path, fix="save the mask as an 8-bit PNG") from e
    if m.ndim == 3 and m.shape[2] in (2, 4) and m[..., -1].min() != m[..., -1].max():
        m = m[..., -1]  # a cut-out: the alpha channel is the mask
    elif m.ndim == 3:
        m = m[..., : min(3, m.shape[2])].max(axis=-1)
    if m.dtype.kind == "f":
        m = np.nan_to_num(m)
    # The encoding's full scale from the file's own values: an area resize rounds 255 up to 255.00002, which
    # must not read as a 16-bit mask. 0/1 masks (max 1) and 0/255 or 0/65535 alike: above half of it.
    top = float(m.max())
    m = mask_at_photo_size(m, size, path)
    if top <= 0:
        log.warning("%s: the mask is empty (no object pixels)", path)
        return np.zeros(m.shape, bool)
    full = 1.0 if top <= 1.0 else (255.0 if top <= 255.0 else 65535.0)
    return m > full / 2
