"""Panorama geometry (pipeline.panorama): equirectangular rays against their analytic definition, a panorama of
known depth as points, the environment's virtual cameras."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.config import ExportConfig
from pipeline.panorama import (
    environment_cameras,
    equirect_directions,
    equirect_rays,
    panorama_frame,
    panorama_points,
)


def test_equirect_directions_match_longitude_and_elevation():
    w, h = 64, 32
    dirs, solid = equirect_directions(w, h)
    assert dirs.shape == (h, w, 3) and solid.shape == (h, w)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1, atol=1e-12)
    assert solid.sum() == pytest.approx(4 * math.pi, rel=1e-12), "the pixels tile the sphere"
    # back to angles: pixel centres at phi = pi (1 - 2 (j + 0.5) / W), theta = pi (1/2 - (i + 0.5) / H)
    phi = np.arctan2(dirs[..., 1], dirs[..., 0])
    theta = np.arcsin(dirs[..., 2])
    j = np.arange(w) + 0.5
    expected_phi = np.angle(np.exp(1j * np.pi * (1 - 2 * j / w)))  # wrapped to (-pi, pi]
    np.testing.assert_allclose(phi, np.broadcast_to(expected_phi, (h, w)), atol=1e-12)
    np.testing.assert_allclose(theta[:, 0], np.pi * (0.5 - (np.arange(h) + 0.5) / h), atol=1e-12)
    # landmarks: the middle looks forward, a quarter to the left looks left, the top row up
    assert dirs[h // 2, w // 2] @ [1, 0, 0] > math.cos(math.pi / h * 1.01)
    assert dirs[h // 2, w // 4] @ [0, 1, 0] > math.cos(math.pi / h * 1.01)
    assert dirs[0, 0, 2] > math.cos(math.pi / h)
    # solid angle of a pixel ~ (2 pi / W)(pi / H) cos(theta)
    np.testing.assert_allclose(solid[:, 0], 2 * np.pi / w * np.pi / h * np.cos(theta[:, 0]), rtol=2e-3)


def test_equirect_rays_in_a_tilted_frame():
    up = np.array([0.0, 1.0, 1.0]) / math.sqrt(2)
    frame = panorama_frame(up)
    np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)
    np.testing.assert_allclose(frame[:, 2], up)
    centre = np.array([0.1, 0.2, 0.3])
    origins, dirs, radii = equirect_rays(16, 8, centre, frame)
    assert origins.shape == dirs.shape == (128, 3) and radii.shape == (128,)
    np.testing.assert_allclose(origins, np.broadcast_to(centre, (128, 3)))
    top = dirs.reshape(8, 16, 3)[0]
    assert (top @ up > math.cos(math.pi / 8 * 1.01)).all(), "the top row looks up the frame's up"
    assert radii.max() > radii.min() > 0, "pixels shrink towards the poles"


def test_a_panorama_of_known_depth_becomes_points_at_that_distance():
    frame = panorama_frame(np.array([0.0, 0.0, 1.0]))
    depth = np.full((8, 16), 2.0, np.float32)
    depth[0, 0] = np.inf
    depth[1, 1] = 50.0  # beyond max_depth: left out
    rgb = np.full((8, 16, 3), 0.5, np.float32)
    points, colors = panorama_points(rgb, depth, np.array([0.0, 0.0, 0.5]), frame, max_depth=10.0)
    assert len(points) == 8 * 16 - 2
    np.testing.assert_allclose(np.linalg.norm(points - [0, 0, 0.5], axis=1), 2.0, rtol=1e-6)
    assert colors.min() >= 0 and colors.max() <= 1


def test_environment_cameras_look_where_named():
    frame = panorama_frame(np.array([0.0, 0.0, 1.0]))
    cfg = ExportConfig(view_size=16, translated_offsets=[-0.5, 0.5], rotated_yaw_deg=[90.0])
    cams = {c.name: c for c in environment_cameras(cfg, frame)}
    assert set(cams) == {"cube_px", "cube_nx", "cube_py", "cube_ny", "cube_pz", "cube_nz", "shift_0", "shift_1",
                         "turn_90"}
    np.testing.assert_allclose(cams["cube_px"].c2w[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cams["cube_nz"].c2w[:3, 2], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(cams["turn_90"].c2w[:3, 2], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(cams["shift_1"].center, [0, 0.5, 0], atol=1e-12)
    assert cams["cube_px"].fx == pytest.approx(8.0), "90-degree faces"
    for c in cams.values():
        assert np.linalg.norm(c.center) <= 0.5 + 1e-12, "inside the object's bounding sphere"
