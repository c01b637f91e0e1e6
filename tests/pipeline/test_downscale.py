"""Downscaling for evaluation (pipeline.downscale): whole blocks only, depth without mixing hits and misses."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.downscale import block_mean, downscale_depth


def test_downscaling_keeps_only_whole_blocks():
    d = np.ones((4, 4), np.float32)
    d[0, 0] = np.inf
    out = downscale_depth(d, 2)
    assert np.isinf(out[0, 0]) and np.all(out.ravel()[1:] == 1)
    assert block_mean(np.arange(16, dtype=np.float32).reshape(4, 4), 2)[0, 0] == pytest.approx(2.5)
