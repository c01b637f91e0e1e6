"""Input encodings: positional encoding (NeRF), integrated positional encoding (mip-NeRF), and a
multiresolution hash grid (Instant-NGP) written in plain PyTorch so it runs on CPU and CUDA alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn
from torch.autograd.function import once_differentiable

from . import hashgrid_cpu


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


def corner_indices(
    base: torch.Tensor, resolutions: torch.Tensor, sizes: torch.Tensor, starts: torch.Tensor, n_dense: int
) -> torch.Tensor:
    """Table rows of the 8 corners of each point's voxel at every level.

    The first ``n_dense`` levels are indexed densely (their ``(res + 1)^3`` corners fit their table), the others
    by Instant-NGP's spatial hash, whose table sizes are powers of two. Each axis' term is computed for the two
    corners along that axis (``(N, L, 2)``, in int64 where the hash's products need it) and only their sum or
    XOR is formed at full size, in int32: the full-size ``(N, L, 2, 2, 2)`` arithmetic is most of the encoding's
    time on the CPU. The hash's ``& (size - 1)`` distributes over XOR, so it too is applied per axis.

    Args:
        base: ``(N, L, 3)`` long, each level's lower voxel corner.
        resolutions, sizes, starts: ``(L,)`` long: voxels per axis, table rows and first row of each level.
    Returns:
        ``(N, L, 8)`` int32 rows, corner ``(i, j, k)`` (x, y, z offsets in {0, 1}) at position ``4i + 2j + k``.
    """
    n, levels, _ = base.shape
    corners = torch.stack([base, base + 1], dim=-1)  # (N, L, 3, 2)
    parts = []
    nd = n_dense
    if nd:
        side = (resolutions[:nd] + 1)[:, None]
        c = corners[:, :nd]
        tx = (c[:, :, 0] * side * side + starts[:nd, None]).int()
        ty = (c[:, :, 1] * side).int()
        tz = c[:, :, 2].int()
        parts.append(tx[..., :, None, None] + ty[..., None, :, None] + tz[..., None, None, :])
    if nd < levels:
        mask = (sizes[nd:] - 1)[:, None]
        _, p1, p2 = _PRIMES
        c = corners[:, nd:]
        hx = (c[:, :, 0] & mask).int()
        hy = ((c[:, :, 1] * p1) & mask).int()
        hz = ((c[:, :, 2] * p2) & mask).int()
        rows = hx[..., :, None, None] ^ hy[..., None, :, None] ^ hz[..., None, None, :]
        parts.append(rows + starts[nd:, None, None, None].int())
    return torch.cat([p.reshape(n, p.shape[1], 8) for p in parts], dim=1)


def _as_pairs(t: torch.Tensor) -> torch.Tensor:
    """``(..., 2)`` real -> ``(...)`` complex, the same memory: a row of two features moves as one 8-byte
    element, which makes the CPU's gather and scatter-add about 1.5-2x faster than on ``(rows, 2)``."""
    return torch.view_as_complex(t.contiguous())


class _TableLookup(torch.autograd.Function):
    """``table[idx]`` whose backward accumulates with ``index_add_``: 6x faster on the CPU than
    embedding's or indexing's backward (with int64 indices: int32 ones take a 10x slower path there). Tables
    of two features per row (the default) are gathered and scattered as complex numbers (:func:`_as_pairs`).
    Its backward is not differentiated again: the SDF's second derivatives reach the table through the
    interpolation weights, not through this lookup's backward."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(idx)
        ctx.rows = table.shape[0]
        rows = idx.reshape(-1)
        if table.shape[1] == 2:
            values = torch.view_as_real(_as_pairs(table).index_select(0, rows))
        else:
            values = table.index_select(0, rows)
        return values.reshape(*idx.shape, table.shape[1])

    @staticmethod
    @once_differentiable
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (idx,) = ctx.saved_tensors
        features = grad.shape[-1]
        rows = idx.reshape(-1).long()
        if features == 2:
            pairs = _as_pairs(grad.new_zeros(ctx.rows, 2)).index_add_(0, rows, _as_pairs(grad.reshape(-1, 2)))
            return torch.view_as_real(pairs), None
        return grad.new_zeros(ctx.rows, features).index_add_(0, rows, grad.reshape(-1, features)), None


class HashGrid(nn.Module):
    """Multiresolution hash encoding of points in ``[0, 1]^3`` (trilinear interpolation per level).

    Coarse levels whose dense grid fits in the table are indexed densely (no collisions); finer ones hash.
    """

    def __init__(self, spec: HashGridSpec = HashGridSpec(), first_order: bool = False):
        """``first_order``: the grid's gradients are never differentiated again (the environment field's; not
        the SDF's, whose gradient the eikonal term differentiates): on the CPU it may then use the fused
        lookup of :mod:`orca.hashgrid_cpu`."""
        super().__init__()
        self.spec = spec
        self.first_order = first_order
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
        # Per-level constants as tensors so that all levels are indexed in one vectorized pass.
        self.register_buffer("_res", torch.tensor(resolutions)[:, None], persistent=False)  # (L, 1)
        self.register_buffer("_start", torch.tensor(self.offsets[:-1]), persistent=False)  # (L,)
        self.register_buffer("_size", torch.tensor(sizes), persistent=False)  # (L,)
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
        if self.first_order and hashgrid_cpu.usable(self.table, x):
            feats = hashgrid_cpu.FusedLookup.apply(self.table, x, self._res[:, 0], self._start, self._size,
                                                   self.n_dense)
        else:
            feats = self._lookup(x, res)
        feats = feats * self.level_weights[:, None].to(x.dtype)  # (N, L, F)
        if scale is not None:
            feats = feats * torch.erf(1.0 / torch.sqrt(8 * (scale[:, None] * res[:, 0]).square() + 1e-12))[..., None]
        return feats.reshape(n, self.spec.out_dim)

    def _lookup(self, x: torch.Tensor, res: torch.Tensor) -> torch.Tensor:
        """``(N, 3)`` -> ``(N, L, F)`` trilinearly interpolated rows, in tensor operations (any device, any order
        of differentiation)."""
        n = x.shape[0]
        pos = x.clamp(0.0, 1.0)[:, None, :] * res  # (N, L, 3)
        base = pos.detach().floor().long().minimum(self._res - 1)  # res-1 keeps x == 1 inside the last voxel
        frac = pos - base
        idx = corner_indices(base, self._res[:, 0], self._size, self._start, self.n_dense)
        values = _TableLookup.apply(self.table, idx)  # (N, L, 8, F)
        # trilinear weights as the same outer product of per-axis (1 - frac, frac)
        a = torch.stack([1.0 - frac, frac], dim=-2)  # (N, L, 2, 3)
        w = (a[..., :, None, None, 0] * a[..., None, :, None, 1] * a[..., None, None, :, 2]).reshape(-1, 1, 8)
        levels, f = self.spec.levels, self.spec.features_per_level
        # one (1, 8) x (8, F) product per point and level: bmm is ~2x faster than multiply-and-sum on the CPU
        return torch.bmm(w, values.reshape(-1, 8, f)).reshape(n, levels, f)
