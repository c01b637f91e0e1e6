"""Encodings: analytic values of PE/IPE, and the hash grid's interpolation and gradients."""

from __future__ import annotations

import itertools
import math

import torch

from orca.encoding import (
    HashGrid,
    HashGridSpec,
    corner_indices,
    integrated_positional_encoding,
    positional_encoding,
)


def test_positional_encoding_values_and_shape():
    x = torch.tensor([[0.25, -1.0]])
    enc = positional_encoding(x, num_freqs=3)
    assert enc.shape == (1, 2 * (2 * 3 + 1))
    # layout: [x, sin(2^k x) for k, d..., cos(...)]
    torch.testing.assert_close(enc[0, :2], x[0])
    torch.testing.assert_close(enc[0, 2 + 2 * 2], torch.sin(torch.tensor(4 * 0.25)))


def test_ipe_matches_monte_carlo_expectation():
    torch.manual_seed(0)
    mean = torch.tensor([[0.3, -0.7, 1.1]], dtype=torch.float64)
    var = torch.tensor([[0.02, 0.3, 0.001]], dtype=torch.float64)
    enc = integrated_positional_encoding(mean, var, 0, 4)
    samples = mean + var.sqrt() * torch.randn(400_000, 3, dtype=torch.float64)
    mc = positional_encoding(samples, 4, include_input=False)
    # positional_encoding orders (sin of all freqs, cos of all freqs) exactly as IPE does
    torch.testing.assert_close(enc[0], mc.mean(0), atol=4e-3, rtol=0)


def test_ipe_of_zero_variance_is_positional_encoding():
    mean = torch.rand(5, 3)
    torch.testing.assert_close(
        integrated_positional_encoding(mean, torch.zeros_like(mean), 0, 6),
        positional_encoding(mean, 6, include_input=False),
    )


def test_hash_grid_interpolates_trilinearly_and_is_continuous():
    grid = HashGrid(HashGridSpec(levels=4, log2_table_size=12, base_resolution=4, max_resolution=64))
    with torch.no_grad():
        grid.table.normal_()
    # continuity across a voxel face: values on either side of a grid plane converge
    eps = 1e-6
    a = torch.tensor([[0.25 - eps, 0.4, 0.6]])
    b = torch.tensor([[0.25 + eps, 0.4, 0.6]])
    assert (grid(a) - grid(b)).abs().max() < 1e-3
    # along one axis inside a voxel of the coarsest (dense) level the encoding is linear
    f = lambda t: grid(torch.tensor([[t, 0.1, 0.1]]))[0, :2]  # noqa: E731  (level 0 features)
    torch.testing.assert_close(f(0.3), 0.5 * (f(0.26) + f(0.34)), atol=1e-5, rtol=0)


def test_hash_grid_gradients_reach_the_table_and_inputs():
    grid = HashGrid(HashGridSpec(levels=6, log2_table_size=10))
    with torch.no_grad():
        grid.table.normal_()
    x = torch.rand(64, 3, requires_grad=True)
    grid(x).square().sum().backward()
    assert grid.table.grad.abs().sum() > 0
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    assert grid(x).shape == (64, grid.out_dim)


def test_hash_grid_levels_span_requested_resolutions():
    spec = HashGridSpec(levels=8, base_resolution=16, max_resolution=1024)
    grid = HashGrid(spec)
    assert grid.resolutions[0] == 16 and abs(grid.resolutions[-1] - 1024) <= 1
    assert grid.dense[0] and not grid.dense[-1]
    assert math.isclose(grid.table.shape[0], grid.offsets[-1])


def test_hash_grid_footprint_downweights_fine_levels_only():
    grid = HashGrid(HashGridSpec(levels=5, base_resolution=4, max_resolution=256))
    with torch.no_grad():
        grid.table.normal_()
    x = torch.rand(32, 3)
    sharp = grid(x, scale=torch.full((32,), 1e-6))
    torch.testing.assert_close(sharp, grid(x), atol=1e-6, rtol=0)
    wide = grid(x, scale=torch.full((32,), 0.05)).reshape(32, 5, 2)
    plain = grid(x).reshape(32, 5, 2)
    ratio = (wide.norm(dim=(0, 2)) / plain.norm(dim=(0, 2)))
    assert ratio[0] > 0.9 and ratio[-1] < 0.1, ratio  # 4-voxel level kept, 256-voxel level suppressed
    assert (ratio[1:] <= ratio[:-1] + 1e-6).all()


def test_corner_indices_are_instant_ngps_rows():
    # the reference: each corner's row computed on its own, in int64, as Instant-NGP writes it
    grid = HashGrid(HashGridSpec(levels=6, log2_table_size=10, base_resolution=4, max_resolution=200))
    assert 0 < grid.n_dense < 6  # both kinds of level
    x = torch.rand(300, 3)
    x[:5] = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.5], [0.999999, 1e-7, 1.0], [0.5, 0.5, 0.5]])
    res = torch.tensor(grid.resolutions)
    base = (x[:, None, :] * res[:, None]).floor().long().minimum(res[:, None] - 1)
    rows = corner_indices(base, res, torch.tensor(grid.offsets[1:]) - torch.tensor(grid.offsets[:-1]),
                          torch.tensor(grid.offsets[:-1]), grid.n_dense)
    assert rows.dtype == torch.int32 and rows.shape == (300, 6, 8)
    for level, r in enumerate(grid.resolutions):
        start, size = grid.offsets[level], grid.offsets[level + 1] - grid.offsets[level]
        for corner, (i, j, k) in enumerate(itertools.product((0, 1), repeat=3)):
            c = base[:, level] + torch.tensor([i, j, k])
            if grid.dense[level]:
                expected = (c[:, 0] * (r + 1) + c[:, 1]) * (r + 1) + c[:, 2]
            else:
                expected = (c[:, 0] ^ (c[:, 1] * 2654435761) ^ (c[:, 2] * 805459861)) % size
            assert torch.equal(rows[:, level, corner].long(), expected + start), (level, corner)
    assert rows.min() >= 0 and rows.max() < grid.table.shape[0]
