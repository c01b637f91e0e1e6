"""The SDF's start from the visual hull: a torus's masks carve its hole, and the fitted field has it."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import orbit_cameras

from orca.encoding import HashGridSpec
from orca.fields import SDFField, SDFFieldSpec
from orca.initialization import fit_sdf, sample_grid, signed_distance, visual_hull
from orca.rays import camera_rays

MAJOR, MINOR = 0.5, 0.18  # a torus lying flat (axis z): its hole is 0.32 across from its centre to the tube


def torus_sdf(x: torch.Tensor) -> torch.Tensor:
    ring = torch.stack([x[:, :2].norm(dim=-1) - MAJOR, x[:, 2]], dim=-1)
    return ring.norm(dim=-1) - MINOR


def sphere_traced_masks(K: torch.Tensor, c2w: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """``(N, H, W)`` bool: the pixels whose centre ray meets the torus (64 steps of sphere tracing)."""
    cols, rows = torch.meshgrid(torch.arange(width) + 0.5, torch.arange(height) + 0.5, indexing="xy")
    uv = torch.stack([cols, rows], -1).reshape(-1, 2)
    masks = []
    for k, pose in zip(K, c2w):
        origins, dirs, _ = camera_rays(uv, k.expand(len(uv), 3, 3), pose.expand(len(uv), 4, 4))
        t = torch.zeros(len(uv))
        for _ in range(64):
            t = t + torus_sdf(origins + t[:, None] * dirs).clamp_min(0)
        masks.append((torus_sdf(origins + t[:, None] * dirs) < 1e-3).reshape(height, width))
    return torch.stack(masks)


@pytest.fixture(scope="module")
def torus_views():
    """24 views of the torus from two rings (35 and 65 degrees up), 64x48, with their exact masks."""
    cams = [c for e in (35.0, 65.0) for c in orbit_cameras(12, 64, 48, 3.0, e, 45.0, prefix=f"e{e:.0f}_").cameras]
    K = torch.tensor(np.stack([c.K for c in cams]), dtype=torch.float32)
    c2w = torch.tensor(np.stack([c.c2w for c in cams]), dtype=torch.float32)
    return sphere_traced_masks(K, c2w, 64, 48), K, c2w


def test_visual_hull_keeps_the_torus_and_carves_its_hole(torus_views):
    masks, K, c2w = torus_views
    assert masks.any(dim=(1, 2)).all()
    res, bound = 48, 1.0
    hull = visual_hull(masks, K, c2w, res, bound, carve_share=1e-3, carve_min=1)  # the exact intersection
    ax = (torch.arange(res) + 0.5) / res * 2 - 1
    x = torch.stack(torch.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    inside = torus_sdf(x) < -0.07  # deeper than a pixel's footprint (0.064 at the far side of the torus)
    assert hull.reshape(-1)[inside].all(), "exact masks cut no voxel of the object"
    hole = (x[:, :2].norm(dim=-1) < 0.15) & (x[:, 2].abs() < 0.1)
    assert not hull.reshape(-1)[hole].any(), "the views from above see through the hole"
    far = torus_sdf(x) > 0.3
    assert hull.reshape(-1)[far].float().mean() < 0.02
    # three wrong masks of 24 (the object missing) cut the exact intersection, not a hull that needs a share of
    # a fifth of the views to cut, which still has the hole
    wrong = masks.clone()
    wrong[:3] = False
    assert not visual_hull(wrong, K, c2w, res, bound, carve_share=1e-3, carve_min=1).reshape(-1)[inside].all()
    robust = visual_hull(wrong, K, c2w, res, bound, carve_share=0.2).reshape(-1)
    assert robust[inside].all() and not robust[hole].any()


def test_floor_cuts_the_space_no_photo_sees_under_the_object(torus_views):
    """Seen only from 65 degrees up, every ray through the space under the tube meets the tube first: the masks
    keep that space. Standing on a floor at the tube's bottom, the floor cuts it and nothing of the torus."""
    masks, K, c2w = (t[12:] for t in torus_views)
    res, bound = 48, 1.0
    ax = (torch.arange(res) + 0.5) / res * 2 - 1
    x = torch.stack(torch.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    under = ((x[:, :2].norm(dim=-1) - MAJOR).abs() < 0.05) & (x[:, 2] < -MINOR - 0.08) & (x[:, 2] > -MINOR - 0.2)
    inside = torus_sdf(x) < -0.07
    free = visual_hull(masks, K, c2w, res, bound, carve_share=0.2).reshape(-1)
    assert free[under].float().mean() > 0.9 and free[inside].all()
    floor = (torch.tensor([0.0, 0.0, 1.0]), -MINOR)
    cut = visual_hull(masks, K, c2w, res, bound, carve_share=0.2, floor=floor).reshape(-1)
    assert not cut[x[:, 2] < -MINOR].any() and cut[inside].all()


def test_signed_distance_of_a_voxelized_ball():
    res, bound, radius = 40, 1.0, 0.5
    ax = (torch.arange(res) + 0.5) / res * 2 - 1
    x = torch.stack(torch.meshgrid(ax, ax, ax, indexing="ij"), -1)
    sdf = signed_distance(x.norm(dim=-1) < radius, bound, smoothing=0.0)
    probe = torch.tensor([[0.0, 0.0, 0.0], [0.75, 0.0, 0.0], [0.0, -0.3, 0.2], [0.3, 0.3, 0.3]])
    exact = probe.norm(dim=-1) - radius
    assert (sample_grid(sdf, probe, bound) - exact).abs().max() < 2 * (2 * bound / res)
    with pytest.raises(ValueError, match="no surface"):
        signed_distance(torch.zeros(8, 8, 8, dtype=torch.bool), bound, 1.0)


def test_fitted_sdf_has_the_hole_a_sphere_start_lacks(torus_views):
    masks, K, c2w = torus_views
    torch.manual_seed(0)
    field = SDFField(SDFFieldSpec(hash_grid=HashGridSpec(levels=6, log2_table_size=14, base_resolution=8,
                                                         max_resolution=64), init_radius=0.5, bound=1.2))
    centre, tube = torch.tensor([[0.0, 0.0, 0.0]]), torch.tensor([[MAJOR, 0.0, 0.0], [0.0, -MAJOR, 0.0]])
    assert field.sdf(centre).item() < 0, "the sphere start fills the hole"
    target = signed_distance(visual_hull(masks, K, c2w, 48, 1.2, carve_share=0.1), 1.2, smoothing=1.0)
    loss = fit_sdf(field, target, 1.2, steps=200, batch=4096, lr=5e-3, generator=torch.Generator().manual_seed(0))
    assert loss < 0.02
    assert field.sdf(centre).item() > 0.1, "the hole is open"
    assert (field.sdf(tube) < 0).all(), "the tube is solid"
    # on the torus's surface the fitted field is near zero (within a voxel and a half of the 48^3 hull's)
    angles = torch.linspace(0, 2 * np.pi, 50)
    top = torch.stack([MAJOR * angles.cos(), MAJOR * angles.sin(), torch.full_like(angles, MINOR)], -1)
    assert field.sdf(top).abs().max() < 1.5 * 2 * 1.2 / 48
