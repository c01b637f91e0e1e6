"""Photo reading (pipeline.raw): EXIF orientations turn an image as Pillow turns it."""

from __future__ import annotations

import numpy as np

from pipeline.raw import apply_orientation


def test_apply_orientation_matches_pillow():
    from PIL import Image, ImageOps

    a = np.arange(3 * 5 * 3, dtype=np.uint8).reshape(3, 5, 3)
    for o in range(1, 9):
        im = Image.fromarray(a)
        exif = im.getexif()
        exif[0x0112] = o
        im.info["exif"] = exif.tobytes()
        expected = np.asarray(ImageOps.exif_transpose(im))
        assert np.array_equal(apply_orientation(a, o), expected), o
