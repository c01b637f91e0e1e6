"""The model's objective: finite, phase-dependent terms, and a few optimizer steps that lower the loss on
rays of an analytic glossy sphere."""

from __future__ import annotations

import torch
from analytic_fields import AnalyticEnvironment

from orca.encoding import HashGridSpec
from orca.fields import EnvironmentFieldSpec, SDFFieldSpec
from orca.model import Batch, LossWeights, ModelSpec, OrcaModel, objective
from orca.render import RenderSpec, render_environment_along

GRID = HashGridSpec(levels=4, log2_table_size=10, base_resolution=4, max_resolution=32)


def _model() -> OrcaModel:
    return OrcaModel(ModelSpec(
        sdf=SDFFieldSpec(hash_grid=GRID, init_radius=0.4),
        env=EnvironmentFieldSpec(hash_grid=GRID),
        render=RenderSpec(n_coarse=24, n_fine=16, env_samples=16),
    ))


def _batch(n=128, seed=0, radius=0.55) -> Batch:
    """Rays at a sphere of the given radius: mask from the analytic hit, a flat grey target on the object,
    a brighter background."""
    g = torch.Generator().manual_seed(seed)
    o = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 2.5
    d = torch.nn.functional.normalize((torch.rand(n, 3, generator=g) - 0.5) * 1.6 - o, dim=-1)
    b = (o * d).sum(-1)
    hit = (b**2 - (o.square().sum(-1) - radius**2)) > 0
    rgb = torch.where(hit[:, None], torch.tensor([0.3, 0.2, 0.1]), torch.tensor([0.8, 0.8, 0.8]))
    return Batch(o, d, torch.full((n,), 1e-3), rgb, hit.float(), torch.ones(n, dtype=torch.bool))


def test_objective_terms_by_phase():
    model = _model()
    total, terms, _ = objective(model, _batch(), LossWeights(), "mask")
    # the warm-up already teaches the environment field the background (it does not touch the object)
    assert set(terms) == {"mask", "eikonal", "background"} and torch.isfinite(total)
    total, terms, _ = objective(model, _batch(), LossWeights(), "joint")
    assert {"photometric", "orientation", "distortion", "background"} <= set(terms)
    assert all(torch.isfinite(v) for v in terms.values())


def test_warm_up_then_joint_steps_lower_mask_and_photometric_losses():
    torch.manual_seed(0)
    model = _model()
    opt = torch.optim.Adam(model.parameters(), lr=5e-3)
    batch = _batch()
    history = []
    for step in range(30):
        total, terms, _ = objective(model, batch, LossWeights(), "mask" if step < 15 else "joint")
        history.append({k: v.item() for k, v in terms.items()})
        opt.zero_grad()
        total.backward()
        opt.step()
    _, final, _ = objective(model, batch, LossWeights(), "joint")
    assert history[14]["mask"] < 0.6 * history[0]["mask"], "warm-up grows the sphere toward the silhouettes"
    assert final["photometric"] < 0.5 * history[15]["photometric"]
    # joint training must not undo the silhouettes (colour is compared per unit opacity)
    assert final["mask"] < history[0]["mask"]


def test_schedule_opens_sdf_levels_coarse_to_fine_and_caps_beta():
    model = _model()  # 4-level SDF grid, beta_init 0.05, beta_final 0.005 at half of training
    spec = model.spec
    model.apply_schedule(0.0)
    weights = model.sdf_field.grid.level_weights
    assert weights.tolist() == [1.0, 1.0, 1.0, 1.0]  # sdf_levels_start = 4: all of this small grid
    model = OrcaModel(ModelSpec(sdf=SDFFieldSpec(hash_grid=GRID), sdf_levels_start=2, sdf_levels_full=0.5))
    model.apply_schedule(0.0)
    assert model.sdf_field.grid.level_weights.tolist() == [1.0, 1.0, 0.0, 0.0]
    model.apply_schedule(0.125)  # a quarter of the ramp: half a level more
    torch.testing.assert_close(model.sdf_field.grid.level_weights, torch.tensor([1.0, 1.0, 0.5, 0.0]))
    model.apply_schedule(0.9)
    assert model.sdf_field.grid.level_weights.tolist() == [1.0, 1.0, 1.0, 1.0]
    # an inactive level contributes nothing: its table entries get no gradient
    model.apply_schedule(0.0)
    x = torch.rand(64, 3) * 0.5
    model.sdf_field.sdf(x).sum().backward()
    grid = model.sdf_field.grid
    fine = slice(grid.offsets[2], grid.offsets[4])
    assert grid.table.grad[fine].abs().max() == 0 and grid.table.grad[: grid.offsets[2]].abs().max() > 0
    # β: capped on a geometric schedule, never raised
    model = _model()
    model.apply_schedule(0.25)
    cap = spec.beta_init * (spec.beta_final / spec.beta_init) ** 0.5
    torch.testing.assert_close(model.beta, torch.tensor(cap), rtol=1e-5, atol=0)
    with torch.no_grad():
        model.log_beta.fill_(-9.0)  # learned sharper than the cap: left alone
    model.apply_schedule(0.3)
    assert model.beta.item() < cap


def test_warm_up_renders_geometry_without_virtual_cones():
    """``specular=False`` (the mask phase) gives the same geometry and diffuse as a full render, no specular
    and no cone weights; the object rays then give the environment field no gradient."""
    from dataclasses import replace

    model = _model()
    model.spec = replace(model.spec, render=replace(model.spec.render, deterministic=True))  # same samples twice
    batch = _batch(seed=3)
    with torch.no_grad():
        full = model(batch.origins, batch.dirs, batch.radii)
        plain = model(batch.origins, batch.dirs, batch.radii, specular=False)
    for key in ("opacity", "diffuse", "normal", "depth"):
        assert torch.allclose(getattr(full, key), getattr(plain, key), atol=1e-6), key
    assert full.specular.abs().sum() > 0 and plain.specular.abs().sum() == 0
    assert plain.env_weights.numel() == 0 and torch.equal(plain.rgb, plain.diffuse)
    total, _, _ = objective(model, batch, LossWeights(background=0.0), "mask")
    total.backward()
    assert all(p.grad is None or p.grad.abs().sum() == 0 for p in model.env_field.parameters())


def test_specular_for_chosen_rays_only():
    """A bool tensor casts cones for the rays it marks: their specular is a full render's, the others' is zero
    and their cones cost nothing (the cone weights are the marked rays'); geometry is unchanged. In training the
    object pixels are marked, so a batch's off-object rays give the environment field no gradient through
    cones."""
    from dataclasses import replace

    model = _model()
    model.spec = replace(model.spec, render=replace(model.spec.render, deterministic=True))
    batch = _batch(seed=3)
    chosen = torch.arange(batch.radii.shape[0]) % 3 == 0
    with torch.no_grad():
        full = model(batch.origins, batch.dirs, batch.radii)
        some = model(batch.origins, batch.dirs, batch.radii, specular=chosen)
    for key in ("opacity", "diffuse", "normal", "depth"):
        assert torch.allclose(getattr(full, key), getattr(some, key), atol=1e-6), key
    assert full.specular[chosen].abs().sum() > 0
    torch.testing.assert_close(some.specular[chosen], full.specular[chosen], atol=1e-6, rtol=1e-5)
    assert some.specular[~chosen].abs().sum() == 0
    with torch.no_grad():
        every = model(batch.origins, batch.dirs, batch.radii, specular=torch.ones_like(chosen))
    torch.testing.assert_close(every.specular, full.specular)
    assert some.env_weights.shape[0] == int(chosen.sum())
    torch.testing.assert_close(some.env_weights, full.env_weights[chosen], atol=1e-6, rtol=1e-5)
    # rays less opaque than shade_min_opacity cast no cones (a rendered view's pixels beside the object)
    threshold = float(full.opacity.median())
    model.spec = replace(model.spec, render=replace(model.spec.render, shade_min_opacity=threshold))
    with torch.no_grad():
        opaque_only = model(batch.origins, batch.dirs, batch.radii)
    opaque = full.opacity > threshold
    assert 0 < int(opaque.sum()) < opaque.numel()
    torch.testing.assert_close(opaque_only.specular[opaque], full.specular[opaque], atol=1e-6, rtol=1e-5)
    assert opaque_only.specular[~opaque].abs().sum() == 0
    assert model.spec.render.for_rendering().shade_min_opacity == model.spec.render.shade_min_opacity_render > 0
    # none marked: a joint step still works (no distortion term), and gradients stay finite
    nothing = batch._replace(mask=torch.zeros_like(batch.mask))
    total, terms, _ = objective(model, nothing, LossWeights(background=0.0), "joint")
    total.backward()
    assert "distortion" not in terms and torch.isfinite(total)


def test_background_batch_trains_only_the_environment_field():
    """Extra off-object rays add to the background term; their gradient reaches the environment field,
    never the SDF (the object's inside is masked without a graph)."""
    model = _model()
    batch = _batch(seed=1)
    extra = _batch(n=64, seed=2)
    extra = extra._replace(rgb=torch.full_like(extra.rgb, 5.0))  # far from what the field predicts
    weights = LossWeights(mask=0.0, eikonal=0.0)
    _, plain, _ = objective(model, batch, weights, "mask")
    total, more, _ = objective(model, batch, weights, "mask", background=extra)
    assert more["background"] > plain["background"] + 1.0
    total.backward()
    env_grad = sum(p.grad.abs().sum() for p in model.env_field.parameters() if p.grad is not None)
    sdf_grad = sum(p.grad.abs().sum() for p in model.sdf_field.parameters() if p.grad is not None)
    assert env_grad > 0 and sdf_grad == 0


def test_environment_views_from_inside_the_object_start_at_its_surface():
    """A camera at the object's centre (the paper's environment views) sees no environment density inside
    the object: with a field dense everywhere, the rendered depth is where the rays leave the SDF's sphere
    (radius 0.4), not at the camera."""
    model = OrcaModel(ModelSpec(
        sdf=SDFFieldSpec(hash_grid=GRID, init_radius=0.4),
        env=EnvironmentFieldSpec(hash_grid=GRID, density_bias=6.0),  # ~6 per unit: opaque within ~0.5
        render=RenderSpec(env_samples=32, env_fine=32, env_near=0.01, env_far=100.0, deterministic=True),
    ))
    dirs = torch.nn.functional.normalize(torch.randn(64, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    origins, radii = torch.zeros(64, 3), torch.full((64,), 1e-3)
    with torch.no_grad():
        _, depth = model.environment(origins, dirs, radii)
        # the same field without the object's inside emptied is opaque right at the camera
        _, unmasked, _, _ = render_environment_along(model.env_field, origins, dirs, radii, torch.zeros(64),
                                                     model.spec.render)
    assert bool((depth > 0.4).all()), depth.min()
    assert bool((unmasked < 0.3).all()), unmasked.max()


class _FloaterBeforeTheLens(AnalyticEnvironment):
    """White fog within 0.5 of a camera at x = -4, a grey wall at x > 3: the colour a floater gives a photo's
    background, unseen by any other camera."""

    def forward(self, means, variances, dirs):
        x = means[..., 0]
        fog = x < -3.5
        density = torch.where(fog | (x > 3.0), 1e3, 0.0)
        return density, torch.where(fog[..., None], 1.0, 0.5).expand(*means.shape[:-1], 3)


def test_background_rays_start_part_way_to_the_object_so_a_floater_at_the_lens_explains_nothing():
    from dataclasses import replace

    n = 32
    g = torch.Generator().manual_seed(0)
    dirs = torch.nn.functional.normalize(torch.tensor([1.0, 0.6, 0.0]) + 0.05 * torch.randn(n, 3, generator=g), dim=-1)
    grey = torch.full((n, 3), 0.5)
    batch = Batch(torch.tensor([-4.0, 0.0, 0.0]).expand(n, 3), dirs, torch.full((n,), 1e-3), grey, torch.zeros(n),
                  torch.ones(n, dtype=torch.bool))  # off the object (radius 0.4): background rays only
    weights = LossWeights(mask=0.0, eikonal=0.0)
    losses = {}
    for near in (0.0, 0.25):
        model = _model()
        model.spec = replace(model.spec, background_near=near, render=replace(model.spec.render, env_fine=16))
        model.env_field = _FloaterBeforeTheLens()
        losses[near] = objective(model, batch, weights, "mask")[1]["background"].item()
        _, depth = model.environment(batch.origins, batch.dirs, batch.radii, torch.full((n,), 4.0 * near))
        assert bool((depth > 4.0 * near).all())  # ray depth from the camera, not from the near bound
    assert losses[0.0] > 0.1 and losses[0.25] < 0.01, losses  # white fog vs the grey wall (0.001: the loss floor)


def test_sparse_depth_places_the_environment_where_the_points_are():
    """Rays from a ring of cameras through points on a sphere of radius 3 (a room's walls): a few hundred
    steps of the sparse-depth term alone move the field's depth there from its initial fog."""
    from orca.model import DepthBatch

    torch.manual_seed(0)
    model = _model()
    spec = RenderSpec(env_samples=32, env_fine=16, depth_quantile=0.5)
    model = OrcaModel(ModelSpec(sdf=model.spec.sdf, env=model.spec.env, render=spec))
    g = torch.Generator().manual_seed(1)

    def rays(n):
        o = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 1.5
        d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
        b = (o * d).sum(-1)
        t = -b + torch.sqrt(b**2 - (o.square().sum(-1) - 9.0))  # where each ray leaves the radius-3 sphere
        return DepthBatch(o, d, torch.full((n,), 1e-3), t)

    test = rays(256)

    def depth_error():
        with torch.no_grad():
            _, depth = model.environment(test.origins, test.dirs, test.radii)
        return ((depth - test.distance).abs() / test.distance).median().item()

    before = depth_error()
    weights = LossWeights(photometric=0, mask=0, eikonal=0, background=0, sparse_depth=1.0)
    optimizer = torch.optim.Adam(model.env_field.parameters(), lr=1e-2)
    few = _batch(8)  # the object terms are weighed 0; only the sparse-depth rays teach the field
    losses = []
    for _ in range(150):
        total, terms, _ = objective(model, few, weights, "mask", depth=rays(256))
        losses.append(terms["sparse_depth"].item())
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
    after = depth_error()
    print(f"median relative depth error {before:.3f} -> {after:.3f}, loss {losses[0]:.3f} -> {losses[-1]:.3f}")
    assert losses[-1] < 0.6 * losses[0], losses  # measured: 0.97 -> 0.52 (a coarse grid: not all in the band)
    assert after < 0.05 and after < 0.2 * before, (before, after)  # measured: 0.27 -> 0.02
