"""``render_capture``: a synthetic capture folder, as a phone would write it, plus exact ground truth.

Layout written (``<stem>`` = ``IMG_0001`` ...; see :data:`LAYOUT` and ``ground_truth/scene.json``)::

    OUT/
      IMG_0001.dng ...            RAW photos (Bayer mosaic, EXIF exposure varies like auto-exposure) and/or
      IMG_0001.jpg ...            sRGB JPEGs (--format jpg|both)
      capture.yaml                the object's coat IOR for training (what a user knowing the material sets)
      ground_truth/
        cameras.json              every photo's pose + intrinsics (OpenCV, world frame below), image -> photo
        scene.json                object centre/radius, props, lights, exposure per photo, radiance<->decoded
                                  factor, render settings, measured diffuse+specular residual
        manifest.json             config, versions, timing
        object.ply                the object mesh, world frame (x y z nx ny nz u v)
        object_albedo.png         the object's diffuse texture (sRGB 8-bit of the linear albedo), if textured
        linear/<stem>.exr         full render, linear radiance (float16)          \
        diffuse/<stem>.exr        object with its specular lobe off (float16)     | 0 outside the object's
        specular/<stem>.exr       object with its diffuse lobe off (float16)      | pixels (see below)
        albedo/<stem>.exr         diffuse albedo at the pixel-centre hit (float16)|
        normals/<stem>.exr        world-space unit normals at the pixel-centre hit (float16)
        depth/<stem>.exr          z-depth along the optical axis (float32), +inf where the pixel-centre ray
                                  does not hit the object first
        masks/<stem>.png          object mask, 0/255: occlusion-aware pixel coverage >= 0.5
        coverage/<stem>.png       the coverage itself, 0..255 (255: every sample of the pixel hit the object)
        environment/
          cameras.json            environment cameras (inside the object, object removed)
          rgb/<name>.exr          linear radiance (float16), same units as linear/
          depth/<name>.exr        z-depth (float32), +inf for no hit

World frame: z up, object bounding sphere centred at the origin with radius ``scene.json: object.radius``.
Depth and normals come from one ray through each pixel centre (COLMAP's pixel (j + 0.5, i + 0.5));
masks from the average over ``coverage_spp`` samples per pixel of "the first hit is the object", thresholded
at 0.5; the diffuse/specular/albedo images hold values on pixels with any object coverage (> 0).
The radiance images (linear, diffuse, specular) are sensor-plane images: blurred by the camera's optics
(``SynthOptions.optics_blur_px``, a Gaussian PSF) exactly as the photos are; geometry (masks, coverage, depth,
normals, albedo) is per pixel. diffuse + specular = linear holds on interior pixels (coverage 1, at least
3 sigma of the blur from the silhouette); on silhouette pixels each lobe render also contains the room's share
of the pixel (see ``decomposition_residual``).

``SynthOptions.truth = "front_end"`` (for benchmarking poses and masks on many scenes) writes only the photos,
``capture.yaml``, ``cameras.json``, ``scene.json``, ``manifest.json``, ``object.ply``, ``object_albedo.png``,
``masks/`` and ``coverage/``: no linear, lobe, albedo, normal or depth images and no environment views, and
only the full render and the coverage pass are rendered (``scene.json: truth`` says which).
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..artifacts import atomic_dir, atomic_path, write_json, write_manifest
from ..cameras import CameraSet, Frame, save_cameras
from ..dng import Exposure, SensorModel, decoded_from_linear, decoded_scale, write_dng
from ..errors import InputError
from ..imageio import to_srgb8, write_exr, write_png
from ..layout import CAMERAS_JSON, CAPTURE_YAML, GROUND_TRUTH, MANIFEST
from ..log import progress
from ..provenance import capture_record
from . import build, geometry
from .rig import PinholeView, capture_views, environment_views
from .scenes import ObjectSpec, ResolvedScene, SceneSpec, get_scene, resolve

log = logging.getLogger("orca.synth")

PhotoFormat = Literal["dng", "jpg", "both"]
Truth = Literal["full", "front_end"]
# What a front_end capture's ground_truth/ holds besides cameras.json, scene.json, object.ply (LAYOUT keys).
FRONT_END_TRUTH = ("masks", "coverage")

# Shutter speeds a camera offers (1/3-stop series), in seconds.
SHUTTER_SPEEDS_S: tuple[float, ...] = tuple(1.0 / d for d in (
    8, 10, 13, 15, 20, 25, 30, 40, 50, 60, 80, 100, 125, 160, 200, 250, 320, 400, 500, 640, 800, 1000))


@dataclass(frozen=True)
class ExposureSpec:
    """Simulated auto-exposure. The first photo is the reference: base settings exactly."""

    shutter_s: float = 1 / 60
    iso: float = 200.0
    f_number: float = 2.8  # fixed, like a phone's aperture
    # Fraction of a view's brightness change (vs the reference) that auto-exposure compensates, and its range.
    compensation: float = 0.6
    max_stops: float = 1.0
    iso_choices: tuple[float, ...] = (160.0, 200.0, 250.0)
    # `gain` (brightness not recorded in EXIF) is chosen once, on the reference view, so that this percentile
    # of the green channel over pixels that are neither a light nor the object lands at `white_level` of the
    # sensor's full scale: only the lights themselves and their mirror images clip.
    white_percentile: float = 99.5
    white_level: float = 0.8
    sensor_width_mm: float = 6.4  # for EXIF focal lengths
    jpeg_quality: int = 95
    start_time: str = "2024-06-01T10:00:00"  # EXIF DateTimeOriginal of the first photo
    seconds_between_photos: float = 3.0


@dataclass(frozen=True)
class SynthOptions:
    """What to render. Defaults: the demo capture's settings."""

    views: int = 32
    width: int = 320
    height: int = 240
    spp: int = 64  # samples per pixel of the photos and of the diffuse/specular ground truth
    format: PhotoFormat = "dng"
    seed: int = 0
    env_size: int = 128  # environment views are env_size x env_size
    env_spp: int | None = None  # default: spp
    coverage_spp: int = 36  # samples per pixel of the mask (coverage) pass (a 6 x 6 stratified grid)
    sampler: Literal["multijitter", "independent", "stratified", "ldsampler"] = "multijitter"
    exposure: ExposureSpec = field(default_factory=ExposureSpec)
    # The lens and optical low-pass filter of a real camera blur the image on the sensor a little (a Gaussian
    # PSF, sigma in pixels). Without it a Bayer mosaic of a perfectly sharp render loses information no
    # demosaicing recovers at sharp texture edges (27 dB on the demo against 34 dB at 0.7 px).
    optics_blur_px: float = 0.7
    # full: every ground truth above; front_end: photos, cameras, scene.json, mesh, masks and coverage only
    truth: Truth = "full"

    def validate(self) -> None:
        problems = []
        if self.views < 1:
            problems.append(f"views must be >= 1, got {self.views}")
        if self.width < 8 or self.height < 8:
            problems.append(f"image size must be at least 8x8, got {self.width}x{self.height}")
        if self.spp < 1 or self.coverage_spp < 1 or (self.env_spp is not None and self.env_spp < 1):
            problems.append("samples per pixel must be >= 1")
        if not 0 <= self.optics_blur_px <= 5:
            problems.append(f"optics_blur_px must be in [0, 5], got {self.optics_blur_px}")
        if self.env_size < 8:
            problems.append(f"env_size must be >= 8, got {self.env_size}")
        if self.format not in ("dng", "jpg", "both"):
            problems.append(f"format must be dng, jpg or both, got {self.format!r}")
        if self.truth not in ("full", "front_end"):
            problems.append(f"truth must be full or front_end, got {self.truth!r}")
        if problems:
            raise InputError("invalid synth options: " + "; ".join(problems))


GT = GROUND_TRUTH
LAYOUT = {
    "cameras": f"{GT}/cameras.json",
    "scene": f"{GT}/scene.json",
    "mesh": f"{GT}/object.ply",
    "linear": f"{GT}/linear",
    "diffuse": f"{GT}/diffuse",
    "specular": f"{GT}/specular",
    "albedo": f"{GT}/albedo",
    "normals": f"{GT}/normals",
    "depth": f"{GT}/depth",
    "masks": f"{GT}/masks",
    "coverage": f"{GT}/coverage",
    "environment": f"{GT}/environment",
}


def photo_stem(i: int) -> str:
    return f"IMG_{i + 1:04d}"


# ------------------------------------------------------------------------------------------- the passes


@dataclass
class ViewTruth:
    """Per-view ground truth (arrays ``(H, W, ...)``, float32)."""

    linear: np.ndarray  # (H, W, 3) full render
    coverage: np.ndarray  # (H, W) object pixel coverage in [0, 1]
    object_hit: np.ndarray  # (H, W) bool: pixel-centre ray's first hit is the object
    depth: np.ndarray  # (H, W) z-depth of the object, inf elsewhere
    normals: np.ndarray  # (H, W, 3)
    albedo: np.ndarray  # (H, W, 3)
    diffuse: np.ndarray | None  # (H, W, 3); None when the lobes are not rendered (front_end)
    specular: np.ndarray | None  # (H, W, 3)
    light_hit: np.ndarray  # (H, W) bool: pixel-centre ray hits a light
    interior: np.ndarray  # (H, W) bool: object pixels whose whole optics-blur footprint is object (identity holds)


class _Renderer:
    """The loaded Mitsuba scenes of one capture; each is loaded once and rendered from every camera."""

    def __init__(self, scene: ResolvedScene, assets: build.SceneAssets, options: SynthOptions):
        self.scene, self.options = scene, options
        self.full, self.index = build.load_scene(scene, assets, "full")
        self.coverage, _ = build.load_scene(scene, assets, "coverage")
        if options.truth == "full":
            self.diffuse, _ = build.load_scene(scene, assets, "diffuse")
            self.specular, _ = build.load_scene(scene, assets, "specular")
            self.env, self.env_index = build.load_scene(scene, assets, "environment")
        self.variants = 5 if options.truth == "full" else 2
        self.object_index = self.index[build.OBJECT_ID]
        self.geometry_aov = build.aov_integrator("pp:position,nn:sh_normal,si:shape_index,al:albedo")
        self.coverage_aov = build.aov_integrator("al:albedo")
        self.env_aov = build.aov_integrator("pp:position,si:shape_index")

    def _sensor(self, v: PinholeView, spp: int, sampler: str, crop: build.Crop | None = None):
        return build.sensor(v.c2w, v.width, v.height, v.fx, spp=build.effective_spp(sampler, spp), sampler=sampler,
                            crop=crop)

    def view(self, v: PinholeView, seed: int) -> ViewTruth:
        o = self.options
        g = build.render(self.full, self._sensor(v, 1, "centre"), integrator=self.geometry_aov)
        if g.shape[-1] != 10:
            raise RuntimeError(f"unexpected AOV layout: {g.shape[-1]} channels")
        position, normals, index, albedo = g[..., 0:3], g[..., 3:6], np.rint(g[..., 6]), g[..., 7:10]
        object_hit = index == self.object_index
        self._check_object_index(position, object_hit)
        depth = np.where(object_hit, _z_depth(position, v.c2w), np.inf).astype(np.float32)
        normals = np.where(object_hit[..., None], normals, 0.0).astype(np.float32)
        albedo = np.where(object_hit[..., None], albedo, 0.0).astype(np.float32)
        light_hit = on_lights(position, self.scene.lights)

        cov = build.render(self.coverage, self._sensor(v, o.coverage_spp, "stratified"),
                           integrator=self.coverage_aov, seed=seed)[..., 0]
        cov = np.clip(cov, 0.0, 1.0)

        linear = _repair_non_finite(build.render(self.full, self._sensor(v, o.spp, o.sampler), seed=seed),
                                    f"{v.name} (full render)")
        if o.truth == "front_end":
            return ViewTruth(optics_blur(linear, o.optics_blur_px), cov.astype(np.float32), object_hit, depth,
                             normals, albedo, None, None, light_hit, interior_mask(cov, o.optics_blur_px))
        diffuse = np.zeros_like(linear)
        specular = np.zeros_like(linear)
        crop = _crop_of(cov > 0)
        if crop is not None:
            # Only the object's pixels matter: render the two lobes in its bounding box (a fraction of the cost).
            # Same sampler seed as the full render, so each pixel starts from the same random numbers.
            sl = (slice(crop.y0, crop.y0 + crop.height), slice(crop.x0, crop.x0 + crop.width))
            diffuse[sl] = _repair_non_finite(build.render(
                self.diffuse, self._sensor(v, o.spp, o.sampler, crop), seed=seed), f"{v.name} (diffuse)")
            specular[sl] = _repair_non_finite(build.render(
                self.specular, self._sensor(v, o.spp, o.sampler, crop), seed=seed), f"{v.name} (specular)")
            outside = (cov <= 0)[..., None]
            diffuse = np.where(outside, 0.0, diffuse).astype(np.float32)
            specular = np.where(outside, 0.0, specular).astype(np.float32)
        # Radiance images are sensor-plane images (what the photos record); geometry stays per pixel centre.
        linear, diffuse, specular = (optics_blur(x, o.optics_blur_px) for x in (linear, diffuse, specular))
        return ViewTruth(linear, cov.astype(np.float32), object_hit, depth, normals, albedo, diffuse, specular,
                         light_hit, interior_mask(cov, o.optics_blur_px))

    def environment(self, v: PinholeView, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Linear RGB ``(S, S, 3)`` and z-depth ``(S, S)`` of the room without the object."""
        spp = self.options.env_spp or self.options.spp
        rgb = _repair_non_finite(build.render(self.env, self._sensor(v, spp, self.options.sampler), seed=seed),
                                 f"{v.name} (environment)")
        g = build.render(self.env, self._sensor(v, 1, "centre"), integrator=self.env_aov)
        hit = np.rint(g[..., 3]) > 0
        depth = np.where(hit, _z_depth(g[..., 0:3], v.c2w), np.inf).astype(np.float32)
        return rgb, depth

    def _check_object_index(self, position: np.ndarray, object_hit: np.ndarray) -> None:
        """Guard the shape-index bookkeeping: object hits lie in its bounding sphere, nothing else does."""
        r = np.linalg.norm(position, axis=-1)
        radius = self.scene.object_radius
        inside = r < radius * (1 - 1e-3)  # only the object and the floor under it can be hit in there
        if np.any(r[object_hit] > radius * (1 + 1e-3)) or (inside.any() and not object_hit.any()):
            raise RuntimeError("shape index of the object does not match the geometry (Mitsuba shape order?)")


# Lights sit 1 cm in front of their wall or ceiling; hits closer to a light's plane than this are on the light.
_LIGHT_PLANE_TOLERANCE = 1e-3


def on_lights(position: np.ndarray, lights) -> np.ndarray:
    """``(H, W)`` bool: pixel-centre hits ``(H, W, 3)`` lying on one of the rectangular lights.

    Found from geometry rather than from the shape-index AOV: it needs no bookkeeping of each light's index.
    """
    hit = np.zeros(position.shape[:2], dtype=bool)
    for light in lights:
        centre, normal = np.asarray(light.centre, float), np.asarray(light.normal, float)
        offset = position - centre
        in_plane = np.abs(offset @ normal) < _LIGHT_PLANE_TOLERANCE
        # the rectangle's bounding circle in its plane: nothing else lies in that plane near the light
        within = np.linalg.norm(offset, axis=-1) <= 0.5 * float(np.hypot(*light.size)) + _LIGHT_PLANE_TOLERANCE
        hit |= in_plane & within
    return hit


def _repair_non_finite(img: np.ndarray, what: str) -> np.ndarray:
    """Replace pixels holding NaN/inf (a Monte Carlo sample gone wrong inside Mitsuba; rare) by the mean of
    their finite 3x3 neighbours, with a warning: one bad sample must not cost a whole capture (the DNG
    writer rejects non-finite input)."""
    bad = ~np.isfinite(img).all(axis=-1)
    if not bad.any():
        return img
    log.warning("%s: %d pixel(s) with NaN/inf from the renderer, replaced by their neighbours' mean",
                what, int(bad.sum()))
    out = img.copy()
    h, w = bad.shape
    for i, j in np.argwhere(bad):
        win = img[max(0, i - 1):i + 2, max(0, j - 1):j + 2].reshape(-1, img.shape[-1])
        ok = np.isfinite(win).all(axis=-1)
        out[i, j] = win[ok].mean(axis=0) if ok.any() else 0.0
    return out


def _z_depth(position: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """z-depth along the optical axis: ``(p - C) . z_cam``. (Mitsuba's ``depth`` AOV is neither: it is the
    distance along the ray measured from the near-clip plane, so positions are used instead.)"""
    return ((position - c2w[:3, 3]) @ c2w[:3, 2]).astype(np.float32)


def _crop_of(mask: np.ndarray, margin: int = 1) -> build.Crop | None:
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return None
    h, w = mask.shape
    y0, y1 = max(0, ys.min() - margin), min(h, ys.max() + 1 + margin)
    x0, x1 = max(0, xs.min() - margin), min(w, xs.max() + 1 + margin)
    return build.Crop(int(x0), int(y0), int(x1 - x0), int(y1 - y0))


# Pixels whose every coverage sample hit the object. On silhouette pixels (0 < coverage < 1) each lobe render
# also holds the room's share of the pixel, so diffuse + specular counts it twice; the identity is checked on
# interior pixels only.
INTERIOR_COVERAGE = 0.999


def blur_radius(sigma_px: float) -> int:
    """Pixels beyond which the optics blur's Gaussian (cut at 3 sigma) has no weight."""
    return int(np.ceil(3 * sigma_px))


def optics_blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """The camera's lens + optical low-pass filter: a Gaussian PSF of ``sigma_px`` pixels, ``(H, W, C)``."""
    if sigma_px <= 0:
        return image
    import cv2

    k = 2 * blur_radius(sigma_px) + 1
    return cv2.GaussianBlur(image, (k, k), sigma_px, borderType=cv2.BORDER_REFLECT).astype(np.float32)


def dilate_mask(mask: np.ndarray, radius: int) -> np.ndarray:
    """``(H, W)`` bool mask grown by ``radius`` pixels (a square neighbourhood)."""
    if radius <= 0:
        return mask
    import cv2

    return cv2.dilate(mask.astype(np.uint8), np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)) > 0


def interior_mask(coverage: np.ndarray, sigma_px: float) -> np.ndarray:
    """Object pixels (coverage 1) whose whole blur footprint is also object pixels: where the blurred
    diffuse + specular must equal the blurred full render."""
    import cv2

    interior = (coverage >= INTERIOR_COVERAGE).astype(np.uint8)
    r = blur_radius(sigma_px)
    if r > 0:
        interior = cv2.erode(interior, np.ones((2 * r + 1, 2 * r + 1), np.uint8))
    return interior > 0


def decomposition_residual(truth: ViewTruth) -> dict[str, float]:
    """How well diffuse + specular reproduce the full render on interior object pixels (coverage = 1, and
    the optics blur's footprint entirely on the object).

    ``relative_mean``: |mean(full - diffuse - specular)| / mean(full), the bias a missing lobe or missing
    interreflections would show; ``relative_rmse``: per-pixel RMS residual / mean(full), which Monte Carlo
    noise dominates (the three renders share sampler seeds, but their paths diverge at the first bounce).
    """
    m = truth.interior
    if truth.diffuse is None or truth.specular is None:
        raise ValueError("decomposition_residual needs the diffuse and specular renders (truth='full')")
    if not m.any():
        return {"pixels": 0, "relative_mean": 0.0, "relative_rmse": 0.0}
    full, parts = truth.linear[m].astype(np.float64), (truth.diffuse[m] + truth.specular[m]).astype(np.float64)
    scale = full.mean()
    return {"pixels": int(m.sum()), "relative_mean": float(abs((full - parts).mean()) / scale),
            "relative_rmse": float(np.sqrt(((full - parts) ** 2).mean()) / scale)}


# ---------------------------------------------------------------------------------------------- exposure


def _snap_shutter(seconds: float) -> float:
    speeds = np.asarray(SHUTTER_SPEEDS_S)
    return float(speeds[np.argmin(np.abs(np.log(speeds) - np.log(seconds)))])


def auto_exposure(spec: ExposureSpec, metering: float, reference_metering: float, rng: np.random.Generator):
    """EXIF settings for a view: the brightness change vs the reference, partly compensated, within
    ``max_stops``, realized as an ISO from ``iso_choices`` and the nearest standard shutter speed."""

    stops = -spec.compensation * np.log2(max(metering, 1e-12) / max(reference_metering, 1e-12))
    stops = float(np.clip(stops, -spec.max_stops, spec.max_stops))
    base = Exposure(spec.shutter_s, spec.iso, spec.f_number)
    iso = float(rng.choice(spec.iso_choices))
    shutter = _snap_shutter(base.value * 2**stops * spec.f_number**2 / (iso / 100.0))
    return Exposure(shutter, iso, spec.f_number)


def choose_gain(spec: ExposureSpec, linear: np.ndarray, exclude: np.ndarray) -> float:
    """``gain`` so the reference view's bright (non-light, non-object) pixels sit at ``white_level``."""

    green = linear[..., 1][~exclude] if (~exclude).any() else linear[..., 1].ravel()
    bright = float(np.percentile(green, spec.white_percentile))
    reference = Exposure(spec.shutter_s, spec.iso, spec.f_number)
    return spec.white_level * SensorModel().full_scale_exposure / (max(bright, 1e-12) * reference.value)


def _write_jpeg(path: Path, linear: np.ndarray, info: dict[str, Any], exposure, spec: ExposureSpec,
                rng: np.random.Generator, when: dt.datetime, focal_mm: float, focal_35: float) -> None:
    """An sRGB JPEG as the phone's ISP would make it from the same exposure (with sensor-like noise)."""
    from PIL import Image
    from PIL.TiffImagePlugin import IFDRational


    sensor = SensorModel()
    m = np.asarray(info["decoded_from_linear"], dtype=np.float64)
    x = np.einsum("ij,hwj->hwi", m, linear.astype(np.float64))
    electrons_full = sensor.full_well_e * 100.0 / exposure.iso
    sigma = np.sqrt(np.clip(x, 0, None) / electrons_full + (sensor.read_noise_e / electrons_full) ** 2)
    x = x + rng.normal(size=x.shape) * sigma
    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = sensor.make, sensor.model
    exif[0x0132] = when.strftime("%Y:%m:%d %H:%M:%S")
    sub = exif.get_ifd(0x8769)
    sub[0x829A] = IFDRational(1, round(1 / exposure.shutter_s)) if exposure.shutter_s < 1 else exposure.shutter_s
    sub[0x829D] = IFDRational(exposure.f_number)
    sub[0x8827] = int(round(exposure.iso))
    sub[0x9003] = when.strftime("%Y:%m:%d %H:%M:%S")
    sub[0x920A] = IFDRational(round(focal_mm * 1000), 1000)
    sub[0xA405] = int(round(focal_35))

    with atomic_path(path) as tmp:
        Image.fromarray(to_srgb8(x.astype(np.float32))).save(tmp, format="JPEG", quality=spec.jpeg_quality,
                                                             exif=exif)


# -------------------------------------------------------------------------------------------- main entry


def render_capture(scene: str | SceneSpec, out_dir: str | Path, options: SynthOptions = SynthOptions(), *,
                   overwrite: bool = False) -> Path:
    """Render the capture folder ``out_dir`` (layout in this module's docstring) and return its path.

    Everything is written into a temporary sibling folder that replaces ``out_dir`` only when all of it
    succeeded: an interrupted or failed render leaves nothing (and an existing folder untouched).
    """

    options.validate()
    spec = get_scene(scene)
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise InputError("output folder exists", out_dir, "choose another folder or pass --overwrite")
    started = time.time()
    mi = build.mitsuba()
    resolved = resolve(spec)
    exp = options.exposure
    names = [photo_stem(i) for i in range(options.views)]
    views = capture_views(spec.rig, options.views, options.width, options.height,
                          np.random.default_rng([options.seed, 1]), names)
    full_truth = options.truth == "full"
    env_views = environment_views(resolved, options.env_size) if full_truth else []
    exposure_rng = np.random.default_rng([options.seed, 2])
    reference = Exposure(exp.shutter_s, exp.iso, exp.f_number)
    start_time = dt.datetime.fromisoformat(exp.start_time)
    fx = views[0].fx
    focal_mm, focal_35 = fx / options.width * exp.sensor_width_mm, fx / options.width * 36.0

    with atomic_dir(out_dir, "synth", manifest=f"{GT}/{MANIFEST}") as tmp:
        gt = tmp / GT
        per_view = _PER_VIEW_TRUTH if full_truth else FRONT_END_TRUTH
        for key in per_view:
            (tmp / LAYOUT[key]).mkdir(parents=True)
        for sub in ("rgb", "depth") if full_truth else ():
            (tmp / LAYOUT["environment"] / sub).mkdir(parents=True)
        mesh_path = geometry.write_ply(tmp / LAYOUT["mesh"], resolved.mesh)
        t0 = time.time()
        assets = build.make_assets(resolved, None if spec.object.kind == "sphere" else mesh_path)
        renderer = _Renderer(resolved, assets, options)
        log.info("scene %r ready in %.1f s (textures and %d Mitsuba scene variants)", spec.name,
                 time.time() - t0, renderer.variants)
        if spec.object.albedo.texture:
            write_png(gt / "object_albedo.png", to_srgb8(assets.textures[build.OBJECT_ID]))

        gain = None
        reference_metering = None
        photos: list[dict[str, Any]] = []
        residuals: list[dict[str, float]] = []
        view_seconds: list[float] = []
        photo_ext = "jpg" if options.format == "jpg" else "dng"
        with progress() as bar:
            task = bar.add_task(f"synth {spec.name}", total=len(views) + len(env_views))
            for i, v in enumerate(views):
                tv = time.time()
                seed = options.seed * 100_003 + i
                truth = renderer.view(v, seed)
                metering = float(np.median(truth.linear[..., 1]))
                if gain is None:
                    # lights' pixels and, past the optics blur, their halos are allowed to clip
                    exclude = dilate_mask(truth.light_hit, blur_radius(options.optics_blur_px)) | (truth.coverage > 0)
                    gain = choose_gain(exp, truth.linear, exclude)
                    reference_metering = metering
                    exposure = reference
                else:
                    exposure = auto_exposure(exp, metering, reference_metering, exposure_rng)
                when = start_time + dt.timedelta(seconds=i * exp.seconds_between_photos)
                rng = np.random.default_rng([options.seed, 3, i])
                record: dict[str, Any] = {"name": v.name, "image": f"{v.name}.{photo_ext}"}
                info = None
                if options.format in ("dng", "both"):
                    info = write_dng(tmp / f"{v.name}.dng", truth.linear, exposure=exposure, gain=gain, rng=rng,
                                     focal_length_mm=focal_mm, focal_length_35mm=focal_35, datetime=when)
                    info = {k: info[k] for k in _PHOTO_KEYS if k in info}
                if options.format in ("jpg", "both"):
                    if info is None:
                        info = _simulated_info(exposure, gain)
                    _write_jpeg(tmp / f"{v.name}.jpg", truth.linear, info, exposure, exp, rng, when, focal_mm,
                                focal_35)
                record.update(info or {})
                photos.append(record)
                _write_view_truth(tmp, v.name, truth, per_view)
                if full_truth:
                    residuals.append(decomposition_residual(truth))
                view_seconds.append(time.time() - tv)
                log.debug("%s: %.1f s, decomposition residual %s", v.name, view_seconds[-1],
                          residuals[-1] if residuals else None)
                bar.advance(task)

            env_seconds = []
            for k, v in enumerate(env_views):
                te = time.time()
                rgb, depth = renderer.environment(v, options.seed * 100_003 + 50_000 + k)
                write_exr(tmp / LAYOUT["environment"] / "rgb" / f"{v.name}.exr", rgb, half=True)
                write_exr(tmp / LAYOUT["environment"] / "depth" / f"{v.name}.exr", depth)
                env_seconds.append(time.time() - te)
                bar.advance(task)

        save_cameras(tmp / LAYOUT["cameras"], CameraSet(
            frame=Frame(), cameras=[v.camera(f"../{p['image']}") for v, p in zip(views, photos)]))
        if full_truth:
            save_cameras(tmp / LAYOUT["environment"] / CAMERAS_JSON, CameraSet(
                frame=Frame(), cameras=[v.camera(f"rgb/{v.name}.exr") for v in env_views]))
        factor = decoded_scale(gain, reference, SensorModel())
        # What a person who knows the material would write: the coat's index of refraction (Fresnel), or that
        # the object is a metal.
        material = ("  sdf:\n    reflectance: tinted  # a bare metal\n" if spec.object.conductor is not None else
                    f"  render:\n    ior: {spec.object.int_ior}  # the object's coat (plastic, glaze)\n")
        (tmp / CAPTURE_YAML).write_text(
            f"# Settings for this capture (see pipeline/config.py); written by orca synth.\ntrain:\n{material}",
            encoding="utf-8")
        write_json(tmp / LAYOUT["scene"], _scene_json(
            resolved, options, photos, residuals, factor, gain, env_views, mi.__version__))
        timing = {"views": len(views), "seconds_per_view": float(np.mean(view_seconds)),
                  "environment_views": len(env_views),
                  "seconds_per_environment_view": float(np.mean(env_seconds)) if env_seconds else 0.0,
                  "total_seconds": round(time.time() - started, 2)}
        # the capture record of the photos as they will lie in out_dir: evaluate checks a model against its own
        capture = {**capture_record(tmp, [tmp / p["image"] for p in photos]), "folder": str(out_dir.resolve())}
        write_manifest(gt, stage="synth", config={"scene": spec.name, "options": asdict(options)},
                       started=started, extra={"timing": timing}, capture=capture)
        log.info("rendered %d views (%.1f s each) and %d environment views (%.1f s each) in %.0f s -> %s",
                 len(views), timing["seconds_per_view"], len(env_views), timing["seconds_per_environment_view"],
                 time.time() - started, out_dir)
        if residuals:
            worst = max(r["relative_mean"] for r in residuals)
            log.info("diffuse + specular vs full on object pixels: worst relative mean residual %.2e", worst)
    return out_dir


# What scene.json keeps per photo from pipeline.dng.write_dng's report.
_PHOTO_KEYS = ("exposure", "gain", "raw_scale", "decoded_from_linear", "as_shot_neutral", "clipped_fraction")


def _simulated_info(exposure, gain: float) -> dict[str, Any]:
    """What :func:`pipeline.dng.write_dng` reports, for JPEG-only captures (no DNG written)."""

    sensor = SensorModel()
    raw_scale = gain * exposure.value / sensor.full_scale_exposure
    return {"exposure": {"shutter_s": exposure.shutter_s, "iso": exposure.iso, "f_number": exposure.f_number,
                         "value": exposure.value},
            "gain": float(gain), "raw_scale": float(raw_scale),
            "decoded_from_linear": (raw_scale * decoded_from_linear(sensor)).tolist()}


# Per-view ground-truth folders of a full capture (LAYOUT keys), in writing order.
_PER_VIEW_TRUTH = ("linear", "diffuse", "specular", "albedo", "normals", "depth", "masks", "coverage")


def _write_view_truth(root: Path, stem: str, t: ViewTruth, kinds: tuple[str, ...] = _PER_VIEW_TRUTH) -> None:
    """Write the per-view ground truth named in ``kinds`` (LAYOUT keys)."""
    half_exr = {"linear": t.linear, "diffuse": t.diffuse, "specular": t.specular, "albedo": t.albedo,
                "normals": t.normals}
    for kind in kinds:
        folder = root / LAYOUT[kind]
        if kind in half_exr:
            write_exr(folder / f"{stem}.exr", half_exr[kind], half=True)
        elif kind == "depth":
            write_exr(folder / f"{stem}.exr", t.depth)
        elif kind == "masks":
            write_png(folder / f"{stem}.png", np.where(t.coverage >= 0.5, 255, 0).astype(np.uint8))
        elif kind == "coverage":
            write_png(folder / f"{stem}.png", np.round(t.coverage * 255).astype(np.uint8))


def _material_json(obj: ObjectSpec) -> dict[str, Any]:
    rough = obj.roughness is not None
    if obj.conductor is not None:
        return {"type": "roughconductor" if rough else "conductor", "metal": obj.conductor,
                "roughness": obj.roughness}
    return {"type": "roughplastic" if rough else "plastic", "int_ior": obj.int_ior, "ext_ior": 1.0,
            "roughness": obj.roughness, "nonlinear": False}


def _scene_json(scene: ResolvedScene, options: SynthOptions, photos: list[dict], residuals: list[dict],
                factor: float, gain: float, env_views: list[PinholeView], mitsuba_version: str) -> dict[str, Any]:
    spec, obj = scene.spec, scene.spec.object
    rel = [r["relative_mean"] for r in residuals]
    rmse = [r["relative_rmse"] for r in residuals]
    room = spec.room
    return {
        "scene": spec.name,
        "truth": options.truth,
        "world_frame": "z up; object bounding sphere centred at the origin (object.centre, object.radius); "
                       "cameras OpenCV (x right, y down, z forward), camera-to-world",
        "object": {
            "kind": obj.kind, "centre": [0.0, 0.0, 0.0], "radius": obj.radius, "mesh": "object.ply",
            "material": _material_json(obj),
            "albedo": None if obj.conductor else "object_albedo.png" if obj.albedo.texture else list(obj.albedo.rgb),
            "albedo_uv": "texel (row, column) = (v * height, u * width) of object_albedo.png (v = 0: top row), "
                         "(u, v) from object.ply; for the sphere also Mitsuba's analytic sphere UV: u = longitude "
                         "/ 2 pi (atan2(y, x)), v = polar angle from +z / pi",
        },
        "floor_z": scene.floor_z,
        "lift": spec.lift,
        "room": {"min": scene.room_min.tolist(), "max": scene.room_max.tolist(),
                 "finish": {s: asdict(room.finish(s)) for s in ("walls", "floor", "ceiling")}},
        "props": [p.to_json() for p in scene.props],
        "lights": [{"name": lt.name, "type": "rectangle area light, one-sided", "centre": list(lt.centre),
                    "size": list(lt.size), "normal": list(lt.normal), "radiance": list(lt.radiance)}
                   for lt in scene.lights],
        "radiance_to_decoded": {
            "factor": factor,
            "reference_image": photos[0]["image"],
            "meaning": "decode stage output (white balance from the reference image, exposure normalized to it) "
                       "= factor x linear render (ground_truth/linear, diffuse, specular, environment/rgb), up to "
                       "noise, demosaicing and clipping",
            "gain": gain,
        },
        "photos": photos,
        "render": {
            "renderer": f"mitsuba {mitsuba_version} scalar_rgb", "integrator": "path",
            "max_depth": spec.max_depth, "spp": build.effective_spp(options.sampler, options.spp),
            "sampler": options.sampler,
            "coverage_spp": build.effective_spp("stratified", options.coverage_spp),
            "env_spp": build.effective_spp(options.sampler, options.env_spp or options.spp),
            "seed": options.seed, "width": options.width, "height": options.height,
        },
        "ground_truth": {
            "depth": "z-depth along the optical axis ((p - C) . z_cam), world units, float32; +inf where the ray "
                     "through the pixel centre does not hit the object first (environment: +inf for no hit)",
            "normals": "world-space unit shading normals at the pixel-centre hit; 0 where it is not the object",
            "masks": "0/255; 255 where the occlusion-aware object coverage (fraction of the pixel's "
                     f"{build.effective_spp('stratified', options.coverage_spp)} samples whose first hit is the "
                     "object) is >= 0.5",
            "diffuse_specular": "renders with the specular / diffuse lobe off (plastic, nonlinear=false); values on "
                                "pixels with coverage > 0, else 0, then blurred by the optics like linear/. "
                                "diffuse + specular = linear on interior object pixels (coverage 255 and 3 sigma "
                                "of blur inside the silhouette) up to Monte Carlo noise and paths meeting the "
                                "object more than once; on silhouette pixels both also hold the room's share",
            "optics_blur_px": options.optics_blur_px,
            "albedo": "diffuse reflectance (linear) at the pixel-centre hit on the object, else 0",
            "coverage": "8-bit occlusion-aware object coverage (255 = all samples hit the object); the "
                        "diffuse + specular = linear identity is exact (up to noise) where it is 255",
        },
        "decomposition_residual": None if not residuals else {
            "relative_mean": {"max": max(rel), "mean": float(np.mean(rel))},
            "relative_rmse": {"max": max(rmse), "mean": float(np.mean(rmse))},
            "definition": "over interior object pixels (coverage 255, 3 sigma of optics blur inside the "
                          "silhouette): |mean(linear - diffuse - specular)| / "
                          "mean(linear), and the per-pixel RMS of the same difference / mean(linear)",
        },
        "environment": None if not env_views else {
            "cameras": "environment/cameras.json",
            "views": [v.name for v in env_views],
            "object_removed": True,
            "note": "rendered without the object (so also without its shadow and interreflections); cube_* from "
                    "the object centre, parallax_* translated inside the bounding sphere, looking at "
                    + (f"prop {spec.env.parallax_prop!r}" if spec.env.parallax_prop else "+x"),
        },
    }
