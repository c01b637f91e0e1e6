"""Find the object in a set of cameras and build the normalized frame of the design: the object's bounding
sphere becomes the unit sphere at the origin, z up.

- **Centre**: where the cameras look. People aim at the object, so the least-squares point nearest to all
  optical axes (iteratively reweighted, so a few photos of the surroundings do not pull it) is the object's
  centre; its error is the photographer's aim error averaged over the photos. With object masks the centre
  of their visual hull is used instead (exact up to the voxel size). When the axes are nearly parallel (a
  forward-facing capture, not an orbit) the convergence is undetermined; then the median of the sparse points
  seen in the middle of most photos is used.
- **Radius**: with masks, the bounding sphere of their visual hull, cut at the support plane (cameras that
  all look down leave the hull an open cone under the object). On the synthetic sphere (20 views) the hull's
  sphere is 7 % wider than the object and its centre 0.7 % of the radius off. Without masks, the largest of
  1. the framing: the sphere at the centre that fills ``object_window`` of the shorter side of the median
     photo (the design's captures frame the object at a third of the photo or less, so 0.6 is generous);
  2. the support plane: the object stands on a table or floor, found by RANSAC among the sparse points in
     the middle of most photos (normal along the cameras' up, below the centre); the object touches it, so
     its bounding sphere reaches at least that far (times ``radius_margin``).
  On the synthetic captures (the object spans ~0.38 of the shorter side) the framing wins and gives 1.55x
  the true radius: the object fills the inner 0.64 of the unit sphere.
  Why not the sparse points on the object: a glossy object has almost none. On the synthetic glossy sphere
  (16 views, 320x240) not one of ~1000 sparse points lies on its surface; the points that survive a
  "central in nearly every photo" test are the floor around it, props' edges and view-dependent reflection
  points inside the object, and their 95th percentile put the radius at 2.1 for a true 1.0.
  Failure modes: an object framed larger than ``object_window`` and not standing on a plane is cut (raise
  ``poses.object_window``, or give masks); an object framed small gets a loose sphere (the unit sphere is then
  mostly empty: training wastes resolution but loses nothing); photos not aimed at the object put the
  centre off. ``poses.png`` draws the sphere over the points and cameras to check at a glance.
- **Up**: the mean of the cameras' up vectors (-y in OpenCV), as people hold cameras upright.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .alignment import Similarity
from .cameras import Camera, CameraSet, Frame

if TYPE_CHECKING:
    import pycolmap  # noqa: TID251 - annotations only

MIN_OBJECT_POINTS = 20


@dataclass
class Posed:
    """Cameras in the source frame (COLMAP's, or a known-cameras file's) before normalization, one per
    registered photo (name order)."""

    names: list[str]
    c2w: np.ndarray  # (N, 4, 4) OpenCV camera-to-world
    lens: list[pycolmap.Camera]  # per photo: the full lens model (pinhole part and distortion), decoded size
    points: np.ndarray | None  # (M, 3) sparse points with tracks of 3+ photos, or None
    point_colors: np.ndarray | None  # (M, 3) uint8
    stats: dict[str, Any]


@dataclass(frozen=True)
class ObjectSphere:
    """The object's bounding sphere in the cameras' frame, and how it was found."""

    center: np.ndarray  # (3,)
    radius: float
    up: np.ndarray  # (3,) unit vector
    method: str  # what set the radius: "masks" | "framing" | "support plane"
    convergence: np.ndarray  # (3,) least-squares point of the optical axes
    axes_rms: float  # RMS distance of the optical axes from the convergence point
    points_used: int = 0  # sparse points on the support plane
    notes: list[str] = field(default_factory=list)


def axes_convergence(centers: np.ndarray, dirs: np.ndarray,
                     iterations: int = 10) -> tuple[np.ndarray, np.ndarray, float]:
    """Point nearest to all lines ``centers[i] + t dirs[i]`` (least squares, Cauchy-reweighted).

    Args:
        centers, dirs: ``(N, 3)``; ``dirs`` need not be unit.

    Returns:
        (point ``(3,)``, distance of each line from it ``(N,)``, conditioning: the smallest eigenvalue of the
        normal matrix over N, in [0, 2/3]; near 0 when the lines are nearly parallel).
    """
    d = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]  # (N, 3, 3) projectors orthogonal to each line
    w = np.ones(len(d))
    point = np.zeros(3)
    for _ in range(iterations):
        a = (w[:, None, None] * proj).sum(0)
        b = (w[:, None, None] * proj @ centers[:, :, None]).sum(0)[:, 0]
        point = np.linalg.lstsq(a, b, rcond=None)[0]
        resid = np.linalg.norm((proj @ (point - centers)[:, :, None])[:, :, 0], axis=1)
        scale = max(2.0 * float(np.median(resid)), 1e-12)
        w = 1.0 / (1.0 + (resid / scale) ** 2)
    resid = np.linalg.norm((proj @ (point - centers)[:, :, None])[:, :, 0], axis=1)
    conditioning = float(np.linalg.eigvalsh(proj.sum(0))[0] / len(d))
    return point, resid, conditioning


def camera_up(c2w: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` OpenCV cameras -> ``(3,)`` the mean of their up vectors (-y), unit length."""
    up = -c2w[:, :3, 1].sum(0)
    return up / np.linalg.norm(up)


def project(points: np.ndarray, c2w: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(M, 3)`` world points into ``N`` pinhole cameras -> pixels ``(N, M, 2)`` and depths ``(N, M)``."""
    w2c = np.linalg.inv(c2w)
    # matmul, not einsum: BLAS, several times faster on the hull's million voxels
    cam = np.matmul(points, np.swapaxes(w2c[:, :3, :3], 1, 2)) + w2c[:, None, :3, 3]
    z = cam[..., 2]
    uv = np.matmul(cam, np.swapaxes(K, 1, 2))[..., :2] / np.where(np.abs(z) < 1e-12, 1e-12, z)[..., None]
    return uv, z


def window_fraction(points: np.ndarray, c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray, window: float) -> np.ndarray:
    """``(M,)`` share of the cameras in whose central ``window`` (fraction of width and height) each point lies.

    Args:
        points ``(M, 3)``; c2w ``(N, 4, 4)``; K ``(N, 3, 3)``; sizes ``(N, 2)`` (width, height).
    """
    uv, z = project(points, c2w, K)
    lo = sizes[:, None, :] * (1 - window) / 2
    hi = sizes[:, None, :] * (1 + window) / 2
    inside = (z > 0) & np.all((uv >= lo) & (uv <= hi), axis=-1)
    return inside.mean(0)


def support_plane(points: np.ndarray, up: np.ndarray, tolerance: float, rng: np.random.Generator,
                  trials: int = 300, min_share: float = 0.2, max_tilt_deg: float = 30.0) -> np.ndarray:
    """``(M,)`` bool: points on the dominant plane roughly perpendicular to ``up`` (a table or floor), or none.

    The plane must hold ``min_share`` of the points and lie in their lower half (the object stands on it).
    """
    m = len(points)
    best = np.zeros(m, bool)
    if m < 10:
        return best
    cos_max = np.cos(np.deg2rad(max_tilt_deg))
    for _ in range(trials):
        a, b, c = points[rng.choice(m, 3, replace=False)]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) < 1e-12:
            continue
        n /= np.linalg.norm(n)
        if abs(n @ up) < cos_max:
            continue
        inliers = np.abs((points - a) @ n) < tolerance
        if inliers.sum() > best.sum():
            best = inliers
    heights = points @ up
    if best.sum() < min_share * m or np.median(heights[best]) > np.median(heights):
        return np.zeros(m, bool)
    return best


def plane_normal(points: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``(3,)`` unit normal of the least-squares plane through ``points`` ``(M, 3)``, on ``up``'s side. The thin
    SVD: the full one makes an ``(M, M)`` matrix (2 GB for the blowtorch's 12000 floor points)."""
    n = np.linalg.svd(points - points.mean(0), full_matrices=False)[2][2]
    return n if n @ up > 0 else -n


def footprint_radius(center: np.ndarray, c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray, window: float) -> float:
    """Radius of the sphere at ``center`` that fills ``window`` of the shorter image side, median over cameras."""
    dist = np.linalg.norm(c2w[:, :3, 3] - center, axis=1)
    half = window * np.minimum(sizes[:, 0] / K[:, 0, 0], sizes[:, 1] / K[:, 1, 1]) / 2  # tan of the half-angle
    return float(np.median(dist * np.sin(np.arctan(half))))


def pixels_of(points: np.ndarray, c2w: np.ndarray, K: np.ndarray,
              shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which of ``points`` ``(M, 3)`` one camera (c2w ``(4, 4)``, K ``(3, 3)``) sees inside its ``(H, W)`` image:
    their indices ``(V,)`` and integer pixels ``x``, ``y`` ``(V,)``."""
    uv, z = project(points, c2w[None], K[None])
    h, w = shape
    x = np.floor(uv[0, :, 0]).astype(np.int64)
    y = np.floor(uv[0, :, 1]).astype(np.int64)
    inside = np.nonzero((z[0] > 0) & (x >= 0) & (x < w) & (y >= 0) & (y < h))[0]
    return inside, x[inside], y[inside]


def mask_votes(masks: Sequence[np.ndarray], c2w: np.ndarray, K: np.ndarray,
               points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point, in how many photos it projects inside the image (``seen``) and onto the object (``hits``).

    Args:
        masks: ``N`` ``(H, W)`` bool (or 0/1), True on the object, in the cameras' pixel grid.
        c2w ``(N, 4, 4)``; K ``(N, 3, 3)``; points ``(V, 3)``.

    Returns:
        ``(V,)`` int32 ``seen`` and ``hits``. One camera at a time: memory stays O(points).
    """
    seen = np.zeros(len(points), np.int32)
    hits = np.zeros(len(points), np.int32)
    for m, c, k in zip(masks, c2w, K):
        inside, x, y = pixels_of(points, c, k, m.shape)
        seen[inside] += 1
        hits[inside] += m[y, x]
    return seen, hits


def _carve(masks: Sequence[np.ndarray], c2w: np.ndarray, K: np.ndarray, lo: np.ndarray, hi: np.ndarray,
           resolution: int, keep_fraction: float,
           floor: tuple[np.ndarray, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """Voxel centres ``(V, 3)`` of the box ``[lo, hi]`` kept by the masks, and the voxel size ``(3,)``."""
    size = (hi - lo) / resolution
    axes = [lo[k] + (np.arange(resolution) + 0.5) * size[k] for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    seen, hits = mask_votes(masks, c2w, K, grid)
    keep = (seen >= 0.5 * len(masks)) & (hits >= keep_fraction * seen)
    if floor is not None:
        keep &= grid @ floor[0] >= floor[1]
    return grid[keep], size


def sphere_from_masks(masks: Sequence[np.ndarray], c2w: np.ndarray, K: np.ndarray, center: np.ndarray,
                      extent: float, resolution: int = 64, keep_fraction: float = 0.95,
                      floor: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, float] | None:
    """Bounding sphere of the visual hull of object masks (a voxel carving), or None if it is empty.

    Two passes: the cube ``center +- extent``, then the box around what survived (so the voxels are small
    where the object is: the sphere's centre and radius are good to a fraction of a percent).

    Args:
        masks: ``N`` ``(H, W)`` bool, True on the object, in the cameras' pixel grid.
        keep_fraction: a voxel stays if it projects onto the object in this share of the photos that see it
            (a mask that misses a sliver then does not cut the object); it must be seen by half the photos
            (a voxel outside most photos has no evidence for it either).
        floor: ``(n, d)``, the support plane ``n . x = d`` with ``n`` up: voxels below it are cut. Cameras
            that all look down leave the hull a cone under the object down to (and through) the floor; the
            plane cuts it off.
    """
    lo, hi = center - extent, center + extent
    for _ in range(2):
        kept, size = _carve(masks, c2w, K, lo, hi, resolution, keep_fraction, floor)
        if len(kept) == 0:
            return None
        lo, hi = kept.min(0) - size, kept.max(0) + size  # one voxel of slack around the first pass's hull
    lo, hi = kept.min(0) - size / 2, kept.max(0) + size / 2
    c = (lo + hi) / 2
    return c, float(np.linalg.norm(kept - c, axis=1).max() + np.linalg.norm(size) / 2)


def find_object(
    c2w: np.ndarray,
    K: np.ndarray,
    sizes: np.ndarray,
    *,
    points: np.ndarray | None = None,
    masks: Sequence[np.ndarray] | None = None,
    mask_scale: float = 1.0,
    window: float = 0.6,
    margin: float = 1.1,
    seed: int = 0,
) -> ObjectSphere:
    """The object's bounding sphere from cameras (and sparse points or masks); see the module doc.

    Args:
        c2w ``(N, 4, 4)`` OpenCV camera-to-world; K ``(N, 3, 3)`` pinhole; sizes ``(N, 2)`` (width, height);
        points ``(M, 3)`` sparse points (reliable ones: tracks of 3+ photos); masks: ``N`` ``(H, W)`` bool,
        at ``mask_scale`` times the photos' size (reduced masks carve as well and take less memory).
    """
    centers, dirs = c2w[:, :3, 3], c2w[:, :3, 2]
    up = camera_up(c2w)
    conv, resid, conditioning = axes_convergence(centers, dirs)
    axes_rms = float(np.sqrt(np.mean(resid**2)))
    notes: list[str] = []
    have_points = points is not None and len(points) >= MIN_OBJECT_POINTS
    frac = window_fraction(points, c2w, K, sizes, window) if have_points else None
    center = conv
    if conditioning < 0.01:  # axes within ~6 degrees of each other: no orbit around anything
        notes.append("the optical axes are nearly parallel (not an orbit): centre from the sparse points")
        if have_points:
            center = np.median(points[frac >= np.quantile(frac, 0.75)], axis=0)
        else:
            center = centers.mean(0) + dirs.mean(0) * np.median(np.linalg.norm(centers - centers.mean(0), axis=1))

    # The support plane (table or floor): the object stands on it, nothing of it lies below.
    plane: tuple[np.ndarray, float] | None = None  # (unit normal pointing up, offset): n . x = offset on it
    used = 0
    if have_points:
        near = points[frac >= 0.5]
        dist = np.linalg.norm(near - center, axis=1)
        on_plane = support_plane(near, up, tolerance=0.02 * float(np.median(dist)) if len(near) else 0.0,
                                 rng=np.random.default_rng(seed))
        if on_plane.any():
            on = near[on_plane]
            n = plane_normal(on, up)
            plane = (n, float(n @ on.mean(0)))
            used = int(on_plane.sum())
            notes.append(f"support plane {float(n @ center) - plane[1]:.3g} below the centre ({used} points)")

    framing = footprint_radius(center, c2w, K, sizes, window)
    if masks is not None:
        k_masks = K.copy()
        k_masks[:, :2] *= mask_scale  # pixel (0, 0) is the image corner: every coordinate scales
        hull = sphere_from_masks(masks, c2w, k_masks, center, 2.0 * framing, floor=plane)
        if hull is not None:
            c, r = hull
            return ObjectSphere(c, r * margin, up, "masks", conv, axes_rms, used, notes)
        notes.append("the masks' visual hull is empty (masks and cameras disagree); masks not used")

    radius, method = framing, "framing"
    if plane is not None:
        h = float(plane[0] @ center) - plane[1]
        if h * margin > radius:
            radius, method = h * margin, "support plane"
    return ObjectSphere(center, radius, up, method, conv, axes_rms, used, notes)


def normalizing_similarity(sphere: ObjectSphere, c2w: np.ndarray) -> Similarity:
    """The similarity normalized frame -> cameras' frame: ``x = radius * R @ x_n + center``.

    R's columns are the normalized frame's axes in the cameras' frame: z = up, x towards the first camera's
    horizontal direction (so the frame is deterministic and the first photo looks along -x).
    """
    z = sphere.up
    toward = c2w[0, :3, 3] - sphere.center
    x = toward - (toward @ z) * z
    if np.linalg.norm(x) < 1e-9 * max(1.0, np.linalg.norm(toward)):
        x = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return Similarity(float(sphere.radius), np.stack([x, y, z], axis=1), np.asarray(sphere.center, float))


def normalized_cameras(posed: Posed, K: np.ndarray, to_source: Similarity, image_of: dict[str, str]) -> CameraSet:
    """The posed cameras in the normalized frame (``to_source``: normalized -> source frame, recorded as
    ``frame.to_colmap``), pinhole ``K`` ``(N, 3, 3)``, images at ``image_of[name]``."""
    c2w_n = to_source.inverse().apply_c2w(posed.c2w)
    cams = [
        Camera(name=n, image=image_of[n], width=int(c.width), height=int(c.height), fx=float(k[0, 0]),
               fy=float(k[1, 1]), cx=float(k[0, 2]), cy=float(k[1, 2]), camera_to_world=m.tolist())
        for n, c, k, m in zip(posed.names, posed.lens, K, c2w_n)
    ]
    return CameraSet(frame=Frame(to_colmap=to_source.matrix.tolist()), cameras=cams)


def renormalized(cameras: CameraSet, centre: np.ndarray, radius: float) -> CameraSet:
    """The cameras in the frame where the sphere ``(centre, radius)`` of theirs is the unit sphere:
    ``x_old = radius * x_new + centre``; ``frame.to_colmap`` composed with it."""
    to_old = Similarity(float(radius), np.eye(3), np.asarray(centre, float))
    c2w = to_old.inverse().apply_c2w(cameras.c2w())
    cams = [c.model_copy(update={"camera_to_world": m.tolist()}) for c, m in zip(cameras.cameras, c2w)]
    to_colmap = cameras.frame.to_colmap
    frame = Frame(to_colmap=(np.asarray(to_colmap) @ to_old.matrix).tolist() if to_colmap is not None else None)
    return cameras.model_copy(update={"cameras": cams, "frame": frame})
