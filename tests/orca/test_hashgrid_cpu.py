"""The fused CPU lookup (orca.hashgrid_cpu) against the hash grid's tensor path: features, the table's and the
points' gradients."""

from __future__ import annotations

import pytest
import torch

from orca import hashgrid_cpu
from orca.encoding import HashGrid, HashGridSpec

pytestmark = pytest.mark.skipif(not hashgrid_cpu.AVAILABLE, reason="numba is not installed")


@pytest.mark.parametrize("spec", [
    HashGridSpec(levels=6, log2_table_size=12, base_resolution=4, max_resolution=300),  # dense and hashed levels
    HashGridSpec(levels=3, log2_table_size=10, base_resolution=3, max_resolution=40, features_per_level=3),
])
def test_fused_lookup_equals_the_tensor_path(spec):
    torch.manual_seed(0)
    plain, fused = HashGrid(spec), HashGrid(spec, first_order=True)
    with torch.no_grad():
        plain.table.normal_()
        fused.table.copy_(plain.table)
    x = torch.rand(2000, 3) * 1.2 - 0.1  # some outside [0, 1]: clamped, no gradient there
    x[:4] = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.5, 0.0], [0.999999, 1e-7, 0.5]])
    scale = torch.rand(2000) * 0.02
    xa, xb = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    a, b = plain(xa, scale), fused(xb, scale)
    torch.testing.assert_close(b, a, atol=1e-6, rtol=1e-6)
    weights = torch.randn_like(a)
    (a * weights).sum().backward()
    (b * weights).sum().backward()
    torch.testing.assert_close(fused.table.grad, plain.table.grad, atol=1e-5, rtol=1e-5)
    assert plain.table.grad.abs().sum() > 0
    torch.testing.assert_close(xb.grad, xa.grad, atol=1e-3, rtol=1e-4)  # d/dx grows with the resolution
    outside = ((x < 0) | (x > 1))
    assert outside.any() and (xb.grad[outside] == 0).all()


def test_fused_lookup_without_point_gradients_and_without_any():
    spec = HashGridSpec(levels=4, log2_table_size=10, base_resolution=4, max_resolution=64)
    plain, fused = HashGrid(spec), HashGrid(spec, first_order=True)
    fused.load_state_dict(plain.state_dict())
    x = torch.rand(300, 3)
    fused(x).square().sum().backward()  # points need no gradient: the table's alone
    plain(x).square().sum().backward()
    torch.testing.assert_close(fused.table.grad, plain.table.grad, atol=1e-6, rtol=1e-5)
    with torch.no_grad():
        torch.testing.assert_close(fused(x), plain(x))
    assert fused(torch.rand(0, 3)).shape == (0, spec.out_dim)


def test_only_first_order_grids_take_the_fused_path():
    """The SDF's grid is differentiated twice (the eikonal term): it keeps the tensor path, the environment
    field's takes the fused one."""
    from orca.fields import EnvironmentField, EnvironmentFieldSpec, SDFField, SDFFieldSpec

    assert EnvironmentField(EnvironmentFieldSpec()).grid.first_order
    sdf = SDFField(SDFFieldSpec())
    assert not sdf.grid.first_order
    x = torch.rand(50, 3, requires_grad=True)
    (g,) = torch.autograd.grad(sdf.sdf(x).sum(), x, create_graph=True)
    g.square().sum().backward()  # second order reaches the table
    assert sdf.grid.table.grad.abs().sum() > 0
