"""Undistortion (pipeline.undistort): the map sends each pinhole pixel to where the lens put it."""

from __future__ import annotations

import numpy as np

from pipeline.undistort import undistort_map


def test_undistort_map_sends_pinhole_pixels_to_where_the_lens_put_them():
    import pycolmap

    cam = pycolmap.Camera(model="OPENCV", width=80, height=60, params=[70.0, 71.0, 40.3, 29.8, -0.2, 0.05, 1e-3, -2e-3])
    mx, my, shift = undistort_map(cam)
    assert mx.shape == (60, 80) and shift > 1.0
    for x, y in [(0, 0), (79, 59), (10, 45), (40, 30)]:
        ray = np.array([(x + 0.5 - 40.3) / 70.0, (y + 0.5 - 29.8) / 71.0, 1.0])
        distorted = cam.img_from_cam(ray[None])[0]
        np.testing.assert_allclose([mx[y, x] + 0.5, my[y, x] + 0.5], distorted, atol=1e-4)
