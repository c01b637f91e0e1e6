"""The render stage: ``orca render`` round-trips a camera file (views.json holds the input cameras as rendered,
every image has its camera's size, rendering is deterministic, and views.json of a downscaled render renders
to the same images again) and refuses a downscale larger than a camera."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import orbit_cameras, write_untrained_train_dir

from pipeline.cameras import CameraSet, load_cameras, save_cameras
from pipeline.cli import main
from pipeline.errors import InputError
from pipeline.imageio import read_exr, read_image

OBJECT_PARTS = ("rgb", "diffuse", "specular", "normal", "depth")


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("render")
    train = write_untrained_train_dir(root / "train")
    wide = orbit_cameras(1, width=20, height=14, prefix="wide")
    tall = orbit_cameras(2, width=12, height=16, distance=2.5, prefix="tall")
    to_colmap = np.eye(4)
    to_colmap[:3, :3] *= 3.0
    cams = CameraSet(frame={"to_colmap": to_colmap.tolist()}, cameras=wide.cameras + tall.cameras[1:])
    cams.cameras[0] = cams.cameras[0].model_copy(update={"image": "photos/wide0.jpg", "cx": 9.5, "fy": 21.0})
    return train, save_cameras(root / "cameras.json", cams), cams


def test_a_camera_file_round_trips_through_orca_render(setup, tmp_path):
    train, path, cams = setup
    out = tmp_path / "views"
    assert main(["render", str(train), "--cameras", str(path), "--out", str(out), "--device", "cpu"]) == 0
    views = load_cameras(out / "views.json")
    assert views.frame == cams.frame
    assert len(views) == len(cams)
    for cam, view in zip(cams.cameras, views.cameras, strict=True):
        assert view.image == f"{cam.name}_rgb.exr"
        assert view.model_dump(exclude={"image"}) == cam.model_dump(exclude={"image"})
        for part in OBJECT_PARTS:
            image = read_exr(out / f"{cam.name}_{part}.exr")
            assert image.shape[:2] == (cam.height, cam.width), part
        assert read_image(out / f"{cam.name}_mask.png").shape == (cam.height, cam.width)
        assert read_image(out / f"{cam.name}_rgb.png").shape == (cam.height, cam.width, 3)
    mask = read_image(out / "wide0_mask.png") > 127
    depth = read_exr(out / "wide0_depth.exr")
    assert mask.any() and np.isfinite(depth[mask]).all() and np.isinf(depth[~mask]).all()

    again = tmp_path / "again"
    assert main(["render", str(train), "--cameras", str(path), "--out", str(again), "--device", "cpu"]) == 0
    for cam in cams.cameras:
        np.testing.assert_array_equal(read_exr(again / f"{cam.name}_rgb.exr"), read_exr(out / f"{cam.name}_rgb.exr"),
                                      err_msg="rendering is deterministic")


def test_views_json_of_a_downscaled_render_describes_its_images(setup, tmp_path):
    train, path, cams = setup
    half = tmp_path / "half"
    assert main(["render", str(train), "--cameras", str(path), "--out", str(half), "--downscale", "2",
                 "--environment", "--device", "cpu"]) == 0
    views = load_cameras(half / "views.json")
    for cam, view in zip(cams.cameras, views.cameras, strict=True):
        assert (view.width, view.height) == (cam.width // 2, cam.height // 2)
        assert (view.fx, view.fy, view.cx, view.cy) == (cam.fx / 2, cam.fy / 2, cam.cx / 2, cam.cy / 2)
        assert read_exr(half / f"{cam.name}_rgb.exr").shape == (view.height, view.width, 3)
        assert read_exr(half / f"{cam.name}_depth.exr").shape == (view.height, view.width)
        assert not (half / f"{cam.name}_normal.exr").exists(), "environment views: RGB and depth only"
    # the written cameras render the written images again
    full = tmp_path / "full"
    assert main(["render", str(train), "--cameras", str(half / "views.json"), "--out", str(full), "--environment",
                 "--device", "cpu"]) == 0
    for cam in views.cameras:
        for part in ("rgb", "depth"):
            np.testing.assert_allclose(read_exr(full / f"{cam.name}_{part}.exr"),
                                       read_exr(half / f"{cam.name}_{part}.exr"), rtol=1e-5, atol=1e-6)


def test_render_refuses_a_downscale_larger_than_a_camera(setup, tmp_path):
    from pipeline.stages.render import run_render

    train, path, _ = setup
    with pytest.raises(InputError, match="smaller than the downscale"):
        run_render(train, path, tmp_path / "x", downscale=13, device="cpu")
    assert not (tmp_path / "x").exists()
