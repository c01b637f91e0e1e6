"""cameras.json (pipeline.cameras): round trips, look_at in the OpenCV convention, validation, view selection."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.cameras import Camera, CameraSet, intrinsics_from_fov, load_cameras, look_at, save_cameras, select_views
from pipeline.errors import InputError


def _camera(name="c0", eye=(3.0, 0.0, 1.0)) -> Camera:
    fx, fy, cx, cy = intrinsics_from_fov(64, 48, 60)
    return Camera(name=name, image=f"{name}.dng", width=64, height=48, fx=fx, fy=fy, cx=cx, cy=cy,
                  camera_to_world=look_at(np.array(eye), np.zeros(3)).tolist())


def test_cameras_round_trip_and_look_at_projects_target_to_centre(tmp_path):
    cams = CameraSet(cameras=[_camera("a"), _camera("b", eye=(0.0, -2.0, 0.5))])
    save_cameras(tmp_path / "cameras.json", cams)
    back = load_cameras(tmp_path / "cameras.json")
    assert back == cams
    for cam in back.cameras:
        w2c = np.linalg.inv(cam.c2w)
        p = w2c[:3, :3] @ np.zeros(3) + w2c[:3, 3]
        assert p[2] > 0, "target must be in front of the camera (OpenCV z forward)"
        uv = (cam.K @ p)[:2] / p[2]
        np.testing.assert_allclose(uv, [cam.cx, cam.cy], atol=1e-9)
        # OpenCV: image y points down, so world up (+z) must map to negative camera y
        assert (w2c[:3, :3] @ np.array([0, 0, 1.0]))[1] < 0


def test_cameras_reject_non_rigid_pose_and_name_the_file(tmp_path):
    bad = _camera().model_dump()
    bad["camera_to_world"][0][:3] = [2.0 * v for v in bad["camera_to_world"][0][:3]]
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"cameras": [bad]}))
    with pytest.raises(InputError, match=r"(?s)cameras.json.*(rigid|orthogonal)"):
        load_cameras(path)
    with pytest.raises(InputError, match="not found"):
        load_cameras(tmp_path / "missing.json")


def test_select_views_evenly_spaced():
    names = [f"v{i}" for i in range(10)]
    assert select_views(names, None) == names
    assert select_views(names, 1) == ["v0"]
    assert select_views(names, 4) == ["v0", "v3", "v6", "v9"]
    assert select_views(names, 50) == names
    with pytest.raises(InputError, match="unknown view"):
        select_views(names, ["nope"])
