"""Mitsuba 3 scene dictionaries from a :class:`~pipeline.synth.scenes.ResolvedScene`, and sensors from cameras.

Mitsuba is imported inside functions (``scalar_rgb``), so importing this module is cheap.

Variants of one scene (same geometry, same shape order, so shape indices agree):

- ``full``: what the camera sees.
- ``diffuse`` / ``specular``: the object's specular lobe switched off (``specular_reflectance = 0``) / its
  diffuse lobe switched off (``diffuse_reflectance = 0``). The object is Mitsuba's ``plastic`` with
  ``nonlinear = false``: its BSDF is then *exactly* ``f_spec(specular_reflectance) + f_diff(diffuse_reflectance)``
  with each term linear in its own parameter and independent of the other (the diffuse term's internal
  scattering is the constant ``1 / (1 - F_dr)`` instead of the colour-dependent ``1 / (1 - R_d F_dr)``),
  so the two lobe renders add up to the full render for every light path that meets the object once.
  Paths that meet it twice or more (object -> room -> object, or self-reflection on the torus and blob)
  carry products of both lobes and are missing from the sum; they are small and measured in the tests.
- ``coverage``: geometry only; the object white, everything else black, for the ``albedo`` AOV, which
  averaged over many samples per pixel is the object's (occlusion-aware) pixel coverage.
- ``environment``: ``full`` without the object (targets for the environment field).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import OrcaError
from .scenes import ResolvedProp, ResolvedScene
from .textures import poster, tile

Variant = Literal["full", "diffuse", "specular", "coverage", "environment"]
OBJECT_ID = "object"

# Diffuse reflectance left in the specular-only variant (see object_bsdf).
SPECULAR_ONLY_DIFFUSE = 1e-6

# OpenCV camera axes (x right, y down, z forward) -> Mitsuba's (x left, y up, z forward).
CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0, 1.0])

# Tile textures have at least this many texels across a grout line, so the lines stay crisp up close.
MIN_GROUT_TEXELS = 2.0


def mitsuba():
    """The ``mitsuba`` module with the ``scalar_rgb`` variant set (imported lazily: it is the ``synth`` extra).

    Raises:
        OrcaError: mitsuba is not installed, with the command that installs it.
    """
    try:
        import mitsuba as mi
    except ImportError as e:
        raise OrcaError(f"synthetic captures render with Mitsuba 3, which is not installed ({e})",
                        fix='pip install -e ".[synth]" in the repository (or pip install "mitsuba>=3.5")') from e

    if mi.variant() != "scalar_rgb":
        mi.set_variant("scalar_rgb")
    return mi


# ------------------------------------------------------------------------------------------------ textures


@dataclass
class SceneAssets:
    """Everything that is costly to make once per scene: textures (linear reflectance arrays), and how each
    surface or prop uses them."""

    textures: dict[str, np.ndarray]  # surface name -> (H, W, 3) float32
    object_ply: Path | None  # the object's mesh file (None for the analytic sphere)
    plain: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # name -> uniform reflectance
    repeats: dict[str, tuple[float, float]] = field(default_factory=dict)  # name -> texture repeats along (u, v)

    def bitmap(self, name: str) -> dict[str, Any]:
        mi = mitsuba()
        d = {"type": "bitmap", "bitmap": mi.Bitmap(self.textures[name]), "filter_type": "bilinear",
             "wrap_mode": "repeat"}
        if name in self.repeats:
            d["to_uv"] = mi.ScalarTransform4f.scale([*self.repeats[name], 1.0])
        return d

    def material(self, name: str) -> dict[str, Any]:
        """The diffuse BSDF of a room surface or prop: plain paint or its texture."""
        return _diffuse(self.plain[name]) if name in self.plain else _diffuse(self.bitmap(name))


def _texture_size(extent_u: float, extent_v: float, texels_per_unit: float, max_size: int) -> tuple[int, int]:
    """Texture (width, height) keeping the surface's aspect, capped at ``max_size`` on the long side."""
    w, h = extent_u * texels_per_unit, extent_v * texels_per_unit
    s = min(1.0, max_size / max(w, h))
    return max(16, int(w * s)), max(16, int(h * s))


def room_surfaces(scene: ResolvedScene) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The room's six inward-facing rectangles: name -> (centre, u half-vector, v half-vector).

    The facing normal is ``u x v`` (normalized): inward everywhere, and ``v`` is up on the walls, so
    the posters' letters read upright from inside.
    """
    lo, hi = scene.room_min, scene.room_max
    c = (lo + hi) / 2
    hx, hy, hz = (hi - lo) / 2
    ex, ey, ez = np.eye(3)
    return {
        "floor": (np.array([c[0], c[1], lo[2]]), ex * hx, ey * hy),
        "ceiling": (np.array([c[0], c[1], hi[2]]), ex * hx, -ey * hy),
        "wall_north": (np.array([c[0], hi[1], c[2]]), ex * hx, ez * hz),  # y = +half_y, faces -y
        "wall_south": (np.array([c[0], lo[1], c[2]]), -ex * hx, ez * hz),  # faces +y
        "wall_east": (np.array([hi[0], c[1], c[2]]), -ey * hy, ez * hz),  # x = +half_x, faces -x
        "wall_west": (np.array([lo[0], c[1], c[2]]), ey * hy, ez * hz),  # faces +x
    }


def make_assets(scene: ResolvedScene, object_ply: Path | None) -> SceneAssets:
    """Generate every texture of the scene (posters deterministic in ``scene.spec.texture_seed``; one tile,
    repeated, for a tiled surface; none for plain ones)."""
    spec, room = scene.spec, scene.spec.room
    textures: dict[str, np.ndarray] = {}
    plain: dict[str, tuple[float, float, float]] = {}
    repeats: dict[str, tuple[float, float]] = {}
    for i, (name, (_, u, v)) in enumerate(room_surfaces(scene).items()):
        finish = room.finish(name)
        extent_u, extent_v = 2 * float(np.linalg.norm(u)), 2 * float(np.linalg.norm(v))
        if finish.kind == "plain":
            plain[name] = finish.colour
        elif finish.kind == "tiles":
            texels = max(room.texels_per_unit, MIN_GROUT_TEXELS / finish.grout_width)
            size = min(room.max_texture, int(round(finish.tile_size * texels)))
            textures[name] = tile(size, finish.grout_width / finish.tile_size * size, finish.colour,
                                  finish.grout_colour)
            repeats[name] = (extent_u / finish.tile_size, extent_v / finish.tile_size)
        else:
            w, h = _texture_size(extent_u, extent_v, room.texels_per_unit, room.max_texture)
            textures[name] = poster(w, h, seed=spec.texture_seed * 1000 + i, style=room.style)
    for p in scene.props:
        if p.colour is not None:
            plain[p.name] = p.colour
            continue
        eu, ev = _prop_uv_extent(p)
        w, h = _texture_size(eu, ev, room.prop_texels_per_unit, room.max_texture // 2)
        textures[p.name] = poster(w, h, seed=p.texture_seed, style=room.style)
    albedo = spec.object.albedo
    if albedo.texture:
        w, h = albedo.texture_size
        textures[OBJECT_ID] = poster(w, h, seed=spec.texture_seed * 1000 + 999, style=albedo.style)
    return SceneAssets(textures, object_ply, plain, repeats)


def _prop_uv_extent(p: ResolvedProp) -> tuple[float, float]:
    """World extent covered by the prop's UV square, so posters are not stretched much."""
    if p.kind == "box":
        return 2 * float(max(p.size[0], p.size[1])), 2 * float(p.size[2])
    if p.kind == "cylinder":
        return 2 * np.pi * float(p.size[0]), float(p.size[2])
    return 2 * np.pi * float(p.size[0]), np.pi * float(p.size[0])


# ---------------------------------------------------------------------------------------------- transforms


def _affine(columns: tuple[np.ndarray, np.ndarray, np.ndarray], origin: np.ndarray):
    mi = mitsuba()
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = columns[0], columns[1], columns[2], origin
    return mi.ScalarTransform4f(m.tolist())


def rectangle_transform(centre: np.ndarray, u: np.ndarray, v: np.ndarray):
    """Mitsuba ``rectangle`` ([-1, 1]^2, normal +z) mapped to centre + s u + t v, facing ``u x v``."""
    n = np.cross(u, v)
    return _affine((u, v, n / np.linalg.norm(n)), centre)


def rectangle_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (u, v) with u x v = normal."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    helper = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _yaw(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


# -------------------------------------------------------------------------------------------------- scene


def _diffuse(tex: dict[str, Any] | float | tuple[float, float, float]) -> dict[str, Any]:
    """A diffuse BSDF: grey ``float``, linear RGB ``tuple``, or a texture ``dict``."""
    if isinstance(tex, float):
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [tex, tex, tex]}}
    if isinstance(tex, tuple):
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [float(c) for c in tex]}}
    return {"type": "diffuse", "reflectance": tex}


def object_bsdf(scene: ResolvedScene, assets: SceneAssets, variant: Variant) -> dict[str, Any]:
    """The object's coated material; ``diffuse``/``specular`` variants switch one lobe off (see module doc). A bare
    metal has no diffuse lobe: black in the ``diffuse`` variant, itself in the ``specular`` one."""
    obj = scene.spec.object
    if variant == "coverage":
        return _diffuse(1.0)
    if obj.conductor is not None:
        if variant == "diffuse":
            return _diffuse(0.0)
        metal: dict[str, Any] = {"type": "conductor" if obj.roughness is None else "roughconductor",
                                 "material": obj.conductor}
        if obj.roughness is not None:
            metal |= {"alpha": obj.roughness, "distribution": "ggx"}
        return metal
    if obj.albedo.texture:
        diffuse: dict[str, Any] = assets.bitmap(OBJECT_ID)
    else:
        diffuse = {"type": "rgb", "value": list(obj.albedo.rgb)}
    bsdf: dict[str, Any] = {"type": "plastic" if obj.roughness is None else "roughplastic",
                            "int_ior": obj.int_ior, "ext_ior": 1.0, "nonlinear": False,
                            "diffuse_reflectance": diffuse}
    if obj.roughness is not None:
        bsdf["alpha"] = obj.roughness
        bsdf["distribution"] = "ggx"
    if variant == "diffuse":
        bsdf["specular_reflectance"] = {"type": "rgb", "value": [0.0, 0.0, 0.0]}
    elif variant == "specular":
        # Not exactly 0: plastic's lobe-selection probability is F w / (F w + (1 - F)(1 - w)) with
        # w = s / (s + d), which is 0/0 = NaN for d = 0 where F vanishes (seen as NaN pixels). 1e-6 of diffuse
        # reflectance adds ~1e-5 of the diffuse image to the specular one, far below the Monte Carlo noise.
        eps = SPECULAR_ONLY_DIFFUSE
        bsdf["diffuse_reflectance"] = {"type": "rgb", "value": [eps, eps, eps]}
    return bsdf


def object_shape(scene: ResolvedScene, assets: SceneAssets, variant: Variant) -> dict[str, Any]:
    obj = scene.spec.object
    bsdf = object_bsdf(scene, assets, variant)
    if obj.kind == "sphere":
        # Mitsuba's analytic sphere: exact normals and silhouettes for the analytic tests.
        return {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": obj.radius, "bsdf": bsdf}
    if assets.object_ply is None:
        raise ValueError("a mesh object needs its PLY file")
    return {"type": "ply", "filename": str(assets.object_ply), "bsdf": bsdf}


def prop_shapes(p: ResolvedProp, material: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """One or more Mitsuba shapes for a prop (a cylinder gets two cap disks)."""
    c = p.centre
    if p.kind == "box":
        r = _yaw(p.yaw_deg)
        return {p.name: {"type": "cube", "to_world": _affine(tuple(r[:, k] * p.size[k] for k in range(3)), c),
                         "bsdf": material}}
    if p.kind == "sphere":
        return {p.name: {"type": "sphere", "center": c.tolist(), "radius": float(p.size[0]), "bsdf": material}}
    if p.kind == "cylinder":
        radius, height = float(p.size[0]), float(p.size[2])
        bottom, top = c - [0, 0, height / 2], c + [0, 0, height / 2]
        ex, ey, ez = np.eye(3)
        return {
            p.name: {"type": "cylinder", "p0": bottom.tolist(), "p1": top.tolist(), "radius": radius,
                     "bsdf": material},
            f"{p.name}__top": {"type": "disk", "to_world": _affine((ex * radius, ey * radius, ez), top),
                               "bsdf": material},
            f"{p.name}__bottom": {"type": "disk", "to_world": _affine((ex * radius, -ey * radius, -ez), bottom),
                                  "bsdf": material},
        }
    raise ValueError(f"unknown prop kind {p.kind!r}")


def scene_dict(scene: ResolvedScene, assets: SceneAssets, variant: Variant, max_depth: int | None = None) -> dict:
    """The Mitsuba scene dictionary of one variant (no sensor: sensors are passed per render).

    Shapes are inserted in a fixed order (object first when present), so Mitsuba's ``shape_index`` AOV is
    ``1 + position`` in :meth:`mi.Scene.shapes` and agrees across variants.
    """
    geometry_only = variant == "coverage"
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth or scene.spec.max_depth, "hide_emitters": False},
    }
    if variant != "environment":
        d[OBJECT_ID] = object_shape(scene, assets, variant)
    for name, (centre, u, v) in room_surfaces(scene).items():
        material = _diffuse(0.0) if geometry_only else assets.material(name)
        d[name] = {"type": "rectangle", "to_world": rectangle_transform(centre, u, v), "bsdf": material}
    for p in scene.props:
        material = _diffuse(0.0) if geometry_only else assets.material(p.name)
        d.update(prop_shapes(p, material))
    for light in scene.lights:
        u, v = rectangle_frame(np.array(light.normal))
        shape: dict[str, Any] = {
            "type": "rectangle",
            "to_world": rectangle_transform(np.array(light.centre), u * light.size[0] / 2, v * light.size[1] / 2),
            "bsdf": _diffuse(0.0),
        }
        if not geometry_only:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(light.radiance)}}
        d[light.name] = shape
    return d


def load_scene(scene: ResolvedScene, assets: SceneAssets, variant: Variant):
    """``mi.load_dict`` of :func:`scene_dict`; returns ``(mi.Scene, {shape id: shape_index AOV value})``.

    The ``shape_index`` AOV is ``1 +`` the shape's position in ``Scene.shapes()``. It is read from a second,
    throw-away load of the same dictionary: once Python has touched a scene's shapes (``shapes()``,
    ``mi.traverse``), rendering *that* scene in ``scalar_rgb`` runs about 5x slower (measured with Mitsuba 3.9.1).
    Both loads keep the dictionary's order (``optimize=False``): Mitsuba's optimizing load merges shapes on
    several threads and returns them in an order that differs from load to load, and with it the order of the
    lights, which the path tracer's random numbers pick from: the same capture rendered twice had different noise
    (a mean 5 of 255 per pixel at 16 samples), enough to move SfM on a tiled room between 0.5 and 1.2 degrees.
    """
    mi = mitsuba()
    d = scene_dict(scene, assets, variant)
    probe = mi.load_dict(d, optimize=False)
    index = {s.id(): i + 1 for i, s in enumerate(probe.shapes())}
    del probe
    return mi.load_dict(d, optimize=False), index


# ------------------------------------------------------------------------------------------------ sensors


@dataclass(frozen=True)
class Crop:
    """A pixel window ``[x0, x0 + width) x [y0, y0 + height)`` of the full image."""

    x0: int
    y0: int
    width: int
    height: int


def sensor(
    c2w: np.ndarray,
    width: int,
    height: int,
    fx: float,
    *,
    spp: int,
    sampler: Literal["independent", "stratified", "centre"] = "independent",
    crop: Crop | None = None,
    near_clip: float = 1e-3,
    far_clip: float = 1e4,
):
    """A Mitsuba perspective sensor for an OpenCV camera-to-world pose and a centred pinhole.

    ``sampler="centre"``: one sample exactly at each pixel's centre (``stratified``, 1 sample, no jitter),
    used for depth / normals / object-id ground truth, so they refer to the ray through the pixel centre
    (COLMAP pixel (j + 0.5, i + 0.5)) instead of a blend of surfaces at silhouettes.
    """
    mi = mitsuba()
    fov_x = float(np.degrees(2 * np.arctan(width / (2 * fx))))
    film: dict[str, Any] = {"type": "hdrfilm", "width": int(width), "height": int(height), "pixel_format": "rgb",
                            "rfilter": {"type": "box"}, "component_format": "float32"}
    if crop is not None:
        film.update(crop_offset_x=crop.x0, crop_offset_y=crop.y0, crop_width=crop.width, crop_height=crop.height)
    if sampler == "centre":
        smp: dict[str, Any] = {"type": "stratified", "sample_count": 1, "jitter": False}
    else:
        smp = {"type": sampler, "sample_count": int(spp)}
    to_world = np.asarray(c2w, dtype=np.float64) @ CV_TO_MITSUBA
    return mi.load_dict({
        "type": "perspective", "fov": fov_x, "fov_axis": "x", "near_clip": near_clip, "far_clip": far_clip,
        "to_world": mi.ScalarTransform4f(to_world.tolist()), "film": film, "sampler": smp,
    })


def effective_spp(sampler: str, spp: int) -> int:
    """The sample count Mitsuba really uses for ``sampler`` (stratified rounds up to a square, multijitter to a
    product of two near-equal factors), found without the warning it prints on each rounding."""
    if sampler in ("independent", "centre"):
        return int(spp) if sampler == "independent" else 1
    mi = mitsuba()
    level = mi.logger().log_level()
    mi.set_log_level(mi.LogLevel.Error)
    try:
        return int(mi.load_dict({"type": sampler, "sample_count": int(spp)}).sample_count())
    finally:
        mi.set_log_level(level)


def render(scene, sensor_obj, *, integrator=None, seed: int = 0) -> np.ndarray:
    """Render to a float32 ``(H, W, C)`` array."""
    mi = mitsuba()
    img = mi.render(scene, sensor=sensor_obj, integrator=integrator, seed=int(seed))
    return np.array(img, dtype=np.float32)


def aov_integrator(aovs: str):
    mi = mitsuba()
    return mi.load_dict({"type": "aov", "aovs": aovs})
