"""The evaluation's metrics (pipeline.metrics) on analytic cases: PSNR and SSIM over masks and highlights, normal
angles, mask IoU, depth errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import rotation

from pipeline.metrics import (
    PSNR_CAP_DB,
    depth_errors,
    iou,
    normal_angular_error,
    psnr,
    psnr_linear,
    psnr_srgb,
    ssim,
)

RNG = np.random.default_rng(0)


def _image(h=32, w=40):
    """A smooth, textured linear image in [0.05, 0.95]."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    base = 0.5 + 0.45 * np.sin(x[..., None] / 3 + np.array([0, 1, 2])) * np.cos(y[..., None] / 5)
    return base.astype(np.float32)


def test_identical_images_score_the_cap_and_ssim_one():
    img = _image()
    mask = np.ones(img.shape[:2], bool)
    assert psnr(img, img, mask, 1.0) == pytest.approx(PSNR_CAP_DB)
    assert ssim(img, img, mask, 1.0) == pytest.approx(1.0, abs=1e-6)


def test_psnr_of_known_noise():
    img = _image(64, 64)
    sigma = 0.02
    noisy = img + RNG.normal(0, sigma, img.shape).astype(np.float32)
    mask = np.ones(img.shape[:2], bool)
    mse = np.mean((noisy - img).astype(np.float64) ** 2)
    expected = 10 * math.log10(1.0 / sigma**2)
    assert psnr(noisy, img, mask, 1.0) == pytest.approx(expected, abs=0.1)
    assert psnr(noisy, img, mask, 2.0) == pytest.approx(10 * math.log10(4.0 / mse), abs=1e-6)
    assert ssim(noisy, img, mask, 1.0) < 0.99


def test_psnr_and_ssim_count_only_masked_pixels():
    img = _image()
    bad = img.copy()
    bad[:, 20:] = 0.0  # wrong outside the mask only
    mask = np.zeros(img.shape[:2], bool)
    mask[8:24, 2:12] = True  # 8+ pixels from the damage: the SSIM window (sigma 1.5) does not reach it
    assert psnr(bad, img, mask, 1.0) == pytest.approx(PSNR_CAP_DB)
    assert ssim(bad, img, mask, 1.0) == pytest.approx(1.0, abs=1e-6)
    assert math.isnan(psnr(img, img, np.zeros_like(mask), 1.0)), "empty mask: undefined, not perfect"
    assert psnr(bad, img, ~mask, 1.0) < 20


def test_sensor_psnrs_clip_highlights_and_the_raw_psnr_does_not():
    gt = _image()
    pred = gt.copy()
    gt[10, 10] = pred[10, 10] = 0.5
    gt[5, 5], pred[5, 5] = 8.0, 2.0  # a light source: both above the white level
    mask = np.ones(gt.shape[:2], bool)
    assert psnr_srgb(pred, gt, mask) == pytest.approx(PSNR_CAP_DB), "both clip to white: no visible error"
    assert psnr(pred, gt, mask) == pytest.approx(10 * math.log10(1 / (36 * 3 / gt.size)), abs=1e-4)
    assert psnr_linear(pred, gt, mask) == pytest.approx(PSNR_CAP_DB), "the sensor saw white in both"
    worse = pred.copy()
    worse[10, 10] = 0.25
    assert psnr_srgb(worse, gt, mask) < 60


def test_ssim_works_on_tiny_images():
    img = _image(4, 6)
    assert ssim(img, img, np.ones((4, 6), bool), 1.0) == pytest.approx(1.0, abs=1e-6)


def test_normals_rotated_by_a_known_angle():
    h, w = 8, 8
    theta = RNG.uniform(0, 2 * np.pi, (h, w))
    gt = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], -1)  # in the xy plane: z-rotation exact
    pred = gt @ rotation([0, 0, 1], 17.0).T * 3.0  # not unit length: normalized inside
    mask = np.ones((h, w), bool)
    assert normal_angular_error(pred, gt, mask) == pytest.approx(17.0, abs=1e-6)
    gt_off = gt.copy()
    gt_off[:, :4] = 0  # no ground-truth normal there: not counted
    pred_off = pred.copy()
    pred_off[:, :4] = -pred_off[:, :4]
    assert normal_angular_error(pred_off, gt_off, mask) == pytest.approx(17.0, abs=1e-6)
    assert normal_angular_error(np.zeros_like(gt), gt, mask) == pytest.approx(90.0), "no prediction: 90 deg"


def test_mask_iou():
    a = np.zeros((10, 10), bool)
    b = np.zeros((10, 10), bool)
    a[:, :6] = True
    b[:, 4:] = True
    assert iou(a, b) == pytest.approx(20 / 100)
    assert iou(a, a) == 1.0


def test_depth_scaled_by_1_1_has_absrel_0_1():
    gt = RNG.uniform(1, 5, (6, 7)).astype(np.float32)
    gt[0, 0] = np.inf  # no hit: not counted
    pred = np.where(np.isfinite(gt), gt * 1.1, 3.0)
    e = depth_errors(pred, gt)
    assert e["absrel"] == pytest.approx(0.1, rel=1e-5)
    assert e["pixels"] == 41
    finite = gt[np.isfinite(gt)]
    assert e["rmse"] == pytest.approx(np.sqrt(np.mean((0.1 * finite.astype(np.float64)) ** 2)), rel=1e-5)
    assert depth_errors(pred, gt, np.zeros(gt.shape, bool))["pixels"] == 0
