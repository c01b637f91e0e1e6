"""Image I/O (pipeline.imageio): EXR and PNG round trips, the sRGB transfer function."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.imageio import linear_to_srgb, read_exr, read_image, srgb_to_linear, write_exr, write_png


@pytest.mark.parametrize("shape", [(6, 9), (6, 9, 3), (6, 9, 4)])
def test_exr_round_trip_is_exact_in_float32(tmp_path, shape):
    rng = np.random.default_rng(0)
    image = (rng.standard_normal(shape) * 100).astype(np.float32)
    image.flat[0] = np.inf  # depth maps use inf for "no hit"
    write_exr(tmp_path / "a.exr", image)
    back = read_exr(tmp_path / "a.exr")
    assert back.shape == shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, image)


def test_exr_half_precision_is_close(tmp_path):
    image = np.linspace(0.01, 10, 60, dtype=np.float32).reshape(4, 5, 3)
    write_exr(tmp_path / "h.exr", image, half=True)
    np.testing.assert_allclose(read_exr(tmp_path / "h.exr"), image, rtol=1e-3)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_png_round_trip_keeps_rgb_order(tmp_path, dtype):
    image = np.zeros((4, 5, 3), dtype=dtype)
    image[..., 0] = np.iinfo(dtype).max  # pure red must stay red (OpenCV is BGR inside)
    write_png(tmp_path / "r.png", image)
    back = read_image(tmp_path / "r.png")
    np.testing.assert_array_equal(back, image)


def test_srgb_transfer_inverts_and_matches_reference_points():
    x = np.linspace(0, 1, 1001, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=2e-6)
    # IEC 61966-2-1: 18 % grey encodes to ~0.4614, the linear segment ends at 0.0031308 -> 0.04045
    np.testing.assert_allclose(linear_to_srgb(np.float32(0.18)), 0.46135, atol=1e-4)
    np.testing.assert_allclose(linear_to_srgb(np.float32(0.0031308)), 0.04045, atol=1e-5)
