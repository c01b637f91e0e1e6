"""The simulated camera (pipeline.dng): the DNG it writes is read back by LibRaw (rawpy), exifread, tifffile."""

from __future__ import annotations

import datetime as dt

import exifread
import numpy as np
import pytest
import rawpy
import tifffile
from helpers import colourful

from pipeline.dng import (
    Exposure,
    SensorModel,
    as_shot_neutral,
    decoded_from_linear,
    decoded_scale,
    simulate_raw,
    write_dng,
)
from pipeline.metrics import psnr

EXP = Exposure(shutter_s=1 / 100, iso=100, f_number=4.0)
WHEN = dt.datetime(2024, 5, 6, 7, 8, 9)


def test_exposure_value():
    assert Exposure(1 / 100, 100, 4.0).value == pytest.approx(0.01 / 16)
    assert Exposure(1 / 50, 200, 4.0).value == pytest.approx(4 * Exposure(1 / 100, 100, 4.0).value)
    assert Exposure(1, 100, 1).value == 1.0
    with pytest.raises(ValueError):
        Exposure(0, 100, 4)


def test_sensor_defaults():
    s = SensorModel()
    assert s.white_level == 16383 and s.black_level == 512 and s.cfa_pattern == "RGGB"
    c = s.camera_from_srgb
    assert c[1].sum() == pytest.approx(1.0)
    assert not np.allclose(c / c.sum(axis=1, keepdims=True), np.eye(3), atol=0.05)  # really not identity
    assert np.allclose(decoded_from_linear(s), np.eye(3), atol=1e-9)
    n = as_shot_neutral(s)
    assert n[1] == 1 and 0.2 < n[0] < 0.6 and 0.5 < n[2] < 0.9


def test_mosaic_round_trip_exact(tmp_path):
    img = colourful()
    for noise in (False, True):
        path = tmp_path / f"n{int(noise)}.dng"
        info = write_dng(path, img, exposure=EXP, noise=noise, rng=np.random.default_rng(3), datetime=WHEN)
        expected = simulate_raw(img, exposure=EXP, noise=noise, rng=np.random.default_rng(3))
        with rawpy.imread(str(path)) as r:
            assert np.array_equal(r.raw_image_visible, expected)
            assert r.raw_pattern.tolist() == [[0, 1], [3, 2]] and r.color_desc == b"RGBG"  # RGGB
        assert info["width"] == 128 and info["height"] == 96 and info["noise"] is noise


def test_rawpy_metadata(tmp_path):
    s = SensorModel()
    path = tmp_path / "a.dng"
    info = write_dng(path, colourful(), exposure=EXP, noise=False, datetime=WHEN, focal_length_mm=35,
                     focal_length_35mm=52)
    with rawpy.imread(str(path)) as r:
        assert list(r.black_level_per_channel) == [512] * 4
        assert r.white_level == 16383
        wb = np.array(r.camera_whitebalance[:3])
        assert np.allclose(wb / wb[1], 1 / as_shot_neutral(s), rtol=1e-5)
        assert np.allclose(wb / wb[1], info["white_balance_multipliers"], rtol=1e-5)
        # LibRaw's camera -> sRGB matrix, derived from ColorMatrix1 (D65): the inverse of our row-normalized C.
        c = s.camera_from_srgb
        assert np.allclose(r.color_matrix[:, :3], np.linalg.inv(c / c.sum(1, keepdims=True)), atol=2e-4)
        # LibRaw 0.22 leaves rgb_xyz_matrix (cam_xyz) empty for DNGs, the real Blackmagic DNG included.
        assert r.rgb_xyz_matrix.shape == (4, 3)
        o = r.other
        assert o.iso_speed == 100 and o.shutter_speed == pytest.approx(0.01) and o.aperture == pytest.approx(4)
        assert o.focal_length == pytest.approx(35)
        assert o.timestamp == WHEN
        assert r.sizes.flip == 0


def test_exif_and_dng_tags(tmp_path):
    path = tmp_path / "a.dng"
    write_dng(path, colourful(), exposure=Exposure(1 / 250, 400, 5.6), noise=False, datetime=WHEN,
              focal_length_mm=24.5, focal_length_35mm=35)
    with open(path, "rb") as f:
        tags = exifread.process_file(f, details=False)
    assert str(tags["EXIF ExposureTime"]) == "1/250"
    assert float(tags["EXIF FNumber"].values[0]) == pytest.approx(5.6)
    assert tags["EXIF ISOSpeedRatings"].values[0] == 400
    assert float(tags["EXIF FocalLength"].values[0]) == pytest.approx(24.5)
    assert tags["EXIF FocalLengthIn35mmFilm"].values[0] == 35
    assert str(tags["EXIF DateTimeOriginal"]) == "2024:05:06 07:08:09"
    assert str(tags["Image Make"]) == "ORCa" and str(tags["Image Model"]) == "SimCam 14"
    assert tags["Image Orientation"].values[0] == 1
    with tifffile.TiffFile(path) as tf:
        page = tf.pages.first
        t = {tag.code: tag.value for tag in page.tags.values()}
    assert t[254] == 0 and t[262] == 32803 and t[258] == 16
    assert tuple(t[33421]) == (2, 2) and bytes(t[33422]) == b"\x00\x01\x01\x02"
    assert bytes(t[50706]) == b"\x01\x04\x00\x00"
    assert t[50708] == "ORCa SimCam 14"
    assert t[50778] == 21 and t[50714] == 512 and t[50717] == 16383
    assert len(t[50721]) == 18 and len(t[50728]) == 6


def test_raw_scales_with_exposure_value(tmp_path):
    img = colourful()
    a, b = Exposure(1 / 60, 100, 4.0), Exposure(1 / 250, 400, 5.6)
    ra = simulate_raw(img, exposure=a, gain=0.4, noise=False).astype(np.float64) - 512
    rb = simulate_raw(img, exposure=b, gain=0.4, noise=False).astype(np.float64) - 512
    ratio = a.value / b.value
    assert abs(ratio - 1) > 0.5  # the two really differ
    big = (ra > 500) & (ra < 15000)
    assert big.mean() > 0.5
    assert np.allclose(rb[big] * ratio, ra[big], rtol=0.01, atol=1.5 * ratio)


def test_noise_statistics():
    s = SensorModel()
    flat = np.full((200, 200, 3), 0.1, np.float32)
    exp = Exposure(1 / 100, 400, 4.0)
    raw = simulate_raw(flat, exposure=exp, noise=True, rng=np.random.default_rng(0)).astype(np.float64)
    green = np.concatenate([raw[0::2, 1::2].ravel(), raw[1::2, 0::2].ravel()])
    e_full = s.full_well_e * 100 / exp.iso
    span = s.white_level - s.black_level
    signal = 0.1 * 4 * span  # ISO 400 = 4x the full-scale exposure's signal
    mean_e = signal / span * e_full
    expected_sd = np.sqrt(mean_e + s.read_noise_e**2) * span / e_full
    expected_sd = np.sqrt(expected_sd**2 + s.read_noise_dn**2 + 1 / 12)
    assert green.mean() - 512 == pytest.approx(signal, rel=0.005)
    assert green.std() == pytest.approx(expected_sd, rel=0.05)


def test_clipping_at_white_level(tmp_path):
    img = colourful() * 50
    info = write_dng(tmp_path / "c.dng", img, exposure=EXP, noise=True, rng=np.random.default_rng(1))
    with rawpy.imread(str(tmp_path / "c.dng")) as r:
        assert r.raw_image_visible.max() == 16383
    assert info["clipped_fraction"] > 0.5


def test_bad_input_writes_nothing(tmp_path):
    img = colourful()
    img[3, 3, 0] = np.nan
    with pytest.raises(ValueError):
        write_dng(tmp_path / "x.dng", img, exposure=EXP)
    with pytest.raises(ValueError):
        write_dng(tmp_path / "x.dng", img[..., :2], exposure=EXP)
    assert list(tmp_path.iterdir()) == []


def test_rawpy_decode_matches_input(tmp_path):
    """The plain LibRaw pipeline (as-shot WB, linear, sRGB) returns the input times decoded_scale."""
    img = colourful()
    exp = Exposure(1 / 60, 100, 4.0)
    gain = 0.5
    info = write_dng(tmp_path / "d.dng", img, exposure=exp, gain=gain, noise=False)
    k = decoded_scale(gain, exp)
    assert np.allclose(info["decoded_from_linear"], k * np.eye(3), atol=1e-9)
    with rawpy.imread(str(tmp_path / "d.dng")) as r:
        out = r.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, adjust_maximum_thr=0,
                            use_camera_wb=True, output_color=rawpy.ColorSpace.sRGB)
    out = out.astype(np.float64) / 65535 / k
    p = psnr(out[2:-2, 2:-2], img[2:-2, 2:-2])
    print(f"rawpy AHD, no noise: PSNR {p:.1f} dB")
    assert p > 40
