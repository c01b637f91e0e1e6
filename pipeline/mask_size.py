"""A mask file's size against its photo's: the one rule the masks stage (user masks) and training (``--masks``)
both apply, so a file one of them refuses the other does not silently stretch.

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
