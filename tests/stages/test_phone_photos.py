"""Real photos as a phone would give them: blowtorch photos re-encoded each with its own exposure and white balance
(bench/phone_photos.py), trained with the photographers' cameras and masks. The realistic run (the phone capture
and the originals trained apart, held-out PSNR of both) is bench/phone_photos.py's; here one training sees each
view twice, as shot and re-encoded, and must tell the two appearances apart."""

from __future__ import annotations

import pytest
from helpers import TESTDATA

from bench.blowtorch import select_photos
from bench.phone_photos import run_paired

DATASET = TESTDATA / "real" / "blowtorch"
PHOTOS, EVERY, DOWNSCALE = 8, 8, 16  # 8 photos around the walk-around at 132x88
TRAIN = ["train.iterations=300", "train.mask_warmup=100"]
# How closely the gains must come back: the median relative error over photos and channels (0.048 measured; the
# largest 0.23) and the share of the applied exposures' variance (in stops) recovered (0.94 measured). Trained apart,
# the phone capture and the originals reach 0.10 and 0.81 (bench/results/phone_photos.jsonl): there a photo whose
# view no other photo shares can have its tint painted into the room instead.
GAIN_ERROR_MEDIAN, EXPOSURE_EXPLAINED = 0.10, 0.85

pytestmark = pytest.mark.skipif(not DATASET.is_dir(), reason="no blowtorch test data")


@pytest.mark.slow(seconds=300)
def test_each_photos_exposure_and_white_balance_come_back_from_its_view_shot_twice(tmp_path):
    figures = run_paired(tmp_path, select_photos(DATASET, every=EVERY, limit=PHOTOS), DOWNSCALE, TRAIN)
    print({k: v for k, v in figures.items() if k != "per_photo"})
    assert figures["applied_stops_range"] > 0.8  # differences worth recovering
    assert figures["gain_error_median"] < GAIN_ERROR_MEDIAN, figures["per_photo"]
    assert figures["exposure_explained"] > EXPOSURE_EXPLAINED, figures["per_photo"]
