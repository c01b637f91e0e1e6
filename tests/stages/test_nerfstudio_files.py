"""nerfstudio's transforms.json as the poses and masks stages write it: every image and mask opens as 8-bit the way
nerfstudio opens it (PIL), the sparse points' PLY is in the file's frame (they project onto their own 2D points
through the file's cameras), and the cameras are those of the cameras.json beside it. nerfstudio's own parser
reading these files: bench/nerfstudio_check.py (it does not install beside this package's pins)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import open3d as o3d
from helpers import colmap_model
from PIL import Image

from pipeline.artifacts import read_json
from pipeline.cameras import load_cameras
from pipeline.config import MasksConfig, PosesConfig
from pipeline.signals import import_pycolmap
from pipeline.stages.masks import run_masks
from pipeline.stages.poses import run_poses
from pipeline.transforms import load_transforms, opengl_from_opencv

POINTS = 30  # helpers.colmap_model's


def _open_8bit(path: Path, channels: int, size: tuple[int, int]) -> None:
    """``path`` opens with PIL as nerfstudio opens it: 8-bit, ``channels`` channels, ``size`` (w, h)."""
    with Image.open(path) as im:
        a = np.asarray(im)
    assert a.dtype == np.uint8, path
    assert (a.shape[:2], a.shape[2] if a.ndim == 3 else 1) == ((size[1], size[0]), channels), path


def _check_file(folder: Path, name: str, model: Path, masks: bool) -> dict:
    """One transforms.json: images (and masks) open as 8-bit at the cameras' size, and its PLY's points, read as
    nerfstudio reads them (open3d), project through the file's cameras onto the 2D points the COLMAP ``model``
    observed them at."""
    doc = read_json(folder / name)
    size = (doc["w"], doc["h"])
    for frame in doc["frames"]:
        _open_8bit(folder / frame["file_path"], 3, size)
        if masks:
            _open_8bit(folder / frame["mask_path"], 1, size)
            assert np.asarray(Image.open(folder / frame["mask_path"])).max() == 255  # 0 = left out of training
        else:
            assert "mask_path" not in frame
    assert np.asarray(doc["applied_transform"]).shape == (3, 4)
    cloud = o3d.io.read_point_cloud(str(folder / doc["ply_file_path"]))
    xyz = np.asarray(cloud.points)
    assert len(xyz) == POINTS and np.asarray(cloud.colors).shape == (POINTS, 3)

    rec = import_pycolmap().Reconstruction(str(model))
    observed = {Path(im.name).stem: np.array([p.xy for p in im.points2D]) for im in rec.images.values()}
    K = np.array([[doc["fl_x"], 0, doc["cx"]], [0, doc["fl_y"], doc["cy"]], [0, 0, 1]])
    for frame in doc["frames"]:
        w2c = np.linalg.inv(opengl_from_opencv(frame["transform_matrix"]))
        uvw = (xyz @ w2c[:3, :3].T + w2c[:3, 3]) @ K.T
        seen = observed[Path(frame["file_path"]).stem]  # the PLY's order is not the model's: the nearest
        gap = np.linalg.norm((uvw[:, None, :2] / uvw[:, None, 2:]) - seen[None], axis=-1).min(axis=1)
        assert gap.max() < 1e-4, (name, frame["file_path"], gap.max())
    return doc


def test_poses_and_masks_write_nerfstudio_files_in_their_frames(tiny_capture, tiny_decode, tmp_path):
    capture = tmp_path / "capture"
    truth = load_cameras(tiny_capture / "ground_truth" / "cameras.json")
    model = colmap_model(truth, capture / "sparse" / "0")
    run_poses(capture, tiny_decode, tmp_path / "poses", PosesConfig(use_masks=False))
    run_masks(capture, tmp_path / "poses", tmp_path / "masks", MasksConfig(),
              user_masks_dir=tiny_capture / "ground_truth" / "masks")

    # the masks stage's: the frame training uses (its cameras.json), with masks
    masks = tmp_path / "masks"
    doc = _check_file(masks, "transforms.json", model, masks=True)
    trained = load_cameras(masks / "cameras.json")
    assert doc["ply_file_path"] == "sparse_pc.ply"
    for a, b in zip(trained.cameras, load_transforms(masks / "transforms.json").cameras.cameras):
        assert (a.name, a.fx, a.fy, a.cx, a.cy) == (b.name, b.fx, b.fy, b.cx, b.cy)
        np.testing.assert_allclose(b.c2w, a.c2w, atol=1e-12)
    # applied_transform takes COLMAP's frame to the file's: cameras.json's to_colmap undone
    to_colmap = np.asarray(trained.frame.to_colmap)
    np.testing.assert_allclose(np.vstack([doc["applied_transform"], [0, 0, 0, 1]]) @ to_colmap, np.eye(4),
                               atol=1e-9)

    # and in COLMAP's frame: the model's own cameras, the identity applied
    colmap = _check_file(masks, "transforms_colmap.json", model, masks=True)
    assert colmap["ply_file_path"] == "sparse_pc_colmap.ply"
    np.testing.assert_allclose(colmap["applied_transform"], np.eye(4)[:3], atol=1e-12)
    for a, b in zip(truth.cameras, load_transforms(masks / "transforms_colmap.json").cameras.cameras):
        np.testing.assert_allclose(b.c2w, a.c2w, atol=1e-9)

    # the poses stage's: its own frame, no masks yet
    poses = _check_file(tmp_path / "poses", "transforms.json", model, masks=False)
    for a, b in zip(load_cameras(tmp_path / "poses" / "cameras.json").cameras,
                    load_transforms(tmp_path / "poses" / "transforms.json").cameras.cameras):
        np.testing.assert_allclose(b.c2w, a.c2w, atol=1e-12)
    assert poses["ply_file_path"] == "sparse_pc.ply"


def test_known_cameras_without_points_give_files_without_a_ply(tiny_capture, tiny_decode, tmp_path):
    """Known cameras from a cameras.json have no sparse points: no ply_file_path (splatfacto then starts from random
    points), the rest as with points."""
    capture = tmp_path / "capture"
    capture.mkdir()
    shutil.copy(tiny_capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    run_poses(capture, tiny_decode, tmp_path / "poses", PosesConfig(use_masks=False))
    run_masks(capture, tmp_path / "poses", tmp_path / "masks", MasksConfig(),
              user_masks_dir=tiny_capture / "ground_truth" / "masks")
    for folder, name in ((tmp_path / "poses", "transforms.json"), (tmp_path / "masks", "transforms.json"),
                         (tmp_path / "masks", "transforms_colmap.json")):
        doc = read_json(folder / name)
        assert "ply_file_path" not in doc and not list(folder.glob("*.ply"))
        for frame in doc["frames"]:
            _open_8bit(folder / frame["file_path"], 3, (doc["w"], doc["h"]))
