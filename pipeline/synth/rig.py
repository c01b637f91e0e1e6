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


def planned_path(rig: RigSpec, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Nominal azimuth and elevation (degrees, ``(n,)`` each) of ``n`` photos along the rig's path, before the
    per-photo hand-held jitter.

    ``interleaved``: one pass around, photo ``i`` on ring ``i % rings``. ``sequential``: the photos split as
    evenly as possible between the rings, one full ring after the other, each from a random start. Along a
    pass the azimuth steps vary by ``spacing_jitter`` (relative), and ``dropped`` of the planned positions get
    no photo. With the defaults nothing is drawn from ``rng``: azimuth ``360 i / n``.
    """
    rings = np.asarray(rig.elevations_deg, dtype=np.float64)
    if rig.ring_order == "interleaved":
        passes = [(np.arange(n + rig.dropped) % len(rings), n)]
    elif rig.ring_order == "sequential":
        counts = np.full(len(rings), n // len(rings)) + (np.arange(len(rings)) < n % len(rings))
        passes = [(np.full(int(c), k), int(c)) for k, c in enumerate(counts) if c > 0]
    else:
        raise ValueError(f"unknown ring order {rig.ring_order!r}")
    # the dropped positions fall on the passes in proportion to their photos
    drops = (np.bincount(rng.choice(len(passes), rig.dropped, p=[c / n for _, c in passes]), minlength=len(passes))
             if rig.dropped and rig.ring_order == "sequential" else np.zeros(len(passes), int))
    azimuths, elevations = [], []
    for (ring, count), dropped in zip(passes, drops):
        planned = count + (rig.dropped if rig.ring_order == "interleaved" else int(dropped))
        ring = np.resize(ring, planned) if rig.ring_order == "sequential" else ring
        if rig.spacing_jitter > 0:
            steps = 1 + rig.spacing_jitter * rng.uniform(-1, 1, planned)
            az = 360.0 * np.concatenate([[0.0], np.cumsum(steps)[:-1]]) / steps.sum()
        else:
            az = 360.0 * np.arange(planned) / planned
        if rig.ring_order == "sequential":
            az = az + rng.uniform(0, 360)
        keep = np.ones(planned, bool)
        if planned > count:
            keep[rng.choice(planned, planned - count, replace=False)] = False
        azimuths.append(az[keep])
        elevations.append(rings[ring[keep]])
    return np.concatenate(azimuths), np.concatenate(elevations)


def capture_views(rig: RigSpec, n: int, width: int, height: int, rng: np.random.Generator,
                  names: list[str]) -> list[PinholeView]:
    """``n`` views along the rig's path (:func:`planned_path`), with per-photo jitter in azimuth, elevation,
    distance, aim, roll and (``position_jitter``) camera position.

    Neighbouring photos overlap heavily, like someone walking around the object; the jitter keeps it from being
    a perfect turntable.
    """
    fx, _, _, _ = intrinsics_from_fov(width, height, rig.fov_x_deg)
    if rig.ring_order == "interleaved" and rig.spacing_jitter == 0 and rig.dropped == 0:
        # the original path, drawn inside the loop below exactly as before (captures stay reproducible)
        planned_az = planned_el = None
    else:
        planned_az, planned_el = planned_path(rig, n, rng)
    views = []
    for i in range(n):
        az0 = 360.0 * i / n if planned_az is None else planned_az[i]
        el0 = rig.elevations_deg[i % len(rig.elevations_deg)] if planned_el is None else planned_el[i]
        az = np.deg2rad(az0 + rng.uniform(-1, 1) * rig.azimuth_jitter_deg)
        el = np.deg2rad(el0 + rng.uniform(-1, 1) * rig.elevation_jitter_deg)
        dist = rng.uniform(*rig.distance)
        eye = dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        target = rng.uniform(-1, 1, 3) * rig.target_jitter
        c2w = _roll(look_at(eye, target), rng.uniform(-1, 1) * rig.roll_jitter_deg)
        if rig.position_jitter > 0:
            c2w[:3, 3] += rng.uniform(-1, 1, 3) * rig.position_jitter
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
      rotation, so a pure translation reveals different parts of what lies behind it (no prop: along +x).
    """
    env = scene.spec.env
    origin = np.zeros(3)
    fx_cube, _, _, _ = intrinsics_from_fov(size, size, env.cube_fov_deg)
    views = [PinholeView(f"cube_{name}", look_at(origin, np.array(d, float), np.array(up, float)), size, size,
                         fx_cube) for name, d, up in _CUBE]
    if env.parallax_prop is None:
        direction = np.array([1.0, 0.0, 0.0])
    else:
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
