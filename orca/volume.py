"""Volume rendering along rays: VolSDF density from an SDF, compositing weights, and the distortion loss.

Samples along a ray are given by interval edges ``t`` of shape ``(..., S + 1)``; per-interval quantities
(density, colour) have shape ``(..., S)``.
"""

from __future__ import annotations

import torch


def laplace_cdf(s: torch.Tensor, beta: torch.Tensor | float) -> torch.Tensor:
    """CDF of a zero-mean Laplace distribution with scale ``beta`` (VolSDF's Ψ_β), stable for large |s|."""
    e = 0.5 * torch.exp(-s.abs() / beta)
    return torch.where(s <= 0, e, 1.0 - e)


def volsdf_density(sdf: torch.Tensor, beta: torch.Tensor | float) -> torch.Tensor:
    """VolSDF density σ = α Ψ_β(−f) with α = 1/β: ~1/β inside the object, decaying outside.

    Args:
        sdf: ``(...)`` signed distances (positive outside).
        beta: scalar or broadcastable; smaller is a sharper surface.
    """
    return laplace_cdf(-sdf, beta) / beta


def composite_weights(density: torch.Tensor, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Alpha-compositing weights of piecewise-constant density.

    Args:
        density: ``(..., S)`` densities per interval.
        t: ``(..., S + 1)`` interval edges, increasing.
    Returns:
        weights ``(..., S)`` and the transmittance left after the last interval ``(...)``.
    """
    tau = density * (t[..., 1:] - t[..., :-1])
    # transmittance before interval i = exp(-sum_{j<i} tau_j); exclusive cumsum keeps it exact at i = 0
    acc = torch.cumsum(tau, dim=-1)
    trans = torch.exp(-torch.cat([torch.zeros_like(acc[..., :1]), acc[..., :-1]], dim=-1))
    alpha = 1.0 - torch.exp(-tau)
    return trans * alpha, torch.exp(-acc[..., -1])


def quantile_depth(weights: torch.Tensor, t: torch.Tensor, quantile: float = 0.5) -> torch.Tensor:
    """Where a ray's accumulated weight reaches ``quantile`` of its total, interpolated inside that interval.

    The expected depth ``Σ w t`` is a poor depth map for a radiance field: a few per cent of weight left in
    the far, long intervals (a thin start, a wall not quite opaque) moves it by several times the true
    depth. The median (``quantile=0.5``) is the surface the ray mostly sees; a lower quantile is the first
    surface that takes a good part of the weight, which a field that left an opaque surface semi-transparent
    (seen from few directions, in few pixels) puts at the surface where the median passes through it.

    Args:
        weights: ``(..., S)``; t: ``(..., S + 1)`` increasing edges; quantile in (0, 1).
    Returns:
        ``(...)`` depths; the last edge where the weights are all zero.
    """
    cum = torch.cumsum(weights, dim=-1)
    level = quantile * cum[..., -1:]
    i = torch.searchsorted(cum.contiguous(), level.contiguous()).clamp(max=weights.shape[-1] - 1)
    w_i = weights.gather(-1, i)
    before = cum.gather(-1, i) - w_i
    frac = ((level - before) / w_i.clamp_min(1e-12)).clamp(0, 1)
    t0, t1 = t.gather(-1, i), t.gather(-1, i + 1)
    depth = (t0 + frac * (t1 - t0)).squeeze(-1)
    return torch.where(cum[..., -1] > 0, depth, t[..., -1])


def distortion_loss(weights: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """mip-NeRF 360's distortion loss of a step histogram, in O(S) with prefix sums (differentiable).

    ``Σ_ij w_i w_j |m_i − m_j| + ⅓ Σ_i w_i² (s_{i+1} − s_i)`` with interval midpoints m, computed in
    normalized ray distance ``s`` so near and far intervals count alike.

    Args:
        weights: ``(..., S)``.
        s: ``(..., S + 1)`` normalized interval edges.
    Returns:
        ``(...)`` per-ray loss.
    """
    mid = 0.5 * (s[..., 1:] + s[..., :-1])
    width = s[..., 1:] - s[..., :-1]
    wm = weights * mid
    w_cum = torch.cumsum(weights, dim=-1)
    wm_cum = torch.cumsum(wm, dim=-1)
    # Σ_{i,j} w_i w_j |m_i - m_j| = 2 Σ_i w_i (m_i W_{<i} - WM_{<i}) for sorted midpoints
    w_before = w_cum - weights
    wm_before = wm_cum - wm
    inter = 2.0 * (weights * (mid * w_before - wm_before)).sum(-1)
    intra = (weights.square() * width).sum(-1) / 3.0
    return inter + intra
