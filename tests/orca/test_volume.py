"""Volume rendering: VolSDF density limits, compositing against closed forms, distortion loss vs brute force."""

from __future__ import annotations

import pytest
import torch

from orca.volume import composite_weights, distortion_loss, laplace_cdf, volsdf_density

pytestmark = pytest.mark.usefixtures("float64")


def test_laplace_cdf_limits_symmetry_and_no_overflow():
    s = torch.tensor([-1e6, -1.0, 0.0, 1.0, 1e6])
    c = laplace_cdf(s, 0.1)
    torch.testing.assert_close(c, torch.tensor([0.0, 0.5 * torch.exp(torch.tensor(-10.0)), 0.5,
                                                1 - 0.5 * torch.exp(torch.tensor(-10.0)), 1.0]))
    torch.testing.assert_close(laplace_cdf(-s, 0.1), 1 - c)


def test_volsdf_density_inside_outside():
    beta = 0.01
    sig = volsdf_density(torch.tensor([-1.0, 0.0, 1.0]), beta)
    torch.testing.assert_close(sig, torch.tensor([1 / beta, 0.5 / beta, 0.0]), atol=1e-30, rtol=1e-12)


def test_constant_density_weights_match_closed_form():
    sigma, t = 2.0, torch.linspace(0, 3, 301)
    w, t_left = composite_weights(torch.full((300,), sigma), t)
    # accumulated weight up to distance d is 1 - exp(-sigma d)
    torch.testing.assert_close(w.sum(), 1 - torch.exp(torch.tensor(-sigma * 3)))
    torch.testing.assert_close(t_left, torch.exp(torch.tensor(-sigma * 3)))
    torch.testing.assert_close(w[:100].sum(), 1 - torch.exp(torch.tensor(-sigma * 1.0)))


def test_sdf_surface_gives_weight_peak_at_the_surface():
    # a ray along +x hitting the plane x = 1 (SDF = 1 - x toward the solid side x > 1)
    t = torch.linspace(0, 2, 2001)
    mid = 0.5 * (t[1:] + t[:-1])
    w, _ = composite_weights(volsdf_density(1.0 - mid, 0.005), t)
    expected_depth = (w * mid).sum() / w.sum()
    assert abs(expected_depth - 1.0) < 0.01 and w.sum() > 0.999


def test_distortion_loss_matches_brute_force_and_has_gradients():
    g = torch.Generator().manual_seed(0)
    s = torch.sort(torch.rand(4, 17, generator=g), dim=-1).values
    w = torch.rand(4, 16, generator=g, requires_grad=True)
    mid = 0.5 * (s[:, 1:] + s[:, :-1])
    brute = (w[:, :, None] * w[:, None, :] * (mid[:, :, None] - mid[:, None, :]).abs()).sum((1, 2))
    brute = brute + (w.square() * (s[:, 1:] - s[:, :-1])).sum(-1) / 3
    fast = distortion_loss(w, s)
    torch.testing.assert_close(fast, brute)
    (gw,) = torch.autograd.grad(fast.sum(), w)
    (gb,) = torch.autograd.grad(brute.sum(), w)
    torch.testing.assert_close(gw, gb)
    # a single concentrated spike costs less than the same mass spread out
    spike = torch.zeros(16); spike[8] = 1.0  # noqa: E702
    spread = torch.full((16,), 1 / 16)
    s1 = torch.linspace(0, 1, 17)
    assert distortion_loss(spike, s1) < distortion_loss(spread, s1)


def test_median_depth_is_the_wall_a_thin_far_tail_does_not_move():
    from orca.volume import quantile_depth

    t = torch.tensor([[0.0, 1.0, 2.0, 3.0, 4.0, 100.0]])
    w = torch.tensor([[0.0, 0.0, 0.9, 0.0, 0.1]])  # a wall in [2, 3], 10 % left for the long last interval
    mid = 0.5 * (t[:, 1:] + t[:, :-1])
    assert (w * mid).sum() > 6.0  # the expected depth is more than twice the wall's
    assert quantile_depth(w, t).item() == pytest.approx(2.0 + 0.5 / 0.9 * 1.0, abs=1e-5)
    uniform = torch.full((1, 5), 0.2)
    assert quantile_depth(uniform, t).item() == pytest.approx(2.5, abs=1e-5)  # halfway through the middle interval
    assert quantile_depth(torch.zeros(1, 5), t).item() == 100.0  # nothing seen: the far end
    batch = torch.rand(4, 7, 5)
    edges = torch.cumsum(torch.rand(4, 7, 6), dim=-1)
    d = quantile_depth(batch, edges)
    assert d.shape == (4, 7) and ((d >= edges[..., 0]) & (d <= edges[..., -1])).all()


def test_a_lower_depth_quantile_finds_a_semi_transparent_prop_the_median_passes_through():
    from orca.volume import quantile_depth

    t = torch.tensor([[0.0, 2.0, 3.0, 8.0, 9.0, 100.0]])
    w = torch.tensor([[0.0, 0.4, 0.0, 0.6, 0.0]])  # a prop in [2, 3] taking 40 %, the wall in [8, 9] the rest
    assert quantile_depth(w, t).item() == pytest.approx(8.0 + 0.1 / 0.6, abs=1e-5)  # the median: in the wall
    assert quantile_depth(w, t, 0.3).item() == pytest.approx(2.0 + 0.3 / 0.4, abs=1e-5)  # the prop
    assert quantile_depth(w * 5.0, t, 0.3).item() == pytest.approx(2.75, abs=1e-5), "a share of the total weight"
