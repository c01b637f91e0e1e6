"""Reducing full-size images to ``(H // k, W // k)`` over k x k blocks (the bottom/right remainder cropped), each
kind of image by the rule that keeps it meaningful: radiance by the mean, masks by the majority of the block
(regions that must hold throughout: by the whole block), depth and normals only where the whole block has them."""

from __future__ import annotations

import numpy as np


def _blocks(a: np.ndarray, k: int) -> np.ndarray:
    """``(H, W, ...)`` -> ``(H // k, k, W // k, k, ...)``, cropping the remainder."""
    h, w = a.shape[0] // k, a.shape[1] // k
    return a[: h * k, : w * k].reshape(h, k, w, k, *a.shape[2:])


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """k x k area average of ``(H, W[, C])``."""
    return a if k == 1 else _blocks(np.asarray(a, np.float32), k).mean((1, 3))


def block_all(a: np.ndarray, k: int) -> np.ndarray:
    """``(H, W)`` bool -> True where the whole k x k block is True."""
    return np.asarray(a, bool) if k == 1 else _blocks(np.asarray(a, bool), k).all((1, 3))


def downscale_mask(mask: np.ndarray, k: int) -> np.ndarray:
    """``(H, W)`` bool -> True where at least half of the k x k block is True."""
    return block_mean(mask.astype(np.float32), k) >= 0.5 if k > 1 else mask


def downscale_depth(depth: np.ndarray, k: int) -> np.ndarray:
    """Block mean of a z-depth map where the whole block is finite, else +inf."""
    if k == 1:
        return depth
    finite = block_all(np.isfinite(depth), k)
    mean = block_mean(np.where(np.isfinite(depth), depth, 0.0), k)
    return np.where(finite, mean, np.inf).astype(np.float32)


def downscale_normals(normals: np.ndarray, k: int) -> np.ndarray:
    """Normalized block mean of ``(H, W, 3)`` unit normals where the whole block has normals, else 0."""
    if k == 1:
        return normals
    valid = block_all(np.linalg.norm(normals, axis=-1) > 1e-6, k)
    mean = block_mean(normals, k)
    mean /= np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-12)
    return np.where(valid[..., None], mean, 0.0).astype(np.float32)
