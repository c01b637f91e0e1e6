"""The ground truth's props (pipeline.props): which points lie in a sphere, cylinder or yawed box, and depth maps
as points."""

from __future__ import annotations

import numpy as np

from pipeline.props import Prop, points_from_depth, points_in_props


def test_point_in_prop_for_each_kind():
    sphere = Prop("ball", "sphere", (1.0, 2.0, 0.5), (0.5, 0.5, 0.5))
    assert sphere.contains(np.array([1.0, 2.0, 1.0]))  # on the top
    assert not sphere.contains(np.array([1.0, 2.0, 1.1]))
    assert sphere.contains(np.array([1.0, 2.0, 1.04]), margin=0.05)

    cyl = Prop("drum", "cylinder", (0.0, 0.0, 1.0), (0.4, 0.4, 2.0))  # z in [0, 2]
    assert cyl.contains(np.array([0.39, 0.0, 1.99]))
    assert not cyl.contains(np.array([0.0, 0.0, 2.1]))
    assert not cyl.contains(np.array([0.3, 0.3, 1.0])), "outside the radius though inside the bounding square"
    assert cyl.contains(np.array([0.0, 0.0, 2.04]), margin=0.05)

    box = Prop("crate", "box", (0.0, 0.0, 0.0), (1.0, 0.2, 0.5), yaw_deg=90.0)  # long axis along y after yaw
    assert box.contains(np.array([0.0, 0.9, 0.0]))
    assert not box.contains(np.array([0.9, 0.0, 0.0])), "the yaw turned the long side away from x"
    assert box.contains(np.array([0.24, 0.0, 0.0]), margin=0.05)
    yawed = Prop("b", "box", (2.0, 1.0, 0.0), (1.0, 0.1, 1.0), yaw_deg=45.0)
    along = np.array([2.0, 1.0, 0.0]) + 0.9 * np.array([1, 1, 0]) / np.sqrt(2)
    across = np.array([2.0, 1.0, 0.0]) + 0.9 * np.array([1, -1, 0]) / np.sqrt(2)
    assert yawed.contains(along) and not yawed.contains(across)

    pts = np.stack([along, across, [np.inf, 0, 0], [1.0, 2.0, 0.5]])
    assert points_in_props(pts, [yawed, sphere], margin=0.0).tolist() == [True, False, False, True]


def test_points_from_depth_reproject_pixel_centres():
    K = np.array([[50.0, 0, 20], [0, 50.0, 15], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[:3, 3] = [1, 2, 3]
    depth = np.full((30, 40), 2.0)
    p = points_from_depth(depth, K, c2w)
    # pixel (col 19, row 14) has its centre at (19.5, 14.5): half a pixel left/up of the principal point
    assert np.allclose(p[14, 19], [1 + (-0.5 / 50) * 2, 2 + (-0.5 / 50) * 2, 5])
    assert np.allclose(p[..., 2], 5)
