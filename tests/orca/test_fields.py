"""Neural fields: sphere initialization, shapes, gradients, both encodings."""

from __future__ import annotations

import pytest
import torch

from orca.differential import normals_and_curvature_autograd
from orca.encoding import HashGridSpec
from orca.fields import EnvironmentField, EnvironmentFieldSpec, SDFField, SDFFieldSpec
from orca.frustum import conical_frustum_gaussian

SMALL_GRID = HashGridSpec(levels=4, log2_table_size=10, base_resolution=4, max_resolution=32)


@pytest.mark.parametrize("encoding", ["hashgrid", "frequency"])
def test_sdf_starts_as_a_sphere_with_its_curvature(encoding):
    torch.manual_seed(0)
    field = SDFField(SDFFieldSpec(encoding=encoding, hash_grid=SMALL_GRID, init_radius=0.5))
    d = torch.nn.functional.normalize(torch.randn(100, 3), dim=-1)
    x = 0.5 * d
    sdf, feats = field(x)
    assert sdf.abs().max() < 5e-3 and feats.shape == (100, field.spec.feature_dim)
    n, h = normals_and_curvature_autograd(field.sdf, x)
    assert (n * d).sum(-1).min() > 0.99
    assert (h - 2.0).abs().median() < 0.2  # H = 1 / 0.5
    rgb = field.diffuse(x, feats)
    assert rgb.shape == (100, 3) and (rgb >= 0).all()


@pytest.mark.parametrize("encoding", ["hashgrid", "ipe"])
def test_environment_field_shapes_and_gradients(encoding):
    torch.manual_seed(0)
    env = EnvironmentField(EnvironmentFieldSpec(encoding=encoding, hash_grid=SMALL_GRID, ipe_max_deg=6))
    o = torch.zeros(8, 3)
    d = torch.nn.functional.normalize(torch.randn(8, 3), dim=-1).requires_grad_(True)
    t = torch.linspace(0.1, 10.0, 17).expand(8, 17)
    mean, var = conical_frustum_gaussian(o, d, torch.full((8,), 0.01), t[:, :-1], t[:, 1:])
    density, rgb = env(mean, var, d)
    assert density.shape == (8, 16) and rgb.shape == (8, 16, 3)
    assert (density >= 0).all() and (rgb >= 0).all()
    (density.sum() + rgb.sum()).backward()
    assert d.grad is not None and torch.isfinite(d.grad).all() and d.grad.abs().sum() > 0


@pytest.mark.parametrize("encoding", ["hashgrid", "ipe"])
def test_the_environment_fields_density_alone_is_its_full_passs(encoding):
    torch.manual_seed(0)
    env = EnvironmentField(EnvironmentFieldSpec(encoding=encoding, hash_grid=SMALL_GRID, ipe_max_deg=6))
    with torch.no_grad():
        if env.grid is not None:
            env.grid.table.normal_()
    means, variances = torch.randn(8, 5, 3) * 3, torch.rand(8, 5, 3) * 0.1
    density, _ = env(means, variances, torch.nn.functional.normalize(torch.randn(8, 3), dim=-1))
    torch.testing.assert_close(env.density(means, variances), density, rtol=1e-6, atol=1e-7)
    assert density.std() > 0


def test_directional_environment_map_ignores_position_and_has_no_depth():
    from orca.render import RenderSpec, render_environment_along

    torch.manual_seed(0)
    env = EnvironmentField(EnvironmentFieldSpec(encoding="direction", hash_grid=SMALL_GRID))
    with torch.no_grad():
        env.grid.table.normal_()
    d = torch.nn.functional.normalize(torch.randn(8, 3), dim=-1)
    spread = torch.full((8,), 1e-3)
    spec = RenderSpec(env_samples=8)
    rgb_a, depth, w, _ = render_environment_along(env, torch.zeros(8, 3), d, spread, torch.zeros(8), spec)
    rgb_b, _, _, _ = render_environment_along(env, torch.randn(8, 3), d, spread, torch.rand(8), spec)
    torch.testing.assert_close(rgb_a, rgb_b)  # a 2D map: the same radiance from anywhere
    assert torch.isinf(depth).all() and (w == 0).all()
    other = env.radiance_at_infinity(torch.nn.functional.normalize(d + 0.5, dim=-1), spread)
    assert (other - rgb_a).abs().max() > 1e-4  # but it does depend on the direction


def test_diffuse_head_reads_its_own_texture_grid_and_survives_feature_drift():
    torch.manual_seed(0)
    field = SDFField(SDFFieldSpec(hash_grid=SMALL_GRID, texture_grid=SMALL_GRID, diffuse_init=0.05))
    x = torch.rand(32, 3) - 0.5
    sdf, feats = field(x)
    rgb = field.diffuse(x, feats)
    torch.testing.assert_close(rgb, torch.full_like(rgb, 0.05), atol=0.03, rtol=0)  # starts at diffuse_init
    rgb.sum().backward()
    assert field.texture_grid.table.grad.abs().sum() > 0
    # features a thousand times larger (what the mask warm-up can do to them) leave the output in range
    drifted = field.diffuse(x, feats.detach() * 1000)
    assert drifted.max() < 1.0 and drifted.min() > 1e-3


def test_a_tinted_surface_starts_as_a_clear_coat_and_the_dielectric_has_no_reflectance():
    torch.manual_seed(0)
    x = torch.rand(32, 3) - 0.5
    for reflectance, expected in (("dielectric", None), ("tinted", 0.04)):
        field = SDFField(SDFFieldSpec(hash_grid=SMALL_GRID, reflectance=reflectance, reflectance_init=0.04))
        diffuse, f0 = field.surface(x, field(x)[1])
        torch.testing.assert_close(diffuse, torch.full_like(diffuse, 0.05), atol=0.03, rtol=0)
        if expected is None:
            assert f0 is None
        else:
            assert f0.shape == (32, 3)
            torch.testing.assert_close(f0, torch.full_like(f0, expected), atol=0.01, rtol=0)


def test_environment_field_gradients_stay_finite_for_zero_length_frustums():
    """A frustum of zero length at a cone's apex has zero variance; its gradient must not be NaN (it was,
    through the footprint's square root, and stopped a naive-cone training run)."""
    from orca.fields import EnvironmentField, EnvironmentFieldSpec

    spec = EnvironmentFieldSpec(hash_grid=HashGridSpec(levels=4, log2_table_size=10, base_resolution=4,
                                                       max_resolution=32))
    field = EnvironmentField(spec)
    means = torch.randn(4, 5, 3, requires_grad=True)
    variances = torch.zeros(4, 5, 3, requires_grad=True)
    density, radiance = field(means, variances, torch.nn.functional.normalize(torch.randn(4, 3), dim=-1))
    (density.sum() + radiance.sum()).backward()
    assert torch.isfinite(means.grad).all() and torch.isfinite(variances.grad).all()
    assert means.grad.abs().sum() > 0
