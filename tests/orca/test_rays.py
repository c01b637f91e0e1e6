"""Camera rays: COLMAP pixel convention, OpenCV axes, projection round trip, cone radii."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from orca.rays import PIXEL_RADIUS_FACTOR, camera_rays, pixel_centers
from pipeline.cameras import look_at

pytestmark = pytest.mark.usefixtures("float64")


def test_pixel_centres_follow_colmap():
    uv = pixel_centers(2, 3)
    torch.testing.assert_close(uv[0, 0], torch.tensor([0.5, 0.5]))
    torch.testing.assert_close(uv[1, 2], torch.tensor([2.5, 1.5]))


def test_rays_reproject_to_their_pixels_and_principal_ray_is_the_optical_axis():
    K = torch.tensor([[100.0, 0, 32.0], [0, 110.0, 24.0], [0, 0, 1]])
    c2w = torch.from_numpy(look_at(np.array([2.0, -1.0, 0.5]), np.zeros(3)))
    uv = pixel_centers(48, 64).reshape(-1, 2)
    o, d, r = camera_rays(uv, K, c2w)
    torch.testing.assert_close(d.norm(dim=-1), torch.ones(len(d)))
    # project a point along each ray back into the image
    p = o + 3.0 * d
    w2c = torch.linalg.inv(c2w)
    pc = p @ w2c[:3, :3].T + w2c[:3, 3]
    proj = pc @ K.T
    torch.testing.assert_close(proj[:, :2] / proj[:, 2:], uv)
    o0, d0, r0 = camera_rays(torch.tensor([[32.0, 24.0]]), K, c2w)
    torch.testing.assert_close(d0[0], c2w[:3, 2])  # OpenCV: +z is the viewing direction
    torch.testing.assert_close(r0[0], PIXEL_RADIUS_FACTOR / torch.sqrt(torch.tensor(100.0 * 110.0)))
    assert (r <= r0 * (1 + 1e-12)).all(), "off-axis pixels subtend less angle per unit distance"
    assert r.min() < 0.95 * r0
