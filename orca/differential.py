"""Differential geometry of an implicit surface f(x) = 0: unit normals and mean curvature.

Convention: n = ∇f / |∇f| points outward (f > 0 outside); mean curvature H = ½ ∇·n, so a convex sphere of
radius R has H = +1/R at its surface, a plane has 0, and the inside of a concave bowl is negative.
Two ways, compared in the tests: autograd (exact, costs second derivatives) and central finite differences
(cheap, works with any network, biased by O(eps²) and blind to detail finer than eps).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from .geometry_utils import safe_normalize

SDF = Callable[[torch.Tensor], torch.Tensor]
"""An SDF: ``(N, 3)`` points -> ``(N,)`` signed distances."""

# Below this gradient norm the normal is undefined (medial axis, flat SDF); guard the division.
_GRAD_EPS = 1e-8


def gradient(sdf: SDF, x: torch.Tensor, create_graph: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """SDF values and gradients by autograd.

    Args:
        x: ``(N, 3)`` points.
    Returns:
        ``(N,)`` values, ``(N, 3)`` gradients (differentiable when ``create_graph``).
    """
    with torch.enable_grad():
        if not x.requires_grad:
            x = x.detach().requires_grad_(True)
        f = sdf(x)
        (g,) = torch.autograd.grad(f.sum(), x, create_graph=create_graph)
    return f, g


def normals_and_curvature_autograd(sdf: SDF, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals and mean curvature H = ½ div(∇f/|∇f|) by autograd (differentiable).

    Args:
        x: ``(N, 3)`` points.
    Returns:
        ``(N, 3)`` normals, ``(N,)`` mean curvature.
    """
    with torch.enable_grad():
        x = x if x.requires_grad else x.detach().requires_grad_(True)
        _, g = gradient(sdf, x, create_graph=True)
        n = safe_normalize(g, _GRAD_EPS)
        div = torch.zeros(x.shape[0], dtype=x.dtype, device=x.device)
        if n.requires_grad:  # an affine SDF (a plane) has a constant normal and no second derivatives
            for i in range(3):
                (dni,) = torch.autograd.grad(n[:, i].sum(), x, create_graph=True, materialize_grads=True)
                div = div + dni[:, i]
    return n, 0.5 * div


def normals_and_curvature_fd(sdf: SDF, x: torch.Tensor, eps: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals and mean curvature from central differences of f (no second-order autograd).

    Uses the implicit-surface formula ``div(∇f/|∇f|) = (|g|² tr(Hf) - gᵀ Hf g) / |g|³`` with the gradient
    g and Hessian Hf of f from a 19-point stencil (value, 6 axis and 12 edge samples).

    Args:
        x: ``(N, 3)`` points.
        eps: stencil step in world units (pick about a voxel of the finest feature you trust).
    Returns:
        ``(N, 3)`` normals, ``(N,)`` mean curvature; differentiable w.r.t. the SDF's parameters.
    """
    n_pts = x.shape[0]
    eye = torch.eye(3, dtype=x.dtype, device=x.device)
    axis = torch.cat([eye, -eye]) * eps  # (6, 3): +x +y +z -x -y -z
    pairs = [(0, 1), (0, 2), (1, 2)]
    edge = torch.stack(
        [s * eye[i] + t * eye[j] for i, j in pairs for s, t in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
    ) * eps  # (12, 3)
    offsets = torch.cat([torch.zeros(1, 3, dtype=x.dtype, device=x.device), axis, edge])  # (19, 3)
    f = sdf((x[:, None, :] + offsets).reshape(-1, 3)).reshape(n_pts, 19)
    f0, fp, fm, fe = f[:, 0], f[:, 1:4], f[:, 4:7], f[:, 7:].reshape(n_pts, 3, 4)
    g = (fp - fm) / (2 * eps)  # (N, 3)
    hess_diag = (fp - 2 * f0[:, None] + fm) / eps**2  # (N, 3)
    # mixed partials: (f(++) - f(+-) - f(-+) + f(--)) / (4 eps²)
    mixed = (fe[..., 0] - fe[..., 1] - fe[..., 2] + fe[..., 3]) / (4 * eps**2)  # (N, 3) for xy, xz, yz
    hess = torch.diag_embed(hess_diag)
    for k, (i, j) in enumerate(pairs):
        hess[:, i, j] = mixed[:, k]
        hess[:, j, i] = mixed[:, k]
    gn2 = (g * g).sum(-1).clamp_min(_GRAD_EPS**2)
    trace = hess_diag.sum(-1)
    ghg = torch.einsum("ni,nij,nj->n", g, hess, g)
    div = (gn2 * trace - ghg) / gn2.pow(1.5)
    return safe_normalize(g, _GRAD_EPS), 0.5 * div
