"""Where to put samples along rays: bounds from the object's sphere, inverse-CDF resampling, and
coarse-to-fine upsampling that finds the SDF's zero crossing.

The object lives in the unit sphere of its normalized frame, so primary rays are sampled only between
their entry and exit of that sphere; a coarse pass on the SDF then concentrates samples at the surface.

Two ways to choose the samples that are rendered (with gradients):

* ``upsample_to_surface`` alone (the ``paper`` preset): every coarse and fine sample is rendered, as NeuS
  and the paper's code do.
* ``upsample_to_surface`` then ``surface_band`` (``fast``/``standard``): the no-gradient samples only locate
  the first zero crossing; the rendered samples are a narrow band around it, a few β wide (divided by the
  SDF's slope along the ray, so grazing rays get a wider band). VolSDF's density in front of the band is
  below ``exp(-half_width_betas)`` of its peak, so dropping it changes the colour by less than that, and
  the expensive pass (SDF with double-differentiable gradients) runs on 3x fewer points.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from .volume import composite_weights, volsdf_density


def ray_sphere_bounds(
    origins: torch.Tensor, dirs: torch.Tensor, radius: float = 1.0
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Entry and exit distances of rays through a sphere at the origin.

    Args:
        origins: ``(N, 3)``; dirs: ``(N, 3)`` unit.
    Returns:
        near ``(N,)``, far ``(N,)`` (clamped to >= 0), hit ``(N,)`` bool. Missed rays get near = far = 0.
    """
    b = (origins * dirs).sum(-1)
    c = origins.square().sum(-1) - radius**2
    disc = b.square() - c
    hit = disc > 0
    root = disc.clamp_min(0).sqrt()
    near = (-b - root).clamp_min(0)
    far = (-b + root).clamp_min(0)
    hit = hit & (far > near)
    return torch.where(hit, near, 0), torch.where(hit, far, 0), hit


def sample_pdf(
    bins: torch.Tensor, weights: torch.Tensor, n_samples: int, *, deterministic: bool = False,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Inverse-CDF samples of a piecewise-constant PDF (no gradient: where to sample, not what).

    Args:
        bins: ``(N, S + 1)`` increasing edges; weights: ``(N, S)`` non-negative.
        n_samples: samples per ray.
        deterministic: evenly spaced quantiles instead of random ones (evaluation).
    Returns:
        ``(N, n_samples)`` sorted sample positions.
    """
    bins, weights = bins.detach(), weights.detach()
    w = weights + 1e-5  # a floor keeps the CDF strictly increasing on empty rays
    pdf = w / w.sum(-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, -1)], -1).clamp_max(1.0)
    n = bins.shape[0]
    if deterministic:
        u = torch.linspace(0.5 / n_samples, 1 - 0.5 / n_samples, n_samples, dtype=bins.dtype, device=bins.device)
        u = u.expand(n, n_samples).contiguous()
    else:
        u = torch.rand(n, n_samples, dtype=bins.dtype, device=bins.device, generator=generator)
    idx = torch.searchsorted(cdf, u, right=True).clamp(1, bins.shape[1] - 1)
    c0, c1 = cdf.gather(1, idx - 1), cdf.gather(1, idx)
    b0, b1 = bins.gather(1, idx - 1), bins.gather(1, idx)
    frac = ((u - c0) / (c1 - c0).clamp_min(1e-12)).clamp(0, 1)
    return torch.sort(b0 + frac * (b1 - b0), dim=-1).values


def upsample_to_surface(
    sdf: Callable[[torch.Tensor], torch.Tensor],
    origins: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    *,
    n_coarse: int,
    n_fine: int,
    steps: int,
    beta_start: float,
    deterministic: bool = False,
) -> torch.Tensor:
    """Coarse-to-fine interval edges that concentrate on the first zero crossing of the SDF.

    A uniform pass is refined ``steps`` times: each refinement turns the SDF into VolSDF density with a
    β that shrinks geometrically from ``beta_start`` (sharper each round, as NeuS's upsampling does), and
    draws ``n_fine // steps`` more samples from the resulting weights. The SDF is evaluated without
    gradients here; the caller evaluates the final samples with gradients.

    Args:
        origins, dirs: ``(N, 3)``; near, far: ``(N,)``.
    Returns:
        ``(N, n_coarse + n_fine)`` sorted sample edges and ``(N, n_coarse + n_fine)`` SDF values there.
    """
    n = origins.shape[0]
    u = torch.linspace(0, 1, n_coarse, dtype=origins.dtype, device=origins.device)
    t = near[:, None] + (far - near)[:, None] * u
    per_step = max(n_fine // max(steps, 1), 1)
    with torch.no_grad():
        values = sdf((origins[:, None] + t[..., None] * dirs[:, None]).reshape(-1, 3)).reshape(n, -1)
        for k in range(steps):
            beta = beta_start / 2**k
            mid_sdf = 0.5 * (values[:, 1:] + values[:, :-1])
            w, _ = composite_weights(volsdf_density(mid_sdf, beta), t)
            extra = per_step if k < steps - 1 else n_fine - per_step * (steps - 1)
            t_new = sample_pdf(t, w, extra, deterministic=deterministic)
            v_new = sdf((origins[:, None] + t_new[..., None] * dirs[:, None]).reshape(-1, 3)).reshape(n, -1)
            t, order = torch.sort(torch.cat([t, t_new], -1), dim=-1)
            values = torch.cat([values, v_new], -1).gather(1, order)
    return t, values


def surface_band(
    t: torch.Tensor,
    values: torch.Tensor,
    beta: float,
    n_samples: int,
    *,
    half_width_betas: float,
    min_slope: float,
    deterministic: bool = False,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Interval edges of a band around each ray's first zero crossing of the SDF.

    Args:
        t: ``(N, S)`` sorted distances where the SDF was evaluated; values: ``(N, S)`` the SDF there.
        beta: the current VolSDF β (the band's width scales with it).
        n_samples: intervals in the band.
        half_width_betas: half the band's width in units of β / slope.
        min_slope: floor of |df/dt| used for the width (rays that graze or miss the surface).
        deterministic: evenly spaced edges; otherwise the whole comb is shifted by a random fraction of one
            spacing per ray (stratified sampling).
    Returns:
        ``(N, n_samples + 1)`` sorted edges. Rays without a crossing get a band at their SDF minimum (the
        point where the mask loss can pull the surface towards them).
    """
    t, values = t.detach(), values.detach()
    crossing = (values[:, :-1] > 0) & (values[:, 1:] <= 0)
    has_crossing = crossing.any(-1)
    first = crossing.to(torch.uint8).argmax(-1)  # the first True
    nearest = values[:, :-1].abs().argmin(-1)
    i = torch.where(has_crossing, first, nearest)[:, None]
    t0, t1 = t.gather(1, i), t.gather(1, i + 1)
    v0, v1 = values.gather(1, i), values.gather(1, i + 1)
    slope = ((v0 - v1) / (t1 - t0).clamp_min(1e-9)).abs()
    frac = (v0 / (v0 - v1)).nan_to_num(0.0).clamp(0, 1)
    centre = torch.where(has_crossing[:, None], t0 + frac * (t1 - t0), t0)  # (N, 1)
    half = half_width_betas * beta / slope.clamp(min_slope, 1.0)
    comb = torch.linspace(-1, 1, n_samples + 1, dtype=t.dtype, device=t.device)
    if not deterministic:
        shift = torch.rand(t.shape[0], 1, dtype=t.dtype, device=t.device, generator=generator) - 0.5
        comb = comb + shift * (2.0 / n_samples)
    return (centre + half * comb).clamp_min(0.0)
