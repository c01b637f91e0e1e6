"""The report's figures (pipeline.report): training curves from a long metrics log, the photos' appearance."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import png_data_uri_image

from pipeline.report.curves import appearance_figure, read_metrics, training_curves
from pipeline.report.reader import figure_data_uri


def test_training_curves_from_a_long_metrics_log(tmp_path):
    """A long log (running mean drawn), NaN PSNRs, zero loss terms on log axes, and a damaged line."""
    lines = [json.dumps({"step": s, "seconds": 0.1 * s, "phase": "mask" if s <= 50 else "joint", "loss": 1 / s,
                         "psnr_object": float("nan") if s % 7 == 0 else 10 + s / 20, "beta": 0.1 / s, "lr": 1e-3,
                         "mask": 0.1, "photometric": 0.0 if s <= 50 else 0.05}) for s in range(1, 301)]
    path = tmp_path / "metrics.jsonl"
    path.write_text("\n".join([*lines[:150], '{"step": 151, "lo', "", *lines[150:]]) + "\n")
    rows, bad = read_metrics(path)
    assert len(rows) == 300 and bad == 1
    fig = training_curves(rows)
    image = png_data_uri_image(figure_data_uri(fig))
    assert image.shape[0] > 300 and image.shape[1] > 600
    loss, psnr = fig.axes[0], fig.axes[1]
    assert loss.get_yscale() == "log" and any("running mean" in t.get_text() for t in loss.get_legend().get_texts())
    assert np.nanmax(psnr.lines[0].get_ydata()) == pytest.approx(10 + 300 / 20)
    assert any(np.allclose(line.get_xdata(), 51)
               for a in fig.axes for line in a.lines[1:] if len(line.get_xdata()) == 2)


def test_the_appearance_figure_shows_each_photos_exposure_and_white_balance():
    gains = {"IMG_1": [2.0, 2.0, 2.0], "IMG_2": [0.5, 0.5, 0.5], "IMG_3": [1.2, 1.0, 0.8]}
    fig = appearance_figure(gains)
    stops, balance = fig.axes[0], fig.axes[1]
    assert [b.get_height() for b in stops.patches] == pytest.approx([1.0, -1.0, np.log2([1.2, 1.0, 0.8]).mean()])
    red, blue = balance.lines
    assert red.get_ydata() == pytest.approx([1.0, 1.0, 1.2]) and blue.get_ydata() == pytest.approx([1.0, 1.0, 0.8])
    assert [t.get_text() for t in stops.get_xticklabels()] == list(gains)
    assert png_data_uri_image(figure_data_uri(fig)).shape[1] > 600
