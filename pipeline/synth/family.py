"""A randomized family of synthetic scenes: one seed, one scene (``orca synth random-<seed>``).

The presets (:data:`pipeline.synth.scenes.SCENES`) are one kind of capture: poster walls, a textured floor,
many props, the object on the floor a third of the frame wide. Poses and masks tuned on them alone fail
elsewhere, so :func:`random_scene` draws, from a ``numpy`` Generator seeded with the seed only:

- the object (:data:`SHAPES`): sphere, torus, blob, vase (a surface of revolution with a waist) or mug (a body
  of revolution with a torus handle); a glossy dielectric coat (Mitsuba plastic) of a dark or light colour,
  sometimes textured, IOR 1.4-1.9, sometimes slightly rough; tilted where it floats or where it may lie;
- its placement (:data:`PLACEMENTS`): standing on the floor, on a plain table (a box prop of one colour),
  or floating above the floor;
- the room (:data:`ROOMS`): poster walls as the presets, plain painted walls (plain or poster floor) with a
  few textured props, or (rarely) tiled walls and floor: a grid of identical tiles that fools SIFT;
- the object's size in the frame: its bounding sphere spans :attr:`FamilyRanges.size_fraction` of the
  height of a 4:3 frame, which sets the camera distance from the field of view (:func:`distance_for_fraction`);
- the camera path: one to three rings at different heights, walked one after the other or interleaved, with
  uneven azimuth steps, hand-held jitter of position, aim and roll, and a few photos missing;
- the lights: one to four area lights on the ceiling and walls, of varied size, colour temperature and power;
- 0 to several textured props around the object, not touching it, the table or each other, and clear of every
  camera and of every camera's line of sight to the object's centre (checked against the rig's whole range).

:func:`tiles_scene` is the same scene in a tiled room; :func:`traits` says what a scene is;
:data:`FRONT_END_SUITE` is a fixed list of seeds covering every kind, for benchmarking poses and masks.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from ..imageio import srgb_to_linear
from ..props import Prop
from .scenes import (
    OBJECT_PALETTE,
    AlbedoSpec,
    EnvViewSpec,
    LightSpec,
    ObjectKind,
    ObjectSpec,
    PropSpec,
    RigSpec,
    RoomSpec,
    SceneSpec,
    SurfaceFinish,
    Vec3,
    object_mesh,
)
from .textures import PosterStyle

SHAPES: tuple[ObjectKind, ...] = ("sphere", "torus", "blob", "vase", "mug")
PLACEMENTS = ("floor", "table", "floating")
ROOMS = ("poster", "plain", "tiles")
TABLE = "table"  # the name of the table prop

# The frame the size fraction refers to (the family's captures are rendered 4:3, e.g. 320x240).
FAMILY_ASPECT = 4.0 / 3.0

# Linear reflectances of painted walls (off-white, beige, greys, pale blue, sage), floors, tiles and grout.
WALL_PAINTS: tuple[Vec3, ...] = ((0.70, 0.68, 0.62), (0.55, 0.45, 0.33), (0.45, 0.45, 0.45), (0.40, 0.50, 0.60),
                                 (0.40, 0.50, 0.38), (0.25, 0.25, 0.27))
FLOOR_PAINTS: tuple[Vec3, ...] = ((0.30, 0.18, 0.10), (0.20, 0.20, 0.20), (0.50, 0.42, 0.30), (0.12, 0.10, 0.09))
CEILING_PAINT: Vec3 = (0.75, 0.75, 0.72)
TILE_COLOURS: tuple[Vec3, ...] = ((0.75, 0.75, 0.72), (0.68, 0.62, 0.48), (0.35, 0.50, 0.62), (0.30, 0.50, 0.35),
                                  (0.15, 0.15, 0.17))
GROUT_COLOURS: tuple[Vec3, ...] = ((0.45, 0.45, 0.43), (0.25, 0.25, 0.25), (0.70, 0.70, 0.68))
TABLE_COLOURS: tuple[Vec3, ...] = ((0.35, 0.22, 0.12), (0.70, 0.70, 0.68), (0.15, 0.15, 0.16), (0.45, 0.40, 0.33))

# A light object's textured albedo: brighter than AlbedoSpec's dark default, still no near-white.
LIGHT_ALBEDO_STYLE = PosterStyle(reflectance=(0.08, 0.5), shapes_per_megapixel=50.0, min_scale=0.06,
                                 max_scale=0.6, glyph_weight=0.0, palette=OBJECT_PALETTE)

# Rec. 709 luminance weights (linear RGB), to give lights of every colour temperature the same luminance.
LUMINANCE = (0.2126, 0.7152, 0.0722)


@dataclass(frozen=True)
class FamilyRanges:
    """What :func:`random_scene` draws from: weights of each kind (in the order of :data:`SHAPES`,
    :data:`PLACEMENTS`, :data:`ROOMS`) and ranges ``(lo, hi)``; lengths are in object radii."""

    shape_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0)
    placement_weights: tuple[float, ...] = (0.45, 0.3, 0.25)
    room_weights: tuple[float, ...] = (0.4, 0.45, 0.15)
    # object
    size_fraction: tuple[float, float] = (0.2, 2.0 / 3.0)  # bounding sphere / frame height (log-uniform)
    ior: tuple[float, float] = (1.4, 1.9)
    rough_probability: float = 0.3
    roughness: tuple[float, float] = (0.02, 0.12)  # GGX alpha: slightly rough
    textured_probability: float = 0.3
    dark_probability: float = 0.5
    dark_reflectance: tuple[float, float] = (0.02, 0.08)  # brightest channel of a dark colour
    light_reflectance: tuple[float, float] = (0.25, 0.6)
    # placement
    table_height: tuple[float, float] = (0.6, 2.0)
    table_margin: tuple[float, float] = (0.2, 1.0)  # table top beyond the object's bounding circle, each side
    float_gap: tuple[float, float] = (0.4, 1.5)
    # room
    room_half: tuple[float, float] = (6.0, 9.0)  # before growing it to hold the cameras
    room_height: tuple[float, float] = (5.5, 7.0)
    floor_plain_probability: float = 0.5  # in a plain room (else a poster floor)
    tile_size: tuple[float, float] = (0.2, 0.5)
    grout_width: tuple[float, float] = (0.01, 0.03)
    # props
    props: dict[str, tuple[int, int]] | None = None  # room kind -> (min, max) count; None: PROP_COUNTS
    prop_gap: tuple[float, float] = (0.25, 3.0)  # from the object's bounding sphere (or the table) to the prop
    # camera path
    fov_x_deg: tuple[float, float] = (55.0, 75.0)
    ring_weights: tuple[float, ...] = (0.25, 0.35, 0.4)  # one, two or three rings
    elevation_deg: tuple[float, float] = (8.0, 50.0)
    min_ring_separation_deg: float = 10.0
    sequential_probability: float = 0.7
    distance_spread: float = 0.05  # relative, either way
    azimuth_jitter_deg: tuple[float, float] = (1.5, 5.0)
    elevation_jitter_deg: tuple[float, float] = (1.0, 4.0)
    roll_jitter_deg: tuple[float, float] = (1.0, 5.0)
    position_jitter: tuple[float, float] = (0.02, 0.12)
    spacing_jitter: tuple[float, float] = (0.1, 0.6)
    dropped: tuple[int, int] = (0, 4)
    # lights
    ceiling_lights: tuple[int, int] = (0, 3)
    windows: tuple[int, int] = (0, 2)
    max_lights: int = 4
    ceiling_light_side: tuple[float, float] = (0.5, 3.0)
    window_size: tuple[tuple[float, float], tuple[float, float]] = ((1.0, 3.0), (0.8, 2.5))  # width, height
    ceiling_kelvin: tuple[float, float] = (2700.0, 6500.0)
    window_kelvin: tuple[float, float] = (5500.0, 9000.0)
    ceiling_power: tuple[float, float] = (20.0, 100.0)  # radiance x area
    window_power: tuple[float, float] = (8.0, 40.0)


PROP_COUNTS = {"poster": (0, 6), "plain": (1, 4), "tiles": (0, 4)}

# Clearances (object radii): cameras from the walls and ceiling, props from the walls, props from each other,
# and the margin around a prop that sight lines and cameras must keep.
CAMERA_WALL_CLEARANCE = 1.0
PROP_WALL_CLEARANCE = 0.3
PROP_PROP_GAP = 0.1
SIGHT_MARGIN = 0.15
PROP_TRIES = 40  # placement attempts per prop before giving up on it
# Light placement: distance from the room's edges, and lights sit this far in front of their surface.
LIGHT_EDGE_CLEARANCE = 0.5
LIGHT_OFFSET = 0.01
WINDOW_SILL = 1.5  # lowest window centre above the floor
# How the rig is sampled for the prop checks: azimuth step (degrees) and points per sight line.
CHECK_AZIMUTH_STEP_DEG = 5.0
CHECK_SIGHT_POINTS = 24


# --------------------------------------------------------------------------------------------- helpers


def distance_for_fraction(fraction: float, fov_x_deg: float, radius: float = 1.0,
                          aspect: float = FAMILY_ASPECT) -> float:
    """Camera distance at which a sphere of ``radius`` on the optical axis spans ``fraction`` of the frame
    height (``aspect`` = width / height, square pixels): its silhouette's radius is ``f R / sqrt(d^2 - R^2)``."""
    focal_over_height = aspect / (2 * math.tan(math.radians(fov_x_deg) / 2))  # f / H
    return radius * math.sqrt(1 + (2 * focal_over_height / fraction) ** 2)


def fraction_for_distance(distance: float, fov_x_deg: float, radius: float = 1.0,
                          aspect: float = FAMILY_ASPECT) -> float:
    """The inverse of :func:`distance_for_fraction`."""
    focal_over_height = aspect / (2 * math.tan(math.radians(fov_x_deg) / 2))
    return 2 * focal_over_height * radius / math.sqrt(distance**2 - radius**2)


def kelvin_rgb(kelvin: float) -> Vec3:
    """Linear RGB of a black body at ``kelvin`` (Tanner Helland's fit to the sRGB colours of the Planckian
    locus), scaled to unit luminance."""
    t = kelvin / 100.0
    r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    g = 99.4708025861 * math.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307)
    srgb = np.clip(np.array([r, g, b]) / 255.0, 0.0, 1.0)
    linear = srgb_to_linear(srgb)
    return tuple(float(c) for c in linear / float(np.dot(linear, LUMINANCE)))


def _uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(*lo_hi))


def _pick(rng: np.random.Generator, options, weights=None):
    p = None if weights is None else np.asarray(weights, float) / np.sum(weights)
    return options[int(rng.choice(len(options), p=p))]


# ---------------------------------------------------------------------------------------------- object


def _object(rng: np.random.Generator, r: FamilyRanges, shape: ObjectKind, floating: bool) -> ObjectSpec:
    albedo = _albedo(rng, r)
    ior = _uniform(rng, r.ior)
    roughness = _uniform(rng, r.roughness) if rng.random() < r.rough_probability else None
    base = ObjectSpec(shape, albedo=albedo, int_ior=round(ior, 3),
                      roughness=None if roughness is None else round(roughness, 4))
    yaw = _uniform(rng, (0.0, 360.0))
    if shape == "sphere":  # Mitsuba's analytic sphere cannot be rotated (its UV map would disagree with the mesh)
        return base
    if shape == "torus":
        minor = _uniform(rng, (0.22, 0.4))
        return replace(base, torus_major=1 - minor, torus_minor=minor, tilt_deg=(_uniform(rng, (0.0, 70.0)), 0.0, yaw))
    if shape == "blob":
        return replace(base, **_bumps(rng))
    tilt = (_uniform(rng, (0.0, 35.0)), 0.0, yaw) if floating else (0.0, 0.0, yaw)
    if shape == "vase":
        base_r, belly, waist, lip = (_uniform(rng, lo_hi) for lo_hi in ((0.3, 0.55), (0.5, 0.8), (0.2, 0.4),
                                                                        (0.3, 0.6)))
        radii = (base_r, belly, waist, lip) if rng.random() < 0.5 else (base_r, waist, belly, lip)
        return replace(base, profile_radii=tuple(round(x, 4) for x in radii),
                       profile_height=_uniform(rng, (1.6, 3.0)), profile_squareness=_uniform(rng, (4.0, 12.0)),
                       mesh_resolution=(160, 120), tilt_deg=tilt)
    radius = _uniform(rng, (0.45, 0.6))
    taper = _uniform(rng, (0.85, 1.15))
    return replace(base, profile_radii=(radius, radius * (1 + taper) / 2, radius * taper),
                   profile_height=_uniform(rng, (0.9, 1.4)), profile_squareness=_uniform(rng, (8.0, 14.0)),
                   handle_major=_uniform(rng, (0.22, 0.3)), handle_minor=_uniform(rng, (0.04, 0.07)),
                   handle_height=_uniform(rng, (0.45, 0.6)), mesh_resolution=(160, 120), tilt_deg=tilt)


def _albedo(rng: np.random.Generator, r: FamilyRanges) -> AlbedoSpec:
    dark = rng.random() < r.dark_probability
    if rng.random() < r.textured_probability:
        return AlbedoSpec(texture=True) if dark else AlbedoSpec(texture=True, style=LIGHT_ALBEDO_STYLE)
    colour = srgb_to_linear(np.asarray(_pick(rng, OBJECT_PALETTE), float) / 255.0)
    peak = _uniform(rng, r.dark_reflectance if dark else r.light_reflectance)
    return AlbedoSpec(rgb=tuple(round(float(c), 4) for c in colour / colour.max() * peak))


# Blob bumps: count, amplitude and sharpness ranges, and the smallest radius a dent may leave (a deep enough dent
# stays concave; overlapping dents must not pinch the surface).
BLOB_BUMPS = (6, 10)
BLOB_AMPLITUDE = (0.2, 0.45)
BLOB_SHARPNESS = (3.0, 8.0)
BLOB_MIN_RADIUS = 0.45


def _bumps(rng: np.random.Generator) -> dict:
    from .geometry import bump_radius

    n = int(rng.integers(BLOB_BUMPS[0], BLOB_BUMPS[1] + 1))
    centres = rng.normal(size=(n, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    amplitudes = rng.uniform(*BLOB_AMPLITUDE, n) * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    sharpness = rng.uniform(*BLOB_SHARPNESS, n)
    probe = rng.normal(size=(2000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    lowest = float(bump_radius(probe, centres, amplitudes, sharpness).min())
    if lowest < BLOB_MIN_RADIUS:  # shallower dents
        dents = amplitudes < 0
        amplitudes[dents] *= (1 - BLOB_MIN_RADIUS) / (1 - lowest)
    return {"bump_centres": tuple(tuple(round(float(c), 4) for c in row) for row in centres),
            "bump_amplitudes": tuple(round(float(a), 4) for a in amplitudes),
            "bump_sharpness": tuple(round(float(k), 3) for k in sharpness)}


# ------------------------------------------------------------------------------------------------ room


def _finishes(rng: np.random.Generator, r: FamilyRanges, kind: str) -> dict[str, SurfaceFinish]:
    if kind == "poster":
        return {}
    ceiling = SurfaceFinish("plain", CEILING_PAINT)
    if kind == "plain":
        walls = SurfaceFinish("plain", _pick(rng, WALL_PAINTS))
        floor = SurfaceFinish("plain", _pick(rng, FLOOR_PAINTS)) if rng.random() < r.floor_plain_probability \
            else SurfaceFinish()
        return {"walls": walls, "floor": floor, "ceiling": ceiling}

    def tiles() -> SurfaceFinish:
        return SurfaceFinish("tiles", _pick(rng, TILE_COLOURS), tile_size=round(_uniform(rng, r.tile_size), 3),
                             grout_width=round(_uniform(rng, r.grout_width), 4), grout_colour=_pick(rng, GROUT_COLOURS))

    return {"walls": tiles(), "floor": tiles(), "ceiling": ceiling}


def _lights(rng: np.random.Generator, r: FamilyRanges, half_x: float, half_y: float, height: float
            ) -> tuple[LightSpec, ...]:
    """Ceiling panels and windows (positions relative to the floor at z = 0), at least one light."""
    n_ceiling = int(rng.integers(r.ceiling_lights[0], r.ceiling_lights[1] + 1))
    n_windows = int(rng.integers(r.windows[0], r.windows[1] + 1))
    if n_ceiling + n_windows == 0:
        n_ceiling = 1
    n_ceiling = min(n_ceiling, r.max_lights)
    n_windows = min(n_windows, r.max_lights - n_ceiling)
    lights = []
    for k in range(n_ceiling):
        w, d = _uniform(rng, r.ceiling_light_side), _uniform(rng, r.ceiling_light_side)
        reach = max(w, d) / 2 + LIGHT_EDGE_CLEARANCE  # either side may lie along x
        x = _uniform(rng, (-1, 1)) * (half_x - reach)
        y = _uniform(rng, (-1, 1)) * (half_y - reach)
        power = _uniform(rng, r.ceiling_power)
        colour = kelvin_rgb(_uniform(rng, r.ceiling_kelvin))
        lights.append(LightSpec((x, y, height - LIGHT_OFFSET), (w, d), (0.0, 0.0, -1.0),
                                tuple(c * power / (w * d) for c in colour), name=f"ceiling_{k}"))
    for k in range(n_windows):
        w, h = _uniform(rng, r.window_size[0]), _uniform(rng, r.window_size[1])
        wall = int(rng.integers(4))  # +x, -x, +y, -y
        axis, sign = wall // 2, 1.0 if wall % 2 == 0 else -1.0
        half_along = half_y if axis == 0 else half_x
        half_across = half_x if axis == 0 else half_y
        along = _uniform(rng, (-1, 1)) * (half_along - w / 2 - LIGHT_EDGE_CLEARANCE)
        z = _uniform(rng, (WINDOW_SILL, max(WINDOW_SILL, height - h / 2 - LIGHT_EDGE_CLEARANCE)))
        centre = [0.0, 0.0, z]
        centre[axis], centre[1 - axis] = sign * (half_across - LIGHT_OFFSET), along
        normal = [0.0, 0.0, 0.0]
        normal[axis] = -sign
        power = _uniform(rng, r.window_power)
        colour = kelvin_rgb(_uniform(rng, r.window_kelvin))
        # size (width along the wall, height): rectangle_frame gives u horizontal, v = n x u vertical on walls
        lights.append(LightSpec(tuple(centre), (w, h), tuple(normal), tuple(c * power / (w * h) for c in colour),
                                name=f"window_{k}"))
    return tuple(lights)


# ------------------------------------------------------------------------------------------------ rig


def _rig(rng: np.random.Generator, r: FamilyRanges, fraction: float) -> RigSpec:
    fov = round(_uniform(rng, r.fov_x_deg), 2)
    d = distance_for_fraction(fraction, fov)
    n_rings = 1 + int(rng.choice(len(r.ring_weights), p=np.asarray(r.ring_weights) / sum(r.ring_weights)))
    while True:  # rings far enough apart to be different heights
        elevations = np.sort(rng.uniform(*r.elevation_deg, n_rings))
        if n_rings == 1 or np.diff(elevations).min() >= r.min_ring_separation_deg:
            break
    return RigSpec(
        distance=(round(d * (1 - r.distance_spread), 4), round(d * (1 + r.distance_spread), 4)),
        elevations_deg=tuple(round(float(e), 2) for e in elevations),
        fov_x_deg=fov,
        azimuth_jitter_deg=round(_uniform(rng, r.azimuth_jitter_deg), 2),
        elevation_jitter_deg=round(_uniform(rng, r.elevation_jitter_deg), 2),
        roll_jitter_deg=round(_uniform(rng, r.roll_jitter_deg), 2),
        ring_order="sequential" if rng.random() < r.sequential_probability else "interleaved",
        spacing_jitter=round(_uniform(rng, r.spacing_jitter), 3),
        position_jitter=round(_uniform(rng, r.position_jitter), 3),
        dropped=int(rng.integers(r.dropped[0], r.dropped[1] + 1)),
    )


def camera_envelope(rig: RigSpec) -> np.ndarray:
    """``(N, 3)`` camera centres (object centre at the origin) spanning the rig's whole range: every ring at its
    elevation +- the jitter, the nearest and farthest distance, every few degrees of azimuth. Position and aim
    jitter are left to the clearances."""
    az = np.deg2rad(np.arange(0.0, 360.0, CHECK_AZIMUTH_STEP_DEG))
    points = []
    for ring in rig.elevations_deg:
        for el in np.deg2rad([ring - rig.elevation_jitter_deg, ring, ring + rig.elevation_jitter_deg]):
            for dist in rig.distance:
                points.append(dist * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                               np.full_like(az, np.sin(el))], -1))
    return np.concatenate(points)


def sight_lines(cameras: np.ndarray, radius: float) -> np.ndarray:
    """``(N, CHECK_SIGHT_POINTS, 3)`` points on each camera's segment to the object centre, from the camera to the
    object's bounding sphere."""
    t = np.linspace(0.0, 1.0, CHECK_SIGHT_POINTS)[None, :, None]
    dist = np.linalg.norm(cameras, axis=1)[:, None, None]
    end = cameras * (radius / dist[:, :, 0])
    return cameras[:, None] + t * (end[:, None] - cameras[:, None])


# ---------------------------------------------------------------------------------------------- props


def _prop_json(p: PropSpec, floor_z: float) -> dict:
    """A :class:`PropSpec` in the world frame as ``scene.json`` writes it (for :class:`pipeline.props.Prop`)."""
    height = 2 * p.size[2] if p.kind != "cylinder" else p.size[2]
    return {"name": p.name, "kind": p.kind, "centre": [p.xy[0], p.xy[1], floor_z + p.lift + height / 2],
            "size": list(p.size), "yaw_deg": p.yaw_deg}


def footprint_radius(p: PropSpec) -> float:
    """Radius of the prop's bounding circle on the floor plan."""
    return math.hypot(p.size[0], p.size[1]) if p.kind == "box" else p.size[0]


def _random_prop(rng: np.random.Generator, r: FamilyRanges, k: int, inner: float) -> PropSpec:
    kind = _pick(rng, ("box", "cylinder", "sphere"))
    if kind == "box":
        size = (_uniform(rng, (0.2, 0.6)), _uniform(rng, (0.2, 0.6)), _uniform(rng, (0.15, 0.8)))
    elif kind == "cylinder":
        radius = _uniform(rng, (0.2, 0.5))
        size = (radius, radius, _uniform(rng, (0.3, 1.8)))
    else:
        radius = _uniform(rng, (0.2, 0.5))
        size = (radius, radius, radius)
    size = tuple(round(s, 3) for s in size)
    probe = PropSpec(kind, (0.0, 0.0), size)
    rho = inner + footprint_radius(probe) + _uniform(rng, r.prop_gap)
    angle = _uniform(rng, (0.0, 2 * math.pi))
    return PropSpec(kind, (round(rho * math.cos(angle), 4), round(rho * math.sin(angle), 4)), size,
                    yaw_deg=round(_uniform(rng, (0.0, 180.0)), 2) if kind == "box" else 0.0, name=f"prop_{k}")


def prop_fits(p: PropSpec, others: list[PropSpec], floor_z: float, inner: float, half: float,
              cameras: np.ndarray, lines: np.ndarray) -> bool:
    """Whether prop ``p`` stays clear of the object (and table) disc of radius ``inner``, of the other props, of
    the walls, of every camera and of every sight line to the object (world frame, object centre at the
    origin; ``cameras`` ``(N, 3)``, ``lines`` ``(N, M, 3)``)."""
    radius = footprint_radius(p)
    rho = math.hypot(*p.xy)
    if rho - radius < inner or rho + radius > half - PROP_WALL_CLEARANCE:
        return False
    for q in others:
        if math.dist(p.xy, q.xy) < radius + footprint_radius(q) + PROP_PROP_GAP:
            return False
    prop = Prop.from_json(_prop_json(p, floor_z))
    return not (prop.contains(cameras, SIGHT_MARGIN).any() or prop.contains(lines, SIGHT_MARGIN).any())


# --------------------------------------------------------------------------------------------- scenes


def random_scene(seed: int, *, room: str | None = None, ranges: FamilyRanges = FamilyRanges()) -> SceneSpec:
    """The family's scene number ``seed`` (deterministic in ``seed`` and ``ranges``), named ``random-<seed>``.

    ``room`` (one of :data:`ROOMS`) overrides the drawn room kind and nothing else: every other draw is the
    same (the scene is then named ``<room>-<seed>``).
    """
    if seed < 0:
        raise ValueError(f"random_scene: seed must be >= 0, got {seed}")
    if room is not None and room not in ROOMS:
        raise ValueError(f"random_scene: room must be one of {ROOMS}, got {room!r}")
    r = ranges
    rng = np.random.default_rng([seed, 0x0CA])
    shape = _pick(rng, SHAPES, r.shape_weights)
    placement = _pick(rng, PLACEMENTS, r.placement_weights)
    drawn_room = _pick(rng, ROOMS, r.room_weights)
    room_kind = room or drawn_room
    obj = _object(rng, r, shape, placement == "floating")
    mesh = object_mesh(obj)
    lowest = float(mesh.vertices[:, 2].min())  # the object's lowest point (object centre at the origin)

    props: list[PropSpec] = []
    lift = 0.0
    inner = obj.radius  # props stay outside this disc about the object's axis
    if placement == "table":
        lift = round(_uniform(rng, r.table_height), 3)
        half_top = obj.radius + _uniform(rng, r.table_margin)
        props.append(PropSpec("box", (0.0, 0.0), (round(half_top, 3), round(half_top, 3), lift / 2),
                              yaw_deg=round(_uniform(rng, (0.0, 90.0)), 2), name=TABLE,
                              colour=_pick(rng, TABLE_COLOURS)))
        inner = math.hypot(half_top, half_top)
    elif placement == "floating":
        lift = round(_uniform(rng, r.float_gap), 3)
    floor_z = lowest - lift

    fraction = float(np.exp(rng.uniform(*np.log(r.size_fraction))))
    rig = _rig(rng, r, fraction)
    reach = rig.distance[1] + rig.position_jitter
    top_el = math.radians(max(rig.elevations_deg) + rig.elevation_jitter_deg)
    half = max(_uniform(rng, r.room_half), reach + CAMERA_WALL_CLEARANCE)
    half_x, half_y = half, max(_uniform(rng, r.room_half), reach + CAMERA_WALL_CLEARANCE)
    height = max(_uniform(rng, r.room_height), -floor_z + reach * math.sin(top_el) + CAMERA_WALL_CLEARANCE)
    finishes = _finishes(rng, r, drawn_room)
    if room_kind != drawn_room:
        finishes = _finishes(np.random.default_rng([seed, 0x0CA, ROOMS.index(room_kind)]), r, room_kind)

    counts = (r.props or PROP_COUNTS)[drawn_room]  # (not room_kind: an overridden room keeps the same props)
    n_props = int(rng.integers(counts[0], counts[1] + 1))
    cameras = camera_envelope(rig)
    lines = sight_lines(cameras, obj.radius)
    for k in range(n_props):
        for _ in range(PROP_TRIES):
            candidate = _random_prop(rng, r, k, inner)
            if prop_fits(candidate, props, floor_z, inner, min(half_x, half_y), cameras, lines):
                props.append(candidate)
                break

    lights = _lights(rng, r, half_x, half_y, height)
    textured = [p.name for p in props if p.colour is None]
    name = f"random-{seed}" if room is None else f"{room}-{seed}"
    return SceneSpec(
        name=name,
        object=obj,
        props=tuple(props),
        lights=lights,
        room=RoomSpec(half_x=round(half_x, 3), half_y=round(half_y, 3), height=round(height, 3), **finishes),
        rig=rig,
        env=EnvViewSpec(parallax_prop=textured[0] if textured else None),
        texture_seed=10_000 + seed,
        lift=lift,
    )


def tiles_scene(seed: int) -> SceneSpec:
    """:func:`random_scene` ``(seed)`` in a tiled room (walls and floor): named ``tiles-<seed>``."""
    return random_scene(seed, room="tiles")


_NAME = re.compile(r"(random|tiles)-(\d+)")


def scene_by_name(name: str) -> SceneSpec | None:
    """``random-<seed>`` or ``tiles-<seed>`` -> the scene; any other name -> None."""
    m = _NAME.fullmatch(name.strip().lower())
    if m is None:
        return None
    seed = int(m.group(2))
    return random_scene(seed) if m.group(1) == "random" else tiles_scene(seed)


def traits(spec: SceneSpec) -> dict:
    """What a scene is, as the family varies it: shape, placement, room kind, object size in the frame, the
    number of props (besides a table), rings and lights."""
    has_table = any(p.name == TABLE for p in spec.props)
    rig = spec.rig
    return {
        "shape": spec.object.kind,
        "placement": "table" if has_table else ("floating" if spec.lift > 0 else "floor"),
        "room": spec.room.walls.kind,
        "floor": spec.room.floor.kind,
        "size_fraction": round(fraction_for_distance(sum(rig.distance) / 2, rig.fov_x_deg, spec.object.radius), 3),
        "props": sum(p.name != TABLE for p in spec.props),
        "rings": len(rig.elevations_deg),
        "ring_order": rig.ring_order,
        "dropped": rig.dropped,
        "lights": len(spec.lights),
        "textured_object": spec.object.albedo.texture,
        "rough": spec.object.roughness is not None,
    }


# Seeds of :func:`random_scene` that together cover every shape, placement and room kind, for benchmarking the
# front end (poses, masks) on a distribution (see traits()); rendered with
# ``orca synth random-<seed> OUT --views 40 --spp 16 --coverage-spp 16 --truth front_end`` (320x240):
#    0 vase on a table, tiled room, small (0.22 of the frame height), 3 rings
#    1 torus floating, poster room, 6 props
#    4 mug on the floor, plain walls and floor, 2 props, 3 rings
#    6 blob floating, poster room, large (0.61)
#    9 blob on a table, poster room, 2 photos dropped
#   10 mug floating, tiled room, the smallest (0.20), one interleaved ring, 3 photos dropped
#   11 mug on the floor, plain walls and floor, 1 prop, one ring
#   13 torus floating, plain walls, poster floor, slightly rough coat
#   27 torus on the floor, plain walls, poster floor, 1 prop, the largest (0.63)
#   32 sphere on a table, plain walls and floor, 2 props
#   57 vase on the floor, poster room, large (0.64), 4 lights
FRONT_END_SUITE: tuple[int, ...] = (0, 1, 4, 6, 9, 10, 11, 13, 27, 32, 57)
