"""The decode stage: simulated DNGs round-trip, exposure normalization, bad input, JPEG/PNG, real RAW files, and
``orca synth`` DNGs brought back to their ground-truth linear render (times scene.json's factor) by one white
balance and exposure normalization, measured as PSNR."""

from __future__ import annotations

import argparse
import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
import rawpy
from helpers import TESTDATA, colourful
from scipy.ndimage import binary_dilation

from pipeline.artifacts import read_json
from pipeline.config import DecodeConfig
from pipeline.dng import Exposure, decoded_scale, write_dng
from pipeline.errors import InputError
from pipeline.imageio import linear_to_srgb, read_exr, read_image, write_png
from pipeline.metrics import psnr
from pipeline.raw import apply_orientation
from pipeline.results import load_decode
from pipeline.stages.decode import register, run_decode
from pipeline.synth import SCENES, SynthOptions, render_capture

RAW_DIR = TESTDATA / "raw"
needs_testdata = pytest.mark.skipif(
    not RAW_DIR.is_dir(), reason=f"real-camera test data not found at {RAW_DIR} (clone the repo next to shared/)"
)

E_REF = Exposure(1 / 60, 100, 4.0)
E_OTHER = Exposure(1 / 250, 400, 5.6)
GAIN = 0.5


def cfg(**kw) -> DecodeConfig:
    return DecodeConfig(**kw)


def decode_json(out: Path) -> dict:
    return json.loads((out / "decode.json").read_text())


def write_srgb_png(path: Path, linear: np.ndarray, bits: int = 8) -> None:
    top = (1 << bits) - 1
    write_png(path, np.round(linear_to_srgb(linear) * top).astype(np.uint8 if bits == 8 else np.uint16))


# ------------------------------------------------------------------------------------ simulated DNG round trip


@pytest.mark.parametrize("noise", [True, False])
def test_dng_round_trip_psnr(tmp_path, noise):
    img = colourful()
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "a.dng", img, exposure=E_REF, gain=GAIN, noise=noise, rng=np.random.default_rng(7))
    res = run_decode(cap, tmp_path / "out", cfg(min_images=1))
    out = read_exr(tmp_path / "out" / "linear" / "a.exr")
    assert out.shape == img.shape and out.dtype == np.float32
    k = decoded_scale(GAIN, E_REF)  # what write_dng promises: decoded = k * linear_rgb
    p = psnr(out / k, img)
    print(f"\nDNG -> decode, AHD, noise {'on' if noise else 'off'}: PSNR {p:.1f} dB (peak 1.0, 96x128)")
    assert p > (40 if noise else 48)
    assert res.images[0].clipped_fraction == 0
    doc = decode_json(tmp_path / "out")
    assert doc["images"][0]["exif"]["iso"] == 100 and doc["reference_image"] == "a.dng"
    srgb = read_image(tmp_path / "out" / "srgb" / "a.png")
    assert srgb.dtype == np.uint8 and srgb.shape == img.shape
    mask = read_image(tmp_path / "out" / "clipped" / "a.png")
    assert mask.shape == img.shape[:2] and mask.max() == 0
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["stage"] == "decode" and "photo:a.dng" in manifest["inputs"]


def test_exposure_normalization(tmp_path):
    img = colourful()
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "a.dng", img, exposure=E_REF, gain=GAIN, rng=np.random.default_rng(1))
    write_dng(cap / "b.dng", img, exposure=E_OTHER, gain=GAIN, rng=np.random.default_rng(2))
    with rawpy.imread(str(cap / "a.dng")) as ra, rawpy.imread(str(cap / "b.dng")) as rb:
        sa = (ra.raw_image_visible.astype(float) - 512).mean()
        ratio_raw = sa / (rb.raw_image_visible.astype(float) - 512).mean()
    assert ratio_raw == pytest.approx(E_REF.value / E_OTHER.value, rel=0.01)  # the raw data really differ (~2x)
    res = run_decode(cap, tmp_path / "out", cfg(min_images=2))
    a = read_exr(tmp_path / "out" / "linear" / "a.exr")
    b = read_exr(tmp_path / "out" / "linear" / "b.exr")
    scales = {im.name: im.exposure_scale for im in res.images}
    assert scales["a"] == 1.0 and scales["b"] == pytest.approx(E_REF.value / E_OTHER.value, rel=1e-6)
    assert np.mean(b) / np.mean(a) == pytest.approx(1.0, abs=0.003)
    k = decoded_scale(GAIN, E_REF)
    p, pa, pb = psnr(a, b), psnr(a / k, img), psnr(b / k, img)
    print(f"\nsame scene at 1/60 s ISO 100 f/4 and 1/250 s ISO 400 f/5.6 (noise on): PSNR a vs b {p:.1f} dB, "
          f"a vs truth {pa:.1f} dB, b vs truth {pb:.1f} dB")
    assert p > 32 and pa > 40 and pb > 32  # b: half the light at 4x ISO, so more shot noise
    # noise off: equal up to quantization and demosaicing
    quiet = tmp_path / "quiet"
    quiet.mkdir()
    write_dng(quiet / "a.dng", img, exposure=E_REF, gain=GAIN, noise=False)
    write_dng(quiet / "b.dng", img, exposure=E_OTHER, gain=GAIN, noise=False)
    run_decode(quiet, tmp_path / "quiet_out", cfg(min_images=2))
    qa = read_exr(tmp_path / "quiet_out" / "linear" / "a.exr")
    qb = read_exr(tmp_path / "quiet_out" / "linear" / "b.exr")
    print(f"noise off: PSNR a vs b {psnr(qa, qb):.1f} dB")
    assert psnr(qa, qb) > 55
    # without normalization they differ by the exposure ratio
    run_decode(cap, tmp_path / "raw_out", cfg(min_images=2, normalize_exposure=False))
    b0 = read_exr(tmp_path / "raw_out" / "linear" / "b.exr")
    assert np.mean(a) / np.mean(b0) == pytest.approx(E_REF.value / E_OTHER.value, rel=0.01)


def test_white_balance_one_for_the_set(tmp_path):
    """The reference's as-shot WB applies to every RAW image, even one shot with another as-shot WB."""
    img = colourful()
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "a.dng", img, exposure=E_REF, gain=GAIN, noise=False)
    write_dng(cap / "b.dng", img, exposure=E_REF, gain=GAIN, noise=False, white_balance_illuminant=(1.0, 0.8, 0.5))
    run_decode(cap, tmp_path / "out", cfg(min_images=2))
    doc = decode_json(tmp_path / "out")
    with rawpy.imread(str(cap / "a.dng")) as r:
        wb = np.array(r.camera_whitebalance[:3]) / r.camera_whitebalance[1]
    assert np.allclose(doc["white_balance"]["multipliers"], wb, rtol=1e-6)
    assert [im["white_balance"] for im in doc["images"]] == [doc["white_balance"]["multipliers"]] * 2
    a = read_exr(tmp_path / "out" / "linear" / "a.exr")
    b = read_exr(tmp_path / "out" / "linear" / "b.exr")
    assert psnr(a, b) > 60
    # explicit multipliers win; the reference can be chosen by name
    run_decode(cap, tmp_path / "out2", cfg(min_images=2, white_balance=(2.0, 1.0, 1.5), reference_image="b"))
    doc2 = decode_json(tmp_path / "out2")
    assert doc2["white_balance"]["multipliers"] == [2.0, 1.0, 1.5] and doc2["reference_image"] == "b.dng"


def test_clipped_mask(tmp_path):
    img = colourful()
    img[40:50, 60:70] = 5.0  # a highlight far above the white level
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "a.dng", img, exposure=E_REF, gain=GAIN, noise=True, rng=np.random.default_rng(0))
    res = run_decode(cap, tmp_path / "out", cfg(min_images=1, downscale=2))
    mask = read_image(tmp_path / "out" / "clipped" / "a.png")
    assert mask.shape == (48, 64) and set(np.unique(mask)) == {0, 255}
    ys, xs = np.nonzero(mask)
    assert ys.min() == 20 and ys.max() == 24 and xs.min() == 30 and xs.max() == 34  # the photosites 40..49 / 2
    assert res.images[0].clipped_fraction == pytest.approx(25 / (48 * 64))
    assert read_exr(tmp_path / "out" / "linear" / "a.exr").shape == (48, 64, 3)
    # grown by 2 raw pixels on request: 38..51 / 2
    run_decode(cap, tmp_path / "out2", cfg(min_images=1, downscale=2, clip_dilate_raw=2))
    ys, xs = np.nonzero(read_image(tmp_path / "out2" / "clipped" / "a.png"))
    assert ys.min() == 19 and ys.max() == 25 and xs.min() == 29 and xs.max() == 35


def test_saturated_highlight_is_neutral(tmp_path):
    """A white light far above the white level decodes to the neutral level at which every channel saturates
    (max of the white-balance multipliers), not to the multipliers' tint through the colour matrix, and no
    clipped pixel exceeds that level (its rim mixes saturated and unsaturated photosites); a red light that
    saturates only the red photosites keeps its colour."""
    img = colourful()
    img[40:50, 60:70] = 5.0
    img[10:20, 10:20] = (10.0, 0.2, 0.2)
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "a.dng", img, exposure=E_REF, gain=GAIN, noise=False)
    run_decode(cap, tmp_path / "out", cfg(min_images=1))
    linear = read_exr(tmp_path / "out" / "linear" / "a.exr")
    wb = decode_json(tmp_path / "out")["white_balance"]["multipliers"]
    assert max(wb) > 2.0  # the sensor's daylight balance is far from neutral: the test has teeth
    np.testing.assert_allclose(linear[41:49, 61:69], max(wb), rtol=1e-5)
    assert linear[36:54, 56:74].max() <= max(wb) * (1 + 1e-6)
    red = linear[13:17, 13:17].reshape(-1, 3)
    assert np.all(red[:, 0] > 5 * red[:, 1]) and np.all(red[:, 0] > 5 * red[:, 2])
    clipped = read_image(tmp_path / "out" / "clipped" / "a.png") > 0
    assert clipped[40:50, 60:70].all() and clipped[36:54, 56:74].sum() == 100 and clipped[13:17, 13:17].all()


def test_raw_orientation_matches_libraw(tmp_path):
    img = colourful()
    cap = tmp_path / "cap"
    cap.mkdir()
    write_dng(cap / "r6.dng", img, exposure=E_REF, gain=GAIN, noise=False, orientation=6)
    write_dng(cap / "r8.dng", img, exposure=E_REF, gain=GAIN, noise=False, orientation=8)
    (tmp_path / "c1").mkdir()
    write_dng(tmp_path / "c1" / "r1.dng", img, exposure=E_REF, gain=GAIN, noise=False)
    run_decode(cap, tmp_path / "out", cfg(min_images=2))
    run_decode(tmp_path / "c1", tmp_path / "out1", cfg(min_images=1))
    upright = read_exr(tmp_path / "out1" / "linear" / "r1.exr")
    for o in (6, 8):
        got = read_exr(tmp_path / "out" / "linear" / f"r{o}.exr")
        assert got.shape == (128, 96, 3)
        assert np.array_equal(got, apply_orientation(upright, o))
        with rawpy.imread(str(cap / f"r{o}.dng")) as r:  # LibRaw's own flip agrees
            lib = r.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True)
        assert lib.shape == got.shape
        assert np.corrcoef(lib[..., 1].ravel(), got[..., 1].ravel())[0, 1] > 0.999


# ------------------------------------------------------------------------------------------------ bad input


def _three_dngs(cap: Path, n: int = 3) -> None:
    cap.mkdir(parents=True, exist_ok=True)
    img = colourful(32, 48)
    for i in range(n):
        write_dng(cap / f"p{i}.dng", img, exposure=E_REF, gain=GAIN, noise=False)


def test_corrupt_file_named(tmp_path):
    cap = tmp_path / "cap"
    _three_dngs(cap)
    (cap / "zz_corrupt.dng").write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    (cap / "zz_empty.nef").write_bytes(b"")
    with pytest.raises(InputError) as e:
        run_decode(cap, tmp_path / "out", cfg())
    msg = str(e.value)
    assert "zz_corrupt.dng" in msg and "zz_empty.nef" in msg and "2 of 5" in msg and "Fix:" in msg
    assert not (tmp_path / "out").exists()


@needs_testdata
def test_truncated_real_dng_named(tmp_path):
    cap = tmp_path / "cap"
    cap.mkdir()
    data = (RAW_DIR / "Blackmagic.dng").read_bytes()
    (cap / "half.dng").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as e:
        run_decode(cap, tmp_path / "out", cfg(min_images=1, downscale=4))
    assert "half.dng" in str(e.value) and "truncated" in str(e.value)
    # a small uncompressed DNG cut in half fails already when its header is read
    _three_dngs(tmp_path / "cap2")
    data = (tmp_path / "cap2" / "p1.dng").read_bytes()
    (tmp_path / "cap2" / "p1.dng").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="p1.dng"):
        run_decode(tmp_path / "cap2", tmp_path / "out", cfg())


def test_failed_run_leaves_previous_output_untouched(tmp_path):
    cap = tmp_path / "cap"
    cap.mkdir()
    lin = colourful(32, 48)
    for name in ("a", "b", "c"):
        write_srgb_png(cap / f"{name}.png", lin)
    out = tmp_path / "out"
    run_decode(cap, out, cfg())
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    # d.jpg's header is fine, its pixel data are cut off: the run fails after a, b, c were decoded
    from PIL import Image

    Image.fromarray((linear_to_srgb(lin) * 255).astype(np.uint8)).save(cap / "d.jpg", quality=95)
    data = (cap / "d.jpg").read_bytes()
    (cap / "d.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="d.jpg"):
        run_decode(cap, out, cfg())
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap", "out"]  # no .partial or .old folders left


def test_non_image_skipped_with_warning(tmp_path, caplog):
    cap = tmp_path / "cap"
    _three_dngs(cap / "images")
    (cap / "images" / "notes.txt").write_text("lens cap on the first try")
    (cap / "images" / "IMG.xmp").write_text("<x/>")
    (cap / "capture.yaml").write_text("decode:\n  min_images: 3\n")
    (cap / "masks").mkdir()
    write_png(cap / "masks" / "p0.png", np.zeros((32, 48), np.uint8))
    with caplog.at_level(logging.WARNING, logger="orca"):
        res = run_decode(cap, tmp_path / "out", cfg())
    warned = " ".join(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert "notes.txt" in warned and "IMG.xmp" in warned
    assert "capture.yaml" not in warned and "p0.png" not in warned
    assert sorted(res.skipped) == ["IMG.xmp", "notes.txt"]
    assert [im.name for im in res.images] == ["p0", "p1", "p2"]
    assert decode_json(tmp_path / "out")["photo_folder"] == "images"


def test_raw_plus_jpeg_prefers_raw(tmp_path, caplog):
    cap = tmp_path / "cap"
    _three_dngs(cap)
    write_srgb_png(cap / "p0.png", colourful(32, 48))
    with caplog.at_level(logging.WARNING, logger="orca"):
        res = run_decode(cap, tmp_path / "out", cfg())
    assert [im.source.name for im in res.images] == ["p0.dng", "p1.dng", "p2.dng"] and res.skipped == ("p0.png",)


def test_mixed_sizes(tmp_path):
    cap = tmp_path / "cap"
    _three_dngs(cap)
    write_dng(cap / "odd.dng", colourful(40, 48), exposure=E_REF, noise=False)
    with pytest.raises(InputError) as e:
        run_decode(cap, tmp_path / "out", cfg())
    msg = str(e.value)
    assert "odd.dng (48x40)" in msg and "3 are 48x32" in msg and "p0.dng" not in msg


def test_too_few_and_empty(tmp_path):
    cap = tmp_path / "cap"
    _three_dngs(cap, n=2)
    with pytest.raises(InputError, match=r"only 2 usable photo.*at least 3.*min_images"):
        run_decode(cap, tmp_path / "out", cfg())
    empty = tmp_path / "empty"
    (empty / "images").mkdir(parents=True)
    (empty / "images" / "readme.txt").write_text("x")
    with pytest.raises(InputError, match="no photos found"):
        run_decode(empty, tmp_path / "out", cfg())
    with pytest.raises(InputError, match="not found"):
        run_decode(tmp_path / "nowhere", tmp_path / "out", cfg())
    assert not (tmp_path / "out").exists()


def test_exif_missing_in_some_photos(tmp_path):
    cap = tmp_path / "cap"
    _three_dngs(cap)
    write_srgb_png(cap / "p3.png", colourful(32, 48))  # no EXIF at all
    with pytest.raises(InputError, match=r"missing in 1 of 4 photos \(p3.png\)"):
        run_decode(cap, tmp_path / "out", cfg())
    run_decode(cap, tmp_path / "out", cfg(normalize_exposure=False))


# -------------------------------------------------------------------------------------------- JPEG / PNG / TIFF


def test_png_linearization(tmp_path):
    lin = colourful(32, 48)
    cap = tmp_path / "cap"
    cap.mkdir()
    write_srgb_png(cap / "a8.png", lin, bits=8)
    write_srgb_png(cap / "b16.png", lin, bits=16)
    import tifffile

    tifffile.imwrite(cap / "c16.tif", np.round(linear_to_srgb(lin) * 65535).astype(np.uint16), photometric="rgb")
    run_decode(cap, tmp_path / "out", cfg(min_images=3))
    doc = decode_json(tmp_path / "out")
    assert {im["format"] for im in doc["images"]} == {"png", "tiff"}
    assert all(im["exposure_scale"] == 1.0 for im in doc["images"])
    a8 = read_exr(tmp_path / "out" / "linear" / "a8.exr")
    b16 = read_exr(tmp_path / "out" / "linear" / "b16.exr")
    c16 = read_exr(tmp_path / "out" / "linear" / "c16.exr")
    assert np.abs(b16 - lin).max() < 5e-5 and np.abs(c16 - lin).max() < 5e-5
    assert np.abs(a8 - lin).max() < 0.004  # 8-bit quantization: half a code step at the top of the range
    print(f"\nPNG linearization PSNR: 8-bit {psnr(a8, lin):.1f} dB, 16-bit {psnr(b16, lin):.1f} dB")


def _jpeg_with_exif(path: Path, image: np.ndarray, *, orientation: int = 1, exposure: Exposure | None = None):
    from PIL import Image
    from PIL.TiffImagePlugin import IFDRational

    exif = Image.Exif()
    exif[0x0112] = orientation
    exif[0x010F] = "PhoneCo"
    exif[0x0110] = "Phone 12"
    if exposure is not None:
        sub = exif.get_ifd(0x8769)
        sub[0x829A] = IFDRational(1, round(1 / exposure.shutter_s))
        sub[0x829D] = IFDRational(round(exposure.f_number * 10), 10)
        sub[0x8827] = int(exposure.iso)
        sub[0x920A] = IFDRational(42, 10)
        sub[0xA405] = 26
    if path.suffix == ".heic":
        import pillow_heif

        pillow_heif.register_heif_opener()
    Image.fromarray(image).save(path, exif=exif.tobytes(), quality=98)


def test_jpeg_orientation_and_exif(tmp_path):
    cap = tmp_path / "cap"
    cap.mkdir()
    stored = np.full((40, 60, 3), 128, np.uint8)
    stored[:8, :8] = (255, 0, 0)  # red in the stored top-left corner
    _jpeg_with_exif(cap / "rot6.jpg", stored, orientation=6, exposure=Exposure(1 / 50, 200, 2.8))
    _jpeg_with_exif(cap / "rot6b.jpg", stored, orientation=6, exposure=Exposure(1 / 100, 200, 2.8))
    res = run_decode(cap, tmp_path / "out", cfg(min_images=2))
    got = read_exr(tmp_path / "out" / "linear" / "rot6.exr")
    assert got.shape == (60, 40, 3)  # turned 90 degrees: displayed upright
    # orientation 6: the stored top-left corner is displayed at the top-right
    assert got[2, -3, 0] > 0.8 and got[2, -3, 1] < 0.1 and got[2, 2, 0] < 0.5
    from PIL import Image, ImageOps

    with Image.open(cap / "rot6.jpg") as im:
        ref = np.asarray(ImageOps.exif_transpose(im))
    assert np.array_equal(read_image(tmp_path / "out" / "srgb" / "rot6.png").shape, ref.shape)
    doc = decode_json(tmp_path / "out")
    exif = doc["images"][0]["exif"]
    assert exif["make"] == "PhoneCo" and exif["model"] == "Phone 12" and exif["orientation"] == 6
    assert exif["shutter_s"] == pytest.approx(1 / 50) and exif["iso"] == 200 and exif["f_number"] == 2.8
    assert exif["focal_length_mm"] == 4.2 and exif["focal_length_35mm"] == 26
    assert res.images[1].exposure_scale == pytest.approx(2.0)  # half the shutter time -> scaled up 2x
    b = read_exr(tmp_path / "out" / "linear" / "rot6b.exr")
    assert b.mean() == pytest.approx(2 * got.mean(), rel=1e-6)


def test_big_photos_are_downscaled_to_the_working_size_unless_a_downscale_is_given(tmp_path):
    cap = tmp_path / "cap"
    cap.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        _jpeg_with_exif(cap / f"IMG_{k}.jpg", rng.integers(0, 255, (300, 400, 3), np.uint8))
    for config, size in ((cfg(max_size=150), (133, 100)), (cfg(max_size=400), (400, 300)),
                         (cfg(max_size=150, downscale=2), (200, 150)), (cfg(max_size=0), (400, 300))):
        out = tmp_path / f"out_{config.max_size}_{config.downscale}"
        run_decode(cap, out, config)
        assert read_exr(out / "linear" / "IMG_0.exr").shape[1::-1] == size, (config, size)
        assert decode_json(out)["downscale"] == round(400 / size[0])


def test_heic_orientation_and_exif(tmp_path):
    """The iPhone's default format: decoded through pillow-heif upright (it applies the rotation the file
    records) with its EXIF, exposure normalized like any photo's."""
    cap = tmp_path / "cap"
    cap.mkdir()
    stored = np.full((40, 60, 3), 128, np.uint8)
    stored[:8, :8] = (255, 0, 0)
    _jpeg_with_exif(cap / "IMG_0001.heic", stored, orientation=6, exposure=Exposure(1 / 50, 200, 2.8))
    _jpeg_with_exif(cap / "IMG_0002.HEIC", stored, orientation=6, exposure=Exposure(1 / 100, 200, 2.8))
    res = run_decode(cap, tmp_path / "out", cfg(min_images=2))
    got = read_exr(tmp_path / "out" / "linear" / "IMG_0001.exr")
    assert got.shape == (60, 40, 3)  # displayed upright, as a JPEG with orientation 6
    assert got[2, -3, 0] > 0.8 and got[2, -3, 1] < 0.1 and got[2, 2, 0] < 0.5
    assert read_image(tmp_path / "out" / "srgb" / "IMG_0001.png").shape == (60, 40, 3)
    doc = decode_json(tmp_path / "out")
    exif = doc["images"][0]["exif"]
    assert doc["images"][0]["format"] == "heif" and exif["make"] == "PhoneCo" and exif["orientation"] == 1
    assert exif["shutter_s"] == pytest.approx(1 / 50) and exif["iso"] == 200 and exif["f_number"] == 2.8
    assert exif["focal_length_mm"] == 4.2 and exif["focal_length_35mm"] == 26
    assert res.images[1].exposure_scale == pytest.approx(2.0)
    (cap / "IMG_0003.heic").write_bytes(b"not a heic file at all")
    with pytest.raises(InputError, match="IMG_0003.heic.*HEIC"):
        run_decode(cap, tmp_path / "out2", cfg(min_images=2))


# --------------------------------------------------------------------------------------------- real RAW files


@needs_testdata
def test_real_kdc_linear_levels_wb(tmp_path):
    cap = tmp_path / "kdc"
    cap.mkdir()
    shutil.copy(RAW_DIR / "RAW_KODAK_DC50.KDC", cap / "k.KDC")  # tmp copy: decode reads a capture folder
    run_decode(cap, tmp_path / "cam", cfg(min_images=1, color_space="camera"))
    cam = read_exr(tmp_path / "cam" / "linear" / "k.exr")
    doc = decode_json(tmp_path / "cam")
    with rawpy.imread(str(cap / "k.KDC")) as r:
        raw = r.raw_image_visible.astype(np.float64)
        colors = r.raw_colors_visible
        black, white = min(r.black_level_per_channel), r.white_level
        wb = np.array(r.camera_whitebalance[:3]) / r.camera_whitebalance[1]
    assert np.allclose(doc["white_balance"]["multipliers"], wb)
    assert doc["images"][0]["levels"]["white_level"] == white == 16383
    # Linear and not rescaled: at every green photosite the decoded G is exactly (raw - black) / (white - black).
    green = (colors == 1) | (colors == 3)
    manual = (raw - black) / (white - black)
    assert np.abs(cam[..., 1][green] - manual[green]).max() < 2e-4
    # a configured black level is honoured (user_black): below it clips to 0
    run_decode(cap, tmp_path / "b100", cfg(min_images=1, color_space="camera", demosaic="LINEAR", black_level=100))
    b100 = read_exr(tmp_path / "b100" / "linear" / "k.exr")
    manual = np.clip((raw - 100) / (white - 100), 0, None)
    assert np.abs(b100[..., 1][green] - manual[green]).max() < 2e-4
    assert decode_json(tmp_path / "b100")["images"][0]["levels"]["black_level"] == 100
    # srgb: halving the signal (white level twice as far) halves the output - no gamma, no auto-brightness.
    # Bilinear demosaicing, because AHD picks edge directions from CIELab values, so it is not scale-invariant.
    run_decode(cap, tmp_path / "s1", cfg(min_images=1, demosaic="LINEAR"))
    run_decode(cap, tmp_path / "s2", cfg(min_images=1, demosaic="LINEAR", white_level=2 * white - black))
    s1 = read_exr(tmp_path / "s1" / "linear" / "k.exr")
    s2 = read_exr(tmp_path / "s2" / "linear" / "k.exr")
    clipped = read_image(tmp_path / "s1" / "clipped" / "k.png") > 0
    assert 0 < clipped.mean() < 0.01
    assert np.abs(s2 * 2 - s1)[~clipped].max() < 2e-4
    # A gamma-encoded decode would not be proportional to the raw data; ours is (median ratio over pixels).
    gamma = rawpy.imread(str(cap / "k.KDC")).postprocess(use_camera_wb=True, output_bps=16)[..., 1] / 65535
    mid = (s1[..., 1] > 0.02) & (s1[..., 1] < 0.5)
    assert np.median(gamma[mid] / s1[..., 1][mid]) > 1.3


@needs_testdata
def test_real_blackmagic_dng(tmp_path):
    cap = tmp_path / "bm"
    cap.mkdir()
    (cap / "bm.dng").symlink_to(RAW_DIR / "Blackmagic.dng")
    res = run_decode(cap, tmp_path / "out", cfg(min_images=1, downscale=4, color_space="camera", demosaic="LINEAR"))
    assert (res.images[0].width, res.images[0].height) == (1032, 544)
    cam = read_exr(tmp_path / "out" / "linear" / "bm.exr")
    doc = decode_json(tmp_path / "out")
    with rawpy.imread(str(RAW_DIR / "Blackmagic.dng")) as r:
        raw = r.raw_image_visible.astype(np.float64)
        colors = r.raw_colors_visible
        black, white = min(r.black_level_per_channel), r.white_level
        wb = np.array(r.camera_whitebalance[:3]) / r.camera_whitebalance[1]
    assert (black, white) == (512, 65535)
    assert np.allclose(doc["white_balance"]["multipliers"], wb)
    assert doc["white_balance"]["source"] == "as-shot of bm.dng"
    assert doc["images"][0]["exif"]["shutter_s"] is None  # this file has no exposure EXIF: left out, scale 1
    assert doc["exposure"]["fields_missing_in_all"] == ["shutter_s", "iso", "f_number"]
    # Levels honoured, output not rescaled: the decoded green (a 4x4 area average) has the mean of
    # (raw - black) / (white - black) over the green photosites (below black clips to 0, as LibRaw does).
    green = (colors == 1) | (colors == 3)
    manual = np.clip((raw - black) / (white - black), 0, None)
    assert cam[..., 1].mean() == pytest.approx(manual[green].mean(), rel=0.01)
    # red: white-balanced by the as-shot multiplier
    assert cam[..., 0].mean() == pytest.approx(wb[0] * manual[colors == 0].mean(), rel=0.02)
    # srgb (default) decode of the same file: plausible and linear sRGB, WB recorded per image
    run_decode(cap, tmp_path / "srgb", cfg(min_images=1, downscale=4))
    lin = read_exr(tmp_path / "srgb" / "linear" / "bm.exr")
    assert lin.shape == (544, 1032, 3) and 0.01 < lin.mean() < 1
    assert np.allclose(decode_json(tmp_path / "srgb")["images"][0]["white_balance"], wb)


# ---------------------------------------------------------------------------------------------------- CLI


def test_cli_register_and_defaults(tmp_path, monkeypatch):
    parser = argparse.ArgumentParser(prog="orca")
    sub = parser.add_subparsers(dest="command")
    register(sub)
    cap = tmp_path / "mycap"
    _three_dngs(cap)
    (cap / "capture.yaml").write_text("decode:\n  downscale: 2\n")
    monkeypatch.chdir(tmp_path)
    args = parser.parse_args(["decode", str(cap), "--set", "min_images=2", "--set", "decode.demosaic=VNG"])
    res = args.func(args)
    assert res.out_dir == Path("results/mycap/decode")
    assert (tmp_path / "results" / "mycap" / "decode" / "decode.json").is_file()
    assert res.images[0].width == 24  # capture.yaml's downscale 2
    manifest = json.loads((tmp_path / "results/mycap/decode/manifest.json").read_text())
    assert manifest["config"]["demosaic"] == "VNG" and manifest["config"]["min_images"] == 2
    help_text = sub.choices["decode"].format_help()
    assert "examples:" in help_text and "orca decode captures/mug" in help_text


# --------------------------------------------------------------- a synthetic capture against its ground truth


# The demo's resolution (demosaicing error depends on texture scale per pixel); few samples per pixel are
# enough because the photos and the ground truth come from the same render.
OPTIONS = dict(views=3, width=320, height=240, spp=8, env_size=8, coverage_spp=4, seed=2)


@pytest.fixture(scope="module")
def decoded_synth(tmp_path_factory) -> tuple[Path, Path]:
    pytest.importorskip("mitsuba")
    spec = SCENES["sphere"]
    capture = render_capture(spec, tmp_path_factory.mktemp("synth_decode") / "sphere", SynthOptions(**OPTIONS))
    out = capture.parent / "decode"
    run_decode(capture, out, DecodeConfig(min_images=2))
    return capture, out


def psnr_per_view(capture: Path, decode_dir: Path) -> dict[str, float]:
    factor = read_json(capture / "ground_truth" / "scene.json")["radiance_to_decoded"]["factor"]
    dec = load_decode(decode_dir)
    out = {}
    for name in dec.names:
        truth = read_exr(capture / "ground_truth" / "linear" / f"{name}.exr")[..., :3] * factor
        got = dec.linear(name)
        # clipped highlights carry no radiance to compare, nor (their colours demosaiced from saturated
        # photosites) the pixels next to them
        ok = ~binary_dilation(dec.clipped(name), np.ones((3, 3), bool)) & (truth.max(-1) < 1.0)
        out[name] = psnr(got, truth, ok)  # peak 1 = the white level
    return out


def test_synthetic_dngs_decode_back_to_ground_truth(decoded_synth):
    capture, decode_dir = decoded_synth
    scene = read_json(capture / "ground_truth" / "scene.json")
    assert len({p["exposure"]["value"] for p in scene["photos"]}) > 1, "views shot at different EXIF exposures"
    per_view = psnr_per_view(capture, decode_dir)
    print("orca synth DNG -> orca decode vs ground truth, PSNR per view (dB):",
          {k: round(v, 1) for k, v in per_view.items()})
    assert min(per_view.values()) > 32.0
