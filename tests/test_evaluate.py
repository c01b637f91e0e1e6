"""The evaluate stage: its metrics on analytic cases, the point-in-prop test, frames, and an end-to-end run
(a few training steps on the tiny synthetic capture, then ``run_evaluate`` and ``orca evaluate``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pipeline.alignment import Similarity
from pipeline.cameras import select_views
from pipeline.downscale import block_mean, downscale_depth
from pipeline.errors import InputError
from pipeline.figures import percentile_peak
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
from pipeline.props import Prop, points_from_depth, points_in_props

RNG = np.random.default_rng(0)


def _image(h=32, w=40):
    """A smooth, textured linear image in [0.05, 0.95]."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    base = 0.5 + 0.45 * np.sin(x[..., None] / 3 + np.array([0, 1, 2])) * np.cos(y[..., None] / 5)
    return base.astype(np.float32)


# -------------------------------------------------------------------------------------------- metrics


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


def test_percentile_peak_for_pictures():
    gt = np.linspace(0, 1, 1001, dtype=np.float32).reshape(1, 1001)
    assert percentile_peak(gt, np.ones_like(gt, bool)) == pytest.approx(0.99, abs=1e-3)
    assert math.isnan(percentile_peak(np.zeros((4, 4, 3)), np.ones((4, 4), bool)))


def test_ssim_works_on_tiny_images():
    img = _image(4, 6)
    assert ssim(img, img, np.ones((4, 6), bool), 1.0) == pytest.approx(1.0, abs=1e-6)


def _rotate_about_z(v, deg):
    a = np.deg2rad(deg)
    r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    return v @ r.T


def test_normals_rotated_by_a_known_angle():
    h, w = 8, 8
    theta = RNG.uniform(0, 2 * np.pi, (h, w))
    gt = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], -1)  # in the xy plane: z-rotation exact
    pred = _rotate_about_z(gt, 17.0) * 3.0  # not unit length: normalized inside
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


# ------------------------------------------------------------------------------------------------ props


def test_point_in_prop_for_each_kind():
    sphere = Prop("ball", "sphere", (1.0, 2.0, 0.5), (0.5, 0.5, 0.5))
    assert sphere.contains(np.array([1.0, 2.0, 1.0]))  # on the top
    assert not sphere.contains(np.array([1.0, 2.0, 1.1]))
    assert sphere.contains(np.array([1.0, 2.0, 1.04]), margin=0.05)

    cyl = Prop("drum", "cylinder", (0.0, 0.0, 1.0), (0.4, 0.4, 2.0))  # z in [0, 2]
    assert cyl.contains(np.array([0.39, 0.0, 1.99]))
    assert not cyl.contains(np.array([0.0, 0.0, 2.1]))
    assert not cyl.contains(np.array([0.3, 0.3, 1.0])), "outside the radius though inside the bounding square"
    assert cyl.contains(np.array([0.0, 0.0, 2.04]), margin=0.05)

    box = Prop("crate", "box", (0.0, 0.0, 0.0), (1.0, 0.2, 0.5), yaw_deg=90.0)  # long axis along y after yaw
    assert box.contains(np.array([0.0, 0.9, 0.0]))
    assert not box.contains(np.array([0.9, 0.0, 0.0])), "the yaw turned the long side away from x"
    assert box.contains(np.array([0.24, 0.0, 0.0]), margin=0.05)
    yawed = Prop("b", "box", (2.0, 1.0, 0.0), (1.0, 0.1, 1.0), yaw_deg=45.0)
    along = np.array([2.0, 1.0, 0.0]) + 0.9 * np.array([1, 1, 0]) / np.sqrt(2)
    across = np.array([2.0, 1.0, 0.0]) + 0.9 * np.array([1, -1, 0]) / np.sqrt(2)
    assert yawed.contains(along) and not yawed.contains(across)

    pts = np.stack([along, across, [np.inf, 0, 0], [1.0, 2.0, 0.5]])
    assert points_in_props(pts, [yawed, sphere], margin=0.0).tolist() == [True, False, False, True]


def test_points_from_depth_reproject_pixel_centres():
    K = np.array([[50.0, 0, 20], [0, 50.0, 15], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[:3, 3] = [1, 2, 3]
    depth = np.full((30, 40), 2.0)
    p = points_from_depth(depth, K, c2w)
    # pixel (col 19, row 14) has its centre at (19.5, 14.5): half a pixel left/up of the principal point
    assert np.allclose(p[14, 19], [1 + (-0.5 / 50) * 2, 2 + (-0.5 / 50) * 2, 5])
    assert np.allclose(p[..., 2], 5)


# ------------------------------------------------------------------------------------- frames, resampling


def test_alignment_moves_cameras_into_the_model_frame():
    from pipeline.cameras import look_at

    a = np.deg2rad(30)
    r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    s, t = 2.5, np.array([0.3, -1.0, 2.0])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = s * r, t
    align = Similarity.from_matrix(m)
    c2w_gt = look_at(np.array([3.0, 1.0, 2.0]), np.zeros(3))
    c2w_model = align.apply_inverse_c2w(c2w_gt)
    assert np.allclose(c2w_model[:3, :3].T @ c2w_model[:3, :3], np.eye(3)), "still rigid"
    # a point 2 model units in front of the model camera is 2 * s in front of the ground-truth one
    p_model = c2w_model[:3, 3] + 2 * c2w_model[:3, 2]
    p_gt = m[:3, :3] @ p_model + t
    assert np.allclose(p_gt, c2w_gt[:3, 3] + 2.0 * align.scale * c2w_gt[:3, 2])
    assert np.allclose(align.rotate(c2w_model[:3, 2]), c2w_gt[:3, 2])
    assert np.allclose(Similarity.identity().apply_inverse_c2w(c2w_gt), c2w_gt)
    with pytest.raises(InputError, match="similarity"):
        Similarity.from_matrix(np.diag([1.0, 2.0, 1.0, 1.0]))


def test_downscaling_keeps_only_whole_blocks():
    d = np.ones((4, 4), np.float32)
    d[0, 0] = np.inf
    out = downscale_depth(d, 2)
    assert np.isinf(out[0, 0]) and np.all(out.ravel()[1:] == 1)
    assert block_mean(np.arange(16, dtype=np.float32).reshape(4, 4), 2)[0, 0] == pytest.approx(2.5)


def test_select_views_evenly_spaced():
    names = [f"v{i}" for i in range(10)]
    assert select_views(names, None) == names
    assert select_views(names, 1) == ["v0"]
    assert select_views(names, 4) == ["v0", "v3", "v6", "v9"]
    assert select_views(names, 50) == names
    with pytest.raises(InputError, match="unknown view"):
        select_views(names, ["nope"])


# ----------------------------------------------------------------------------------------- end to end

TINY = [
    "train.iterations=4", "train.batch_rays=64", "train.mask_warmup=2", "train.logging.checkpoint_every=4",
    "train.logging.preview_every=4", "train.logging.preview_downscale=4", "train.logging.log_every=2",
    "train.render.n_coarse=8", "train.render.n_fine=4", "train.render.env_samples=6", "train.sdf.hash_grid.levels=4",
    "train.sdf.hash_grid.log2_table_size=10", "train.environment.hash_grid.log2_table_size=10", "train.sdf.hidden=16",
    "train.environment.hidden=16", "train.device=cpu",
]


@pytest.fixture(scope="module")
def tiny_train(tiny_capture, tiny_decode, tmp_path_factory):
    from pipeline.config import load_config
    from pipeline.stages.train import run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path_factory.mktemp("eval") / "train"
    cfg = load_config(preset="fast", overrides=TINY).train
    assert run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg) is not None
    return out


def test_run_evaluate_end_to_end(tiny_capture, tiny_train, tmp_path):
    from pipeline.evaluation import ENVIRONMENT_METRICS, OBJECT_METRICS
    from pipeline.stages.evaluate import run_evaluate

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "evaluate"
    res = run_evaluate(tiny_train, gt, out, views=1, downscale=2, device="cpu")
    saved = json.loads((out / "evaluate.json").read_text())
    assert saved["object"]["mean"] == res["object"]["mean"]
    (view,) = saved["object"]["views"]
    figures = saved["object"]["per_view"][view]
    for key in OBJECT_METRICS:
        assert figures[key] is not None and math.isfinite(figures[key]), key
    assert 0 <= figures["mask_iou"] <= 1 and 0 <= figures["normal_mae_deg"] <= 180
    assert figures["pixels"]["region"] > 0
    assert "interior" in saved["object"]["region"], "the synthetic ground truth has coverage/: interior region"
    env = saved["environment"]
    assert env["views"] and set(env["per_view"]) == set(env["views"])
    for key in ("psnr", "psnr_srgb", "ssim", "psnr_all", "ssim_all", "depth_absrel", "depth_rmse"):
        assert env["mean"][key] is not None and math.isfinite(env["mean"][key]), key
    assert set(env["mean"]) == set(ENVIRONMENT_METRICS)
    assert sum(v["pixels"]["props"] for v in env["per_view"].values()) > 0, "props are seen from the centre"

    from pipeline.imageio import read_exr, read_image

    h, w = 36 // 2, 48 // 2
    for suffix in ("rgb", "diffuse", "specular", "normal", "depth"):
        assert read_exr(out / f"{view}_{suffix}.exr").shape[:2] == (h, w)
    assert read_image(out / f"{view}_mask.png").shape == (h, w)
    for name in env["views"]:
        assert (out / f"env_{name}_rgb.exr").is_file() and (out / f"env_{name}_depth.exr").is_file()
    for grid in ("object_grid.png", "environment_grid.png", "manifest.json"):
        assert (out / grid).is_file(), grid


def test_cli_evaluate_and_its_errors(tiny_capture, tiny_train, tmp_path):
    from pipeline.cli import main

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "ev"
    assert main(["evaluate", str(tiny_train), "--ground-truth", str(gt), "--out", str(out), "--views", "1",
                 "--downscale", "3", "--no-environment", "--device", "cpu"]) == 0
    saved = json.loads((out / "evaluate.json").read_text())
    assert "environment" not in saved and saved["object"]["downscale"] == 3

    from pipeline.stages.evaluate import run_evaluate

    with pytest.raises(InputError, match=r"model\.pt[\s\S]*orca train"):
        run_evaluate(tmp_path, gt, tmp_path / "x", views=1, downscale=2)
    no_env = tmp_path / "gt_no_env"
    no_env.mkdir()
    for name in ("cameras.json", "scene.json"):
        (no_env / name).write_bytes((gt / name).read_bytes())
    with pytest.raises(InputError, match="--no-environment"):
        run_evaluate(tiny_train, no_env, tmp_path / "x", views=1, downscale=2)
    assert not (tmp_path / "x").exists()
    assert main(["evaluate", str(tiny_train), "--ground-truth", str(no_env), "--out", str(tmp_path / "x")]) == 2
