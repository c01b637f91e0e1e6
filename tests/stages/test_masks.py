"""The masks stage: user masks of every encoding override on the tiny capture and follow the poses stage's
undistortion, masks that do not fit are refused, and the automatic method on the 20-view synthetic sphere
against its ground-truth masks."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from bench.front_end import with_known_cameras
from pipeline.artifacts import read_json
from pipeline.cameras import load_cameras
from pipeline.config import MasksConfig, PosesConfig
from pipeline.errors import InputError
from pipeline.imageio import read_image, write_png
from pipeline.metrics import iou
from pipeline.results import load_decode, load_masks
from pipeline.stages.masks import run_masks
from pipeline.stages.poses import run_poses
from pipeline.training_data import support_plane
from pipeline.transforms import to_transforms
from pipeline.undistort import recorded_undistortion


def known_poses(capture: Path, decode: Path, out: Path) -> Path:
    """The poses stage on the capture's ground-truth cameras (the known-cameras path, no SfM)."""
    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    try:
        run_poses(capture, decode, out, PosesConfig(use_masks=False))
    finally:
        (capture / "cameras.json").unlink()
    return out


def test_user_masks_of_every_encoding_override_on_the_tiny_capture(tiny_capture, tiny_decode, tmp_path):
    poses = known_poses(tiny_capture, tiny_decode, tmp_path / "poses")
    truth_dir = tiny_capture / "ground_truth" / "masks"
    names = sorted(p.stem for p in truth_dir.glob("*.png"))
    user = tmp_path / "user"
    user.mkdir()
    for k, n in enumerate(names):  # a different encoding per view
        m = read_image(truth_dir / f"{n}.png") > 127
        if k % 3 == 0:
            write_png(user / f"{n}.png", m.astype(np.uint8))  # 0/1
        elif k % 3 == 1:
            rgba = np.dstack([np.full(m.shape + (3,), 90, np.uint8), m.astype(np.uint8) * 255])
            write_png(user / f"{n}.png", rgba)  # alpha channel
        else:
            write_png(user / f"{n}.png", m.astype(np.uint16) * 65535)  # 16-bit
    result = run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=user)
    out = load_masks(tmp_path / "masks")
    for n in names:
        np.testing.assert_array_equal(out.mask(n), read_image(truth_dir / f"{n}.png") > 127)
    assert result.user == names
    report = out.report
    assert all(v["source"] == "user" for v in report["views"])
    assert report["user_masks"]["views"] == names
    for f in ("contact_sheet.jpg", "manifest.json", "cameras.json", *(f"overlays/{n}.jpg" for n in names)):
        assert (tmp_path / "masks" / f).is_file(), f
    # The re-normalized cameras: the tight sphere is the unit sphere; images still found.
    sphere = report["object_sphere"]
    assert 0.2 < sphere["radius"] <= 1.0
    cams, before = out.cameras(), read_json(poses / "cameras.json")
    c_old = np.asarray(before["cameras"][0]["camera_to_world"])[:3, 3]
    c_new = cams.cameras[0].c2w[:3, 3]
    np.testing.assert_allclose(c_new, (c_old - sphere["centre"]) / sphere["radius"], atol=1e-9)
    assert all((tmp_path / "masks" / c.image).is_file() for c in cams.cameras)


@pytest.mark.slow(seconds=85)
def test_user_masks_larger_than_the_poses_stage_sphere_give_the_whole_object(sfm_sphere_capture, sfm_sphere_decode,
                                                                             tmp_path):
    """The poses stage's sphere is a guess (here from a framing window far smaller than the object): the user's
    masks reach past it, and the hull they are carved into must grow until it holds the whole object. The object's
    sphere is then the one found from the default guess (same re-normalized cameras) and the masks agree with it."""
    truth_dir = sfm_sphere_capture / "ground_truth" / "masks"
    capture = with_known_cameras(sfm_sphere_capture, tmp_path / "capture")  # the shared capture stays as it is
    spheres = {}
    for window in (None, 0.25):
        config = PosesConfig(use_masks=False) if window is None else PosesConfig(use_masks=False, object_window=window)
        run_poses(capture, sfm_sphere_decode, tmp_path / f"poses_{window}", config)
        run_masks(capture, tmp_path / f"poses_{window}", tmp_path / f"masks_{window}", MasksConfig(),
                  user_masks_dir=truth_dir)
        out = load_masks(tmp_path / f"masks_{window}")
        assert out.report["agreement"]["median"] > 0.9, out.report["agreement"]
        spheres[window] = (out.report, out.cameras().c2w())
    small = spheres[0.25][0]["sphere_prior"]
    assert small["radius"] > 1.0 and small["probes"][0]["touching_views"] > 0, small
    np.testing.assert_allclose(spheres[0.25][1][:, :3, 3], spheres[None][1][:, :3, 3], atol=0.05)


def test_no_support_plane_is_a_warning_in_the_report(tiny_capture, tiny_decode, tmp_path):
    """Without the floor the automatic masks keep a skirt of it: the report says so (4 views at 48x36: too few
    and too small to find the floor; at a colour tolerance of 1e-4 no plane explains it anyway), and says nothing
    when every view has the user's mask. The sphere test below finds the floor and does not warn."""
    poses = known_poses(tiny_capture, tiny_decode, tmp_path / "poses")
    run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(floor_threshold=1e-4, rounds=1, user_masks="ignore"))
    report = load_masks(tmp_path / "masks").report
    assert report["support_plane"] is None and any("no support plane" in w for w in report["warnings"])
    run_masks(tiny_capture, poses, tmp_path / "user", MasksConfig(floor_threshold=1e-4),
              user_masks_dir=tiny_capture / "ground_truth" / "masks")
    assert not any("no support plane" in w for w in load_masks(tmp_path / "user").report["warnings"])


def test_masks_that_find_the_object_nowhere_stop_the_stage_and_write_nothing(tiny_capture, tiny_decode, tmp_path,
                                                                            monkeypatch):
    """When the rounds' hull empties (on a poster floor a torus's masks collapsed this way with SfM's cameras), every
    automatic mask is empty: the stage stops with what to do instead of writing empty masks that training cannot
    use."""
    import pipeline.stages.masks as stage
    from pipeline.errors import OrcaError
    from pipeline.masking.segment import Segmentation

    def nothing_found(views, opts, **kwargs):
        empty = [np.zeros(v.shape, bool) for v in views]
        return Segmentation(empty, empty, empty, [None] * len(views), [None] * len(views), None,
                            np.zeros((2, 2, 2), np.float32))

    poses = known_poses(tiny_capture, tiny_decode, tmp_path / "poses")
    monkeypatch.setattr(stage, "segment", nothing_found)
    with pytest.raises(OrcaError, match="found the object in none of the 4 photos") as err:
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(user_masks="ignore"))
    assert "CAPTURE/masks" in str(err.value)
    assert not (tmp_path / "masks").exists()


def test_user_masks_follow_the_poses_stage_undistortion(tiny_capture, tiny_decode, tmp_path):
    """A user draws on the photos; when the poses stage resampled them to pinhole, the masks must be resampled
    the same way, or they are off by the lens' shift (a few pixels towards the corners)."""
    capture = tmp_path / "capture"
    capture.mkdir()
    doc = to_transforms(load_cameras(tiny_capture / "ground_truth" / "cameras.json"))
    doc.update(k1=0.2, k2=0.02)
    (capture / "transforms.json").write_text(json.dumps(doc))
    poses = tmp_path / "poses"
    run_poses(capture, tiny_decode, poses, PosesConfig(use_masks=False))
    und = recorded_undistortion(load_decode(poses / "undistorted"))
    assert und is not None and und.max_shift_px > 1
    truth_dir = tiny_capture / "ground_truth" / "masks"
    names = sorted(p.stem for p in truth_dir.glob("*.png"))
    user = tmp_path / "user"
    user.mkdir()
    h, w = read_image(truth_dir / f"{names[0]}.png").shape[:2]
    drawn = np.zeros((h, w), bool)
    drawn[: h // 3, : w // 3] = True  # a block in the corner, where the lens moves pixels most
    for n in names:
        write_png(user / f"{n}.png", drawn.astype(np.uint8) * 255)
    run_masks(capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=user)
    got = load_masks(tmp_path / "masks").mask(names[0])
    assert iou(got, drawn) < 0.97, "the mask must move with the image"
    np.testing.assert_array_equal(got, cv2.remap(drawn.astype(np.uint8), *und.maps[und.lens_of[names[0]]],
                                                 cv2.INTER_NEAREST) > 0)


def test_user_masks_that_do_not_fit_are_refused_with_the_fix(tiny_capture, tiny_decode, tmp_path):
    poses = known_poses(tiny_capture, tiny_decode, tmp_path / "poses")
    user = tmp_path / "user"
    user.mkdir()
    write_png(user / "IMG_0001.png", np.zeros((48, 36), np.uint8))
    with pytest.raises(InputError, match="aspect ratio") as err:
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=user)
    assert "IMG_0001.png" in str(err.value) and "Fix:" in str(err.value)
    (user / "IMG_0001.png").unlink()
    write_png(user / "photo1.png", np.zeros((36, 48), np.uint8))
    with pytest.raises(InputError, match="photo1.png"):
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=user)
    assert not (tmp_path / "masks").exists()


def automatic(capture: Path, decode: Path, tmp_path: Path, config: MasksConfig, user: Path | None = None):
    poses = known_poses(capture, decode, tmp_path / "poses")
    started = time.time()
    result = run_masks(capture, poses, tmp_path / "masks", config, user_masks_dir=user)
    seconds = time.time() - started
    truth = capture / "ground_truth" / "masks"
    scores = {n: iou(read_image(tmp_path / "masks" / "masks" / f"{n}.png") > 127,
                     read_image(truth / f"{n}.png") > 127) for n in result.names}
    return result, scores, seconds


@pytest.mark.slow(seconds=70)
def test_automatic_masks_of_the_sphere_with_two_corrections(sfm_sphere_capture, sfm_sphere_decode, tmp_path):
    """20 views of the glossy sphere: automatic masks against the ground truth; two views get the user's
    masks (corrections), which are written as given."""
    user = tmp_path / "user"
    user.mkdir()
    for n in ("IMG_0003", "IMG_0011"):
        shutil.copy(sfm_sphere_capture / "ground_truth" / "masks" / f"{n}.png", user / f"{n}.png")
    result, scores, seconds = automatic(sfm_sphere_capture, sfm_sphere_decode, tmp_path, MasksConfig(), user)
    auto = [s for n, s in scores.items() if n not in result.user]
    print(f"sphere: IoU median {np.median(auto):.3f} worst {min(auto):.3f} in {seconds:.0f} s; {result.agreement}")
    assert result.user == ["IMG_0003", "IMG_0011"] and scores["IMG_0003"] == scores["IMG_0011"] == 1.0
    # the goal is 0.95 / 0.85 (0.90 for the real blowtorch's worst view). The capture's render noise
    # differs from run to run (docs/method.md, Known limits), and so do the figures: the median 0.959-0.970, the
    # worst view 0.918-0.955 over eight runs of the same code (in one looked at, IMG_0007, where the top of a
    # cylinder in front of the sphere stayed in the mask: the sweep in front of the hull, docs/masks.md step 4)
    assert np.median(auto) >= 0.95 and min(auto) >= 0.90, scores
    # the tight sphere: the true object (radius 1 in the ground truth's frame) nearly fills it
    assert result.sphere_radius < 0.8
    report = load_masks(tmp_path / "masks").report  # the floor was found: no warning about it
    assert report["support_plane"] is not None and not any("no support plane" in w for w in report["warnings"])
    # right masks leave few unexplained pixels beside them (0.17 of a mask's area on cached evidence): no second run
    beside = report["unexplained_beside"]
    assert beside["median"] < beside["threshold"] and not beside["retried"], beside
    assert not any("made again" in w for w in report["warnings"])
    # the floor in the training frame (the object's sphere is the unit sphere): the sphere stands on it, its
    # centre 1 / sphere_margin of that sphere above it; its own cameras only are in that frame
    masks_dir = tmp_path / "masks" / "masks"
    normal, offset = support_plane(masks_dir, tmp_path / "masks" / "cameras.json")
    print("support plane in the training frame", normal, offset)
    assert 0.8 < -offset < 1.1
    assert support_plane(masks_dir, sfm_sphere_capture / "ground_truth" / "cameras.json") is None
    # the known cameras' triangulated points seeded the masks: the floor's as background
    sparse = report["sparse_points"]
    print("sparse points", sparse["points"], sparse["labels"])
    assert sparse["points"] > 100 and sparse["labels"]["floor"] > 0.2 * sparse["points"]
