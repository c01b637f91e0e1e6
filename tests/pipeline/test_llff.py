"""LLFF's poses_bounds.npy: the writer and reader round trip (axes, intrinsics, bounds), the rows' names from
all_image_names.txt or the photos' order, clear errors, and the real blowtorch file."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import TESTDATA, random_rotation

from pipeline.cameras import Camera, CameraSet, look_at
from pipeline.errors import InputError
from pipeline.llff import LLFF_TO_OPENCV, load_poses_bounds, save_poses_bounds, to_poses_bounds
from pipeline.object_frame import axes_convergence

BLOWTORCH = TESTDATA / "real" / "blowtorch"


def cameras(n: int = 5, width: int = 4240, height: int = 2830, f: float = 6881.0, prefix: str = "IMG_") -> CameraSet:
    """``n`` LLFF-shaped cameras (one focal length, centred principal point) at random poses."""
    rng = np.random.default_rng(3)
    cams = []
    for i in range(n):
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = random_rotation(rng), rng.normal(size=3) * 2
        cams.append(Camera(name=f"{prefix}{i:04d}", width=width, height=height, fx=f, fy=f, cx=width / 2,
                           cy=height / 2, camera_to_world=c2w.tolist()))
    return CameraSet(cameras=cams)


def test_round_trip_keeps_poses_intrinsics_and_bounds(tmp_path):
    cams = cameras()
    near_far = np.stack([np.linspace(0.5, 1, 5), np.linspace(4, 6, 5)], axis=1)
    path = save_poses_bounds(tmp_path / "poses_bounds.npy", cams, near_far)
    back = load_poses_bounds(path, [c.name for c in cams.cameras])
    assert np.load(path).shape == (5, 17)
    assert [c.name for c in back.cameras.cameras] == [c.name for c in cams.cameras]
    np.testing.assert_allclose(back.cameras.c2w()[:, :3, :3], cams.c2w()[:, :3, :3], atol=1e-9)
    np.testing.assert_allclose(back.cameras.c2w()[:, :3, 3], cams.c2w()[:, :3, 3], atol=1e-9)
    np.testing.assert_allclose(back.cameras.K(), cams.K(), atol=1e-9)
    np.testing.assert_array_equal(back.near_far, near_far)


def test_axes_are_down_right_back():
    """A camera looking along +x with +z up: LLFF's columns are (down, right, back) = (-z, -y, -x)."""
    c2w = look_at(np.zeros(3), np.array([1.0, 0, 0]))
    cam = Camera(name="a", width=4, height=2, fx=3, fy=3, cx=2, cy=1, camera_to_world=c2w.tolist())
    row = to_poses_bounds(CameraSet(cameras=[cam]), np.array([[1.0, 2.0]]))[0]
    pose = row[:15].reshape(3, 5)
    np.testing.assert_allclose(pose[:, :3], [[0, 0, -1], [0, -1, 0], [-1, 0, 0]], atol=1e-12)
    np.testing.assert_array_equal(pose[:, 4], [2, 4, 3])  # h, w, f
    assert np.linalg.det(LLFF_TO_OPENCV) == pytest.approx(1.0)


def test_rows_are_named_by_all_image_names_when_present(tmp_path):
    """all_image_names.txt lists every row (with extensions); the photos present are a subset."""
    cams = cameras(6)
    files = [f"{c.name}.JPG" for c in cams.cameras]
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.ones((6, 2)), image_names=files)
    back = load_poses_bounds(tmp_path / "poses_bounds.npy", ["IMG_0001", "IMG_0004"])
    assert [c.name for c in back.cameras.cameras] == [c.name for c in cams.cameras]
    np.testing.assert_allclose(back.cameras.c2w(), cams.c2w(), atol=1e-9)


def test_without_names_the_rows_are_the_photos_in_order(tmp_path):
    cams = cameras(3)
    save_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.ones((3, 2)))
    back = load_poses_bounds(tmp_path / "poses_bounds.npy", ["a", "b", "c"])
    assert [c.name for c in back.cameras.cameras] == ["a", "b", "c"]
    np.testing.assert_allclose(back.cameras.c2w(), cams.c2w(), atol=1e-9)


def test_a_count_mismatch_names_the_file_and_the_fix(tmp_path):
    save_poses_bounds(tmp_path / "poses_bounds.npy", cameras(4), np.ones((4, 2)))
    with pytest.raises(InputError, match="4 rows but the capture has 3 photos") as e:
        load_poses_bounds(tmp_path / "poses_bounds.npy", ["a", "b", "c"])
    assert e.value.path.name == "poses_bounds.npy" and "all_image_names.txt" in e.value.fix
    (tmp_path / "all_image_names.txt").write_text("a.jpg\nb.jpg\n")
    with pytest.raises(InputError, match="names 2 images but poses_bounds.npy has 4 rows") as e:
        load_poses_bounds(tmp_path / "poses_bounds.npy", ["a", "b", "c", "d"])
    assert e.value.path.name == "all_image_names.txt"


def test_two_rows_of_one_name_are_refused(tmp_path):
    save_poses_bounds(tmp_path / "poses_bounds.npy", cameras(3), np.ones((3, 2)),
                      image_names=["a.jpg", "b.jpg", "a.png"])
    with pytest.raises(InputError, match="two rows have the same image name: a$"):
        load_poses_bounds(tmp_path / "poses_bounds.npy", ["a", "b"])


def test_bad_arrays_are_refused(tmp_path):
    path = tmp_path / "poses_bounds.npy"
    np.save(path, np.zeros((3, 15)))
    with pytest.raises(InputError, match=r"expected an \(N, 17\) array"):
        load_poses_bounds(path, ["a", "b", "c"])
    rows = to_poses_bounds(cameras(2), np.ones((2, 2)))
    rows[1, 3] = np.nan
    np.save(path, rows)
    with pytest.raises(InputError, match="row 1 holds NaN"):
        load_poses_bounds(path, ["a", "b"])
    rows = to_poses_bounds(cameras(2), np.ones((2, 2)))
    rows[0, :3] *= 2  # not a rotation
    np.save(path, rows)
    with pytest.raises(InputError, match=r"row 0 \(a\):.*camera_to_world"):
        load_poses_bounds(path, ["a", "b"])


def test_the_writer_refuses_cameras_llff_cannot_hold():
    cam = cameras(1).cameras[0]
    for change in ({"fy": cam.fx * 1.01}, {"cx": cam.cx + 3}):
        with pytest.raises(ValueError, match="one focal length and a centred principal point"):
            to_poses_bounds(CameraSet(cameras=[cam.model_copy(update=change)]), np.ones((1, 2)))


@pytest.mark.skipif(not BLOWTORCH.is_dir(), reason="no blowtorch test data")
def test_blowtorch_cameras_look_at_the_object():
    """The real file: 122 rows named by all_image_names.txt (67 of them photos present), at the original
    4240x2830; the optical axes (OpenCV +z after the axes change) meet in front of every camera."""
    photos = sorted(p.stem for p in (BLOWTORCH / "images").glob("*.jpg"))
    known = load_poses_bounds(BLOWTORCH / "poses_bounds.npy", photos)
    assert len(known.cameras) == 122 and len(photos) == 67
    assert set(photos) <= set(known.cameras.by_name())
    assert {(c.width, c.height) for c in known.cameras.cameras} == {(4240, 2830)}
    c2w = known.cameras.c2w()
    centres, axes = c2w[:, :3, 3], c2w[:, :3, 2]
    point, miss, _ = axes_convergence(centres, axes)
    distance = float(np.linalg.norm(centres - point, axis=1).mean())
    assert np.median(miss) < 0.05 * distance and miss.max() < 0.2 * distance
    assert (np.einsum("ij,ij->i", point - centres, axes) > 0.5 * distance).all()  # in front, not behind
    assert (known.near_far[:, 0] < known.near_far[:, 1]).all()
