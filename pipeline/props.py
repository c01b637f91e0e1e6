"""A synthetic scene's props (``scene.json["props"]``: the close-by objects that make the environment field 5D)
as geometry: which 3-D points lie on them, and the 3-D points a depth map sees."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

PROP_MARGIN = 0.05  # world units: how far off a prop's surface a point still counts as on it


@dataclass(frozen=True)
class Prop:
    """A scene prop from ``scene.json``: ``box`` (``size`` = half extents before the yaw about z), ``sphere``
    (``size`` = radius x 3) or ``cylinder`` (``size`` = (radius, radius, height), axis along z through
    ``centre``)."""

    name: str
    kind: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw_deg: float = 0.0

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Prop:
        if d.get("kind") not in ("box", "sphere", "cylinder"):
            raise ValueError(f"prop {d.get('name')!r}: unknown kind {d.get('kind')!r}")
        return cls(str(d.get("name", "")), d["kind"], tuple(map(float, d["centre"])), tuple(map(float, d["size"])),
                   float(d.get("yaw_deg", 0.0)))

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """``(..., 3)`` world points -> ``(...)`` bool: inside the prop or within ``margin`` of it (for a box,
        within ``margin`` of each face plane: the box grown by ``margin``)."""
        p = np.asarray(points, np.float64) - np.asarray(self.centre)
        sx, sy, sz = self.size
        if self.kind == "sphere":
            return np.linalg.norm(p, axis=-1) <= sx + margin
        if self.kind == "cylinder":
            return (np.hypot(p[..., 0], p[..., 1]) <= sx + margin) & (np.abs(p[..., 2]) <= sz / 2 + margin)
        a = np.deg2rad(self.yaw_deg)  # local = R_z(yaw)^T (p - centre)
        lx = np.cos(a) * p[..., 0] + np.sin(a) * p[..., 1]
        ly = -np.sin(a) * p[..., 0] + np.cos(a) * p[..., 1]
        return (np.abs(lx) <= sx + margin) & (np.abs(ly) <= sy + margin) & (np.abs(p[..., 2]) <= sz + margin)


def points_in_props(points: np.ndarray, props: Sequence[Prop], margin: float = PROP_MARGIN) -> np.ndarray:
    """``(..., 3)`` points -> ``(...)`` bool: within ``margin`` of any prop (non-finite points: False)."""
    points = np.asarray(points, np.float64)
    inside = np.zeros(points.shape[:-1], bool)
    finite = np.isfinite(points).all(-1)
    safe = np.where(finite[..., None], points, 0.0)
    for prop in props:
        inside |= prop.contains(safe, margin)
    return inside & finite


def points_from_depth(depth: np.ndarray, K: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World points ``(H, W, 3)`` of a z-depth map ``(H, W)`` seen by a pinhole ``K`` ``(3, 3)`` with OpenCV
    camera-to-world ``c2w`` ``(4, 4)``; pixel centres at (i + 0.5). Non-finite depth gives non-finite points."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    z = depth.astype(np.float64)
    with np.errstate(invalid="ignore"):
        cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)
        return cam @ c2w[:3, :3].T + c2w[:3, 3]
