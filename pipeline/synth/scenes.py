"""Named synthetic scenes as data: a glossy object in a closed, textured room with props close by.

World frame (the ground-truth frame): z up, the object's bounding sphere is centred at the origin with the
radius in :attr:`ObjectSpec.radius` (1 for every preset), the object rests on the floor (``floor_z`` is the
object's lowest point) or, with :attr:`SceneSpec.lift`, that far above it (on a table prop, or floating).
Props stand on the floor (or on another prop) one to three object radii from the object's surface, so the
reflections show close-by things at several depths, and the walls further out.

A preset is a :class:`SceneSpec`; :data:`SCENES` maps names to them; ``random-<seed>`` and ``tiles-<seed>``
name scenes of the randomized family (:mod:`pipeline.synth.family`). Only geometry is resolved here
(:func:`resolve`), nothing imports Mitsuba.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from ..errors import InputError
from . import geometry
from .textures import PosterStyle

Vec3 = tuple[float, float, float]


# Saturated, mid-to-light colours (no near-black): mapped into the object's dark reflectance range they
# still read as colours under the reflections.
OBJECT_PALETTE: tuple[tuple[int, int, int], ...] = (
    (220, 40, 40), (250, 200, 30), (30, 90, 200), (40, 160, 70), (240, 120, 30), (40, 190, 200), (245, 243, 235),
)


@dataclass(frozen=True)
class AlbedoSpec:
    """The object's diffuse colour: a uniform linear RGB, or a poster texture (``texture=True``)."""

    rgb: Vec3 = (0.2, 0.2, 0.2)
    texture: bool = False
    texture_size: tuple[int, int] = (1024, 512)  # (width, height) of the UV texture
    # Dark, calm diffuse pattern (few large shapes, no letters), so the coat's ~10 % reflection of the room
    # stands out on top of it instead of drowning in texture.
    style: PosterStyle = PosterStyle(reflectance=(0.01, 0.12), shapes_per_megapixel=50.0, min_scale=0.06,
                                     max_scale=0.6, glyph_weight=0.0, palette=OBJECT_PALETTE)


ObjectKind = Literal["sphere", "torus", "blob", "vase", "mug"]


@dataclass(frozen=True)
class ObjectSpec:
    """The glossy object: a smooth (or slightly rough) dielectric coat over a diffuse base (Mitsuba plastic), or a
    bare metal (``conductor``)."""

    kind: ObjectKind
    radius: float = 1.0  # bounding-sphere radius, centred at the origin
    albedo: AlbedoSpec = AlbedoSpec()
    int_ior: float = 1.9  # coat IOR (a glaze / lacquer): ~10 % reflected at normal incidence, more at grazing
    roughness: float | None = None  # None: smooth `plastic`; else `roughplastic` (GGX alpha)
    # A Mitsuba conductor's measured metal ("Au", "Cu", "Ag", "Al", "Cr"...): the object is that bare metal
    # (`conductor`, or `roughconductor` with ``roughness``), no diffuse base (albedo and int_ior unused).
    conductor: str | None = None
    # torus: tube centre-line radius and tube radius, as fractions of `radius` (major + minor = 1)
    torus_major: float = 0.68
    torus_minor: float = 0.32
    tilt_deg: Vec3 = (0.0, 0.0, 0.0)  # rotation about x, y, z (applied in that order) for meshes
    # blob: von Mises bumps (amplitude > 0) and dents (< 0) on the unit sphere
    bump_centres: tuple[Vec3, ...] = ()
    bump_amplitudes: tuple[float, ...] = ()
    bump_sharpness: tuple[float, ...] = ()
    mesh_resolution: tuple[int, int] = (160, 80)  # grid (around, across) of parametric meshes
    # vase / mug body: a surface of revolution about z (see geometry.revolution): radii at evenly spaced
    # heights from the bottom up (a smaller middle one makes a waist), the height in the same units, and how
    # square the bottom and top edges are (2: an ellipsoid-like closing, large: flat caps, sharp rims)
    profile_radii: tuple[float, ...] = ()
    profile_height: float = 2.0
    profile_squareness: float = 8.0
    # mug handle: a torus in the xz plane through the body's wall; radii and centre height as fractions of
    # the body's height (centre height from the bottom)
    handle_major: float = 0.28
    handle_minor: float = 0.06
    handle_height: float = 0.55


@dataclass(frozen=True)
class PropSpec:
    """A textured prop. ``xy`` is the centre on the floor plan; it stands on the floor, raised by ``lift``."""

    kind: Literal["box", "cylinder", "sphere"]
    xy: tuple[float, float]
    size: Vec3  # box: half extents (x, y, z); cylinder: (radius, radius, height); sphere: (r, r, r)
    yaw_deg: float = 0.0  # rotation about z (boxes)
    lift: float = 0.0  # extra height of the bottom above the floor (e.g. stacked on another prop)
    name: str = ""
    colour: Vec3 | None = None  # uniform linear reflectance (a plain table, a painted box); None: a poster


@dataclass(frozen=True)
class SurfaceFinish:
    """How a room surface looks: a poster (:attr:`RoomSpec.style`), plain paint of one ``colour``, or a regular
    grid of identical plain ``colour`` tiles of side ``tile_size`` with ``grout_width`` lines of
    ``grout_colour`` between them (a repetitive texture: every tile corner looks the same to SIFT).
    Colours are linear reflectances."""

    kind: Literal["poster", "plain", "tiles"] = "poster"
    colour: Vec3 = (0.6, 0.6, 0.6)
    tile_size: float = 0.3  # world units
    grout_width: float = 0.015  # world units
    grout_colour: Vec3 = (0.25, 0.25, 0.25)


@dataclass(frozen=True)
class RoomSpec:
    """A closed box room: walls at x = +-half_x, y = +-half_y, floor at the object's base, ceiling above."""

    half_x: float = 8.0
    half_y: float = 8.0
    height: float = 6.5
    texels_per_unit: float = 96.0  # wall/floor poster resolution (and tiles' texels per tile side / tile_size)
    max_texture: int = 2048
    style: PosterStyle = PosterStyle()
    prop_texels_per_unit: float = 256.0
    walls: SurfaceFinish = SurfaceFinish()
    floor: SurfaceFinish = SurfaceFinish()
    ceiling: SurfaceFinish = SurfaceFinish()

    def finish(self, surface: str) -> SurfaceFinish:
        """The finish of a surface named as in :func:`pipeline.synth.build.room_surfaces`."""
        return self.floor if surface == "floor" else self.ceiling if surface == "ceiling" else self.walls


@dataclass(frozen=True)
class LightSpec:
    """A one-sided rectangular area light (``size`` = full width, height) facing ``normal``."""

    centre: Vec3
    size: tuple[float, float]
    normal: Vec3
    radiance: Vec3
    name: str = "light"


@dataclass(frozen=True)
class RigSpec:
    """Hand-held cameras around the object: interleaved rings at a few elevations, all looking at it."""

    distance: tuple[float, float] = (5.6, 6.6)  # from the object centre; ~1/3 of the frame width at fov 60
    elevations_deg: tuple[float, ...] = (20.0, 32.0, 42.0)
    fov_x_deg: float = 60.0
    azimuth_jitter_deg: float = 3.0
    elevation_jitter_deg: float = 3.0
    target_jitter: float = 0.08  # look-at point jitter (world units), so the object is not always dead centre
    roll_jitter_deg: float = 2.0
    sensor_width_mm: float = 6.4  # for EXIF focal length (a phone's main camera)
    # interleaved: photo i on ring i % rings, all rings at once; sequential: one full ring after the other
    # (a walk around at one height, then at the next), each starting at a random azimuth
    ring_order: Literal["interleaved", "sequential"] = "interleaved"
    spacing_jitter: float = 0.0  # relative spread of the azimuth steps between photos (uneven walking pace)
    position_jitter: float = 0.0  # hand-held shake of the camera centre (world units, per axis, uniform)
    dropped: int = 0  # planned path positions with no photo (missing photos leave gaps in the path)


@dataclass(frozen=True)
class EnvViewSpec:
    """Environment ground truth: cube views from the object centre, and translated views behind a prop."""

    cube_fov_deg: float = 90.0
    parallax_prop: str | None = "occluder"  # name of the prop to look at; None: along +x
    parallax_offsets: tuple[float, ...] = (-0.75, 0.0, 0.75)  # sideways shifts, fractions of object radius
    parallax_fov_deg: float = 70.0


@dataclass(frozen=True)
class SceneSpec:
    name: str
    object: ObjectSpec
    props: tuple[PropSpec, ...]
    lights: tuple[LightSpec, ...]
    room: RoomSpec = RoomSpec()
    rig: RigSpec = RigSpec()
    env: EnvViewSpec = EnvViewSpec()
    # Path length in Mitsuba's counting: 3 = direct light plus one bounce (camera -> object -> room -> light
    # sample), which is what a reflection of a lit prop needs; 4 looks the same here at twice the cost.
    max_depth: int = 3
    texture_seed: int = 0  # textures depend only on this (and the surface), not on the render seed
    lift: float = 0.0  # height of the object's lowest point above the floor (on a table prop, or floating)


# --------------------------------------------------------------------------------------------- presets

# Props within one to three object radii of the object's surface, at several heights and depths.
DEFAULT_PROPS: tuple[PropSpec, ...] = (
    PropSpec("box", (2.3, 1.0), (0.45, 0.35, 0.5), yaw_deg=25.0, name="crate"),
    PropSpec("sphere", (2.3, 1.0), (0.25, 0.25, 0.25), lift=1.0, name="ball_on_crate"),
    PropSpec("cylinder", (-1.5, 2.1), (0.4, 0.4, 1.6), name="occluder"),
    PropSpec("sphere", (0.9, -2.4), (0.5, 0.5, 0.5), name="ball"),
    PropSpec("box", (-2.5, -1.0), (0.3, 0.55, 0.75), yaw_deg=-35.0, name="tall_box"),
    PropSpec("cylinder", (2.2, -1.5), (0.35, 0.35, 0.7), name="drum"),
    PropSpec("box", (0.3, 3.2), (0.6, 0.25, 0.4), yaw_deg=10.0, name="bench"),
)

# Light positions are relative to the floor at z = 0 here and are shifted with it (see `resolve`).
DEFAULT_LIGHTS: tuple[LightSpec, ...] = (
    LightSpec((0.8, -0.6, 6.49), (2.6, 2.6), (0.0, 0.0, -1.0), (9.0, 9.0, 8.5), name="ceiling_panel"),
    LightSpec((-7.99, 1.0, 3.4), (2.0, 1.4), (1.0, 0.0, 0.0), (3.0, 3.3, 3.8), name="window"),
)

SCENES: dict[str, SceneSpec] = {
    "sphere": SceneSpec(
        name="sphere",
        object=ObjectSpec("sphere", albedo=AlbedoSpec(texture=True)),
        props=DEFAULT_PROPS,
        lights=DEFAULT_LIGHTS,
        texture_seed=101,
    ),
    "torus": SceneSpec(
        name="torus",
        object=ObjectSpec("torus", albedo=AlbedoSpec(rgb=(0.25, 0.04, 0.03)), tilt_deg=(25.0, 0.0, 30.0)),
        props=DEFAULT_PROPS,
        lights=DEFAULT_LIGHTS,
        texture_seed=202,
    ),
    "gold": SceneSpec(  # the demo's room around a polished gold ball: a metal reflects in its own colour
        name="gold",
        object=ObjectSpec("sphere", conductor="Au"),
        props=DEFAULT_PROPS,
        lights=DEFAULT_LIGHTS,
        texture_seed=101,
    ),
    "blob": SceneSpec(
        name="blob",
        object=ObjectSpec(
            "blob",
            albedo=AlbedoSpec(texture=True),
            bump_centres=((1, 0, 0.2), (0, 1, 0.5), (-1, -0.6, 0.8), (0.2, -1, -0.2), (-0.7, 0.6, -0.6),
                          (0.5, 0.5, -1), (0, 0, 1), (0.8, -0.5, 0.7)),
            bump_amplitudes=(0.45, -0.35, 0.4, -0.35, 0.3, -0.3, 0.25, -0.3),
            bump_sharpness=(4.0, 7.0, 5.0, 7.0, 4.0, 7.0, 4.0, 8.0),
        ),
        props=DEFAULT_PROPS,
        lights=DEFAULT_LIGHTS,
        texture_seed=303,
    ),
}


def get_scene(name_or_spec: str | SceneSpec) -> SceneSpec:
    """A preset by name (case-insensitive), a family scene by name (``random-<seed>``, ``tiles-<seed>``, see
    :func:`pipeline.synth.family.scene_by_name`), or the spec itself."""
    if isinstance(name_or_spec, SceneSpec):
        return name_or_spec
    key = str(name_or_spec).lower()
    if key in SCENES:
        return SCENES[key]
    from .family import scene_by_name  # the family builds on this module

    spec = scene_by_name(key)
    if spec is None:
        raise InputError(f"unknown scene {name_or_spec!r}; choose one of: {', '.join(SCENES)}, "
                         "random-<seed>, tiles-<seed> (seed: a non-negative integer)")
    return spec


# ------------------------------------------------------------------------------------- resolved geometry


@dataclass
class ResolvedProp:
    """A prop in world coordinates: ``centre`` of its bounding box, ``size`` as in :class:`PropSpec`."""

    name: str
    kind: str
    centre: np.ndarray  # (3,)
    size: np.ndarray  # (3,)
    yaw_deg: float
    texture_seed: int
    colour: Vec3 | None = None  # plain linear reflectance, or None for a poster texture

    def to_json(self) -> dict:
        d = {"name": self.name, "kind": self.kind, "centre": self.centre.tolist(), "size": self.size.tolist(),
             "size_meaning": _SIZE_MEANING[self.kind], "yaw_deg": self.yaw_deg}
        if self.colour is not None:
            d["colour"] = list(self.colour)
        return d


_SIZE_MEANING = {
    "box": "half extents (x, y, z) before the yaw rotation about z",
    "cylinder": "(radius, radius, height); axis along z through the centre",
    "sphere": "(radius, radius, radius)",
}


@dataclass
class ResolvedScene:
    """A :class:`SceneSpec` with its object mesh built and everything placed in world coordinates."""

    spec: SceneSpec
    mesh: geometry.TriMesh  # the object's mesh in the world frame (a fine UV sphere for the sphere scene)
    floor_z: float
    props: list[ResolvedProp]
    lights: list[LightSpec]  # with world-space centres
    room_min: np.ndarray = field(default_factory=lambda: np.zeros(3))
    room_max: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def object_radius(self) -> float:
        return self.spec.object.radius

    def prop(self, name: str) -> ResolvedProp:
        for p in self.props:
            if p.name == name:
                return p
        raise KeyError(f"scene {self.spec.name!r} has no prop named {name!r}")


def rotation_xyz(deg: Vec3) -> np.ndarray:
    """Rotation about x, then y, then z (degrees), as a 3x3 matrix."""
    ax, ay, az = np.deg2rad(deg)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def object_mesh(obj: ObjectSpec) -> geometry.TriMesh:
    """The object's mesh in the world frame, bounding radius ``obj.radius`` about the origin."""
    around, across = obj.mesh_resolution
    if obj.kind == "sphere":
        mesh = geometry.uv_sphere(1.0, around, across)
    elif obj.kind == "torus":
        total = obj.torus_major + obj.torus_minor
        mesh = geometry.torus(obj.torus_major / total, obj.torus_minor / total, around, max(16, across // 2))
    elif obj.kind == "blob":
        if not (len(obj.bump_centres) == len(obj.bump_amplitudes) == len(obj.bump_sharpness) > 0):
            raise ValueError("blob: bump_centres, bump_amplitudes and bump_sharpness must be equally long, >= 1")
        mesh = geometry.blob(obj.bump_centres, obj.bump_amplitudes, obj.bump_sharpness, around, across)
    elif obj.kind in ("vase", "mug"):
        if len(obj.profile_radii) < 2:
            raise ValueError(f"{obj.kind}: profile_radii needs at least 2 radii")
        body = geometry.revolution(geometry.smooth_profile(obj.profile_radii), obj.profile_height,
                                   obj.profile_squareness, around, across)
        if obj.kind == "vase":
            mesh = body
        else:
            h = obj.profile_height
            mesh = geometry.mug(body, h * obj.handle_major, h * obj.handle_minor, h * (obj.handle_height - 0.5),
                                around, max(16, across // 4))
    else:
        raise ValueError(f"unknown object kind {obj.kind!r}")
    return mesh.transformed(rotation_xyz(obj.tilt_deg), obj.radius / mesh.bounding_radius)


def resolve(spec: SceneSpec) -> ResolvedScene:
    """Build the object mesh and place the floor, props and lights in the world frame."""
    mesh = object_mesh(spec.object)
    floor_z = float(mesh.vertices[:, 2].min()) - spec.lift
    props: list[ResolvedProp] = []
    for i, p in enumerate(spec.props):
        sx, sy, sz = p.size
        height = 2 * sz if p.kind == "box" else (sz if p.kind == "cylinder" else 2 * sz)
        centre = np.array([p.xy[0], p.xy[1], floor_z + p.lift + height / 2])
        props.append(ResolvedProp(p.name or f"prop{i}", p.kind, centre, np.array(p.size, float), p.yaw_deg,
                                  spec.texture_seed * 1000 + 100 + i, p.colour))
    lights = [replace(light, centre=(light.centre[0], light.centre[1], light.centre[2] + floor_z))
              for light in spec.lights]
    room = spec.room
    return ResolvedScene(
        spec, mesh, floor_z, props, lights,
        room_min=np.array([-room.half_x, -room.half_y, floor_z]),
        room_max=np.array([room.half_x, room.half_y, floor_z + room.height]),
    )
