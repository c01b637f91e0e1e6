"""Small vector helpers over ``(..., 3)`` tensors: dot products, safe normalization, mirror reflection,
and an orthonormal basis around a direction. Pure functions, any leading batch shape, differentiable.
"""

from __future__ import annotations

import torch
from torch import Tensor


def dot(a: Tensor, b: Tensor, keepdim: bool = False) -> Tensor:
    """Dot product over the last axis: ``(..., 3), (..., 3) -> (...,)`` (or ``(..., 1)`` with keepdim)."""
    return (a * b).sum(-1, keepdim=keepdim)


def safe_norm(v: Tensor, eps: float | None = None, keepdim: bool = False) -> Tensor:
    """Euclidean norm over the last axis, at least ``eps``; its gradient stays finite at ``v = 0``.

    ``eps`` defaults to ``sqrt(tiny)`` of the dtype, so ``1/|v|`` and its gradient cannot overflow.
    """
    if eps is None:
        eps = torch.finfo(v.dtype).tiny ** 0.5
    # clamp the squared norm (not the norm): sqrt'(0) = inf would otherwise give 0 * inf = NaN.
    return v.square().sum(-1, keepdim=keepdim).clamp_min(eps * eps).sqrt()


def safe_normalize(v: Tensor, eps: float | None = None) -> Tensor:
    """``v / |v|`` over the last axis, ``(..., 3) -> (..., 3)``; zero vectors stay (finite) zero."""
    return v / safe_norm(v, eps, keepdim=True)


def reflect(d: Tensor, n: Tensor) -> Tensor:
    """Mirror reflection ``d − 2 (d·n) n`` of directions ``d`` about unit normals ``n``, ``(..., 3)``.

    Independent of the sign of ``n``; a unit ``d`` gives a unit result.
    """
    return d - 2 * dot(d, n, keepdim=True) * n


def orthonormal_basis(v: Tensor) -> tuple[Tensor, Tensor]:
    """Two unit vectors ``(e1, e2)`` with ``(e1, e2, v)`` a right-handed orthonormal frame, ``(..., 3)`` each.

    Branchless construction of Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 2017):
    smooth everywhere except across the plane ``v_z = 0`` where the sign flips (a measure-zero set).
    ``v`` must be unit.
    """
    x, y, z = v.unbind(-1)
    sign = torch.where(z >= 0, torch.ones_like(z), -torch.ones_like(z))
    a = -1.0 / (sign + z)
    b = x * y * a
    e1 = torch.stack([1 + sign * x * x * a, sign * b, -sign * x], dim=-1)
    e2 = torch.stack([b, sign + y * y * a, -y], dim=-1)
    return e1, e2
