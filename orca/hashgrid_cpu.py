"""The hash grid's lookup as fused CPU loops (numba): corner rows, trilinear weights and the weighted sum of
table rows in one pass per point, and its first-order backward, in place of the dozen full-size tensor
operations of :meth:`orca.encoding.HashGrid.forward` (which remains the reference, and the path for GPUs and for
grids whose gradients are differentiated again, such as the SDF's under the eikonal term).

Each point's rows are those of :func:`orca.encoding.corner_indices`; its features are the same to float32
rounding. The table's gradient is accumulated level by level in parallel (each level owns a disjoint range of
rows, so no two threads add to one row); the points' gradient point by point. The three kernels spell out the
same corner loop: factored into a helper that returns the corners as small arrays, the allocations made the
forward 2x slower.
"""

from __future__ import annotations

import math
import os

import numpy as np
import torch
from torch.autograd.function import once_differentiable

try:
    import numba
    from numba import njit, prange
except ImportError:  # the torch path serves instead
    njit = None
else:
    # numba's OpenMP layer would be a second OpenMP runtime beside PyTorch's: each one's threads spin while the
    # other's work, and a training step was slower with the fused lookup than without. Its own work queue
    # does not spin. NUMBA_THREADING_LAYER still chooses.
    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER = "workqueue"

# Instant-NGP's primes, as orca.encoding._PRIMES (which imports this module, so they cannot be imported here).
_P1, _P2 = 2654435761, 805459861

AVAILABLE = njit is not None


if AVAILABLE:

    @njit(inline="always")
    def _voxel(x, r):
        """A coordinate in [0, 1] (clamped) at resolution ``r``: lower corner and fraction, as the torch path
        computes them in float32."""
        p = np.float32(min(max(x, np.float32(0.0)), np.float32(1.0))) * np.float32(r)
        b = min(int(math.floor(p)), r - 1)
        return b, np.float32(p - np.float32(b))

    @njit(inline="always")
    def _row(level, b0, b1, b2, r, start, size, n_dense):
        if level < n_dense:
            side = r + 1
            return (b0 * side + b1) * side + b2 + start
        return ((b0 ^ (b1 * _P1) ^ (b2 * _P2)) & (size - 1)) + start

    @njit(parallel=True, cache=True)
    def _forward(x, res, starts, sizes, n_dense, table, out):
        n, levels, features = x.shape[0], res.shape[0], table.shape[1]
        for i in prange(n):
            for lv in range(levels):
                r = res[lv]
                b0, f0 = _voxel(x[i, 0], r)
                b1, f1 = _voxel(x[i, 1], r)
                b2, f2 = _voxel(x[i, 2], r)
                for c in range(8):
                    c0, c1, c2 = (c >> 2) & 1, (c >> 1) & 1, c & 1
                    w = ((f0 if c0 else np.float32(1.0) - f0) * (f1 if c1 else np.float32(1.0) - f1)
                         * (f2 if c2 else np.float32(1.0) - f2))
                    row = _row(lv, b0 + c0, b1 + c1, b2 + c2, r, starts[lv], sizes[lv], n_dense)
                    for f in range(features):
                        out[i, lv, f] += w * table[row, f]

    @njit(parallel=True, cache=True)
    def _backward_table(x, res, starts, sizes, n_dense, grad, table_grad):
        n, levels, features = x.shape[0], res.shape[0], grad.shape[2]
        for lv in prange(levels):  # a level's rows are its own: no two threads add to one row
            r = res[lv]
            for i in range(n):
                b0, f0 = _voxel(x[i, 0], r)
                b1, f1 = _voxel(x[i, 1], r)
                b2, f2 = _voxel(x[i, 2], r)
                for c in range(8):
                    c0, c1, c2 = (c >> 2) & 1, (c >> 1) & 1, c & 1
                    w = ((f0 if c0 else np.float32(1.0) - f0) * (f1 if c1 else np.float32(1.0) - f1)
                         * (f2 if c2 else np.float32(1.0) - f2))
                    row = _row(lv, b0 + c0, b1 + c1, b2 + c2, r, starts[lv], sizes[lv], n_dense)
                    for f in range(features):
                        table_grad[row, f] += w * grad[i, lv, f]

    @njit(parallel=True, cache=True)
    def _backward_points(x, res, starts, sizes, n_dense, table, grad, x_grad):
        n, levels, features = x.shape[0], res.shape[0], table.shape[1]
        for i in prange(n):
            g0 = g1 = g2 = np.float32(0.0)
            for lv in range(levels):
                r = res[lv]
                b0, f0 = _voxel(x[i, 0], r)
                b1, f1 = _voxel(x[i, 1], r)
                b2, f2 = _voxel(x[i, 2], r)
                for c in range(8):
                    c0, c1, c2 = (c >> 2) & 1, (c >> 1) & 1, c & 1
                    a0 = f0 if c0 else np.float32(1.0) - f0
                    a1 = f1 if c1 else np.float32(1.0) - f1
                    a2 = f2 if c2 else np.float32(1.0) - f2
                    row = _row(lv, b0 + c0, b1 + c1, b2 + c2, r, starts[lv], sizes[lv], n_dense)
                    dot = np.float32(0.0)
                    for f in range(features):
                        dot += table[row, f] * grad[i, lv, f]
                    # d(weight)/d(fraction) per axis, times d(fraction)/dx = r
                    g0 += dot * (1 if c0 else -1) * a1 * a2 * r
                    g1 += dot * (1 if c1 else -1) * a0 * a2 * r
                    g2 += dot * (1 if c2 else -1) * a0 * a1 * r
            # the clamp to [0, 1] passes no gradient outside it
            x_grad[i, 0] = g0 if 0 <= x[i, 0] <= 1 else 0
            x_grad[i, 1] = g1 if 0 <= x[i, 1] <= 1 else 0
            x_grad[i, 2] = g2 if 0 <= x[i, 2] <= 1 else 0


class FusedLookup(torch.autograd.Function):
    """``(N, 3)`` points in ``[0, 1]^3`` -> ``(N, L, F)`` trilinearly interpolated table rows, on the CPU.

    Args (of ``apply``): table ``(R, F)``; x ``(N, 3)``; then the grid's ``(L,)`` int64 resolutions, first rows
    and sizes, and its count of dense levels. Its backward is not differentiated again.
    """

    @staticmethod
    def forward(ctx, table, x, res, starts, sizes, n_dense):
        numba.set_num_threads(min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))
        x_np = x.detach().contiguous().numpy()
        levels = res.shape[0]
        out = np.zeros((x_np.shape[0], levels, table.shape[1]), np.float32)
        _forward(x_np, res.numpy(), starts.numpy(), sizes.numpy(), n_dense, table.detach().numpy(), out)
        ctx.save_for_backward(table, x, res, starts, sizes)
        ctx.n_dense = n_dense
        return torch.from_numpy(out)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        table, x, res, starts, sizes = ctx.saved_tensors
        args = (x.detach().contiguous().numpy(), res.numpy(), starts.numpy(), sizes.numpy(), ctx.n_dense)
        grad_np = grad.contiguous().numpy()
        table_grad = x_grad = None
        if ctx.needs_input_grad[0]:
            table_grad = np.zeros(table.shape, np.float32)
            _backward_table(*args, grad_np, table_grad)
            table_grad = torch.from_numpy(table_grad)
        if ctx.needs_input_grad[1]:
            x_grad = np.zeros(x.shape, np.float32)
            _backward_points(*args, table.detach().numpy(), grad_np, x_grad)
            x_grad = torch.from_numpy(x_grad)
        return table_grad, x_grad, None, None, None, None


def usable(table: torch.Tensor, x: torch.Tensor) -> bool:
    """Whether :class:`FusedLookup` can serve: numba installed, float32 tensors on the CPU."""
    on_cpu = table.device.type == x.device.type == "cpu"
    return AVAILABLE and on_cpu and table.dtype == x.dtype == torch.float32
