"""transforms.json (pipeline.transforms): cameras round-trip through the OpenGL convention of the file."""

from __future__ import annotations

import numpy as np

from pipeline.artifacts import read_json
from pipeline.cameras import Camera, CameraSet, look_at
from pipeline.transforms import load_transforms, opengl_from_opencv, save_transforms


def test_transforms_json_round_trips_cameras(tmp_path):
    cams = CameraSet(cameras=[
        Camera(name=f"v{i}", image=f"images/v{i}.jpg", width=64, height=48, fx=60.0 + i, fy=61.0, cx=31.5, cy=24.5,
               camera_to_world=look_at(np.array([4.0 * np.cos(i), 4.0 * np.sin(i), 1.0 + i]), np.zeros(3)).tolist())
        for i in range(3)
    ])
    save_transforms(tmp_path / "transforms.json", cams)
    doc = read_json(tmp_path / "transforms.json")
    assert "fl_x" in doc["frames"][0]  # focal lengths differ: per-frame intrinsics
    # OpenGL axes in the file: the camera looks along its -z
    np.testing.assert_allclose(np.asarray(doc["frames"][0]["transform_matrix"])[:3, 2], -cams.cameras[0].c2w[:3, 2])
    back = load_transforms(tmp_path / "transforms.json")
    assert not back.distortion
    for a, b in zip(cams.cameras, back.cameras.cameras):
        assert a.name == b.name
        assert (a.fx, a.fy, a.cx, a.cy, a.width, a.height) == (b.fx, b.fy, b.cx, b.cy, b.width, b.height)
        np.testing.assert_allclose(a.c2w, b.c2w, atol=1e-12)
    np.testing.assert_array_equal(opengl_from_opencv(opengl_from_opencv(cams.cameras[0].c2w)), cams.cameras[0].c2w)
