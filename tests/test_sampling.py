"""Ray bounds, inverse-CDF sampling, and surface-seeking upsampling on an analytic sphere."""

from __future__ import annotations

import pytest
import torch

from orca.sampling import ray_sphere_bounds, sample_pdf, upsample_to_surface

pytestmark = pytest.mark.usefixtures("float64")


def test_ray_sphere_bounds_hit_miss_and_inside():
    o = torch.tensor([[0.0, 0, -3], [0.0, 2, -3], [0.0, 0, 0]])
    d = torch.tensor([[0.0, 0, 1], [0.0, 0, 1], [1.0, 0, 0]])
    near, far, hit = ray_sphere_bounds(o, d, 1.0)
    assert hit.tolist() == [True, False, True]
    torch.testing.assert_close(near, torch.tensor([2.0, 0, 0]))
    torch.testing.assert_close(far, torch.tensor([4.0, 0, 1]))


def test_sample_pdf_follows_the_histogram():
    bins = torch.linspace(0, 4, 5).expand(1, 5)
    weights = torch.tensor([[0.0, 3.0, 1.0, 0.0]])
    s = sample_pdf(bins, weights, 20000, generator=torch.Generator().manual_seed(0))
    in_second = ((s >= 1) & (s < 2)).double().mean()
    assert abs(in_second - 0.75) < 0.02 and ((s < 1) | (s >= 3)).double().mean() < 0.01
    det = sample_pdf(bins, weights, 8, deterministic=True)
    assert (det[:, 1:] >= det[:, :-1]).all()


def test_upsampling_concentrates_samples_at_the_sphere_surface():
    radius = 0.5
    sdf = lambda x: x.norm(dim=-1) - radius  # noqa: E731
    n = 64
    g = torch.Generator().manual_seed(0)
    o = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 3.0
    target = torch.randn(n, 3, generator=g) * 0.1
    d = torch.nn.functional.normalize(target - o, dim=-1)
    near, far, hit = ray_sphere_bounds(o, d, 1.0)
    assert hit.all()
    t = upsample_to_surface(sdf, o, d, near, far, n_coarse=32, n_fine=32, steps=4, beta_start=0.05,
                            deterministic=True)
    assert t.shape == (n, 64) and (t[:, 1:] >= t[:, :-1]).all()
    # exact first intersection with the object sphere
    b = (o * d).sum(-1)
    t_hit = -b - torch.sqrt(b**2 - (o.square().sum(-1) - radius**2))
    close = ((t - t_hit[:, None]).abs() < 0.02).sum(-1)
    assert close.min() >= 16, "at least half of the fine samples should land within 2 cm of the surface"
