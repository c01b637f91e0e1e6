"""Structure from motion (pipeline.sfm): which photo pairs are matched, how many must register."""

from __future__ import annotations

from pipeline.config import PosesConfig
from pipeline.sfm import required_registered, sequential_pairs


def test_sequential_pairs_wrap_around_the_capture():
    names = [f"IMG_{i:02d}" for i in range(10)]
    pairs = set(sequential_pairs(names, overlap=2))
    assert ("IMG_00", "IMG_01") in pairs and ("IMG_00", "IMG_02") in pairs
    assert ("IMG_00", "IMG_09") in pairs and ("IMG_01", "IMG_09") in pairs  # the circle closes
    assert ("IMG_00", "IMG_04") in pairs and ("IMG_00", "IMG_08") in pairs  # 2^k apart: loop closure
    assert ("IMG_00", "IMG_05") not in pairs
    assert all(a < b for a, b in pairs)
    assert len(sequential_pairs(names, overlap=20)) == 45  # more neighbours than photos: every pair once


def test_required_registered_uses_count_and_fraction():
    config = PosesConfig(min_registered=3, min_registered_fraction=0.75)
    assert required_registered(20, config) == 15
    assert required_registered(3, config) == 3
    assert required_registered(2, config) == 2  # never more than there are photos
