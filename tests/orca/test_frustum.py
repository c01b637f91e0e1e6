"""Conical frustum Gaussians vs Monte Carlo samples of the frustum; contraction and its Jacobian."""

from __future__ import annotations

import math

import pytest
import torch

from orca.frustum import conical_frustum_gaussian, contract, contract_gaussian

pytestmark = pytest.mark.usefixtures("float64")


def _sample_frustum(o, d, r, t0, t1, n, g):
    """Uniform samples in the volume of a cone frustum (density ∝ t² along the axis)."""
    u = torch.rand(n, generator=g)
    t = (t0**3 + u * (t1**3 - t0**3)) ** (1 / 3)
    rho = r * t * torch.sqrt(torch.rand(n, generator=g))
    phi = 2 * math.pi * torch.rand(n, generator=g)
    e1 = torch.linalg.cross(d, torch.tensor([0.0, 0.0, 1.0]))
    e1 = e1 / e1.norm()
    e2 = torch.linalg.cross(d, e1)
    return o + t[:, None] * d + (rho * phi.cos())[:, None] * e1 + (rho * phi.sin())[:, None] * e2


def test_frustum_gaussian_matches_monte_carlo_moments():
    g = torch.Generator().manual_seed(0)
    o = torch.tensor([0.1, -0.2, 0.3])
    d = torch.tensor([0.48, 0.6, 0.64])
    d = d / d.norm()
    r, t0, t1 = 0.05, 1.0, 1.6
    mean, var = conical_frustum_gaussian(o[None], d[None], torch.tensor([r]), torch.tensor([[t0]]),
                                         torch.tensor([[t1]]))
    pts = _sample_frustum(o, d, r, t0, t1, 400_000, g)
    torch.testing.assert_close(mean[0, 0], pts.mean(0), atol=2e-3, rtol=0)
    torch.testing.assert_close(var[0, 0], pts.var(0), atol=0, rtol=2e-2)


def test_frustum_gaussian_is_valid_for_signed_intervals_through_the_apex():
    """A converging virtual cone (concave mirror): the segment from -0.3 to 0.5 crosses the real focus."""
    g = torch.Generator().manual_seed(1)
    o, d, r, t0, t1 = torch.zeros(3), torch.tensor([0.0, 0.6, 0.8]), 0.1, -0.3, 0.5
    u = torch.rand(800_000, generator=g)
    # volume ∝ t² on both nappes: invert the CDF of t² on [t0, t1] with a signed cube root
    c = t0**3 + u * (t1**3 - t0**3)
    t = torch.sign(c) * c.abs() ** (1 / 3)
    rho = r * t.abs() * torch.sqrt(torch.rand(800_000, generator=g))
    phi = 2 * math.pi * torch.rand(800_000, generator=g)
    e1 = torch.tensor([1.0, 0, 0])
    e2 = torch.linalg.cross(d, e1)
    pts = o + t[:, None] * d + (rho * phi.cos())[:, None] * e1 + (rho * phi.sin())[:, None] * e2
    mean, var = conical_frustum_gaussian(o[None], d[None], torch.tensor([r]), torch.tensor([[t0]]),
                                         torch.tensor([[t1]]))
    torch.testing.assert_close(mean[0, 0], pts.mean(0), atol=2e-3, rtol=0)
    torch.testing.assert_close(var[0, 0], pts.var(0), atol=2e-4, rtol=2e-2)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_zero_length_frustum_at_the_apex_is_a_point(dtype):
    """An inverse-CDF sample exactly on a camera cone's first edge (0) makes the interval [0, 0]: its
    moments are 0, not 0/0 (a NaN there once crashed a 3000-iteration run in the hash grid's lookup)."""
    o = torch.tensor([[1.0, 2.0, 3.0]], dtype=dtype)
    d = torch.tensor([[0.0, 0.6, 0.8]], dtype=dtype)
    t = torch.tensor([[0.0, 0.0, 0.5]], dtype=dtype)
    mean, var = conical_frustum_gaussian(o, d, torch.tensor([0.01], dtype=dtype), t[:, :-1], t[:, 1:])
    assert torch.isfinite(mean).all() and torch.isfinite(var).all()
    torch.testing.assert_close(mean[0, 0], o[0])
    torch.testing.assert_close(var[0, 0], torch.zeros(3, dtype=dtype))


def test_contract_is_identity_inside_and_bounded_by_two():
    x = torch.tensor([[0.3, 0.2, -0.1], [10.0, 0, 0], [1e6, 1e6, 0]])
    c = contract(x)
    torch.testing.assert_close(c[0], x[0])
    torch.testing.assert_close(c[1], torch.tensor([1.9, 0, 0]))
    assert c.norm(dim=-1).max() < 2


def test_contract_gaussian_uses_the_true_jacobian():
    mean = torch.tensor([[1.5, -2.0, 0.7], [0.2, 0.1, 0.0]])
    var = torch.tensor([[0.01, 0.02, 0.005], [0.001, 0.002, 0.003]])
    _, new_var = contract_gaussian(mean, var)
    for i in range(2):
        jac = torch.autograd.functional.jacobian(lambda p: contract(p[None])[0], mean[i])
        expected = torch.diagonal(jac @ torch.diag(var[i]) @ jac.T)
        torch.testing.assert_close(new_var[i], expected)
