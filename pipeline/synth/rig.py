"""Camera placement: the hand-held capture ring around the object and the environment ground-truth cameras.

All poses are OpenCV camera-to-world 4x4 matrices (x right, y down, z forward) in the ground-truth world
frame (z up, object centre at the origin).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras import Camera, intrinsics_from_fov, look_at
from .scenes import ResolvedScene, RigSpec


@dataclass(frozen=True)
class PinholeView:
    """A named pinhole camera: pose, image size and focal length in pixels (principal point at the centre)."""

    name: str
    c2w: np.ndarray  # (4, 4) OpenCV camera-to-world
    width: int
    height: int
    fx: float

    def camera(self, image: str | None) -> Camera:
        return Camera(name=self.name, image=image, width=self.width, height=self.height, fx=self.fx,
                      fy=self.fx, cx=self.width / 2.0, cy=self.height / 2.0,
                      camera_to_world=self.c2w.tolist())


def _roll(c2w: np.ndarray, deg: float) -> np.ndarray:
    """Rotate a camera about its own optical axis."""
    a = np.deg2rad(deg)
    r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    out = c2w.copy()
    out[:3, :3] = c2w[:3, :3] @ r
    return out


def capture_views(rig: RigSpec, n: int, width: int, height: int, rng: np.random.Generator,
                  names: list[str]) -> list[PinholeView]:
    """``n`` views ordered around the object (azimuth increasing), elevation cycling through the rings.

    Neighbouring photos overlap heavily, like someone walking around the object; jitter in distance,
    elevation, aim and roll keeps it from being a perfect turntable.
    """
    fx, _, _, _ = intrinsics_from_fov(width, height, rig.fov_x_deg)
    views = []
    for i in range(n):
        az = np.deg2rad(360.0 * i / n + rng.uniform(-1, 1) * rig.azimuth_jitter_deg)
        el = np.deg2rad(rig.elevations_deg[i % len(rig.elevations_deg)] + rng.uniform(-1, 1)
                        * rig.elevation_jitter_deg)
        dist = rng.uniform(*rig.distance)
        eye = dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        target = rng.uniform(-1, 1, 3) * rig.target_jitter
        c2w = _roll(look_at(eye, target), rng.uniform(-1, 1) * rig.roll_jitter_deg)
        views.append(PinholeView(names[i], c2w, width, height, fx))
    return views


_CUBE = (
    ("px", (1, 0, 0), (0, 0, 1)),
    ("nx", (-1, 0, 0), (0, 0, 1)),
    ("py", (0, 1, 0), (0, 0, 1)),
    ("ny", (0, -1, 0), (0, 0, 1)),
    ("pz", (0, 0, 1), (0, 1, 0)),
    ("nz", (0, 0, -1), (0, 1, 0)),
)


def environment_views(scene: ResolvedScene, size: int) -> list[PinholeView]:
    """Cameras for the environment ground truth (the object removed from the scene):

    - ``cube_px`` ... ``cube_nz``: six square views from the object centre along +-x, +-y, +-z
      (``cube_fov_deg``, 90 degrees: together they see every direction);
    - ``parallax_<k>``: views from points inside the object's bounding sphere, shifted sideways
      (perpendicular to the direction of ``env.parallax_prop``) and all looking at that prop with the same
      rotation, so a pure translation reveals different parts of what lies behind it.
    """
    env = scene.spec.env
    origin = np.zeros(3)
    fx_cube, _, _, _ = intrinsics_from_fov(size, size, env.cube_fov_deg)
    views = [PinholeView(f"cube_{name}", look_at(origin, np.array(d, float), np.array(up, float)), size, size,
                         fx_cube) for name, d, up in _CUBE]
    prop = scene.prop(env.parallax_prop)
    direction = prop.centre / np.linalg.norm(prop.centre)
    side = np.cross(direction, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    rotation = look_at(origin, direction)
    fx_par, _, _, _ = intrinsics_from_fov(size, size, env.parallax_fov_deg)
    for k, offset in enumerate(env.parallax_offsets):
        c2w = rotation.copy()
        c2w[:3, 3] = offset * scene.object_radius * side
        views.append(PinholeView(f"parallax_{k}", c2w, size, size, fx_par))
    return views
