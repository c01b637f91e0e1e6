"""Rendering a pixel: the object's diffuse radiance by volume rendering the SDF along the primary ray, plus
its specular radiance = Fresnel × the environment radiance field integrated along virtual cones.

Where cones are cast: the official code casts one virtual cone per primary sample (~190 per ray), which is
where its cost goes. Nearly all of a ray's weight sits in the few samples straddling the surface, so here
only the ``cone_samples`` highest-weight samples cast cones, their weights renormalized to the ray's
accumulated opacity. Gradients still reach the SDF through those samples' weights, normals (the reflected
direction) and curvature (the cone's apex and spread).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import torch

from .cones import Method as ConeMethod
from .cones import virtual_cone
from .differential import normals_and_curvature_fd
from .fields import EnvironmentField, SDFField
from .frustum import conical_frustum_gaussian
from .geometry_utils import safe_normalize
from .sampling import ray_sphere_bounds, sample_pdf, surface_band, upsample_to_surface
from .volume import composite_weights, quantile_depth, volsdf_density


@dataclass(frozen=True)
class RenderSpec:
    """Sample counts and choices of the renderer (presets set these; see pipeline.config)."""

    object_radius: float = 1.0  # the object's bounding sphere in the normalized frame
    n_coarse: int = 48
    n_fine: int = 32
    upsample_steps: int = 4
    beta_start: float = 0.1  # first β of the coarse-to-fine search for the surface
    band_samples: int = 0  # > 0: render only this many samples in a band around the surface (sampling.py)
    band_half_width: float = 6.0  # the band's half width, in β (divided by the SDF's slope along the ray)
    band_min_slope: float = 0.1  # caps the band's widening for grazing and missing rays
    cone_samples: int = 2
    cone_method: ConeMethod = "closed_form"
    curvature_eps: float = 2e-3  # finite-difference step for the mean curvature at cone samples
    env_samples: int = 48  # coarse samples along each cone (log-spaced) ...
    env_fine: int = 0  # ... plus this many drawn from the coarse weights (coarse-to-fine; 0: one pass)
    env_fine_render: int | None = None  # env_fine for a trained model's environment depth (None: env_fine); for_depth
    depth_quantile: float = 0.5  # an environment ray's depth: where its weight reaches this share (0.5: median)
    free_space_samples: int = 16  # environment samples between a camera and the object (free_space_opacity)
    env_near: float = 1e-2  # first environment sample past the surface (normalized units)
    env_far: float = 1e3  # the room may be far; the contraction keeps this finite
    ior: float = 1.5  # dielectric coating (Fresnel)
    deterministic: bool = False
    # Rays less opaque than this cast no virtual cones: their specular is at most this share of the
    # environment's radiance. A rendered view's pixels beside the object (inside its bounding sphere) are then
    # nearly free; training keeps 0 (every ray the loss reads is shaded).
    shade_min_opacity: float = 0.0
    shade_min_opacity_render: float = 1e-4  # shade_min_opacity when a trained model renders (for_rendering)

    def for_rendering(self) -> RenderSpec:
        """The spec a trained model renders colour with: deterministic (a view rendered twice is the same image),
        training's fine samples along each cone. The colour is the estimate the model was fitted to: with four
        times training's count the demo's object rendered 0.15 dB worse and its environment views the same, and
        a photo's render took 1.6 times as long."""
        return replace(self, deterministic=True, shade_min_opacity=self.shade_min_opacity_render)

    def for_depth(self) -> RenderSpec:
        """The spec a trained model renders the environment's depth with: ``env_fine_render`` fine samples along
        each cone. More than training's count: training draws new random samples every step, a rendered view
        has one fixed set, and too few of them step through a thin prop to the wall behind it."""
        fine = self.env_fine if self.env_fine_render is None else self.env_fine_render
        return replace(self, env_fine=fine)


class RayOutputs(NamedTuple):
    """Per-ray results, ``N`` rays."""

    rgb: torch.Tensor  # (N, 3) diffuse + specular (object only; background not added)
    diffuse: torch.Tensor  # (N, 3)
    specular: torch.Tensor  # (N, 3)
    normal: torch.Tensor  # (N, 3) composited world normal
    opacity: torch.Tensor  # (N,) accumulated weight of the object
    depth: torch.Tensor  # (N,) expected distance along the ray
    sdf_grad: torch.Tensor  # (N, S, 3) SDF gradients at the samples (eikonal loss)
    weights: torch.Tensor  # (N, S)
    t: torch.Tensor  # (N, S + 1) interval edges
    env_weights: torch.Tensor  # (M, K, E) weights along the shaded rays' virtual cones (distortion loss)
    env_s: torch.Tensor  # (M, K, E + 1) cone interval edges, normalized to [0, 1] (log distance)


def fresnel_dielectric(cos_theta: torch.Tensor, ior: float) -> torch.Tensor:
    """Unpolarized Fresnel reflectance of a dielectric from air, exact (not Schlick).

    Args:
        cos_theta: ``(...)`` cosine of the incidence angle, in [0, 1].
    """
    cos_i = cos_theta.clamp(0.0, 1.0)
    sin_t2 = (1 - cos_i.square()) / ior**2
    cos_t = (1 - sin_t2).clamp_min(0).sqrt()
    rs = (cos_i - ior * cos_t) / (cos_i + ior * cos_t)
    rp = (ior * cos_i - cos_t) / (ior * cos_i + cos_t)
    return 0.5 * (rs.square() + rp.square())


def fresnel_schlick(cos_theta: torch.Tensor, f0: torch.Tensor) -> torch.Tensor:
    """Schlick's Fresnel: ``f0 + (1 - f0) (1 - cos θ)^5`` with an RGB reflectance at normal incidence (a metal's
    colour; a clear coat at IOR 1.5 has 0.04 in every channel, and Schlick's curve then stays within 0.04 of
    the exact :func:`fresnel_dielectric` at any angle).

    Args:
        cos_theta: ``(...)`` cosine of the incidence angle, in [0, 1]; f0: ``(..., 3)``.
    Returns:
        ``(..., 3)``.
    """
    grazing = (1 - cos_theta.clamp(0.0, 1.0)).pow(5)[..., None]
    return f0 + (1 - f0) * grazing


def stratified_edges(
    m: int, n: int, deterministic: bool, dtype: torch.dtype, device: torch.device
) -> torch.Tensor:
    """``(m, n + 1)`` edges of ``n`` bins over [0, 1]: evenly spaced, or (unless ``deterministic``) with each
    inner edge jittered within its own bin, as NeRF's stratified samples."""
    s = torch.linspace(0, 1, n + 1, dtype=dtype, device=device).expand(m, -1)
    if deterministic:
        return s
    jitter = (torch.rand(m, n - 1, dtype=dtype, device=device) - 0.5) / n
    return torch.cat([s[:, :1], s[:, 1:-1] + jitter, s[:, -1:]], dim=-1)


def environment_edges(spec: RenderSpec, m: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``(m, env_samples + 1)`` coarse distances past the start of ``m`` cones, log-spaced (near things get
    the samples they need, far walls still get some), starting exactly at 0.

    Unless ``spec.deterministic``, each cone's inner edges are jittered within their own bin (stratified, as
    NeRF's coarse samples): with fixed edges every training ray of a camera samples the same shells, and
    the field learns density between them that those rays never see but any other viewpoint does (floaters).
    """
    s = stratified_edges(m, spec.env_samples, spec.deterministic, dtype, device)
    u = torch.exp(math.log(spec.env_near) + s * (math.log(spec.env_far) - math.log(spec.env_near)))
    return torch.cat([torch.zeros_like(u[:, :1]), u[:, 1:]], dim=-1)


def normalized_distance(u: torch.Tensor, spec: RenderSpec) -> torch.Tensor:
    """Distances past a cone's start -> [0, 1] by the log spacing of :func:`environment_edges` (the
    distortion loss's coordinate, in which every coarse interval has the same length)."""
    log_near, log_far = math.log(spec.env_near), math.log(spec.env_far)
    s = (torch.log(u.clamp_min(spec.env_near)) - log_near) / (log_far - log_near)
    return torch.where(u > 0, s.clamp(0, 1), torch.zeros_like(s))


Solid = Callable[[torch.Tensor], torch.Tensor]  # (P, 3) points -> (P,) bool: inside the object


def _frustums(env: EnvironmentField, apex, axis, radius_growth, t_start, u, solid: Solid | None = None,
              radiance: bool = True):
    """Density and (unless not ``radiance``: None) radiance of the frustums between edges ``u`` ``(M, E + 1)``
    past ``t_start``; no density where ``solid`` says a frustum's mean lies inside the object."""
    t = t_start[:, None] + u
    means, variances = conical_frustum_gaussian(apex, axis, radius_growth, t[:, :-1], t[:, 1:])
    density, rgb = env(means, variances, axis) if radiance else (env.density(means, variances), None)
    if solid is not None:
        density = torch.where(solid(means.reshape(-1, 3)).reshape(density.shape), 0.0, density)
    return density, rgb


def render_environment_along(
    env: EnvironmentField,
    apex: torch.Tensor,
    axis: torch.Tensor,
    radius_growth: torch.Tensor,
    t_start: torch.Tensor,
    spec: RenderSpec,
    solid: Solid | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Volume-render the environment field along cones that start ``t_start`` from their apex.

    Used for virtual cones (apex behind the surface) and for ordinary camera cones (``t_start = 0``).
    ``solid`` (optional) marks points inside the object, where the environment has no density: a camera
    inside the object (the paper's environment views) otherwise looks through whatever the field holds
    there, which no photo ever constrained.

    Coarse-to-fine (``spec.env_fine > 0``): a first pass without gradients on the log-spaced edges places
    ``env_fine`` more samples where its weights are (inverse CDF); the second pass renders coarse and fine
    edges together, with gradients.

    Args:
        apex, axis: ``(M, 3)``; radius_growth, t_start: ``(M,)``.
    Returns:
        radiance ``(M, 3)``, depth past the start ``(M,)`` (:func:`~orca.volume.quantile_depth`),
        weights ``(M, E)``, normalized edges ``(M, E + 1)`` (E = env_samples + env_fine). A directional (2D map)
        field gives infinite depth and zero weights.
    """
    m = apex.shape[0]
    if env.directional:  # a 2D map: no depth, nothing along the cone to weigh
        rgb = env.radiance_at_infinity(axis, radius_growth)
        depth = torch.full_like(radius_growth, math.inf)
        e = spec.env_samples + spec.env_fine
        s = torch.linspace(0, 1, e + 1, dtype=apex.dtype, device=apex.device).expand(m, -1)
        return rgb, depth, torch.zeros(m, e, dtype=apex.dtype, device=apex.device), s
    w, u, radiance = environment_weights(env, apex, axis, radius_growth, t_start, spec, solid)
    rgb = (w[..., None] * radiance).sum(-2)
    return rgb, quantile_depth(w, u, spec.depth_quantile), w, normalized_distance(u, spec)


def environment_weights(
    env: EnvironmentField,
    apex: torch.Tensor,
    axis: torch.Tensor,
    radius_growth: torch.Tensor,
    t_start: torch.Tensor,
    spec: RenderSpec,
    solid: Solid | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The volume-rendering weights of a (non-directional) environment field along cones, coarse-to-fine as
    :func:`render_environment_along` describes.

    Args:
        apex, axis: ``(M, 3)``; radius_growth, t_start: ``(M,)``.
    Returns:
        weights ``(M, E)``, their intervals' edges ``(M, E + 1)`` as distances past ``t_start``, and the
        frustums' radiance ``(M, E, 3)``.
    """
    u = environment_edges(spec, apex.shape[0], apex.dtype, apex.device)
    if spec.env_fine > 0:
        with torch.no_grad():
            density, _ = _frustums(env, apex, axis, radius_growth, t_start, u, solid, radiance=False)
            w_coarse, _ = composite_weights(density, u)
            fine = sample_pdf(u, w_coarse, spec.env_fine, deterministic=spec.deterministic)
        u = torch.sort(torch.cat([u, fine], dim=-1), dim=-1).values
    density, radiance = _frustums(env, apex, axis, radius_growth, t_start, u, solid)
    w, _ = composite_weights(density, u)
    return w, u, radiance


def free_space_opacity(
    env: EnvironmentField,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    radii: torch.Tensor,
    spec: RenderSpec,
) -> torch.Tensor:
    """Opacity the environment field puts between each camera and the object, along object rays.

    A pixel the mask calls object sees the object unoccluded, so the environment must be empty from the
    camera to the object's bounding sphere. Nothing else says so: object pixels are rendered from the SDF
    alone, and background rays see each patch of the room from one side, so the field is free to explain a
    photo's background with density just before its lens, in space that the neighbouring cameras' object
    rays cross. ``spec.free_space_samples`` stratified frustums from the camera to the sphere's entry.

    Args:
        origins, dirs: ``(N, 3)`` camera rays (unit directions); radii: ``(N,)`` pixel cone radius per unit
            distance.
    Returns:
        ``1 - exp(-∫ σ)`` over that segment, ``(N,)``; 0 for rays that start inside the sphere or miss it.
    """
    if env.directional:  # a 2D map has no density anywhere
        return torch.zeros_like(radii)
    entry, _, hit = ray_sphere_bounds(origins, dirs, spec.object_radius)
    s = stratified_edges(origins.shape[0], spec.free_space_samples, spec.deterministic, origins.dtype,
                         origins.device)
    t = s * torch.where(hit, entry, 0)[:, None]
    means, variances = conical_frustum_gaussian(origins, dirs, radii, t[:, :-1], t[:, 1:])
    density = env.density(means, variances)
    _, transmittance = composite_weights(density, t)
    return 1.0 - transmittance


def shade_specular(
    env_field: EnvironmentField,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    radii: torch.Tensor,
    points: torch.Tensor,
    normals: torch.Tensor,
    curvature: torch.Tensor,
    share: torch.Tensor,
    spec: RenderSpec,
    reflectance: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Specular radiance of ``K`` surface samples per ray: Fresnel × environment along their virtual cones.

    Args:
        origins, dirs: ``(N, 3)``; radii: ``(N,)``.
        points, normals: ``(N, K, 3)``; curvature, share: ``(N, K)`` (share: each sample's weight).
        reflectance: ``(N, K, 3)`` the samples' reflectance at normal incidence (:func:`fresnel_schlick`), or
            None: a clear coat's exact Fresnel at ``spec.ior`` (:func:`fresnel_dielectric`).
    Returns:
        specular ``(N, 3)``, cone weights ``(N, K, E)``, normalized cone edges ``(N, K, E + 1)``.
    """
    n, k = share.shape
    cone = virtual_cone(
        origins[:, None].expand(n, k, 3), dirs[:, None].expand(n, k, 3), radii[:, None].expand(n, k),
        points, normals, curvature, method=spec.cone_method,
    )
    env_rgb, _, env_w, env_s = render_environment_along(
        env_field, cone.apex.reshape(-1, 3), cone.axis.reshape(-1, 3), cone.radius_growth.reshape(-1),
        cone.t_start.reshape(-1), spec,
    )
    cos_i = (-(dirs[:, None] * normals).sum(-1)).abs()
    if reflectance is None:
        fresnel = fresnel_dielectric(cos_i, spec.ior)[..., None]
    else:
        fresnel = fresnel_schlick(cos_i, reflectance)
    specular = (share[..., None] * fresnel * env_rgb.reshape(n, k, 3)).sum(1)
    return specular, env_w.reshape(n, k, -1), env_s.reshape(n, k, -1)


def _shaded_rays(specular: bool | torch.Tensor, opacity: torch.Tensor, min_opacity: float) -> torch.Tensor | None:
    """Indices ``(M,)`` of the rays that cast virtual cones, or None for every ray (see :func:`render_rays`)."""
    chosen = specular if isinstance(specular, torch.Tensor) else torch.full_like(opacity, specular, dtype=torch.bool)
    if min_opacity > 0:
        chosen = chosen & (opacity.detach() > min_opacity)
    return None if bool(chosen.all()) else chosen.nonzero().squeeze(-1)


def render_rays(
    sdf_field: SDFField,
    env_field: EnvironmentField,
    beta: torch.Tensor,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    radii: torch.Tensor,
    spec: RenderSpec = RenderSpec(),
    specular: bool | torch.Tensor = True,
) -> RayOutputs:
    """Render primary rays through the object.

    Args:
        beta: scalar VolSDF β (learnable; positive).
        origins: ``(N, 3)`` camera centres; dirs: ``(N, 3)`` unit directions; radii: ``(N,)`` pixel-cone
            radius growth (mip-NeRF ``radii``).
        specular: False skips the virtual cones (specular zero, no cone weights): geometry alone, as the
            mask-only warm-up needs, at a fraction of the cost. A ``(N,)`` bool tensor casts cones for those
            rays only (training: the pixels whose colour a loss reads); the others' specular is zero. Either way
            rays below ``spec.shade_min_opacity`` cast none.
    Returns:
        :class:`RayOutputs`; its cone weights and edges are the shaded rays' only, ``(M, K, E)``.
    """
    n = origins.shape[0]
    near, far, _ = ray_sphere_bounds(origins, dirs, spec.object_radius)
    # Rays that miss the bounding sphere get an empty interval beyond it: zero weight, no special case.
    far = torch.maximum(far, near + 1e-4)
    t, values = upsample_to_surface(
        sdf_field.sdf, origins, dirs, near, far, n_coarse=spec.n_coarse, n_fine=spec.n_fine,
        steps=spec.upsample_steps, beta_start=spec.beta_start, deterministic=spec.deterministic,
    )
    if spec.band_samples > 0:
        t = surface_band(
            t, values, float(beta.detach()), spec.band_samples, half_width_betas=spec.band_half_width,
            min_slope=spec.band_min_slope, deterministic=spec.deterministic,
        )
    mid = 0.5 * (t[:, 1:] + t[:, :-1])  # (N, S)
    x = origins[:, None] + mid[..., None] * dirs[:, None]  # (N, S, 3)
    flat = x.reshape(-1, 3).detach().requires_grad_(True)
    training = torch.is_grad_enabled()  # rendering under no_grad needs the normals, not their graph
    with torch.enable_grad():  # one pass gives the SDF, its features and (double-differentiable) gradient
        sdf, feats = sdf_field(flat)
        (grad,) = torch.autograd.grad(sdf.sum(), flat, create_graph=training)
    if not training:
        sdf, feats = sdf.detach(), feats.detach()
    s_count = mid.shape[1]
    density = volsdf_density(sdf.reshape(n, s_count), beta)
    w, _ = composite_weights(density, t)
    opacity = w.sum(-1)
    diffuse_radiance, reflectance = sdf_field.surface(flat, feats)
    diffuse = (w[..., None] * diffuse_radiance.reshape(n, s_count, 3)).sum(-2)
    normals = safe_normalize(grad).reshape(n, s_count, 3)
    normal_map = (w[..., None] * normals).sum(-2)
    depth = (w * mid).sum(-1)

    shade = _shaded_rays(specular, opacity, spec.shade_min_opacity)
    if shade is None or shade.numel():
        # Virtual cones at the highest-weight samples only.
        pick = (lambda t: t) if shade is None else (lambda t: t[shade])  # noqa: E731
        m = n if shade is None else shade.numel()
        k = min(spec.cone_samples, s_count)
        w_m, x_m, normals_m = pick(w), pick(x), pick(normals)
        top = torch.topk(w_m.detach(), k, dim=-1).indices  # (M, K)
        w_k = w_m.gather(1, top)  # (M, K) differentiable
        p_k = x_m.gather(1, top[..., None].expand(m, k, 3))
        n_k = normals_m.gather(1, top[..., None].expand(m, k, 3))
        f0_k = None if reflectance is None else pick(reflectance.reshape(n, s_count, 3)).gather(
            1, top[..., None].expand(m, k, 3))
        _, curv = normals_and_curvature_fd(sdf_field.sdf, p_k.reshape(-1, 3), spec.curvature_eps)
        share = w_k / w_k.sum(-1, keepdim=True).clamp_min(1e-8) * pick(opacity)[:, None]  # (M, K)
        shaded, env_w, env_s = shade_specular(
            env_field, pick(origins), pick(dirs), pick(radii), p_k, n_k, curv.reshape(m, k), share, spec, f0_k
        )
        specular_rgb = shaded if shade is None else torch.zeros_like(diffuse).index_put((shade,), shaded)
    else:
        specular_rgb = torch.zeros_like(diffuse)
        env_w = env_s = torch.zeros(0, 0, 0, dtype=w.dtype, device=w.device)
    return RayOutputs(
        rgb=diffuse + specular_rgb, diffuse=diffuse, specular=specular_rgb, normal=normal_map, opacity=opacity,
        depth=depth, sdf_grad=grad.reshape(n, s_count, 3), weights=w, t=t,
        env_weights=env_w, env_s=env_s,
    )

