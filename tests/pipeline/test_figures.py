"""Figures (pipeline.figures): the brightness a picture is scaled to."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.figures import percentile_peak


def test_percentile_peak_for_pictures():
    gt = np.linspace(0, 1, 1001, dtype=np.float32).reshape(1, 1001)
    assert percentile_peak(gt, np.ones_like(gt, bool)) == pytest.approx(0.99, abs=1e-3)
    assert math.isnan(percentile_peak(np.zeros((4, 4, 3)), np.ones((4, 4), bool)))
