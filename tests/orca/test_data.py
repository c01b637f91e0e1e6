"""Ray sampling from posed images (orca/data.py): object and background pixels are drawn where they are."""

from __future__ import annotations

import torch

from orca.data import ImageSet


def _images(mask: torch.Tensor) -> ImageSet:
    n, h, w = mask.shape
    K = torch.tensor([[10.0, 0, w / 2], [0, 10.0, h / 2], [0, 0, 1]]).expand(n, 3, 3)
    c2w = torch.eye(4).expand(n, 4, 4).clone()
    c2w[:, 2, 3] = -3.0
    images = mask[..., None].float().expand(n, h, w, 3).clone()  # colour 1 on the object, 0 off it
    return ImageSet(images, mask, torch.ones_like(mask), K.clone(), c2w)


def test_object_and_background_samples_come_from_their_pixels():
    mask = torch.zeros(2, 8, 10, dtype=torch.bool)
    mask[:, 2:5, 3:7] = True
    data = _images(mask)
    g = torch.Generator().manual_seed(0)
    on = data.sample(200, object_fraction=1.0, generator=g)
    assert bool((on.mask == 1).all()) and bool((on.rgb == 1).all())
    off = data.sample_background(300, generator=g)
    assert off is not None and off.origins.shape == (300, 3)
    assert bool((off.mask == 0).all()) and bool((off.rgb == 0).all())
    mixed = data.sample(400, object_fraction=0.5, generator=g)
    # the first half is on the object; the rest is anywhere (12/80 of the pixels are on it)
    assert bool((mixed.mask[:200] == 1).all()) and 0 < mixed.mask[200:].mean() < 0.4


def test_no_background_pixels_gives_no_background_batch():
    data = _images(torch.ones(1, 4, 4, dtype=torch.bool))
    assert data.sample_background(16) is None
