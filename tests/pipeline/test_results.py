"""Loading artifacts for notebooks: the decode folder's images come back as written."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import DecodeConfig
from pipeline.errors import InputError
from pipeline.imageio import srgb_to_linear, write_png
from pipeline.results import load_decode
from pipeline.stages.decode import run_decode


def test_load_decode_returns_each_image(tmp_path):
    cap = tmp_path / "cap"
    rng = np.random.default_rng(0)
    images = {}
    for i in range(3):
        img = rng.integers(0, 200, (12, 16, 3), dtype=np.uint8)  # below 255: nothing clips
        write_png(cap / f"im{i}.png", img)
        images[f"im{i}"] = img
    run_decode(cap, tmp_path / "decode", DecodeConfig())
    dec = load_decode(tmp_path / "decode")
    assert dec.names == ["im0", "im1", "im2"]
    for name, img in images.items():
        np.testing.assert_allclose(dec.linear(name), srgb_to_linear(img / 255.0), atol=1e-6)
        np.testing.assert_array_equal(dec.srgb(name), img)
        assert not dec.clipped(name).any()
    assert dec.manifest["stage"] == "decode"
    with pytest.raises(KeyError, match="im9"):
        dec.linear("im9")
    with pytest.raises(InputError, match="decode.json"):
        load_decode(tmp_path)
