"""Input encodings: positional encoding (NeRF), integrated positional encoding (mip-NeRF), and a
multiresolution hash grid (Instant-NGP) written in plain PyTorch so it runs on CPU and CUDA alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn
from torch.autograd.function import once_differentiable


def positional_encoding(x: torch.Tensor, num_freqs: int, include_input: bool = True) -> torch.Tensor:
    """NeRF's frequency encoding.

    Args:
        x: ``(..., D)`` coordinates.
        num_freqs: frequencies ``2^0 .. 2^(num_freqs-1)``.
    Returns:
        ``(..., D * (2 * num_freqs + include_input))``.
    """
    freqs = 2.0 ** torch.arange(num_freqs, dtype=x.dtype, device=x.device)
    scaled = (x[..., None, :] * freqs[:, None]).flatten(-2)  # (..., F*D)
    parts = [torch.sin(scaled), torch.cos(scaled)]
    if include_input:
        parts.insert(0, x)
    return torch.cat(parts, dim=-1)


def integrated_positional_encoding(
    mean: torch.Tensor, var: torch.Tensor, min_deg: int, max_deg: int
) -> torch.Tensor:
    """mip-NeRF's IPE of Gaussians with diagonal covariance: E[sin], E[cos] of the frequency features.

    High frequencies of a wide Gaussian are attenuated by ``exp(-0.5 * 4^l * var)``, which is what makes a
    conical frustum far along a wide virtual cone blur instead of alias.

    Args:
        mean: ``(..., D)`` Gaussian means.
        var: ``(..., D)`` per-axis variances.
    Returns:
        ``(..., 2 * D * (max_deg - min_deg))``.
    """
    scales = 2.0 ** torch.arange(min_deg, max_deg, dtype=mean.dtype, device=mean.device)  # (L,)
    m = (mean[..., None, :] * scales[:, None]).flatten(-2)  # (..., L*D)
    v = (var[..., None, :] * scales[:, None] ** 2).flatten(-2)
    damp = torch.exp(-0.5 * v)
    return torch.cat([damp * torch.sin(m), damp * torch.cos(m)], dim=-1)


@dataclass(frozen=True)
class HashGridSpec:
    """Instant-NGP hash grid sizes. Defaults fit a CPU: ~0.5 M parameters."""

    levels: int = 12
    features_per_level: int = 2
    log2_table_size: int = 15
    base_resolution: int = 16
    max_resolution: int = 512

    @property
    def out_dim(self) -> int:
        return self.levels * self.features_per_level


# Instant-NGP's spatial hash primes; the first is 1 so that x-neighbours stay close in memory (and x needs
# no multiplication).
_PRIMES = (1, 2654435761, 805459861)


class _TableLookup(torch.autograd.Function):
    """``table[idx]`` whose backward accumulates with ``index_add_``: 6x faster on the CPU than
    embedding's or indexing's backward. Its backward is not differentiated again: the SDF's second
    derivatives reach the table through the interpolation weights, not through this lookup's backward."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(idx)
        ctx.rows = table.shape[0]
        return table.index_select(0, idx.reshape(-1)).reshape(*idx.shape, table.shape[1])

    @staticmethod
    @once_differentiable
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (idx,) = ctx.saved_tensors
        features = grad.shape[-1]
        table_grad = grad.new_zeros(ctx.rows, features).index_add_(0, idx.reshape(-1), grad.reshape(-1, features))
        return table_grad, None


class HashGrid(nn.Module):
    """Multiresolution hash encoding of points in ``[0, 1]^3`` (trilinear interpolation per level).

    Coarse levels whose dense grid fits in the table are indexed densely (no collisions); finer ones hash.
    """

    def __init__(self, spec: HashGridSpec = HashGridSpec()):
        super().__init__()
        self.spec = spec
        table = 2**spec.log2_table_size
        growth = math.exp((math.log(spec.max_resolution) - math.log(spec.base_resolution)) / max(spec.levels - 1, 1))
        resolutions, sizes, dense = [], [], []
        for level in range(spec.levels):
            res = int(math.floor(spec.base_resolution * growth**level))
            n_dense = (res + 1) ** 3
            resolutions.append(res)
            dense.append(n_dense <= table)
            sizes.append(min(n_dense, table))
        self.resolutions = resolutions
        self.dense = dense
        self.n_dense = sum(dense)  # resolutions grow with the level, so the dense levels are the first ones
        self.offsets = [0, *torch.tensor(sizes).cumsum(0).tolist()]
        # Small uniform init as in Instant-NGP: the grid starts near zero and the MLP's prior dominates.
        self.table = nn.Parameter(torch.empty(self.offsets[-1], spec.features_per_level).uniform_(-1e-4, 1e-4))
        # Per-level constants as (L, 1) tensors so that all levels are indexed in one vectorized pass.
        as_col = lambda v, dt=torch.long: torch.tensor(v, dtype=dt)[:, None]  # noqa: E731
        self.register_buffer("_res", as_col(resolutions), persistent=False)
        self.register_buffer("_start", as_col(self.offsets[:-1]), persistent=False)
        self.register_buffer("_size", as_col(sizes), persistent=False)
        # Coarse-to-fine training (Neuralangelo): a weight per level, 1 = active. Saved with the model so
        # a checkpoint renders as it trained.
        self.register_buffer("level_weights", torch.ones(spec.levels))

    @property
    def out_dim(self) -> int:
        return self.spec.out_dim

    def set_active_levels(self, levels: float) -> None:
        """Enable the first ``levels`` levels (a fractional level is blended in); finer ones output zero."""
        ramp = levels - torch.arange(self.spec.levels, dtype=self.level_weights.dtype, device=self.level_weights.device)
        self.level_weights.copy_(ramp.clamp(0.0, 1.0))

    def forward(self, x: torch.Tensor, scale: torch.Tensor | None = None) -> torch.Tensor:
        """Encode points, optionally blurred to a footprint (Zip-NeRF's feature downweighting).

        Args:
            x: ``(N, 3)`` in ``[0, 1]^3`` (values outside are clamped).
            scale: ``(N,)`` standard deviation of each point's footprint in the same units, or None. A level
                whose cells are much smaller than the footprint would alias; its features are scaled by
                ``erf(1 / sqrt(8 (scale * resolution)^2))``, which is ~1 for fine footprints and ~0 for wide.
        Returns:
            ``(N, levels * features_per_level)``.
        """
        n = x.shape[0]
        res = self._res.to(x.dtype)  # (L, 1)
        pos = x.clamp(0.0, 1.0)[:, None, :] * res  # (N, L, 3)
        base = pos.detach().floor().long().minimum(self._res - 1)  # res-1 keeps x == 1 inside the last voxel
        frac = pos - base
        # Corner indices built per axis and combined by broadcasting to (N, L, 2, 2, 2): an (N, L, 8, 3)
        # tensor of corner coordinates would cost 3x the memory traffic.
        near_far = torch.stack([base, base + 1], dim=-1)  # (N, L, 3, 2)
        cx = near_far[:, :, 0, :, None, None]
        cy = near_far[:, :, 1, None, :, None]
        cz = near_far[:, :, 2, None, None, :]
        per_level = lambda t: t.view(-1, 1, 1, 1)  # noqa: E731  (L, 1) -> (L, 1, 1, 1)
        # Dense levels come first (resolutions grow); each kind of index is computed for its own levels only.
        nd = self.n_dense
        side = per_level(self._res[:nd] + 1)
        dense_idx = (cx[:, :nd] * side + cy[:, :nd]) * side + cz[:, :nd]
        _, p1, p2 = _PRIMES
        # hashed tables are 2^k long: the modulo is a mask
        hash_idx = (cx[:, nd:] ^ (cy[:, nd:] * p1) ^ (cz[:, nd:] * p2)) & per_level(self._size[nd:] - 1)
        corners = (-1, -1, 2, 2, 2)
        idx = torch.cat([dense_idx.expand(*corners), hash_idx.expand(*corners)], dim=1) + per_level(self._start)
        values = _TableLookup.apply(self.table, idx.reshape(n, -1, 8))  # (N, L, 8, F)
        # trilinear weights as the same outer product of per-axis (1 - frac, frac)
        a = torch.stack([1.0 - frac, frac], dim=-2)  # (N, L, 2, 3)
        w = (a[..., :, None, None, 0] * a[..., None, :, None, 1] * a[..., None, None, :, 2]).reshape(-1, 1, 8)
        levels, f = self.spec.levels, self.spec.features_per_level
        # one (1, 8) x (8, F) product per point and level: bmm is ~2x faster than multiply-and-sum on the CPU
        feats = torch.bmm(w, values.reshape(-1, 8, f)).reshape(n, levels, f)
        feats = feats * self.level_weights[:, None].to(x.dtype)  # (N, L, F)
        if scale is not None:
            feats = feats * torch.erf(1.0 / torch.sqrt(8 * (scale[:, None] * res[:, 0]).square() + 1e-12))[..., None]
        return feats.reshape(n, -1)
