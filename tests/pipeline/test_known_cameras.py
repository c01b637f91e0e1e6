"""Known cameras in a capture: which file or COLMAP model is used, LLFF's rows and a COLMAP model's images matched
to the decoded photos with their intrinsics scaled to the decoded size, and our COLMAP model of undistorted
photos."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import TESTDATA, colmap_model, orbit_cameras

from pipeline.cameras import save_cameras
from pipeline.errors import InputError
from pipeline.known_cameras import find_known_cameras, known_cameras, posed_from_file
from pipeline.llff import save_poses_bounds
from pipeline.transforms import save_transforms

BLOWTORCH = TESTDATA / "real" / "blowtorch"


def test_the_known_cameras_file_is_found_and_two_are_ambiguous(tmp_path):
    cams = orbit_cameras()
    assert find_known_cameras(tmp_path, "auto") is None
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.ones((len(cams), 2)))
    assert find_known_cameras(tmp_path, "auto") == tmp_path / "poses_bounds.npy"
    assert find_known_cameras(tmp_path, "ignore") is None
    save_transforms(tmp_path / "transforms.json", cams)
    save_cameras(tmp_path / "cameras.json", cams)
    with pytest.raises(InputError, match="cameras.json and transforms.json and poses_bounds.npy: which cameras"):
        find_known_cameras(tmp_path, "auto")


def test_llff_rows_match_the_photos_present_with_scaled_intrinsics(tmp_path):
    """8 rows named by all_image_names.txt, 5 photos decoded at half size: those 5 get their row's pose and
    the row's intrinsics halved (principal point at the decoded image's centre)."""
    cams = orbit_cameras(8, width=64, height=48)
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.ones((8, 2)),
                      image_names=[f"{c.name}.jpg" for c in cams.cameras])
    present = ["view0", "view2", "view3", "view5", "view7"]
    posed = posed_from_file(tmp_path / "poses_bounds.npy", present, 32, 24)
    assert posed.names == present
    assert posed.stats["cameras_without_photo"] == ["view1", "view4", "view6"]
    truth = cams.by_name()
    np.testing.assert_allclose(posed.c2w, np.stack([truth[n].c2w for n in present]), atol=1e-9)
    f = truth["view0"].fx / 2
    for lens in posed.lens:
        assert lens.model.name == "PINHOLE" and (lens.width, lens.height) == (32, 24)
        np.testing.assert_allclose(lens.params, [f, f, 16, 12], atol=1e-9)


def test_llff_of_another_aspect_ratio_is_refused(tmp_path):
    cams = orbit_cameras(3, width=64, height=48)
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.ones((3, 2)))
    with pytest.raises(InputError, match="different aspect ratio"):
        posed_from_file(tmp_path / "poses_bounds.npy", ["a", "b", "c"], 48, 64)


@pytest.mark.skipif(not BLOWTORCH.is_dir(), reason="no blowtorch test data")
def test_blowtorch_rows_match_the_67_photos_present():
    photos = sorted(p.stem for p in (BLOWTORCH / "images").glob("*.jpg"))
    posed = posed_from_file(BLOWTORCH / "poses_bounds.npy", photos, 2120, 1415)
    assert posed.names == photos and len(photos) == 67
    assert len(posed.stats["cameras_without_photo"]) == 122 - 67
    fx, fy, cx, cy = posed.lens[0].params
    assert fx == pytest.approx(6881.04 / 2, rel=1e-4) and (cx, cy) == (1060, 707.5)


# ------------------------------------------------------------------------------------- a user's COLMAP model


def test_a_colmap_model_is_found_where_colmap_and_nerfstudio_put_it_and_two_are_ambiguous(tmp_path):
    cams = orbit_cameras()
    colmap_model(cams, tmp_path / "sparse" / "0")
    assert find_known_cameras(tmp_path, "auto") == tmp_path / "sparse" / "0"
    assert find_known_cameras(tmp_path, "ignore") is None  # SfM runs
    colmap_model(cams, tmp_path / "colmap" / "sparse" / "0", text=True)
    with pytest.raises(InputError, match="sparse/0 and colmap/sparse/0: which cameras"):
        find_known_cameras(tmp_path, "auto")
    shutil.rmtree(tmp_path / "sparse")
    assert find_known_cameras(tmp_path, "auto") == tmp_path / "colmap" / "sparse" / "0"
    save_cameras(tmp_path / "cameras.json", cams)
    with pytest.raises(InputError, match="cameras.json and colmap/sparse/0: which cameras"):
        find_known_cameras(tmp_path, "auto")
    # LLFF's layout: poses_bounds.npy made from the sparse/0 beside it is one source, the model is read
    (tmp_path / "cameras.json").unlink()
    shutil.rmtree(tmp_path / "colmap")
    colmap_model(cams, tmp_path / "sparse" / "0")
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.tile([[1.0, 10.0]], (len(cams), 1)))
    assert find_known_cameras(tmp_path, "auto") == tmp_path / "sparse" / "0"
    shutil.rmtree(tmp_path / "sparse")
    assert find_known_cameras(tmp_path, "auto") == tmp_path / "poses_bounds.npy"


@pytest.mark.parametrize("text", [False, True], ids=["bin", "txt"])
def test_a_colmap_models_images_match_the_photos_by_stem_scaled_to_the_decoded_size(tmp_path, text):
    """A SIMPLE_RADIAL model of 4 photos at twice the decoded size, named photos/view<i>.JPG; 3 of them decoded
    and one photo it lacks: those 3 get its poses, its lens halved (k unchanged) and its 3D points, whose 2D
    points still land where the lens puts them (reprojection error ~0)."""
    cams = orbit_cameras(4, width=64, height=48)
    folder = colmap_model(cams, tmp_path / "sparse" / "0", lens="SIMPLE_RADIAL", distortion=(0.05,), scale=2.0,
                          text=text)
    photos = ["other", "view0", "view1", "view3"]
    posed, rec = known_cameras(folder, photos, 64, 48)
    assert posed.names == ["view0", "view1", "view3"]
    assert posed.stats["photos_without_camera"] == ["other"] and posed.stats["cameras_without_photo"] == ["view2"]
    truth = cams.by_name()
    np.testing.assert_allclose(posed.c2w, np.stack([truth[n].c2w for n in posed.names]), atol=1e-9)
    for n, lens in zip(posed.names, posed.lens):
        c = truth[n]
        assert lens.model.name == "SIMPLE_RADIAL" and (lens.width, lens.height) == (64, 48)
        np.testing.assert_allclose(lens.params, [c.fx, c.cx, c.cy, 0.05], atol=1e-9)
    assert len(posed.points) == 30 and rec.num_reg_images() == 3
    assert posed.stats["mean_reprojection_error_px"] < 1e-6


def test_a_colmap_model_unreadable_or_of_other_photos_is_refused_with_the_fix(tmp_path):
    cams = orbit_cameras()
    empty = tmp_path / "empty" / "sparse" / "0"
    empty.mkdir(parents=True)
    with pytest.raises(InputError, match="no COLMAP model here") as e:
        known_cameras(empty, ["view0", "view1"], 24, 18)
    assert str(empty) in str(e.value) and "known_poses=ignore" in str(e.value)
    garbage = tmp_path / "garbage"
    garbage.mkdir()
    for f in ("cameras.txt", "images.txt", "points3D.txt"):
        (garbage / f).write_text("1 this is not COLMAP\n")
    with pytest.raises(InputError, match="cannot read the COLMAP model") as e:
        known_cameras(garbage, ["view0", "view1"], 24, 18)
    assert str(garbage) in str(e.value) and "Fix:" in str(e.value)
    other = colmap_model(cams, tmp_path / "other", image_name="DSC_{}.jpg")
    with pytest.raises(InputError, match="only 0 of the 2 photos have a camera in this COLMAP model") as e:
        known_cameras(other, ["view0", "view1"], 24, 18)
    assert "DSC_view0" in str(e.value) and str(other) in str(e.value)
    with pytest.raises(InputError, match="different aspect ratio"):
        known_cameras(colmap_model(cams, tmp_path / "rotated"), ["view0", "view1"], 18, 24)


def test_our_model_is_pinhole_with_the_2d_points_moved(tmp_path):
    """An OPENCV model written for the undistorted photos: PINHOLE cameras with the lens's focal lengths and principal
    point, every 2D point where the pinhole camera projects its 3D point (as COLMAP's image_undistorter gives), each
    image name an 8-bit image in images/ beside sparse/; the model given is left as it was."""
    from pipeline import imageio
    from pipeline.colmap_model import write_dataset
    from pipeline.signals import import_pycolmap

    cams = orbit_cameras(4, width=64, height=48)
    names = [c.name for c in cams.cameras]
    user = colmap_model(cams, tmp_path / "user", lens="OPENCV", distortion=(0.2, 0.02, 0, 0))
    posed, rec = known_cameras(user, names, 64, 48)
    (tmp_path / "srgb").mkdir()
    pngs = {n: imageio.write_png(tmp_path / "srgb" / f"{n}.png", np.zeros((48, 64, 3), np.uint8)) for n in names}
    write_dataset(rec, tmp_path / "out", pngs)
    assert {c.model.name for c in rec.cameras.values()} == {"OPENCV"}
    ours = import_pycolmap().Reconstruction(tmp_path / "out" / "sparse" / "0")
    truth = cams.by_name()
    errors = []
    for image in ours.images.values():
        cam, c = ours.cameras[image.camera_id], truth[Path(image.name).stem]
        assert cam.model.name == "PINHOLE"
        np.testing.assert_allclose(cam.params, [c.fx, c.fy, c.cx, c.cy], atol=1e-9)
        stored = imageio.read_image(tmp_path / "out" / "images" / image.name)
        assert stored.dtype == np.uint8 and stored.shape[:2] == (cam.height, cam.width)
        w2c = np.linalg.inv(c.c2w)
        for p in image.points2D:
            x = w2c[:3, :3] @ ours.points3D[p.point3D_id].xyz + w2c[:3, 3]
            errors.append(np.linalg.norm(c.K[:2, :2] @ (x[:2] / x[2]) + c.K[:2, 2] - p.xy))
    assert len(errors) == 4 * 30 and max(errors) < 1e-6, max(errors)


def test_sparse_points_are_read_from_sparse_0_and_from_an_older_poses_stages_sparse(tmp_path):
    """`orca train --points results/<name>/poses/sparse` reads the model in sparse/0, and in sparse/ itself
    (where poses stages before sparse/0 wrote it)."""
    from pipeline.sparse_depth import load_sparse_points

    cams = orbit_cameras()
    colmap_model(cams, tmp_path / "new" / "sparse" / "0")
    colmap_model(cams, tmp_path / "old" / "sparse")
    for layout in ("new", "old"):
        points = load_sparse_points(tmp_path / layout / "sparse", cams)
        assert len(points.xyz) == 30 and all(len(o) == 4 for o in points.observers), layout
