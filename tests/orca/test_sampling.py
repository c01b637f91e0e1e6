"""Ray bounds, inverse-CDF sampling, and surface-seeking upsampling on an analytic sphere."""

from __future__ import annotations

import pytest
import torch

from orca.sampling import ray_sphere_bounds, sample_pdf, surface_band, upsample_to_surface

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
    t, values = upsample_to_surface(sdf, o, d, near, far, n_coarse=32, n_fine=32, steps=4, beta_start=0.05,
                                    deterministic=True)
    assert t.shape == (n, 64) and (t[:, 1:] >= t[:, :-1]).all()
    # exact first intersection with the object sphere
    b = (o * d).sum(-1)
    t_hit = -b - torch.sqrt(b**2 - (o.square().sum(-1) - radius**2))
    close = ((t - t_hit[:, None]).abs() < 0.02).sum(-1)
    assert close.min() >= 16, "at least half of the fine samples should land within 2 cm of the surface"
    torch.testing.assert_close(values, sdf(o[:, None] + t[..., None] * d[:, None]))


def test_surface_band_brackets_the_first_crossing_and_widens_for_grazing_rays():
    radius = 0.5
    sdf = lambda x: x.norm(dim=-1) - radius  # noqa: E731
    o = torch.tensor([[0.0, 0.0, -3.0], [0.0, 0.49, -3.0], [0.0, 0.8, -3.0]])  # head-on, grazing, miss
    d = torch.tensor([[0.0, 0.0, 1.0]]).expand(3, 3)
    near, far, _ = ray_sphere_bounds(o, d, 1.0)
    t, values = upsample_to_surface(sdf, o, d, near, far, n_coarse=32, n_fine=16, steps=2, beta_start=0.05,
                                    deterministic=True)
    beta = 0.01
    edges = surface_band(t, values, beta, 8, half_width_betas=6.0, min_slope=0.1, deterministic=True)
    assert edges.shape == (3, 9) and (edges[:, 1:] > edges[:, :-1]).all()
    hit = 3.0 - torch.sqrt(radius**2 - o[:2, 1] ** 2)  # exact first intersections
    centre = 0.5 * (edges[:, 0] + edges[:, -1])
    torch.testing.assert_close(centre[0], hit[0], atol=2e-3, rtol=0)
    assert (edges[:2, 0] < hit).all() and (edges[:2, -1] > hit).all()
    width = edges[:, -1] - edges[:, 0]
    torch.testing.assert_close(width[0], torch.tensor(2 * 6.0 * beta), rtol=1e-3, atol=0)  # slope 1 head-on
    assert width[1] > 3 * width[0]  # grazing: the SDF changes slowly along the ray
    torch.testing.assert_close(centre[2], torch.tensor(3.0), atol=0.1, rtol=0)  # miss: closest approach
    # stratified: jittered combs stay sorted and inside one spacing of the deterministic comb
    g = torch.Generator().manual_seed(0)
    jittered = surface_band(t, values, beta, 8, half_width_betas=6.0, min_slope=0.1, generator=g)
    assert (jittered[:, 1:] > jittered[:, :-1]).all()
    assert ((jittered - edges).abs() <= (width / 8)[:, None] * 0.5 + 1e-9).all()
