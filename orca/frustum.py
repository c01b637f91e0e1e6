"""Conical frustums as Gaussians (mip-NeRF) and the scene contraction of mip-NeRF 360.

A cone has an apex ``o``, a unit axis ``d`` and a radius growth ``r`` (radius ``r t`` at distance ``t``
along the axis). The frustum between ``t0`` and ``t1`` is approximated by a Gaussian whose mean and
diagonal covariance feed the integrated positional encoding. Distant surroundings (a room several metres
away) are brought into a ball of radius 2 by the contraction, with the Gaussian pushed through its Jacobian.
"""

from __future__ import annotations

import torch


def conical_frustum_gaussian(
    origins: torch.Tensor,
    dirs: torch.Tensor,
    radius_growth: torch.Tensor,
    t0: torch.Tensor,
    t1: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and diagonal covariance of conical frustums (mip-NeRF eq. 7-8, numerically stable form).

    Args:
        origins: ``(N, 3)`` cone apexes.
        dirs: ``(N, 3)`` unit axes.
        radius_growth: ``(N,)`` cone radius per unit distance.
        t0, t1: ``(N, S)`` frustum bounds along the axis, ``t0 < t1``. Signed values are valid: a virtual
            cone behind a concave mirror converges to a real focus (``t = 0``) and widens again, and a
            frustum straddling 0 is that double cone (the moments depend on ``t`` only through ``t²``).
    Returns:
        means ``(N, S, 3)`` and per-axis variances ``(N, S, 3)``.
    """
    mu = 0.5 * (t0 + t1)
    hw = 0.5 * (t1 - t0)
    # A zero-length frustum at the apex (t0 = t1 = 0: an inverse-CDF sample landing exactly on the first
    # edge) would divide 0 by 0; its moments are all 0.
    denom = (3 * mu.square() + hw.square()).clamp_min(torch.finfo(mu.dtype).eps)
    t_mean = mu + 2 * mu * hw.square() / denom
    t_var = hw.square() / 3 - (4 / 15) * hw.pow(4) * (12 * mu.square() - hw.square()) / denom.square()
    r_var = radius_growth[:, None].square() * (
        mu.square() / 4 + (5 / 12) * hw.square() - (4 / 15) * hw.pow(4) / denom
    )
    means = origins[:, None, :] + t_mean[..., None] * dirs[:, None, :]
    d2 = dirs.square()[:, None, :]  # diag(d dᵀ) for a unit axis
    variances = t_var[..., None] * d2 + r_var[..., None] * (1 - d2)
    return means, variances


def contract(x: torch.Tensor) -> torch.Tensor:
    """mip-NeRF 360 contraction: identity in the unit ball, ``(2 − 1/|x|) x/|x|`` outside (into radius 2).

    Args:
        x: ``(..., 3)``.
    """
    r = x.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return torch.where(r <= 1, x, (2 - 1 / r) * x / r)


def contract_gaussian(mean: torch.Tensor, var: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Push a Gaussian with diagonal covariance through :func:`contract` (linearized, Kalman style).

    Outside the unit ball the Jacobian is ``a (I − x̂x̂ᵀ) + b x̂x̂ᵀ`` with ``a = (2 − 1/r)/r`` (tangential)
    and ``b = 1/r²`` (radial); the diagonal of ``J Σ Jᵀ`` is kept.

    Args:
        mean: ``(..., 3)``; var: ``(..., 3)``.
    Returns:
        contracted mean ``(..., 3)`` and variances ``(..., 3)``.
    """
    r = mean.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    u = mean / r
    outside = r > 1
    a = torch.where(outside, (2 - 1 / r) / r, torch.ones_like(r))
    b = torch.where(outside, 1 / r.square(), torch.ones_like(r))
    # J = a I + (b - a) u uᵀ;  diag(J diag(v) Jᵀ)_i = Σ_k J_ik² v_k
    eye = torch.eye(3, dtype=mean.dtype, device=mean.device)
    jac = a[..., None] * eye + (b - a)[..., None] * u[..., :, None] * u[..., None, :]
    new_var = (jac.square() * var[..., None, :]).sum(-1)
    return contract(mean), new_var
