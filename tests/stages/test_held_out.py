"""Evaluation without ground truth: photos held out of training (train.holdout_every) against the model's renders
of their cameras (`orca evaluate --held-out`), on the tiny capture."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import TINY_TRAIN

from pipeline.artifacts import read_json
from pipeline.cli import main as orca
from pipeline.config import load_config
from pipeline.downscale import block_all, block_mean
from pipeline.errors import InputError
from pipeline.evaluation import held_out_figures
from pipeline.imageio import read_exr
from pipeline.mask_file import read_mask
from pipeline.metrics import PSNR_CAP_DB
from pipeline.results import load_decode, load_evaluate
from pipeline.stages.evaluate import run_held_out
from pipeline.stages.train import run_train


def _cfg(*extra):
    return load_config(preset="fast", overrides=[*TINY_TRAIN, *extra]).train


def test_held_out_figures_of_a_perfect_render_and_of_one_wrong_on_the_object():
    rng = np.random.default_rng(0)
    photo = rng.random((24, 32, 3)).astype(np.float32) * 0.8
    mask = np.zeros((24, 32), bool)
    mask[6:18, 8:24] = True
    valid = np.ones((24, 32), bool)
    perfect = held_out_figures(photo, photo, mask, valid)
    assert perfect["psnr_srgb_object"] == perfect["psnr_srgb_frame"] == PSNR_CAP_DB
    assert perfect["ssim_object"] == pytest.approx(1.0) and perfect["pixels"] == {"object": 192, "frame": 768}
    wrong = np.where(mask[..., None], photo * 0.5, photo)
    f = held_out_figures(wrong, photo, mask, valid)
    assert f["psnr_srgb_object"] < f["psnr_srgb_frame"] < PSNR_CAP_DB and f["ssim_object"] < f["ssim_frame"]
    # clipped pixels are not compared: a wrong object that is all clipped counts as right
    assert held_out_figures(wrong, photo, mask, ~mask)["psnr_srgb_frame"] == PSNR_CAP_DB
    # a photo exposed and white-balanced otherwise than the render: the matched figures see through it
    tinted = held_out_figures(photo * np.array([1.4, 1.0, 0.7], np.float32), photo, mask, valid)
    assert tinted["psnr_srgb_frame"] < 25 and tinted["psnr_srgb_frame_matched"] > 50
    assert tinted["gains"] == pytest.approx([1 / 1.4, 1.0, 1 / 0.7], rel=1e-4)
    assert f["psnr_srgb_object_matched"] < f["psnr_srgb_frame_matched"] < PSNR_CAP_DB


def test_held_out_photos_are_left_out_of_training_and_compared_with_the_renders(tiny_capture, tiny_decode, tmp_path):
    gt = tiny_capture / "ground_truth"
    train = tmp_path / "train"
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", train, _cfg("train.holdout_every=2"))
    report = read_json(train / "train_report.json")
    names = load_decode(tiny_decode).names
    assert report["held_out"] == names[::2] and report["images"] == names[1::2]

    out = tmp_path / "evaluate"
    assert orca(["evaluate", str(train), "--held-out", "--cameras", str(gt / "cameras.json"), "--masks",
                 str(gt / "masks"), "--out", str(out), "--device", "cpu"]) == 0
    result = read_json(out / "evaluate.json")["held_out"]
    assert result["views"] == names[::2] and (out / "held_out_grid.png").is_file()
    assert load_evaluate(out).grid("held_out").ndim == 3  # the loader the notebook uses reads it
    decoded = load_decode(tiny_decode)
    for name in names[::2]:  # the figures are those of the written render against the photo
        render = read_exr(out / f"{name}_render.exr")
        h, w = render.shape[:2]
        expected = held_out_figures(render, block_mean(decoded.linear(name), 1), read_mask(gt / "masks" / f"{name}.png",
                                    (w, h)), block_all(~decoded.clipped(name), 1))
        assert result["per_view"][name]["psnr_srgb_frame"] == pytest.approx(expected["psnr_srgb_frame"])
        assert result["per_view"][name]["psnr_srgb_object"] == pytest.approx(expected["psnr_srgb_object"])
        assert 5 < expected["psnr_srgb_frame"] < PSNR_CAP_DB
    assert result["mean"]["psnr_srgb_frame"] == pytest.approx(
        np.mean([result["per_view"][n]["psnr_srgb_frame"] for n in names[::2]]))
    # the report's evaluation section shows them
    from pipeline.report.reader import Reader
    from pipeline.report.sections import section_evaluate

    summary, data = section_evaluate(Reader(tmp_path, tmp_path / "page"), out)
    assert summary.startswith("held-out photos: object") and data["held_out"]["views"] == 2
    assert data["held_out"]["grid"] is not None and data["object"] is None

    everything = tmp_path / "train_all"
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", everything, _cfg())
    with pytest.raises(InputError, match="(?s)none was held out.*holdout_every"):
        run_held_out(everything, tmp_path / "evaluate_all", cameras=gt / "cameras.json", masks=gt / "masks")
