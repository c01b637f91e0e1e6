"""The zero level set of an SDF as a triangle mesh (open3d marching cubes), and the mesh's cleaning, properties
and picture.

How: the SDF is sampled on a regular grid of ``resolution`` voxels per side over the cube
``[-extent, extent]^3`` and open3d's marching cubes turns the samples into triangles. open3d 0.18-0.20 has no
marching cubes over a dense array; its marching cubes lives in
``open3d.t.geometry.VoxelBlockGrid.extract_triangle_mesh``, a sparse grid of small dense blocks meant for TSDF
fusion. We write the SDF into its ``tsdf`` attribute ourselves (with weight 1 everywhere), at the very voxel
coordinates the grid reports, so no index layout is assumed. Because the grid is sparse, only blocks near the
surface need samples: a coarse pass evaluates the SDF once per block (at its centre) and keeps the blocks whose
value is within twice the block's half diagonal of zero (a learned SDF is only roughly metric; the factor 2
tolerates gradient norms down to 0.5), plus their 26 neighbours (the cells on a block's far faces read the
next block). ``sparse=False`` samples every block.

Outside ``[-extent, extent]^3`` the SDF is not evaluated (the network is not defined there): the sampled
field is ``max(sdf, cube)``, the shape clipped by the cube, so a surface that reaches the cube's faces is closed
by them rather than left open.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .imageio import write_png
from .log import progress

log = logging.getLogger("orca.mesh")

SPARSE_MARGIN = 2.0  # a block is kept if |sdf(centre)| <= SPARSE_MARGIN x its half diagonal

SdfFunction = Callable[[np.ndarray], np.ndarray]  # (N, 3) float32 points -> (N,) signed distances


@dataclass(frozen=True)
class Grid:
    """The sampling grid: voxel ``i`` along an axis sits at ``i * voxel_size`` (open3d's convention: block
    ``k`` holds voxels ``k * block_resolution ... (k + 1) * block_resolution - 1``)."""

    extent: float
    resolution: int
    block_resolution: int

    @property
    def voxel_size(self) -> float:
        return 2 * self.extent / self.resolution

    @property
    def block_size(self) -> float:
        return self.voxel_size * self.block_resolution

    def block_range(self) -> tuple[int, int]:
        """First and last block index along an axis: the cube plus one block past its far face (its cells'
        far corners)."""
        lo = math.floor(-self.extent / self.block_size - 1e-9)
        hi = math.ceil(self.extent / self.block_size + 1e-9)
        return lo, hi

    def all_blocks(self) -> np.ndarray:
        """``(B, 3)`` int32 block keys covering the cube."""
        lo, hi = self.block_range()
        r = np.arange(lo, hi + 1)
        return np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3).astype(np.int32)


def _evaluate(sdf: SdfFunction, points: np.ndarray, extent: float, chunk: int, bar=None, task=None) -> np.ndarray:
    """``max(sdf, box)`` at ``(N, 3)`` points in chunks, ``box = max_i |x_i| - extent`` the cube's own SDF: the
    shape clipped to the cube. ``sdf`` is evaluated only inside the cube (outside, ``box`` > 0 decides)."""
    out = np.empty(len(points), np.float32)
    for i in range(0, len(points), chunk):
        p = points[i : i + chunk]
        box = (np.abs(p).max(axis=1) - extent).astype(np.float32)
        inside = box <= 0
        values = box.copy()
        if inside.any():
            f = np.asarray(sdf(np.ascontiguousarray(p[inside], np.float32)), np.float32).reshape(-1)
            values[inside] = np.maximum(f, box[inside])
        out[i : i + chunk] = values
        if bar is not None:
            bar.advance(task, len(p))
    return out


def _near_surface_blocks(sdf: SdfFunction, grid: Grid, chunk: int) -> np.ndarray:
    """``(B', 3)`` block keys near the surface (coarse pass at block centres) and their 26 neighbours."""
    keys = grid.all_blocks()
    centres = ((keys + 0.5) * grid.block_size).astype(np.float32)
    # a centre outside the cube still has cells inside it: clamp the sample into the cube
    values = _evaluate(sdf, np.clip(centres, -grid.extent, grid.extent), grid.extent, chunk)
    near = np.abs(values) <= SPARSE_MARGIN * math.sqrt(3) / 2 * grid.block_size
    lo, hi = grid.block_range()
    n = hi - lo + 1
    occupied = near.reshape(n, n, n)
    dilated = occupied.copy()
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                shifted = np.zeros_like(occupied)
                src = tuple(slice(max(0, -d), n - max(0, d)) for d in (dx, dy, dz))
                dst = tuple(slice(max(0, d), n - max(0, -d)) for d in (dx, dy, dz))
                shifted[dst] = occupied[src]
                dilated |= shifted
    return keys[dilated.reshape(-1)]


def marching_cubes(
    sdf: SdfFunction, extent: float, resolution: int, *, block_resolution: int = 8, sparse: bool = True,
    chunk: int = 65536, device: str = "CPU:0",
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The zero level set of ``sdf`` over ``[-extent, extent]^3`` by open3d's marching cubes.

    Args:
        sdf: ``(N, 3)`` float32 points -> ``(N,)`` signed distances, negative inside.
        resolution: voxels per side of the cube (voxel size ``2 extent / resolution``).
        sparse: sample only blocks near the surface (see the module doc).
    Returns:
        vertices ``(V, 3)`` float64, triangles ``(F, 3)`` int64 (outward-facing: counter-clockwise seen from
        outside), and statistics (blocks, samples, seconds).
    """
    import open3d as o3d
    import open3d.core as o3c

    grid = Grid(float(extent), int(resolution), int(block_resolution))
    t0 = time.time()
    keys = _near_surface_blocks(sdf, grid, chunk) if sparse else grid.all_blocks()
    total_blocks = len(grid.all_blocks())
    stats: dict[str, Any] = {"voxel_size": grid.voxel_size, "blocks": len(keys), "blocks_dense": total_blocks}
    if len(keys) == 0:
        log.warning("no block near the surface: the SDF has no zero crossing in the cube (empty mesh)")
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), {**stats, "samples": 0, "seconds": time.time() - t0}
    dev = o3c.Device(device)
    vbg = o3d.t.geometry.VoxelBlockGrid(
        ["tsdf", "weight"], [o3c.float32, o3c.float32], [[1], [1]], voxel_size=grid.voxel_size,
        block_resolution=grid.block_resolution, block_count=len(keys) + 1, device=dev,
    )
    vbg.hashmap().activate(o3c.Tensor(keys, device=dev))
    coords, index = vbg.voxel_coordinates_and_flattened_indices()
    points = coords.cpu().numpy()
    flat = index.reshape((-1,))
    with progress() as bar:
        task = bar.add_task("SDF on the grid", total=len(points))
        values = _evaluate(sdf, points, grid.extent, chunk, bar, task)
    t_sdf = time.time() - t0
    # views into the grid's storage: writing through them fills the blocks
    vbg.attribute("tsdf").reshape((-1, 1))[flat] = o3c.Tensor(values[:, None], device=dev)
    vbg.attribute("weight").reshape((-1, 1))[flat] = o3c.Tensor(np.ones((len(values), 1), np.float32), device=dev)
    mesh = vbg.extract_triangle_mesh(weight_threshold=0.5)
    vertices = (mesh.vertex.positions.cpu().numpy().astype(np.float64) if "positions" in mesh.vertex
                else np.zeros((0, 3)))
    triangles = mesh.triangle.indices.cpu().numpy().astype(np.int64) if "indices" in mesh.triangle else np.zeros(
        (0, 3), np.int64)
    triangles = _outward(vertices, triangles, sdf, grid.voxel_size)
    stats.update(samples=len(points), seconds_sdf=round(t_sdf, 3), seconds=round(time.time() - t0, 3))
    return vertices, triangles, stats


def _outward(vertices: np.ndarray, triangles: np.ndarray, sdf: SdfFunction, h: float) -> np.ndarray:
    """Triangles wound so that their normals point to increasing SDF (outward). open3d's TSDF convention
    agrees with ours (positive in front of the surface), but its winding is not documented: check it on a
    sample of triangles and flip all if they face inward."""
    if len(triangles) == 0:
        return triangles
    sample = triangles[np.linspace(0, len(triangles) - 1, min(len(triangles), 256)).astype(int)]
    a, b, c = (vertices[sample[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    centre = (a + b + c) / 3
    step = np.asarray(sdf((centre + h * normal).astype(np.float32)), np.float64) - np.asarray(
        sdf((centre - h * normal).astype(np.float32)), np.float64)
    return triangles[:, ::-1].copy() if np.median(step) < 0 else triangles


# ----------------------------------------------------------------------------------------- the trained SDF


def model_sdf(model, chunk: int = 65536) -> SdfFunction:
    """The trained SDF ``model.sdf_field.sdf`` as an :data:`SdfFunction` (no gradients, in chunks)."""
    import torch

    device = next(model.parameters()).device

    def f(points: np.ndarray) -> np.ndarray:
        out = []
        with torch.no_grad():
            for i in range(0, len(points), chunk):
                x = torch.from_numpy(np.ascontiguousarray(points[i : i + chunk], np.float32)).to(device)
                out.append(model.sdf_field.sdf(x).float().cpu().numpy())
        return np.concatenate(out) if out else np.zeros(0, np.float32)

    return f


def diffuse_colors(model, points: np.ndarray, chunk: int = 65536) -> np.ndarray:
    """Linear diffuse radiance ``(N, 3)`` of the diffuse head at ``(N, 3)`` surface points."""
    import torch

    device = next(model.parameters()).device
    out = []
    with torch.no_grad():
        for i in range(0, len(points), chunk):
            x = torch.from_numpy(np.ascontiguousarray(points[i : i + chunk], np.float32)).to(device)
            _, features = model.sdf_field(x)
            out.append(model.sdf_field.diffuse(x, features).float().cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, 3), np.float32)


# ----------------------------------------------------------------------------------------------- cleaning


def to_open3d(vertices: np.ndarray, triangles: np.ndarray, colors: np.ndarray | None = None):
    """A legacy ``open3d.geometry.TriangleMesh`` with vertex normals (and colours in [0, 1])."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices, np.float64)),
                                     o3d.utility.Vector3iVector(np.asarray(triangles, np.int32)))
    if colors is not None:
        mesh.vertex_colors = o3d.utility.Vector3dVector(np.clip(np.asarray(colors, np.float64), 0, 1))
    mesh.compute_vertex_normals()
    return mesh


def drop_small_components(mesh, min_fraction: float) -> dict[str, int]:
    """Remove connected pieces with fewer triangles than ``min_fraction`` of the largest, in place."""
    if len(mesh.triangles) == 0:
        return {"components": 0, "components_kept": 0, "triangles_removed": 0}
    clusters, counts, _ = mesh.cluster_connected_triangles()
    clusters, counts = np.asarray(clusters), np.asarray(counts)
    small = counts < min_fraction * counts.max()
    remove = small[clusters]
    if remove.any():
        mesh.remove_triangles_by_mask(remove)
        mesh.remove_unreferenced_vertices()
    return {"components": len(counts), "components_kept": int((~small).sum()),
            "triangles_removed": int(remove.sum())}


def mesh_properties(mesh) -> dict[str, Any]:
    """Counts, topology and size of a legacy open3d mesh. Watertight as trimesh defines it (every edge shared
    by exactly two triangles, consistently wound); open3d's ``is_watertight`` also tests self-intersection,
    pairwise over triangles: 56 s for 75k triangles on a CPU, too slow for a report."""
    import trimesh

    v, f = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    props: dict[str, Any] = {"vertices": len(v), "triangles": len(f)}
    if len(f) == 0:
        return {**props, "watertight": False}
    tm = trimesh.Trimesh(v, f, process=False)
    props.update(
        watertight=bool(tm.is_watertight), winding_consistent=bool(tm.is_winding_consistent),
        vertex_manifold=bool(mesh.is_vertex_manifold()), euler_number=int(tm.euler_number),
        bbox_min=v.min(0).tolist(), bbox_max=v.max(0).tolist(),
        max_radius=float(np.linalg.norm(v, axis=1).max()), area=float(tm.area),
    )
    if props["watertight"] and props["winding_consistent"]:
        props["volume"] = float(tm.volume)
    return props


# -------------------------------------------------------------------------------------------------- picture


def mesh_picture(mesh, path: Path, size: int = 256, extent: float | None = None) -> Path:
    """Three shaded views of a legacy mesh (ray cast with open3d, orthographic, z up), side by side."""
    import open3d as o3d

    v = np.asarray(mesh.vertices)
    tiles = []
    if len(v) == 0:
        write_png(path, np.full((size, 3 * size, 3), 40, np.uint8))
        return path
    half = extent if extent is not None else float(np.abs(v).max()) * 1.05
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    colors = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else np.full((len(v), 3), 0.8)
    tri = np.asarray(mesh.triangles)
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    for azimuth in (-60.0, 60.0, 180.0):
        a, e = np.deg2rad(azimuth), np.deg2rad(25.0)
        back = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])  # towards the viewer
        right = np.cross([0.0, 0.0, 1.0], back)
        right /= np.linalg.norm(right)
        up = np.cross(back, right)
        s = (np.arange(size) + 0.5) / size * 2 - 1
        xs, ys = np.meshgrid(s * half, -s * half)
        origins = 3 * half * back + xs[..., None] * right + ys[..., None] * up
        rays = np.concatenate([origins, np.broadcast_to(-back, origins.shape)], -1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6)))
        t = hit["t_hit"].numpy()
        prim = hit["primitive_ids"].numpy().astype(np.int64)
        uv = hit["primitive_uvs"].numpy()
        normal = hit["primitive_normals"].numpy()
        ok = np.isfinite(t)
        image = np.full((size * size, 3), 0.15)
        corners = colors[tri[prim[ok]]]  # (M, 3 corners, 3)
        bary = np.stack([1 - uv[ok, 0] - uv[ok, 1], uv[ok, 0], uv[ok, 1]], -1)
        albedo = (bary[..., None] * corners).sum(1)
        shade = 0.35 + 0.65 * np.abs(normal[ok] @ light)
        image[ok] = albedo * shade[:, None]
        tiles.append(image.reshape(size, size, 3))
    write_png(path, np.round(np.clip(np.concatenate(tiles, 1), 0, 1) * 255).astype(np.uint8))
    return path
