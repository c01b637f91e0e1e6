"""Object meshes for the synthetic scenes, in the ground-truth world frame (object centre at the origin).

Every mesh is a :class:`TriMesh`: float64 ``vertices (V, 3)``, int32 ``faces (F, 3)`` (counter-clockwise
seen from outside, so normals point out), unit ``normals (V, 3)`` and ``uv (V, 2)`` in [0, 1]. Parametric
surfaces are built on a (u, v) grid with the seam column duplicated, so the UV map has no wrap-around
triangles; normals are analytic (torus) or averaged over the seam duplicates (blob, surfaces of revolution),
so shading is smooth across the seam. A mug is two meshes in one (:func:`merge`): they interpenetrate, which
a renderer does not mind, but it is not a watertight solid.
"""

from __future__ import annotations

from collections.abc import Callable
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


def smooth_profile(radii) -> Callable[[np.ndarray], np.ndarray]:
    """``r(s)`` for ``s`` in [0, 1] (bottom to top) through ``radii`` at evenly spaced ``s``: a monotone cubic
    (PCHIP), so it never overshoots below the smallest radius (a waist stays a waist, radii stay positive)."""
    from scipy.interpolate import PchipInterpolator

    radii = np.asarray(radii, dtype=np.float64)
    if len(radii) < 2 or np.any(radii <= 0):
        raise ValueError(f"smooth_profile: need >= 2 positive radii, got {radii.tolist()}")
    return PchipInterpolator(np.linspace(0.0, 1.0, len(radii)), radii)


def revolution(radius_fn: Callable[[np.ndarray], np.ndarray], height: float, squareness: float = 8.0,
               n_around: int = 160, n_profile: int = 120) -> TriMesh:
    """A closed surface of revolution about z, ``height`` tall and centred at the origin: the side wall has radius
    ``radius_fn(s)`` at ``s = (z + height / 2) / height``, closed at the bottom and top like a superellipse
    ``|x|^p + |y|^p = 1`` (``p = squareness``) stretched to the profile,

        (x, y) = (sin t, cos t) / (|sin t|^p + |cos t|^p)^(1 / p),   z = height / 2 * y,   r = radius_fn(s) x,

    ``t`` in [0, pi] from the top down: ``squareness`` 2 rounds the ends like an ellipsoid, 8 or more gives
    nearly flat caps with rounded rims (a vase, a mug). UV: u = angle about z / 2 pi, v = t / pi (0 at the top).
    """
    if height <= 0 or squareness < 2:
        raise ValueError(f"revolution: need height > 0 and squareness >= 2, got {height}, {squareness}")
    def profile(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sin, cos = np.sin(t), np.cos(t)
        sin[(t == 0) | (t == np.pi)] = 0.0  # exact poles
        norm = (np.abs(sin) ** squareness + np.abs(cos) ** squareness) ** (1 / squareness)
        z = height / 2 * cos / norm
        return np.asarray(radius_fn((z + height / 2) / height), dtype=np.float64) * sin / norm, z

    # Uniform t spaces the rows by angle, leaving a tall side wall few of them: place them evenly in arc length
    # plus turning angle instead (a waist and the rims both get rows).
    dense = np.linspace(0.0, np.pi, PROFILE_OVERSAMPLING * n_profile + 1)
    r, z = profile(dense)
    step = np.hypot(np.diff(r), np.diff(z))
    turn = np.abs(np.diff(np.unwrap(np.arctan2(np.diff(z), np.diff(r)))))
    measure = (np.concatenate([[0.0], np.cumsum(step)]) / step.sum()
               + np.concatenate([[0.0, 0.0], np.cumsum(turn)]) / max(turn.sum(), 1e-12))
    t = np.interp(np.linspace(0.0, measure[-1], n_profile + 1), measure, dense)
    t[[0, -1]] = 0.0, np.pi
    r, z = profile(t)
    u = np.linspace(0.0, 1.0, n_around + 1)
    rr, uu = np.meshgrid(r, u, indexing="ij")
    zz, _ = np.meshgrid(z, u, indexing="ij")
    vv, _ = np.meshgrid(t / np.pi, u, indexing="ij")
    phi = uu * 2 * np.pi
    verts = np.stack([rr * np.cos(phi), rr * np.sin(phi), zz], -1).reshape(-1, 3)
    # rows from the top down, u eastwards: the same orientation as radial_surface, (a, c, b) faces outward
    mesh = TriMesh(verts, _grid_faces(n_around, n_profile), np.zeros_like(verts),
                   np.stack([uu.ravel(), vv.ravel()], -1))
    mesh = _drop_degenerate(mesh)
    mesh.normals = _vertex_normals(mesh.vertices, mesh.faces)
    return mesh


def merge(parts: list[tuple[TriMesh, tuple[float, float]]]) -> TriMesh:
    """One mesh of several (they may interpenetrate: a renderer only sees the outermost surface). Each part's
    UV v range [0, 1] is squeezed into its ``(v0, v1)`` band, so one texture covers all of them."""
    vertices, faces, normals, uv = [], [], [], []
    offset = 0
    for mesh, (v0, v1) in parts:
        vertices.append(mesh.vertices)
        faces.append(mesh.faces + offset)
        normals.append(mesh.normals)
        uv.append(np.stack([mesh.uv[:, 0], v0 + (v1 - v0) * mesh.uv[:, 1]], -1))
        offset += len(mesh.vertices)
    return TriMesh(np.concatenate(vertices), np.concatenate(faces).astype(np.int32), np.concatenate(normals),
                   np.concatenate(uv))


# Dense samples per profile row, from which the rows are placed (see revolution).
PROFILE_OVERSAMPLING = 64


# The handle ring's centre lies this fraction of its centre-line radius outside the body's wall, so about
# three fifths of the ring stand out and both of its ends are buried in the body.
HANDLE_OUTSET = 0.3
# UV band of the mug's body; the handle takes the rest of v.
MUG_BODY_V = 0.8


def mug(body: TriMesh, handle_major: float, handle_minor: float, handle_z: float, n_major: int = 96,
        n_minor: int = 24) -> TriMesh:
    """A body of revolution about z with a torus handle on its +x side (the ring in the xz plane at height
    ``handle_z``), merged into one mesh and shifted so its bounding box is centred at the origin."""
    near = np.abs(body.vertices[:, 2] - handle_z) <= handle_minor
    if not near.any():
        raise ValueError(f"mug: the handle height {handle_z} is outside the body")
    wall = float(np.hypot(body.vertices[near, 0], body.vertices[near, 1]).max())
    quarter_turn_x = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    handle = torus(handle_major, handle_minor, n_major, n_minor).transformed(quarter_turn_x)
    handle.vertices = handle.vertices + [wall + HANDLE_OUTSET * handle_major, 0.0, handle_z]
    mesh = merge([(body, (0.0, MUG_BODY_V)), (handle, (MUG_BODY_V, 1.0))])
    mesh.vertices = mesh.vertices - (mesh.vertices.min(0) + mesh.vertices.max(0)) / 2
    return mesh


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
