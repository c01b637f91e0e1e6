"""Known cameras in a capture: which file is used, and LLFF's rows matched to the decoded photos with their
intrinsics scaled to the decoded size."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import TESTDATA, orbit_cameras

from pipeline.cameras import save_cameras
from pipeline.errors import InputError
from pipeline.known_cameras import find_known_cameras, posed_from_file
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
