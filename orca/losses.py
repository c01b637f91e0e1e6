"""Training losses: the paper's five (photometric, mask, eikonal, normal orientation, distortion) and ours
(normal smoothness, sparse depth).

All take per-ray tensors of a batch of ``N`` rays and return scalars.
"""

from __future__ import annotations

import torch
from torch.nn import functional as F

from .volume import distortion_loss


def photometric_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    clipped: torch.Tensor | None = None,
    clipped_excess: float = 0.0,
) -> torch.Tensor:
    """Charbonnier-smoothed L1 on linear radiance over valid pixels, and a lower bound on clipped ones.

    Linear radiance spans orders of magnitude (highlights); L1 keeps the bright few from dominating. A
    clipped pixel's true radiance is at least what was recorded, so a prediction below it is a full error:
    without this, the brightest highlights (light sources in the reflection) are never learned at all.
    Above it, ``clipped_excess`` weighs a weak pull back toward the recorded value: the least radiance that
    explains the photo. Without it nothing bounds a light's brightness, and a light learned several times too
    bright blooms past its edges, into the pixels around it that the photos' clipped masks also flag
    (demosaicing spreads a saturated photosite) but that hold nearly their true values.

    Args:
        pred, target: ``(N, 3)``; valid: ``(N,)`` bool (fitted); clipped: ``(N,)`` bool (bounded below).
        clipped_excess: weight of a clipped pixel's error above its recorded value, in [0, 1].
    """
    diff = torch.where(valid[:, None], pred - target, torch.zeros_like(pred))
    if clipped is not None:
        d = pred - target
        diff = torch.where(clipped[:, None], torch.where(d < 0, d, clipped_excess * d), diff)
        valid = valid | clipped
    if not valid.any():
        return pred.sum() * 0.0
    return torch.sqrt(diff[valid].square() + 1e-6).mean()


def mask_loss(opacity: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy between accumulated opacity ``(N,)`` and the object mask ``(N,)`` in {0, 1}."""
    return F.binary_cross_entropy(opacity.clamp(1e-4, 1 - 1e-4), mask.to(opacity.dtype))


def eikonal_loss(sdf_grad: torch.Tensor) -> torch.Tensor:
    """``(|∇f| − 1)²`` averaged over samples ``(..., 3)``: keeps f a distance function."""
    return (sdf_grad.norm(dim=-1) - 1.0).square().mean()


def normal_orientation_loss(weights: torch.Tensor, normals: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Ref-NeRF's orientation loss: visible samples should not face away from the camera.

    Args:
        weights: ``(N, S)``; normals: ``(N, S, 3)`` unit; dirs: ``(N, 3)`` unit ray directions.
    """
    facing_away = (normals * dirs[:, None]).sum(-1).clamp_min(0)
    return (weights * facing_away.square()).sum(-1).mean()


def normal_smoothness_loss(normals: torch.Tensor, nearby: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Unit normals ``(N, 3)`` at surface points vs ``(N, 3)`` at points a small random step away, weighted
    by ``(N,)`` (the ray's opacity): penalizes bumps finer than the step, which a hash grid's fine levels
    otherwise fit to explain the reflections' detail."""
    return (weights * (normals - nearby).square().sum(-1)).sum() / weights.sum().clamp_min(1e-8)


def cone_distortion_loss(env_weights: torch.Tensor, env_s: torch.Tensor) -> torch.Tensor:
    """Distortion loss along virtual cones: weights ``(N, K, E)``, normalized edges ``(N, K, E + 1)``."""
    return distortion_loss(env_weights, env_s).mean()


def sparse_depth_loss(
    weights: torch.Tensor, edges: torch.Tensor, target: torch.Tensor, band: torch.Tensor
) -> torch.Tensor:
    """Rays through known points of the surroundings (structure from motion's sparse points) must end there:
    1 − the share of each ray's weight within ``band`` of its ``target`` distance, an interval's weight taken
    as spread evenly over it (so a band narrower than the intervals still has a gradient).

    Minimizing it empties the ray before the point and makes it opaque at the point: the line-of-sight prior
    of Urban Radiance Fields. Nothing is asked of the field behind the point.

    Args:
        weights: ``(N, E)`` volume-rendering weights; edges: ``(N, E + 1)`` their intervals' distances along the
            ray; target, band: ``(N,)`` distances.
    """
    lo, hi = edges[:, :-1], edges[:, 1:]
    start, end = (target - band)[:, None], (target + band)[:, None]
    overlap = (torch.minimum(hi, end) - torch.maximum(lo, start)).clamp_min(0)
    share = overlap / (hi - lo).clamp_min(1e-12)
    return (1.0 - (weights * share).sum(-1)).mean()
