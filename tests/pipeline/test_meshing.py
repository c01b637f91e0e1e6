"""Meshing (pipeline.meshing): open3d marching cubes of analytic SDFs lands within a voxel of the true surface
(sparse and dense sampling alike), a surface leaving the cube is closed by it, an empty field gives no mesh."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.meshing import marching_cubes, mesh_properties, to_open3d


def sphere(p: np.ndarray, r: float = 0.7, c=(0.0, 0.0, 0.0)) -> np.ndarray:
    return np.linalg.norm(p - np.asarray(c, np.float32), axis=1) - r


def torus(p: np.ndarray, big: float = 0.6, small: float = 0.25) -> np.ndarray:
    ring = np.stack([np.linalg.norm(p[:, :2], axis=1) - big, p[:, 2]], 1)
    return np.linalg.norm(ring, axis=1) - small


@pytest.mark.parametrize("shape, euler", [(sphere, 2), (torus, 0)])
@pytest.mark.parametrize("sparse", [True, False])
def test_marching_cubes_lands_within_a_voxel_of_an_analytic_surface(shape, euler, sparse):
    v, f, stats = marching_cubes(shape, 1.0, 48, block_resolution=8, sparse=sparse)
    h = stats["voxel_size"]
    assert h == pytest.approx(2 / 48)
    distance = np.abs(shape(v.astype(np.float32))) / h  # an exact SDF: |f| is the distance to the surface
    assert distance.max() < 1.0, distance.max()
    assert distance.max() < 0.1  # measured 0.011 (sphere) and 0.031 (torus) voxels at 32^3, halving with h
    props = mesh_properties(to_open3d(v, f))
    assert props["watertight"] and props["winding_consistent"] and props["euler_number"] == euler
    # triangles face outward: a step along the face normal increases the SDF
    a, b, c = (v[f[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    centre = (a + b + c) / 3
    assert (shape((centre + 1e-3 * n).astype(np.float32)) > shape(centre.astype(np.float32))).all()
    # the surface is sampled everywhere: every point of it is near a vertex
    if shape is sphere:
        dirs = np.random.default_rng(0).normal(size=(500, 3))
        on_surface = 0.7 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        nearest = np.min(np.linalg.norm(on_surface[:, None] - v[None], axis=-1), axis=1)
        assert nearest.max() < h


def test_sparse_sampling_gives_the_dense_mesh_with_fewer_samples():
    dense = marching_cubes(torus, 1.0, 64, sparse=False)
    sparse = marching_cubes(torus, 1.0, 64, sparse=True)
    assert sparse[2]["samples"] < 0.7 * dense[2]["samples"]
    np.testing.assert_array_equal(np.sort(sparse[0], axis=0), np.sort(dense[0], axis=0))
    assert len(sparse[1]) == len(dense[1])


def test_a_surface_leaving_the_cube_is_closed_by_it_and_an_empty_field_gives_no_mesh():
    v, f, _ = marching_cubes(lambda p: sphere(p, 0.6, (0.7, 0.0, 0.0)), 1.0, 32)
    assert v[:, 0].max() <= 1.0 + 1e-6
    assert mesh_properties(to_open3d(v, f))["watertight"]
    v, f, stats = marching_cubes(lambda p: np.ones(len(p), np.float32), 1.0, 32)
    assert len(v) == 0 and len(f) == 0 and stats["blocks"] == 0
