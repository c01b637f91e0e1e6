"""The export stage: a tiny ``orca export`` run on an untrained model writes every file, sizes and counts as
configured."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import orbit_cameras, write_untrained_train_dir

from pipeline.cameras import CameraSet, load_cameras, save_cameras
from pipeline.cli import main
from pipeline.imageio import read_exr, read_image


def test_orca_export_on_a_tiny_model(tmp_path):
    import open3d as o3d

    to_colmap = np.eye(4)
    to_colmap[:3, 3] = [5.0, 0.0, 0.0]
    cameras = save_cameras(tmp_path / "cameras.json",
                           CameraSet(frame={"to_colmap": to_colmap.tolist()}, cameras=orbit_cameras(3).cameras))
    train = write_untrained_train_dir(tmp_path / "train")
    out = tmp_path / "export"
    sets = ["export.view_size=8", "export.panorama_width=16", "export.video_frames=3", "export.video_width=16",
            "export.video_height=12", "export.object_views=2", "export.object_downscale=2",
            "export.rotated_yaw_deg=[45]", "export.translated_offsets=[0.5]"]
    argv = ["export", str(train), "--cameras", str(cameras), "--out", str(out), "--device", "cpu"]
    assert main(argv + [a for s in sets for a in ("--set", s)]) == 0
    report = json.loads((out / "export.json").read_text())
    env = out / "environment"
    assert report["environment_views"] == [c.name for c in load_cameras(env / "cameras.json").cameras]
    assert len(report["environment_views"]) == 6 + 1 + 1
    for name in report["environment_views"]:
        assert read_exr(env / f"{name}_rgb.exr").shape == (8, 8, 3)
        assert read_exr(env / f"{name}_depth.exr").shape == (8, 8)
        assert read_image(env / f"{name}_rgb.png").shape == (8, 8, 3)
        assert read_image(env / f"{name}_depth.png").shape == (8, 8, 3)
    pano_depth = read_exr(out / "panorama" / "panorama_depth.exr")
    assert read_exr(out / "panorama" / "panorama_rgb.exr").shape == (8, 16, 3) and pano_depth.shape == (8, 16)
    assert np.isfinite(pano_depth).all() and (pano_depth > 0).all()
    points = o3d.io.read_point_cloud(str(out / "environment_points.ply"))
    assert len(points.points) == report["point_cloud"]["points"] > 0 and points.has_colors()
    colmap = o3d.io.read_point_cloud(str(out / "environment_points_colmap.ply"))
    np.testing.assert_allclose(np.asarray(colmap.points), np.asarray(points.points) + [5, 0, 0], atol=1e-5)
    for video in ("orbit", "flythrough"):
        path = out / "videos" / f"{video}.mp4"
        assert path.stat().st_size > 0
        import imageio_ffmpeg

        frames = imageio_ffmpeg.read_frames(str(path))
        meta = next(frames)
        assert tuple(meta["size"]) == (16, 12)
        assert sum(1 for _ in frames) == 3
    views = load_cameras(out / "object" / "views.json")
    assert [c.name for c in views.cameras] == report["object_views"] == ["view0", "view2"]
    for cam in views.cameras:
        assert (cam.width, cam.height) == (12, 9)
        for part in ("rgb", "diffuse", "specular", "normal"):
            assert read_exr(out / "object" / f"{cam.name}_{part}.exr").shape == (9, 12, 3)
            assert read_image(out / "object" / f"{cam.name}_{part}.png").shape == (9, 12, 3)
        mask = read_image(out / "object" / f"{cam.name}_mask.png")
        assert mask.shape == (9, 12) and mask.max() == 255, "the untrained sphere (radius 0.7) is in view"
    assert (out / "overview.png").is_file() and (out / "manifest.json").is_file()
    assert report["frame"]["up"] == pytest.approx([0, 0, 1])
