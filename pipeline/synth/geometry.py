"""Object meshes for the synthetic scenes, in the ground-truth world frame (object centre at the origin).

Every mesh is a :class:`TriMesh`: float64 ``vertices (V, 3)``, int32 ``faces (F, 3)`` (counter-clockwise
seen from outside, so normals point out), unit ``normals (V, 3)`` and ``uv (V, 2)`` in [0, 1]. Parametric
surfaces are built on a (u, v) grid with the seam column duplicated, so the UV map has no wrap-around
triangles; normals are analytic (torus) or averaged over the seam duplicates (blob), so shading is smooth
across the seam.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..artifacts import atomic_path


@dataclass
class TriMesh:
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int32
    normals: np.ndarray  # (V, 3) float64, unit
    uv: np.ndarray  # (V, 2) float64 in [0, 1]

    def transformed(self, rotation: np.ndarray, scale: float = 1.0) -> TriMesh:
        """A copy rotated by ``rotation (3, 3)`` and uniformly scaled about the origin."""
        r = np.asarray(rotation, dtype=np.float64)
        return TriMesh(self.vertices @ r.T * scale, self.faces.copy(), self.normals @ r.T, self.uv.copy())

    @property
    def bounding_radius(self) -> float:
        """Radius of the smallest origin-centred sphere holding the mesh."""
        return float(np.linalg.norm(self.vertices, axis=1).max())


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two counter-clockwise triangles per cell of a ``(nv + 1) x (nu + 1)`` vertex grid (row-major)."""
    i, j = np.meshgrid(np.arange(nv), np.arange(nu), indexing="ij")
    a = i * (nu + 1) + j
    b = a + 1
    c = a + (nu + 1)
    d = c + 1
    tri = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return tri.astype(np.int32)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals; vertices at the same position (seams, poles) share one normal."""
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    key = np.round(vertices / 1e-9).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    acc = np.zeros((group.max() + 1, 3))
    for k in range(3):
        np.add.at(acc, group[faces[:, k]], fn)
    n = acc[group]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def _drop_degenerate(mesh: TriMesh) -> TriMesh:
    """Remove zero-area triangles (at the poles of a latitude-longitude grid)."""
    v, f = mesh.vertices, mesh.faces
    area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    return TriMesh(v, f[area2 > 1e-12 * max(1.0, float(area2.max()))], mesh.normals, mesh.uv)


def radial_surface(radius_fn, n_lon: int, n_lat: int) -> TriMesh:
    """A star-shaped closed surface ``r(d) d`` over unit directions ``d`` on a latitude-longitude grid.

    ``radius_fn`` maps ``(N, 3)`` unit directions to ``(N,)`` radii. UV: u = longitude / 2 pi,
    v = polar angle / pi (v = 0 at +z).
    """
    u = np.linspace(0.0, 1.0, n_lon + 1)
    v = np.linspace(0.0, 1.0, n_lat + 1)
    vv, uu = np.meshgrid(v, u, indexing="ij")
    theta, phi = vv * np.pi, uu * 2 * np.pi
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1).reshape(-1, 3)
    verts = d * np.asarray(radius_fn(d), dtype=np.float64)[:, None]
    # Grid rows run from +z (v = 0) down; with u increasing eastwards the triangles (a, c, b) face outward.
    faces = _grid_faces(n_lon, n_lat)
    uv = np.stack([uu.ravel(), vv.ravel()], -1)
    mesh = TriMesh(verts, faces, np.zeros_like(verts), uv)
    mesh = _drop_degenerate(mesh)
    mesh.normals = _vertex_normals(mesh.vertices, mesh.faces)
    return mesh


def uv_sphere(radius: float = 1.0, n_lon: int = 128, n_lat: int = 64) -> TriMesh:
    """A sphere mesh (ground-truth stand-in for Mitsuba's analytic sphere), normals exact."""
    mesh = radial_surface(lambda d: np.full(len(d), radius), n_lon, n_lat)
    mesh.normals = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    return mesh


def torus(major: float, minor: float, n_major: int = 128, n_minor: int = 48) -> TriMesh:
    """A torus around the z axis: ``major`` = distance of the tube's centre line from the axis, ``minor`` = the
    tube radius. UV: u along the ring, v around the tube. Normals analytic."""
    if not 0 < minor < major:
        raise ValueError(f"torus: need 0 < minor < major, got minor={minor}, major={major}")
    u = np.linspace(0.0, 1.0, n_major + 1)
    v = np.linspace(0.0, 1.0, n_minor + 1)
    vv, uu = np.meshgrid(v, u, indexing="ij")
    phi, psi = uu * 2 * np.pi, vv * 2 * np.pi
    normal = np.stack([np.cos(psi) * np.cos(phi), np.cos(psi) * np.sin(phi), np.sin(psi)], -1)
    centre = np.stack([major * np.cos(phi), major * np.sin(phi), np.zeros_like(phi)], -1)
    verts = (centre + minor * normal).reshape(-1, 3)
    faces = _grid_faces(n_major, n_minor)
    # Orientation: with psi increasing "upward" around the tube and phi eastwards, (a, c, b) points inward;
    # flip to outward.
    faces = faces[:, [0, 2, 1]]
    return TriMesh(verts, faces, normal.reshape(-1, 3), np.stack([uu.ravel(), vv.ravel()], -1))


def bump_radius(directions: np.ndarray, centres: np.ndarray, amplitudes: np.ndarray, sharpness: np.ndarray):
    """``1 + sum_k a_k exp(kappa_k (d . mu_k - 1))``: smooth von Mises bumps (a > 0) and dents (a < 0) on the
    unit sphere. Low ``kappa`` = wide, low-frequency features."""
    mu = np.asarray(centres, dtype=np.float64)
    mu = mu / np.linalg.norm(mu, axis=1, keepdims=True)
    cos = directions @ mu.T  # (N, K)
    return 1.0 + (np.asarray(amplitudes)[None] * np.exp(np.asarray(sharpness)[None] * (cos - 1.0))).sum(axis=1)


def blob(centres, amplitudes, sharpness, n_lon: int = 160, n_lat: int = 80) -> TriMesh:
    """A sphere displaced by bumps and dents (see :func:`bump_radius`), scaled to bounding radius 1.

    Dents deep enough give concave regions next to the convex ones.
    """
    mesh = radial_surface(lambda d: bump_radius(d, centres, amplitudes, sharpness), n_lon, n_lat)
    r = mesh.bounding_radius
    return TriMesh(mesh.vertices / r, mesh.faces, mesh.normals, mesh.uv)


def convexity(mesh: TriMesh) -> float:
    """Mesh volume over its convex hull's volume: 1 for convex shapes, < 1 when there are concave regions."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    return float(abs(tm.volume) / tm.convex_hull.volume)


def write_ply(path: str | Path, mesh: TriMesh) -> Path:
    """Binary little-endian PLY with x y z nx ny nz u v per vertex (Mitsuba's ``ply`` reads all of them)."""
    path = Path(path)
    v = np.concatenate([mesh.vertices, mesh.normals, mesh.uv], axis=1).astype("<f4")
    f = np.empty(len(mesh.faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    f["n"] = 3
    f["idx"] = mesh.faces
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment ORCa synthetic object, ground-truth world frame\n"
        f"element vertex {len(v)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float u\nproperty float v\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            fh.write(v.tobytes())
            fh.write(f.tobytes())
    return path
