"""Normals and mean curvature of analytic SDFs, autograd vs finite differences vs the exact values."""

from __future__ import annotations

import pytest
import torch

from orca.differential import normals_and_curvature_autograd, normals_and_curvature_fd

pytestmark = pytest.mark.usefixtures("float64")


def sphere(radius: float):
    return lambda x: x.norm(dim=-1) - radius


def torus(major: float, minor: float):
    def f(x):
        q = torch.stack([torch.sqrt(x[:, 0] ** 2 + x[:, 1] ** 2) - major, x[:, 2]], dim=-1)
        return q.norm(dim=-1) - minor

    return f


def torus_mean_curvature(points, major, minor):
    """Exact H = ½(κ1+κ2) of a torus at surface points: κ1 = 1/r, κ2 = cos v / (R + r cos v)."""
    rho = torch.sqrt(points[:, 0] ** 2 + points[:, 1] ** 2)
    cos_v = (rho - major) / minor
    return 0.5 * (1 / minor + cos_v / (major + minor * cos_v))


def _sphere_points(n, radius, seed=0):
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(n, 3, generator=g)
    return radius * d / d.norm(dim=-1, keepdim=True)


@pytest.mark.parametrize("method", ["autograd", "fd"])
def test_sphere_normals_point_out_and_curvature_is_inverse_radius(method):
    r = 0.7
    x = _sphere_points(200, r)
    fn = normals_and_curvature_autograd if method == "autograd" else (
        lambda s, p: normals_and_curvature_fd(s, p, eps=1e-3)
    )
    n, h = fn(sphere(r), x)
    torch.testing.assert_close(n, x / r, atol=1e-6, rtol=0)
    torch.testing.assert_close(h, torch.full_like(h, 1 / r), atol=1e-5, rtol=0)


def test_plane_has_zero_curvature_and_concave_side_is_negative():
    plane = lambda x: x[:, 2] - 0.1  # noqa: E731
    x = torch.rand(50, 3)
    n, h = normals_and_curvature_autograd(plane, x)
    torch.testing.assert_close(n, torch.tensor([0.0, 0, 1]).expand_as(n))
    assert h.abs().max() < 1e-12
    # the inside of a spherical bowl: the complement of a ball, outward normal pointing to the centre
    bowl = lambda x: 1.5 - x.norm(dim=-1)  # noqa: E731
    _, hb = normals_and_curvature_fd(bowl, _sphere_points(20, 1.5), eps=1e-3)
    torch.testing.assert_close(hb, torch.full_like(hb, -1 / 1.5), atol=1e-5, rtol=0)


def test_autograd_and_finite_differences_agree_on_a_torus_with_both_signs_of_curvature():
    major, minor = 0.4, 0.25  # R < 2r: the inner equator is saddle-shaped with H < 0
    g = torch.Generator().manual_seed(1)
    u, v = torch.rand(300, generator=g) * 6.283, torch.rand(300, generator=g) * 6.283
    x = torch.stack(
        [(major + minor * v.cos()) * u.cos(), (major + minor * v.cos()) * u.sin(), minor * v.sin()], dim=-1
    )
    exact = torus_mean_curvature(x, major, minor)
    assert (exact > 0).any() and (exact < 0).any(), "both signs of H must be tested"
    _, h_ag = normals_and_curvature_autograd(torus(major, minor), x)
    _, h_fd = normals_and_curvature_fd(torus(major, minor), x, eps=1e-3)
    torch.testing.assert_close(h_ag, exact, atol=1e-8, rtol=0)
    torch.testing.assert_close(h_fd, exact, atol=1e-4, rtol=0)


def test_curvature_is_differentiable_wrt_sdf_parameters():
    radius = torch.tensor(0.5, requires_grad=True)
    x = _sphere_points(10, 0.5)
    sdf = lambda p: p.norm(dim=-1) - radius  # noqa: E731
    for fn in (normals_and_curvature_autograd, lambda s, p: normals_and_curvature_fd(s, p, 1e-3)):
        _, h = fn(sdf, x)
        # H of a level set of |x| - r at |x| = 0.5 is 1/|x|, independent of r: gradient exactly 0 is right
        (gr,) = torch.autograd.grad(h.sum(), radius, allow_unused=True)
        assert gr is None or gr.abs() < 1e-6
    # through the points instead: moving points outward lowers the curvature of their level set
    x = x.clone().requires_grad_(True)
    _, h = normals_and_curvature_autograd(sphere(0.5), x * 1.0)
    (gx,) = torch.autograd.grad(h.sum(), x)
    assert (torch.einsum("ni,ni->n", gx, x) < 0).all()
