"""Structure from motion (pipeline.sfm): which photo pairs are matched, how many must register."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.cameras import look_at
from pipeline.config import PosesConfig
from pipeline.sfm import (
    CameraGroup,
    Mapping,
    colmap_name,
    equalized_gray,
    extract_features,
    extraction_options,
    kept_run,
    required_registered,
    sequential_pairs,
    viewing_pairs,
)
from pipeline.signals import import_pycolmap


def test_sequential_pairs_wrap_around_the_capture():
    names = [f"IMG_{i:02d}" for i in range(10)]
    pairs = set(sequential_pairs(names, overlap=2))
    assert ("IMG_00", "IMG_01") in pairs and ("IMG_00", "IMG_02") in pairs
    assert ("IMG_00", "IMG_09") in pairs and ("IMG_01", "IMG_09") in pairs  # the circle closes
    assert ("IMG_00", "IMG_04") in pairs and ("IMG_00", "IMG_08") in pairs  # 2^k apart: loop closure
    assert ("IMG_00", "IMG_05") not in pairs
    assert all(a < b for a, b in pairs)
    assert len(sequential_pairs(names, overlap=20)) == 45  # more neighbours than photos: every pair once


def test_known_cameras_pair_each_photo_with_its_nearest_views():
    """Two rings around an object, shuffled names: each photo pairs with the photos beside it on its own ring and
    the nearest of the other ring, never across the object; forward-facing cameras in a row (axes alike) pair by
    position."""
    rng = np.random.default_rng(0)
    angles = np.radians(np.arange(0, 360, 15))
    eyes = [(3 * np.cos(a), 3 * np.sin(a), h) for h in (0.5, 2.0) for a in angles]
    order = rng.permutation(len(eyes))
    names = [f"IMG_{i:02d}" for i in range(len(eyes))]
    c2w = np.stack([look_at(np.array(eyes[i]), np.zeros(3)) for i in order])
    pairs = viewing_pairs(names, c2w, k=4)
    assert all(a < b for a, b in pairs) and len(set(pairs)) == len(pairs)
    assert len(names) * 4 / 2 <= len(pairs) <= len(names) * 4
    eye = np.array(eyes)[order]
    by_name = dict(zip(names, eye))
    partners = {n: set() for n in names}
    for a, b in pairs:
        partners[a].add(b)
        partners[b].add(a)
    for n, ps in partners.items():
        assert len(ps) >= 4
        apart = [np.degrees(np.arccos(np.clip(by_name[n][:2] @ by_name[p][:2] / 9, -1, 1))) for p in ps]
        assert max(apart) <= 30.0 + 1e-6, (n, apart)  # within two steps of the ring, or straight above/below
    row = np.stack([look_at(np.array([x, -3.0, 0.0]), np.array([x, 0.0, 0.0])) for x in range(10)])
    beside = {(str(i), str(i + 1)) for i in range(9)}
    assert set(viewing_pairs([str(i) for i in range(10)], row, k=2)) == beside | {("0", "2"), ("7", "9")}  # the ends
    assert len(viewing_pairs(names[:3], c2w[:3], k=12)) == 3  # more neighbours than photos: every pair once


def test_required_registered_uses_count_and_fraction():
    config = PosesConfig(min_registered=3, min_registered_fraction=0.75)
    assert required_registered(20, config) == 15
    assert required_registered(3, config) == 3
    assert required_registered(2, config) == 2  # never more than there are photos


def test_a_photo_darkened_by_stops_keeps_its_sift_features_once_equalized():
    """SIFT keeps a feature only above a fixed contrast: a photo that exposure normalization darkened by nearly
    three stops loses almost all of them; equalized to the common median grey it keeps as many as the original."""
    pycolmap = import_pycolmap()
    rng = np.random.default_rng(0)
    texture = sum(cv2.resize(rng.uniform(0, 1, (s, s)).astype(np.float32), (256, 256), interpolation=cv2.INTER_CUBIC)
                  for s in (8, 16, 32, 64))
    photo = (255 * (texture - texture.min()) / (texture.max() - texture.min())).astype(np.uint8)
    dark = (0.15 * photo).astype(np.uint8)
    sift = pycolmap.FeatureExtractor.create()

    def features(image: np.ndarray) -> int:
        return len(sift.extract_from_uint8_array(np.ascontiguousarray(image))[0])  # (keypoints, descriptors)

    equalized = equalized_gray(np.repeat(dark[..., None], 3, -1), 0.45)
    assert abs(np.median(equalized) - 255 * 0.45) < 2
    np.testing.assert_array_equal(equalized_gray(photo, 0.3), photo)  # bright enough: as it is
    assert features(dark) < 0.1 * features(photo)
    assert features(equalized) > 0.8 * features(photo)


def test_a_lower_sift_peak_threshold_finds_features_in_faint_texture():
    """A plain wall's faint shading is below SIFT's default contrast threshold; poses.sift_peak_threshold reaches
    the extractor the poses stage builds and, lowered, finds features there."""
    pycolmap = import_pycolmap()
    rng = np.random.default_rng(1)
    texture = sum(cv2.resize(rng.uniform(0, 1, (s, s)).astype(np.float32), (256, 256), interpolation=cv2.INTER_CUBIC)
                  for s in (8, 16, 32))
    faint = (120 + 4 * (texture - texture.mean()) / texture.std()).clip(0, 255).astype(np.uint8)  # std 4 levels

    def features(peak: float) -> int:
        options = extraction_options(PosesConfig(sift_peak_threshold=peak), threads=1, affine_shape=False)
        assert options.sift.peak_threshold == peak
        sift = pycolmap.FeatureExtractor.create(options, pycolmap.Device.cpu)
        return len(sift.extract_from_uint8_array(faint)[0])

    default, low = features(PosesConfig().sift_peak_threshold), features(0.002)
    assert default < 10 and low > 100, (default, low)


def mapper_run(c2w: np.ndarray, names: list[str], frame_seed: int) -> Mapping:
    """A mapper run's model of the cameras ``c2w`` ``(N, 4, 4)``, in a frame of its own (a rotation, a scale and a
    shift drawn from ``frame_seed``): a real pycolmap model, as the mapper returns it."""
    from helpers import random_rotation

    pycolmap = import_pycolmap()
    rng = np.random.default_rng(frame_seed)
    frame = np.eye(4)
    frame[:3, :3], frame[:3, 3] = random_rotation(rng), rng.normal(size=3)
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=640, height=480,
                                                    params=[500, 500, 320, 240], camera_id=1))
    for i, (m, name) in enumerate(zip(c2w, names), 1):
        placed = frame @ m
        placed[:3, 3] *= 2.0  # the run's scale
        w2c = np.linalg.inv(placed)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"{name}.png", camera_id=1, image_id=i),
                                         pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3]))
    return Mapping([rec], "incremental", None)


def test_the_run_the_others_agree_with_is_kept():
    """Three mapper runs of a 24-photo orbit: the first carried 6 neighbours 25 degrees round the object, the
    other two agree. The second is kept whole; the first's 6 are the ones in dispute."""
    from helpers import rotation

    angles = np.radians(np.arange(0, 360, 15))
    c2w = np.stack([look_at(np.array([3 * np.cos(a), 3 * np.sin(a), 1.0]), np.zeros(3)) for a in angles])
    names = [f"IMG_{i:02d}" for i in range(len(c2w))]
    turn = np.eye(4)
    turn[:3, :3] = rotation([0, 0, 1], 25.0)
    wrong = c2w.copy()
    wrong[5:11] = turn @ wrong[5:11]
    config = PosesConfig()
    runs = [mapper_run(wrong, names, 1), mapper_run(c2w, names, 2), mapper_run(c2w, names, 3)]
    kept, doubts = kept_run(runs, config)
    assert kept == 1 and doubts == [names[5:11], [], []]
    # two runs that disagree leave each in dispute with the other: the first is kept, its block doubted
    kept, doubts = kept_run(runs[:2], config)
    assert kept == 0 and doubts == [names[5:11], names[5:11]]
    # runs that agree: the first is kept and nothing is disputed
    assert kept_run([runs[1], runs[2]], config) == (0, [[], []])


@pytest.mark.parametrize("exif_focal", ["start", "prior"])
def test_an_exif_focal_length_is_a_start_unless_configured_as_a_prior(tmp_path, exif_focal):
    """COLMAP takes a camera's focal length as known when it is marked as a prior (essential matrices with it);
    EXIF's whole-millimetre value is only the estimate's start by default. A calibration stays a prior."""
    pycolmap = import_pycolmap()
    rng = np.random.default_rng(0)
    names = ["IMG_0", "IMG_1"]
    for n in names:
        texture = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.uint8), (0, 0), 1.5)
        cv2.imwrite(str(tmp_path / colmap_name(n)), texture)
    config = PosesConfig(exif_focal=exif_focal)
    groups = [CameraGroup(tuple(names), "SIMPLE_RADIAL", (150.0, 80.0, 60.0, 0.0), "EXIF",
                          prior=config.exif_focal == "prior")]
    db_path = tmp_path / "database.db"
    pycolmap.Database.open(db_path).close()
    extract_features(db_path, tmp_path, groups, extraction_options(config, 1, affine_shape=False))
    db = pycolmap.Database.open(db_path)
    try:
        (camera,) = db.read_all_cameras()
        assert camera.has_prior_focal_length == (exif_focal == "prior")
        assert camera.params[0] == 150.0  # the start either way
        assert all(db.num_keypoints_for_image(im.image_id) > 0 for im in db.read_all_images())
    finally:
        db.close()
