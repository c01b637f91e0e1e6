"""The renderer: Fresnel, a sphere-initialized SDF rendered against the analytic sphere, and gradients
of the photometric loss reaching the SDF through the reflected direction and the weights."""

from __future__ import annotations

import math

import torch
from analytic_fields import AnalyticEnvironment

from orca.encoding import HashGridSpec
from orca.fields import EnvironmentField, EnvironmentFieldSpec, SDFField, SDFFieldSpec
from orca.render import RenderSpec, fresnel_dielectric, fresnel_schlick, render_rays, shade_specular

GRID = HashGridSpec(levels=4, log2_table_size=10, base_resolution=4, max_resolution=32)
SPEC = RenderSpec(n_coarse=32, n_fine=16, env_samples=16, deterministic=True)


def test_fresnel_dielectric_reference_values():
    f = fresnel_dielectric(torch.tensor([1.0, math.cos(math.radians(45)), 0.0]), 1.5)
    torch.testing.assert_close(f, torch.tensor([0.04, 0.0502, 1.0]), atol=2e-4, rtol=0)


def test_schlick_fresnel_is_its_colour_head_on_total_at_grazing_and_a_clear_coats_at_004():
    cos = torch.cos(torch.deg2rad(torch.linspace(0, 90, 91)))
    gold = torch.tensor([1.0, 0.71, 0.29])
    f = fresnel_schlick(cos, gold.expand(91, 3))
    torch.testing.assert_close(f[0], gold)
    torch.testing.assert_close(f[-1], torch.ones(3))
    assert (f[1:] - f[:-1] >= 0).all()  # more reflection toward grazing, in every channel
    coat = fresnel_schlick(cos, torch.full((91, 3), 0.04))
    assert (coat - fresnel_dielectric(cos, 1.5)[:, None]).abs().max() < 0.04  # measured: 0.036, near 83 deg


def _rays(n=64, seed=0):
    g = torch.Generator().manual_seed(seed)
    o = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 2.5
    target = (torch.rand(n, 3, generator=g) - 0.5) * 1.4  # some rays miss the 0.5 sphere
    d = torch.nn.functional.normalize(target - o, dim=-1)
    return o, d, torch.full((n,), 1e-3)


def _analytic_hit(o, d, r):
    b = (o * d).sum(-1)
    disc = b**2 - (o.square().sum(-1) - r**2)
    return disc > 0, -b - disc.clamp_min(0).sqrt()


def test_initial_sphere_renders_opacity_depth_and_normals_of_the_analytic_sphere():
    torch.manual_seed(0)
    sdf = SDFField(SDFFieldSpec(hash_grid=GRID, init_radius=0.5))
    env = EnvironmentField(EnvironmentFieldSpec(hash_grid=GRID))
    o, d, r = _rays()
    out = render_rays(sdf, env, torch.tensor(0.005), o, d, r, SPEC)
    hit, t_hit = _analytic_hit(o, d, 0.5)
    assert hit.sum() > 10
    # a ray grazing within a few β of the surface is legitimately semi-opaque under VolSDF; clear misses are not
    miss_by = (o - (o * d).sum(-1, keepdim=True) * d).norm(dim=-1) - 0.5
    clear_miss = miss_by > 0.02
    assert clear_miss.sum() >= 5
    assert (out.opacity[hit] > 0.98).all() and (out.opacity[clear_miss] < 0.02).all()
    n_true = torch.nn.functional.normalize(o + t_hit[:, None] * d, dim=-1)
    # VolSDF's expected depth lags the surface by O(β / cos θ): tight off-grazing, looser at grazing
    frontal = hit & (-(d * n_true).sum(-1) > 0.3)
    depth_err = (out.depth - t_hit).abs()
    assert depth_err[frontal].max() < 0.01 and depth_err[hit].median() < 0.005
    cos = (torch.nn.functional.normalize(out.normal, dim=-1) * n_true).sum(-1)
    assert cos[frontal].min() > math.cos(math.radians(2.0)) and cos[hit].min() > math.cos(math.radians(10.0))
    assert torch.isfinite(out.rgb).all() and (out.specular[hit] > 0).all()


def test_specular_gradient_reaches_the_normal_through_the_reflected_direction():
    torch.manual_seed(0)
    env = EnvironmentField(EnvironmentFieldSpec(hash_grid=GRID))
    with torch.no_grad():
        env.grid.table.normal_()  # a textured environment: radiance changes with direction
    o, d, r = _rays(16)
    hit, t_hit = _analytic_hit(o, d, 0.5)
    o, d, r, t_hit = o[hit], d[hit], r[hit], t_hit[hit]
    p = (o + t_hit[:, None] * d)[:, None]
    normals = torch.nn.functional.normalize(p, dim=-1).clone().requires_grad_(True)
    share = torch.ones(p.shape[0], 1)
    specular, _, _ = shade_specular(env, o, d, r, p, normals, torch.full((p.shape[0], 1), 2.0), share, SPEC)
    (g,) = torch.autograd.grad(specular.sum(), normals)
    assert torch.isfinite(g).all()
    # tangential components steer the reflected direction; they must carry gradient
    tangential = g - (g * normals).sum(-1, keepdim=True) * normals
    assert tangential.norm(dim=-1).min() > 0


def test_photometric_loss_reaches_sdf_parameters_through_weights_and_reflection():
    torch.manual_seed(0)
    sdf = SDFField(SDFFieldSpec(hash_grid=GRID, init_radius=0.5))
    env = EnvironmentField(EnvironmentFieldSpec(hash_grid=GRID))
    o, d, r = _rays(32)
    out = render_rays(sdf, env, torch.tensor(0.01), o, d, r, SPEC)
    target = torch.rand_like(out.rgb)
    grads = torch.autograd.grad((out.rgb - target).square().mean(), [*sdf.net.parameters(), sdf.grid.table],
                                allow_unused=False)
    assert all(torch.isfinite(g).all() for g in grads)
    assert sum(g.abs().sum() for g in grads) > 0
    # specular alone (diffuse head not involved) still reaches the SDF's geometry network
    out = render_rays(sdf, env, torch.tensor(0.01), o, d, r, SPEC)
    g_spec = torch.autograd.grad(out.specular.sum(), list(sdf.net.parameters()))
    assert sum(g.abs().sum() for g in g_spec) > 0


class _Wall(AnalyticEnvironment):
    """An analytic environment: empty space, then an opaque grey wall at x = ``at``."""

    def __init__(self, at: float):
        super().__init__()
        self.at = at

    def forward(self, means, variances, dirs):
        density = torch.where(means[..., 0] > self.at, 1e4, 0.0)
        return density, torch.full((*means.shape[:-1], 3), 0.5)


def test_coarse_to_fine_cone_sampling_finds_the_walls_depth():
    from orca.render import render_environment_along

    n = 64
    wall = _Wall(at=3.0)
    apex = torch.zeros(n, 3)
    axis = torch.nn.functional.normalize(torch.tensor([1.0, 0.0, 0.0]) + 0.2 * torch.randn(n, 3), dim=-1)
    truth = 3.0 / axis[:, 0]
    errors = {}
    for fine in (0, 16):
        spec = RenderSpec(env_samples=16, env_fine=fine, deterministic=True)
        rgb, depth, w, s = render_environment_along(wall, apex, axis, torch.full((n,), 1e-3), torch.zeros(n), spec)
        assert w.shape == (n, 16 + fine) and s.shape == (n, 17 + fine)
        assert (s[:, 1:] >= s[:, :-1]).all() and s[:, 0].eq(0).all() and s.max() <= 1
        torch.testing.assert_close(rgb, torch.full_like(rgb, 0.5), atol=1e-3, rtol=0)  # the wall, fully opaque
        errors[fine] = ((depth - truth).abs() / truth).mean().item()
    assert errors[16] < 0.06 and errors[16] < 0.15 * errors[0], errors  # measured: 54 % -> 4.4 %


def test_a_tinted_surface_reflects_a_grey_room_in_its_own_colour():
    """A sphere whose reflectance head gives gold everywhere, in a room that is 0.5 grey in every direction: each
    ray's specular is its opacity x Schlick's Fresnel of gold at its incidence x 0.5; the dielectric field gives a
    colourless 4 % at normal incidence. The reflectance head's parameters get the specular's gradient."""
    torch.manual_seed(0)
    gold = torch.tensor([0.9, 0.6, 0.25])
    room = _Wall(at=-1e9)  # opaque and grey from the first sample on
    o, d, r = _rays(64)
    hit, t_hit = _analytic_hit(o, d, 0.5)
    cos = -(d * torch.nn.functional.normalize(o + t_hit[:, None] * d, dim=-1)).sum(-1)
    frontal = hit & (cos > 0.3)
    specular = {}
    for reflectance in ("dielectric", "tinted"):
        sdf = SDFField(SDFFieldSpec(hash_grid=GRID, init_radius=0.5, reflectance=reflectance))
        if reflectance == "tinted":
            with torch.no_grad():
                sdf.diffuse_net[-1].weight[3:].zero_()
                sdf.diffuse_net[-1].bias[3:] = torch.logit(gold)
        out = render_rays(sdf, room, torch.tensor(0.005), o, d, r, SPEC)
        specular[reflectance] = out.specular
        if reflectance == "tinted":
            (g,) = torch.autograd.grad(out.specular.sum(), sdf.diffuse_net[-1].bias)
            assert (g[3:] > 0).all() and (g[:3] == 0).all()
    expected = out.opacity[:, None] * fresnel_schlick(cos, gold.expand(64, 3)) * 0.5
    torch.testing.assert_close(specular["tinted"][frontal], expected[frontal], atol=5e-3, rtol=0.03)
    coat = out.opacity * fresnel_dielectric(cos, 1.5) * 0.5
    torch.testing.assert_close(specular["dielectric"][frontal], coat[frontal, None].expand(-1, 3), atol=2e-3,
                               rtol=0.03)


class _Slab(AnalyticEnvironment):
    """A thin dense slab (a floater) in front of an opaque wall; the wall is grey, the slab white."""

    def __init__(self, lo: float, hi: float, wall: float):
        super().__init__()
        self.lo, self.hi, self.wall = lo, hi, wall

    def forward(self, means, variances, dirs):
        x = means[..., 0]
        slab = (x > self.lo) & (x < self.hi)
        density = torch.where(slab | (x > self.wall), 1e4, 0.0)
        rgb = torch.where(slab[..., None], 1.0, 0.5).expand(*means.shape[:-1], 3)
        return density, rgb


def test_training_cones_jitter_their_coarse_edges_so_no_space_goes_unseen():
    """Fixed edges sample the same shells on every training ray: a floater between two shells is never seen
    (and so never corrected) by that camera. Stratified edges see it on some rays."""
    from orca.frustum import conical_frustum_gaussian
    from orca.render import environment_edges, render_environment_along

    train = RenderSpec(env_samples=16, env_fine=0)
    evaluate = RenderSpec(env_samples=16, env_fine=0, deterministic=True)
    cpu = torch.device("cpu")
    fixed = environment_edges(evaluate, 4, torch.float32, cpu)
    assert torch.equal(fixed[0], fixed[1])
    u = environment_edges(train, 4096, torch.float32, cpu)
    assert (u[:, 1:] > u[:, :-1]).all() and u[:, 0].eq(0).all() and torch.allclose(u[:, -1], fixed[0, -1])
    assert not torch.equal(u[0], u[1])
    # a slab between two neighbouring frustum means of the fixed edges
    n = 512
    apex, axis, radius = torch.zeros(n, 3), torch.tensor([[1.0, 0.0, 0.0]]).expand(n, 3), torch.full((n,), 1e-4)
    means = conical_frustum_gaussian(apex[:1], axis[:1], radius[:1], fixed[:1, :-1], fixed[:1, 1:])[0][0, :, 0]
    k = int(torch.searchsorted(means.contiguous(), torch.tensor(3.0)))
    gap = means[k] - means[k - 1]
    slab = _Slab(means[k - 1].item() + 0.1 * gap.item(), means[k].item() - 0.1 * gap.item(), wall=60.0)
    args = (slab, apex, axis, radius, torch.zeros(n))
    seen_fixed = render_environment_along(*args, evaluate)[0]
    seen_jittered = render_environment_along(*args, train)[0]
    assert (seen_fixed[:, 0] - 0.5).abs().max() < 1e-3, "fixed edges never see the slab"
    assert (seen_jittered[:, 0] > 0.9).float().mean() > 0.1, "jittered edges see it on some rays"


def test_a_trained_model_renders_colour_with_training_samples_and_depth_with_more():
    from dataclasses import replace

    spec = RenderSpec(env_samples=16, env_fine=8, env_fine_render=32)
    rendering = spec.for_rendering()
    assert rendering.deterministic and rendering.env_fine == 8  # the estimate the model was fitted to
    assert rendering.shade_min_opacity == spec.shade_min_opacity_render > 0  # no cones beside the object
    # nothing else changes
    assert replace(rendering, deterministic=False, shade_min_opacity=spec.shade_min_opacity) == spec
    depth = rendering.for_depth()
    assert depth.env_fine == 32 and replace(depth, env_fine=8) == rendering
    assert RenderSpec(env_fine=8).for_depth().env_fine == 8  # no render count: training's


class _Fog(AnalyticEnvironment):
    """Constant density everywhere; grey."""

    def __init__(self, sigma: float):
        super().__init__()
        self.sigma = sigma

    def forward(self, means, variances, dirs):
        return torch.full(means.shape[:-1], self.sigma), torch.full((*means.shape[:-1], 3), 0.5)


def test_free_space_opacity_integrates_density_from_the_camera_to_the_objects_sphere():
    from orca.render import free_space_opacity

    spec = RenderSpec(free_space_samples=16, deterministic=True)
    # cameras on the x axis at distance 3 and 6 looking at the centre, one looking past the sphere, one inside
    origins = torch.tensor([[3.0, 0, 0], [6.0, 0, 0], [3.0, 0, 0], [0.2, 0, 0]])
    dirs = torch.tensor([[-1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0]])
    radii = torch.full((4,), 1e-3)
    sigma = 0.3
    opacity = free_space_opacity(_Fog(sigma), origins, dirs, radii, spec)
    expected = torch.tensor([1 - math.exp(-sigma * 2.0), 1 - math.exp(-sigma * 5.0), 0.0, 0.0])
    torch.testing.assert_close(opacity, expected, atol=1e-5, rtol=0)
    # a floater before the lens is seen in full; one behind the object, which the ray never reaches, is not
    before, behind = _Slab(4.0, 4.5, wall=1e9), _Slab(-4.5, -4.0, wall=1e9)
    assert free_space_opacity(before, origins[1:2], dirs[1:2], radii[1:2], spec).item() > 0.999
    assert free_space_opacity(behind, origins[1:2], dirs[1:2], radii[1:2], spec).item() == 0.0


def test_free_space_loss_empties_the_environment_between_cameras_and_object():
    """The objective's ``free_space`` term reaches the environment field and lowers its density there."""
    from orca.model import Batch, LossWeights, ModelSpec, OrcaModel, objective

    torch.manual_seed(0)
    model = OrcaModel(ModelSpec(render=RenderSpec(n_coarse=16, n_fine=8, env_samples=8, free_space_samples=8)))
    n = 64
    origins = torch.tensor([4.0, 0.0, 0.0]).expand(n, 3) + 0.1 * torch.randn(n, 3)
    dirs = torch.nn.functional.normalize(-origins + 0.2 * torch.randn(n, 3), dim=-1)
    batch = Batch(origins, dirs, torch.full((n,), 1e-3), torch.full((n, 3), 0.5), torch.ones(n), torch.ones(n) > 0)
    weights = LossWeights(
        photometric=0, mask=0, eikonal=0, orientation=0, distortion=0, background=0, free_space=1.0
    )
    optimizer = torch.optim.Adam(model.env_field.parameters(), lr=1e-2)
    losses = []
    for _ in range(20):
        total, terms, _ = objective(model, batch, weights, "mask")
        assert set(terms) >= {"free_space"}
        optimizer.zero_grad()
        total.backward()
        assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.env_field.parameters())
        optimizer.step()
        losses.append(terms["free_space"].item())
    assert losses[0] > 0.05 and losses[-1] < 0.5 * losses[0], losses
