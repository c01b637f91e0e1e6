"""Real photos of a glossy object. The front end: the first 16 blowtorch photos (about 290 degrees of the
walk-around) decoded at 530x353, through ``orca decode``, ``orca poses`` and ``orca masks`` as
bench/blowtorch.py runs them, scored against the photographers' COLMAP poses and object masks; the masks alone on
every sixth photo with the photographers' cameras. Training on phone-like photos: test_phone_photos.py."""

from __future__ import annotations

import json

import pytest
from helpers import TESTDATA

from bench.blowtorch import build_capture, reference_mask, run_front_end, score, select_photos
from pipeline.metrics import iou

DATASET = TESTDATA / "real" / "blowtorch"
PHOTOS, DOWNSCALE = 16, 4  # 2120x1415 -> 530x353
RING_START = 38  # _DSC1618: the highest ring, the photos closest together
OVERRIDES = ["poses.num_threads=2"]
# Targets: every photo registered; poses as close to the reference as SfM at this size allows (1 px is about
# 0.07 degrees); the masks of the issue.
ROTATION_DEG_MEDIAN, ROTATION_DEG_MAX = 0.5, 2.0
# Of the highest ring's 16 photos: 12 registered with SIFT's affine shapes (poses.sift_affine_shape), 8 without;
# one photo of margin for the global mapper, whose result moves a little from machine to machine.
RING_REGISTERED_MIN = 11
CENTRE_MEDIAN_FRACTION, CENTRE_MAX_FRACTION = 0.02, 0.05  # of the cameras' mean distance from their centroid
IOU_MEDIAN, IOU_WORST = 0.95, 0.90
# Every sixth photo with the reference cameras: the sphere the masks ran in (the poses stage's is 1; the probes
# stopped at 1.5 with the tips cut before the share of views touching its outline was lowered) and the masks'
# floor: 0.878 / 0.763 measured here (0.836 / 0.750 before the final masks' colour trim), every third photo
# 0.859 / 0.812 (0.826 / 0.769 before).
SUBSET_EVERY, SUBSET_SPHERE_MIN, SUBSET_IOU_MEDIAN, SUBSET_IOU_WORST = 6, 1.5, 0.85, 0.71

pytestmark = pytest.mark.skipif(not DATASET.is_dir(), reason="no blowtorch test data")


def test_reference_masks_keep_their_object_at_the_decoded_size():
    """Every reference mask resized to decode.downscale 2's 1060x707 covers the share of the photo it covers
    at 2120x1415 (a 0/255 mask resized by area averaging can exceed 255 and be misread as 16-bit, and empty)."""
    for path in sorted((DATASET / "masks").glob("*.png")):
        full, small = reference_mask(path, (2120, 1415)), reference_mask(path, (1060, 707))
        assert small.shape == (707, 1060) and abs(small.mean() - full.mean()) < 0.01, path.name


def test_reference_masks_follow_the_poses_stages_undistortion():
    """When the poses stage resampled the photos to pinhole, the masks are in that grid: the reference is
    resampled the same way (as the pipeline resamples a user's mask), not compared where it was drawn."""
    import pycolmap

    from pipeline.undistort import undistort_mask, undistortion

    path = sorted((DATASET / "masks").glob("*.png"))[0]
    lens = pycolmap.Camera(model="SIMPLE_RADIAL", width=1060, height=707, params=[900.0, 530.0, 353.5, 0.25])
    maps, shift = undistortion([path.stem], [lens], 1.0)
    assert maps is not None and shift > 10
    drawn = reference_mask(path, (1060, 707))
    resampled = reference_mask(path, (1060, 707), maps)
    assert iou(resampled, undistort_mask(drawn, maps, path.stem)) > 0.98
    assert iou(drawn, undistort_mask(drawn, maps, path.stem)) < iou(resampled, undistort_mask(drawn, maps, path.stem))


@pytest.mark.slow(seconds=35)
def test_the_cameras_that_register_agree_with_the_reference(tmp_path):
    """16 photos of the walk-around's highest ring (from _DSC1618) at 530x353: the photos that get a camera have
    the photographers' camera, within a fraction of a degree (a wrong pose reported as good is the failure that
    matters most). 12 register at this size (with SIFT's affine shapes; 8 without them); all of them is the
    target below."""
    photos = select_photos(DATASET, start=RING_START, limit=PHOTOS)
    capture = build_capture(tmp_path / "blowtorch", photos, DOWNSCALE)
    runs = run_front_end(capture, tmp_path / "results", OVERRIDES, ("decode", "poses"))
    failed = [r for r in runs.values() if r.returncode]
    assert not failed, f"{failed[0].stage} failed:\n{failed[0].log[-3000:]}"
    figures = score(tmp_path / "results", photos, DATASET)
    poses = figures["poses"]
    print(figures["registered"], {k: v for k, v in poses.items() if k != "per_camera"})
    assert figures["registered"] >= RING_REGISTERED_MIN, figures["unregistered"]
    assert poses["rotation_deg_median"] <= ROTATION_DEG_MEDIAN and poses["rotation_deg_max"] <= ROTATION_DEG_MAX
    assert poses["center_median_fraction"] <= CENTRE_MEDIAN_FRACTION
    assert poses["center_max_fraction"] <= CENTRE_MAX_FRACTION


@pytest.mark.slow(seconds=230)
def test_masks_of_every_sixth_photo_with_the_reference_cameras_keep_the_whole_object(tmp_path):
    """12 photos (every sixth) at 530x353 with the photographers' cameras, through ``orca decode``, ``orca poses``
    (the LLFF import) and ``orca masks``: the burner and the handle reach past the 1.5 sphere in only 3 views'
    probes (they leave it towards the cameras), and the sphere must still grow to hold them (to 2.25). Measured
    0.878 / 0.763 (median / worst view; 0.836 / 0.750 without masks.trim_colour_log_odds). Below the issue's
    0.95 / 0.90: room between the handle and the tank, which a few views carve less well, and a plain white
    cabinet right behind the handle (_DSC1428) stay. Every third photo (``bench/blowtorch.py --known-poses --every
    3 --downscale 4``, twice as long): 0.859 / 0.812."""
    photos = select_photos(DATASET, every=SUBSET_EVERY)
    capture = build_capture(tmp_path / "blowtorch", photos, DOWNSCALE, known_poses=DATASET)
    runs = run_front_end(capture, tmp_path / "results", OVERRIDES)
    failed = [r for r in runs.values() if r.returncode]
    assert not failed, f"{failed[0].stage} failed:\n{failed[0].log[-3000:]}"
    report = json.loads((tmp_path / "results" / "masks" / "masks_report.json").read_text())
    masks = score(tmp_path / "results", photos, DATASET)["masks"]
    print(report["sphere_prior"]["probes"], {k: v for k, v in masks.items() if k != "per_view"})
    assert report["sphere_prior"]["radius"] > SUBSET_SPHERE_MIN
    assert masks["iou_median"] >= SUBSET_IOU_MEDIAN and masks["iou_worst"] >= SUBSET_IOU_WORST, masks["worst_view"]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "not reached yet: SfM starts no model on these 16 photos at 530 px (their neighbours are 20-60 degrees "
    "apart; 9-10 of 120 pairs verified), and with the reference cameras the automatic masks reach IoU median 0.88, "
    "worst 0.83 (carpet between the handle and the tank that the hull keeps)"))
def test_blowtorch_subset_registers_and_agrees_with_the_reference(tmp_path):
    photos = select_photos(DATASET, limit=PHOTOS)
    capture = build_capture(tmp_path / "blowtorch", photos, DOWNSCALE)
    runs = run_front_end(capture, tmp_path / "results", OVERRIDES)
    failed = [r for r in runs.values() if r.returncode]
    assert not failed, f"{failed[0].stage} failed:\n{failed[0].log[-3000:]}"
    figures = score(tmp_path / "results", photos, DATASET)
    print({s: round(r.seconds, 1) for s, r in runs.items()}, figures["poses"] | figures["masks"])
    assert figures["registered"] == figures["total"] == PHOTOS, figures["unregistered"]
    poses = figures["poses"]
    assert poses["rotation_deg_median"] <= ROTATION_DEG_MEDIAN and poses["rotation_deg_max"] <= ROTATION_DEG_MAX
    assert poses["center_median_fraction"] <= CENTRE_MEDIAN_FRACTION
    assert poses["center_max_fraction"] <= CENTRE_MAX_FRACTION
    masks = figures["masks"]
    assert masks["iou_median"] >= IOU_MEDIAN and masks["iou_worst"] >= IOU_WORST, masks["worst_view"]
