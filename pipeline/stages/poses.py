"""Stage ``poses``: decoded photos -> cameras (intrinsics and poses) in the object-centred normalized frame.

Inputs: the decode stage's folder (``srgb/*.png`` for SIFT, ``decode.json`` for names, size and EXIF) and
the capture folder, where these are optional:

- ``calibration/calibration.json`` (``orca calibrate``): OPENCV intrinsics, scaled to the decoded size and
  held fixed. Without it each lens/zoom (EXIF make, model, focal length) shares one SIMPLE_RADIAL camera
  whose focal length starts from the EXIF 35 mm-equivalent focal length when the photos record it.
- ``cameras.json`` (our schema) or ``transforms.json`` (nerfstudio/instant-ngp, OpenGL axes): known cameras
  (a turntable, a phone's AR session). Then SfM is skipped (``poses.known_poses=ignore`` runs it anyway;
  refining known cameras with SfM is not built). Cameras are matched to photos by file stem.
- ``masks/<name>.png`` (or ``--masks``; white = object): features on the glossy object are ignored (its
  reflections move with the viewpoint and make false matches), and the object's sphere is the masks'
  visual hull.

SfM (:mod:`pipeline.sfm`): SIFT, exhaustive matching up to ``exhaustive_max_images`` photos, else each photo
with its neighbours in name order (wrapping around: no vocabulary tree needed), incremental mapping; the
model with the most photos is used and a split is reported. Bad input stops the stage with an
:class:`~pipeline.errors.InputError` that names the folder and the fix: identical photos, no features,
no initial pair, too few photos registered (``poses.min_registered``, ``poses.min_registered_fraction``).

Normalization (:mod:`pipeline.object_frame`): the object's centre is where the optical axes converge, its
radius from the framing, the support plane or the masks; the normalized frame has the object's bounding
sphere as the unit sphere, z up. ``cameras.json``'s ``frame.to_colmap`` is the 4x4 similarity from the
normalized frame to COLMAP's (for known cameras: to the frame of the given file).

Undistortion: cameras.json is pinhole. When the lens model moves some pixel by more than
``poses.undistort_threshold_px``, the decoded images (linear EXR, sRGB PNG, clipped masks) are resampled
with the same maps (bilinear; clipped masks nearest) to the pinhole camera of the same size and focal length,
into ``undistorted/``, a folder in the decode stage's layout: train on it with
``orca train --decode results/<capture>/poses/undistorted``. Pixels the lens did not see are black and
marked clipped, so training ignores them. Below the threshold (a synthetic capture; a good lens at low
resolution) the decoded images are used as they are and cameras.json points at them.

Outputs (``out_dir``, written atomically): ``cameras.json``, ``transforms.json`` (nerfstudio, same frame),
``sparse/`` (COLMAP binary model, COLMAP's frame; SfM only), ``poses_report.json``, ``poses.png`` (cameras
around the object, top and side views), ``undistorted/`` (only if needed), ``manifest.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import shutil
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..alignment import Similarity
from ..artifacts import stage_dir
from ..cameras import Camera, CameraSet, load_cameras, save_cameras
from ..config import PosesConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..mask_file import read_mask
from ..provenance import FORCE_HELP

if TYPE_CHECKING:
    import pycolmap  # noqa: TID251 - annotations only

    from ..object_frame import ObjectSphere
    from ..results import DecodeArtifacts

log = logging.getLogger("orca.poses")

CAMERAS_JSON = "cameras.json"
TRANSFORMS_JSON = "transforms.json"
REPORT_JSON = "poses_report.json"
FIGURE = "poses.png"
UNDISTORTED = "undistorted"
SCHEMA_VERSION = 1


@dataclass(frozen=True)
class PosesResult:
    out_dir: Path
    cameras: CameraSet  # normalized frame
    source: str  # "sfm" or the known-cameras file
    registered: int
    total: int
    sphere: ObjectSphere  # in the source frame (COLMAP's or the known cameras')
    undistorted: bool
    seconds: float


@dataclass
class Posed:
    """Cameras in the source frame before normalization, one per registered photo (name order)."""

    names: list[str]
    c2w: np.ndarray  # (N, 4, 4) OpenCV camera-to-world
    lens: list[pycolmap.Camera]  # per photo: the full lens model (pinhole part and distortion), decoded size
    points: np.ndarray | None  # (M, 3) sparse points with tracks of 3+ photos, or None
    point_colors: np.ndarray | None  # (M, 3) uint8
    stats: dict[str, Any]


# ------------------------------------------------------------------------------------------------ the stage


def run_poses(
    capture_dir: Path,
    decode_dir: Path,
    out_dir: Path,
    config: PosesConfig,
    *,
    masks_dir: Path | None = None,
    force: bool = False,
) -> PosesResult:
    """Cameras for the decoded photos of ``capture_dir`` into ``out_dir`` (see the module doc)."""
    from ..artifacts import atomic_dir, write_json, write_manifest
    from ..provenance import check_capture_folder, common_capture
    from ..results import load_decode
    from ..sfm import check_not_identical, quiet_colmap, thumbnail

    started = time.time()
    capture_dir, decode_dir, out_dir = Path(capture_dir), Path(decode_dir), Path(out_dir)
    quiet_colmap(log.isEnabledFor(logging.DEBUG))
    decoded = load_decode(decode_dir)
    capture = common_capture([decode_dir, masks_dir], force=force)
    check_capture_folder(capture_dir, capture, force=force)
    names = decoded.names
    width, height = (int(v) for v in decoded.meta["size"])
    photo_dir = capture_dir / decoded.meta.get("photo_folder", ".") if capture_dir.is_dir() else decode_dir
    if len(names) < 2:
        raise InputError(f"only {len(names)} decoded photo(s); poses need at least 2", decode_dir,
                         fix="add photos to the capture and rerun decode")
    known_file = _known_cameras_file(capture_dir, config)
    mask_files = _mask_files(masks_dir, capture_dir, names, (width, height), config)
    calibration = _calibration(capture_dir, width, height)
    inputs: dict[str, Path] = {"decode.json": decode_dir / "decode.json"}
    for key, path in (("known_cameras", known_file), ("calibration", calibration[2] if calibration else None)):
        if path is not None:
            inputs[key] = path
    if (capture_dir / "capture.yaml").is_file():
        inputs["capture.yaml"] = capture_dir / "capture.yaml"

    sources = [p for p in (capture_dir, decode_dir, masks_dir) if p is not None]
    with _collect_warnings() as warnings, atomic_dir(out_dir, "poses", sources) as tmp:
        if known_file is not None:
            log.info("known cameras: %s (SfM skipped)", known_file)
            posed = _posed_from_file(known_file, names, width, height)
            source = str(known_file)
        else:
            duplicates = check_not_identical({n: thumbnail(decoded.srgb(n)) for n in names}, photo_dir)
            if duplicates:
                log.warning("near-identical photos (the camera did not move between them): %s",
                            "; ".join(", ".join(g) for g in duplicates))
            posed = _posed_from_sfm(decoded, names, calibration, mask_files, tmp, config, photo_dir)
            source = "sfm"
            if duplicates:
                posed.stats["duplicates"] = duplicates

        undistort = _undistortion(posed, config)
        if undistort:
            _write_undistorted(decoded, posed, undistort, tmp / UNDISTORTED)
            image_of = {n: f"{UNDISTORTED}/linear/{n}.exr" for n in posed.names}
        else:
            rel = os.path.relpath(decode_dir.resolve(), out_dir.resolve())
            image_of = {n: f"{rel}/{_entry(decoded, n)['linear']}" for n in posed.names}

        from ..object_frame import find_object, normalizing_similarity

        K = np.stack([_pinhole(c) for c in posed.lens])
        sizes = np.array([[c.width, c.height] for c in posed.lens], float)
        hull, mask_scale = _hull_masks(mask_files, posed, undistort, (width, height)) if mask_files else (None, 1.0)
        sphere = find_object(
            posed.c2w, K, sizes, points=posed.points, masks=hull, mask_scale=mask_scale,
            window=config.object_window, margin=config.radius_margin, seed=config.seed,
        )
        to_source = normalizing_similarity(sphere, posed.c2w)
        cameras = _normalized_cameras(posed, K, to_source, image_of)
        save_cameras(tmp / CAMERAS_JSON, cameras)
        from ..transforms import save_transforms

        save_transforms(tmp / TRANSFORMS_JSON, cameras, image_of)
        points_n = to_source.inverse().apply(posed.points) if posed.points is not None else None
        report = _report(posed, names, source, sphere, to_source, undistort, config, cameras)
        report["warnings"] = list(warnings)
        write_json(tmp / REPORT_JSON, report)
        _figure(tmp / FIGURE, cameras, points_n, posed.point_colors, report)
        write_manifest(tmp, stage="poses", inputs=inputs, config=config.model_dump(mode="json"), started=started,
                       extra={"source": source}, capture=capture)
    seconds = time.time() - started
    log.info(
        "poses: %d/%d photos have cameras (%s), object centre %s radius %.3g (%s)%s -> %s (%.1f s)",
        len(posed.names), len(names), "SfM" if source == "sfm" else f"known, {Path(source).name}",
        np.array2string(sphere.center, precision=3), sphere.radius, sphere.method,
        ", undistorted" if undistort else "", out_dir, seconds,
    )
    return PosesResult(out_dir, cameras, source, len(posed.names), len(names), sphere, bool(undistort), seconds)


# ----------------------------------------------------------------------------------------------- inputs


def _known_cameras_file(capture_dir: Path, config: PosesConfig) -> Path | None:
    found = [capture_dir / f for f in (CAMERAS_JSON, TRANSFORMS_JSON) if (capture_dir / f).is_file()]
    if config.known_poses == "ignore" or not found:
        return None
    if len(found) > 1:
        raise InputError(
            "the capture has both cameras.json and transforms.json: which cameras are right is ambiguous",
            capture_dir, fix="remove one of them (or set poses.known_poses=ignore to run SfM instead)",
        )
    return found[0]


def _mask_files(masks_dir: Path | None, capture_dir: Path, names: list[str], size: tuple[int, int],
                config: PosesConfig) -> dict[str, Path] | None:
    """Object mask files per photo, or None when there are none or they are not wanted. Masks are read one
    at a time where needed (200 full-size masks would not fit in memory together).

    Raises:
        InputError: empty masks (one carves the object out of the visual hull the sphere comes from), named.
    """
    if masks_dir is None:
        if not config.use_masks or not (capture_dir / "masks").is_dir():
            return None
        masks_dir = capture_dir / "masks"
    elif not masks_dir.is_dir():
        raise InputError("masks folder not found", masks_dir, fix="pass the folder holding <name>.png masks")
    missing = [n for n in names if not (masks_dir / f"{n}.png").is_file()]
    if missing:
        log.warning("%s: no mask for %d of %d photos (%s); masks are not used", masks_dir, len(missing), len(names),
                    ", ".join(missing[:10]))
        return None
    files = {n: masks_dir / f"{n}.png" for n in names}
    empty = [f.name for f in files.values() if not read_mask(f, size).any()]
    if empty:
        raise InputError(f"{len(empty)} of {len(files)} masks are empty (no object pixel): {', '.join(empty[:10])}"
                         + (" ..." if len(empty) > 10 else ""), masks_dir,
                         fix="draw the object white (non-zero) on them, or set poses.use_masks=false to pose the "
                         "photos without masks")
    log.info("object masks from %s: features on the object are ignored", masks_dir)
    return files


def _hull_masks(files: dict[str, Path], posed: Posed, und: UndistortMaps | None, size: tuple[int, int],
                max_side: int = 640) -> tuple[list[np.ndarray], float]:
    """The posed photos' masks for the visual hull (undistorted like the images), reduced so the longest side is
    at most ``max_side``; returns them and the scale factor for the intrinsics."""
    import cv2

    scale = min(1.0, max_side / max(size))
    small = (max(1, round(size[0] * scale)), max(1, round(size[1] * scale)))
    out = []
    for n in posed.names:
        m = read_mask(files[n], size)
        if und is not None:
            m = undistort_mask(m, und, n)
        m = m.astype(np.uint8)
        if scale < 1.0:
            m = cv2.resize(m * np.uint8(255), small, interpolation=cv2.INTER_AREA) > 127
        out.append(m > 0)
    return out, small[0] / size[0]


def _calibration(capture_dir: Path, width: int, height: int) -> tuple[str, list[float], Path] | None:
    """(COLMAP model, params at the decoded size, file) from ``calibration/calibration.json``, if present."""
    path = capture_dir / "calibration" / "calibration.json"
    if not path.is_file():
        return None
    from calibration import load_calibration

    calib = load_calibration(path).scaled_to(width, height)
    model, params = calib.colmap_params()
    log.info("intrinsics from %s (%s, fx %.1f fy %.1f at %dx%d), held fixed", path, model, params[0], params[1],
             width, height)
    return model, [float(p) for p in params], path


def camera_groups(decoded: DecodeArtifacts, names: list[str], width: int, height: int, config: PosesConfig,
                  calibration: tuple[str, list[float], Path] | None) -> list[Any]:
    """One COLMAP camera per lens and zoom (EXIF make, model, focal length), with its intrinsics prior."""
    from ..sfm import CameraGroup

    if calibration is not None and config.camera_model in ("auto", "OPENCV"):
        model, params, path = calibration
        return [CameraGroup(tuple(names), model, tuple(params), f"calibration ({path})",
                            fixed=not config.refine_calibration)]
    if calibration is not None:
        log.warning("poses.camera_model=%s: the capture's calibration is not used", config.camera_model)
    model = "SIMPLE_RADIAL" if config.camera_model == "auto" else config.camera_model
    exif = {im["name"]: im.get("exif") or {} for im in decoded.meta["images"]}
    keys = {n: tuple(exif[n].get(k) for k in ("make", "model", "focal_length_mm", "focal_length_35mm"))
            for n in names}
    groups = []
    for key in dict.fromkeys(keys[n] for n in names):
        members = tuple(n for n in names if keys[n] == key)
        f35 = key[3]
        if f35:  # 35 mm-equivalent focal length: the long side of the photo spans 36 mm
            f = f35 / 36.0 * max(width, height)
            params, source = _model_params(model, f, width, height), f"EXIF 35 mm focal length {f35:g} mm (prior)"
        else:
            params, source = None, "no EXIF focal length: COLMAP's default guess (1.2 x the longest side)"
        groups.append(CameraGroup(members, model, params, source))
    if len(groups) > 1:
        log.info("%d cameras (lens/zoom settings from EXIF): %s", len(groups),
                 ", ".join(f"{len(g.names)} photos" for g in groups))
    return groups


def _model_params(model: str, f: float, width: int, height: int) -> tuple[float, ...]:
    cx, cy = width / 2.0, height / 2.0
    return {
        "SIMPLE_PINHOLE": (f, cx, cy),
        "PINHOLE": (f, f, cx, cy),
        "SIMPLE_RADIAL": (f, cx, cy, 0.0),
        "RADIAL": (f, cx, cy, 0.0, 0.0),
        "OPENCV": (f, f, cx, cy, 0.0, 0.0, 0.0, 0.0),
    }[model]


# ------------------------------------------------------------------------------------------------ cameras


def _posed_from_sfm(decoded: DecodeArtifacts, names: list[str], calibration: tuple[str, list[float], Path] | None,
                    mask_files: dict[str, Path] | None, tmp: Path, config: PosesConfig, photo_dir: Path) -> Posed:
    from ..log import progress
    from ..sfm import run_sfm, stem_of

    width, height = (int(v) for v in decoded.meta["size"])
    groups = camera_groups(decoded, names, width, height, config, calibration)
    work = tmp / "work"
    work.mkdir()
    feature_masks = (_write_feature_masks(mask_files, (width, height), work / "feature_masks", config)
                     if mask_files else None)
    with progress() as bar:
        sfm = run_sfm(decoded.folder / "srgb", groups, work, config, feature_masks=feature_masks, progress=bar,
                      folder=photo_dir)
    rec = sfm.reconstruction
    sparse = tmp / "sparse"
    sparse.mkdir()
    rec.write(sparse)
    by_name = {stem_of(im.name): im for im in rec.images.values() if im.has_pose}
    posed_names = [n for n in names if n in by_name]
    c2w = np.stack([_c2w(by_name[n]) for n in posed_names])
    lens = [rec.cameras[by_name[n].camera_id] for n in posed_names]
    reliable = [p for p in rec.points3D.values() if p.track.length() >= 3]
    points = np.array([p.xyz for p in reliable]).reshape(-1, 3)
    colors = np.array([p.color for p in reliable], np.uint8).reshape(-1, 3)
    per_image_error = _per_image_reprojection_error(rec)
    stats = {
        "matcher": sfm.matcher,
        "pairs_matched": sfm.num_pairs,
        "pairs_verified": sfm.num_verified_pairs,
        "models": sfm.model_sizes,
        "other_models": sfm.other_models,
        "features": {"min": min(sfm.features.values()), "median": int(np.median(list(sfm.features.values()))),
                     "max": max(sfm.features.values()), "per_image": dict(sorted(sfm.features.items()))},
        "points3D": rec.num_points3D(),
        "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        "mean_track_length": float(rec.compute_mean_track_length()),
        "mean_observations_per_image": float(rec.compute_mean_observations_per_reg_image()),
        "reprojection_error_px_per_image": dict(sorted((stem_of(rec.images[i].name), e)
                                                       for i, e in per_image_error.items())),
        "camera_groups": [{"photos": len(g.names), "model": g.model, "intrinsics_from": g.source, "fixed": g.fixed}
                          for g in groups],
        "seconds": {k: round(v, 2) for k, v in sfm.seconds.items()},
    }
    if config.keep_database:
        shutil.move(str(work / "database.db"), str(tmp / "database.db"))
    shutil.rmtree(work)
    return Posed(posed_names, c2w, lens, points, colors, stats)


def _posed_from_file(path: Path, names: list[str], width: int, height: int) -> Posed:
    """Known cameras matched to the decoded photos by name, intrinsics scaled to the decoded size."""
    from ..signals import import_pycolmap
    from ..transforms import load_transforms

    pycolmap = import_pycolmap()

    if path.name == TRANSFORMS_JSON:
        known = load_transforms(path)
        cams, distortion = known.cameras.by_name(), known.distortion
    else:
        cams, distortion = load_cameras(path).by_name(), {}
    matched = [n for n in names if n in cams]
    no_camera = [n for n in names if n not in cams]
    unused = sorted(set(cams) - set(names))
    if len(matched) < 2:
        raise InputError(
            f"only {len(matched)} of the {len(names)} photos have a camera in this file (cameras are matched to "
            f"photos by file name without extension; the file names {', '.join(sorted(cams)[:5])}, the photos "
            f"{', '.join(names[:5])})", path,
            fix="name the cameras after the photos (IMG_0001 for IMG_0001.dng), or remove the file to run SfM",
        )
    if no_camera:
        log.warning("%s: %d photo(s) have no camera and are left out: %s", path, len(no_camera), ", ".join(no_camera))
    if unused:
        log.warning("%s: %d camera(s) match no photo: %s", path, len(unused), ", ".join(unused[:10]))
    lens = []
    for n in matched:
        c = cams[n]
        sx, sy = width / c.width, height / c.height
        if abs(sx / sy - 1) > 0.01:
            raise InputError(f"camera {n} is {c.width}x{c.height} but the decoded photo is {width}x{height} "
                             "(a different aspect ratio: rotated or cropped?)", path)
        fx, fy, cx, cy = c.fx * sx, c.fy * sy, c.cx * sx, c.cy * sy
        d = distortion.get(n, {})
        if not d:
            lens.append(pycolmap.Camera(model="PINHOLE", width=width, height=height, params=[fx, fy, cx, cy]))
        elif set(d) <= {"k1", "k2", "p1", "p2"}:
            lens.append(pycolmap.Camera(model="OPENCV", width=width, height=height, params=[
                fx, fy, cx, cy, d.get("k1", 0.0), d.get("k2", 0.0), d.get("p1", 0.0), d.get("p2", 0.0)]))
        else:
            lens.append(pycolmap.Camera(model="FULL_OPENCV", width=width, height=height, params=[
                fx, fy, cx, cy, d.get("k1", 0.0), d.get("k2", 0.0), d.get("p1", 0.0), d.get("p2", 0.0),
                d.get("k3", 0.0), d.get("k4", 0.0), 0.0, 0.0]))
    c2w = np.stack([cams[n].c2w for n in matched])
    stats = {"known_cameras": str(path), "photos_without_camera": no_camera, "cameras_without_photo": unused}
    return Posed(matched, c2w, lens, None, None, stats)


def _c2w(image: Any) -> np.ndarray:
    """``(4, 4)`` OpenCV camera-to-world of a posed pycolmap image (COLMAP stores world-to-camera)."""
    m = np.eye(4)
    m[:3] = image.cam_from_world().matrix()
    return np.linalg.inv(m)


def _pinhole(camera: Any) -> np.ndarray:
    """``(3, 3)`` pinhole part of a COLMAP camera (what its undistorted image has)."""
    return np.array([[camera.focal_length_x, 0, camera.principal_point_x],
                     [0, camera.focal_length_y, camera.principal_point_y], [0, 0, 1]], np.float64)


def _per_image_reprojection_error(rec: Any) -> dict[int, float]:
    """Mean reprojection error (px) of each registered image's triangulated observations."""
    sums: dict[int, list[float]] = {}
    for p in rec.points3D.values():
        for el in p.track.elements:
            sums.setdefault(el.image_id, []).append(p.error)
    return {i: float(np.mean(v)) for i, v in sums.items()}


def _normalized_cameras(posed: Posed, K: np.ndarray, to_source: Similarity, image_of: dict[str, str]) -> CameraSet:
    from ..cameras import Frame

    c2w_n = to_source.inverse().apply_c2w(posed.c2w)
    cams = [
        Camera(name=n, image=image_of[n], width=int(c.width), height=int(c.height), fx=float(k[0, 0]),
               fy=float(k[1, 1]), cx=float(k[0, 2]), cy=float(k[1, 2]), camera_to_world=m.tolist())
        for n, c, k, m in zip(posed.names, posed.lens, K, c2w_n)
    ]
    return CameraSet(frame=Frame(to_colmap=to_source.matrix.tolist()), cameras=cams)


# --------------------------------------------------------------------------------------------- undistortion


@dataclass(frozen=True)
class UndistortMaps:
    """cv2.remap maps (OpenCV pixel convention) per distinct lens, and which lens each photo uses."""

    maps: list[tuple[np.ndarray, np.ndarray]]  # (map_x, map_y), each (H, W) float32
    lens_of: dict[str, int]
    max_shift_px: float
    lenses: list[dict[str, Any]]  # COLMAP model, size and parameters of each map's lens (recorded in decode.json)


def undistort_map(camera: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """Maps from the pinhole image (same size, same fx, fy, cx, cy) to the distorted one, and the largest
    pixel shift. Project pixel convention in, cv2.remap's (pixel centres at integers) out."""
    w, h = int(camera.width), int(camera.height)
    K = _pinhole(camera)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    src = np.asarray(camera.img_from_cam(rays, check_cheirality=False)).reshape(h, w, 2)
    shift = float(np.nanmax(np.linalg.norm(src - np.stack([u, v], -1), axis=-1)))
    return (src[..., 0] - 0.5).astype(np.float32), (src[..., 1] - 0.5).astype(np.float32), shift


def _lens_maps(cams: list[Any]) -> tuple[list[tuple[np.ndarray, np.ndarray]], float]:
    """:func:`undistort_map` of each lens, and the largest shift among them (px)."""
    maps, worst = [], 0.0
    for c in cams:
        mx, my, shift = undistort_map(c)
        maps.append((mx, my))
        worst = max(worst, shift)
    return maps, worst


def _undistortion(posed: Posed, config: PosesConfig) -> UndistortMaps | None:
    """Maps for every distinct distorted lens, or None when no lens shifts a pixel by more than the threshold."""
    keys: dict[tuple, int] = {}
    lens_of: dict[str, int] = {}
    cams = []
    for n, c in zip(posed.names, posed.lens):
        key = (c.model_name, int(c.width), int(c.height), tuple(np.round(c.params, 12)))
        if key not in keys:
            keys[key] = len(cams)
            cams.append(c)
        lens_of[n] = keys[key]
    maps, worst = _lens_maps(cams)
    posed.stats["distortion_max_shift_px"] = worst
    if worst <= config.undistort_threshold_px:
        return None
    log.info("lens distortion moves pixels by up to %.2f px: resampling the decoded images to pinhole", worst)
    lenses = [{"model": c.model_name, "width": int(c.width), "height": int(c.height),
               "params": [float(p) for p in c.params]} for c in cams]
    return UndistortMaps(maps, lens_of, worst, lenses)


def recorded_undistortion(decoded: DecodeArtifacts) -> UndistortMaps | None:
    """The undistortion the poses stage applied to an ``undistorted/`` folder (rebuilt from the lenses its
    ``decode.json`` records), so that images made for the original photos (a user's masks) follow it; None
    for a folder of photos as decoded."""
    from ..signals import import_pycolmap

    pycolmap = import_pycolmap()
    record = decoded.meta.get("undistorted")
    if record is None:
        return None
    if "lenses" not in record:
        raise InputError("this undistorted folder does not record its lenses (made by an older version)",
                         decoded.folder / "decode.json", fix="rerun `orca poses` (or snakemake --forcerun poses)")
    cams = [pycolmap.Camera(model=lens["model"], width=lens["width"], height=lens["height"], params=lens["params"])
            for lens in record["lenses"]]
    maps, worst = _lens_maps(cams)
    return UndistortMaps(maps, dict(record["lens_of"]), worst, list(record["lenses"]))


def undistort_mask(mask: np.ndarray, und: UndistortMaps, name: str) -> np.ndarray:
    """``(H, W)`` bool mask drawn on photo ``name`` -> the same mask on its undistorted (pinhole) image."""
    return _remap(mask.astype(np.uint8), und.maps[und.lens_of[name]], nearest=True) > 0


def _remap(img: np.ndarray, maps: tuple[np.ndarray, np.ndarray], nearest: bool = False,
           border: float = 0) -> np.ndarray:
    import cv2

    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(img, maps[0], maps[1], interp, borderMode=cv2.BORDER_CONSTANT, borderValue=border)


def _write_undistorted(decoded: DecodeArtifacts, posed: Posed, und: UndistortMaps, folder: Path) -> None:
    """The decoded images resampled to pinhole, in the decode stage's layout (``decode.json`` included)."""
    from .. import imageio
    from ..artifacts import write_json
    from ..log import progress

    for sub in ("linear", "srgb", "clipped"):
        (folder / sub).mkdir(parents=True)
    with progress() as bar:
        task = bar.add_task("undistort", total=len(posed.names))
        for n in posed.names:
            maps = und.maps[und.lens_of[n]]
            entry = _entry(decoded, n)
            imageio.write_exr(folder / entry["linear"], _remap(decoded.linear(n), maps))
            imageio.write_png(folder / entry["srgb"], _remap(decoded.srgb(n), maps))
            clipped = decoded.clipped(n).astype(np.uint8) * 255
            # Pixels the lens did not see count as clipped: training then ignores them.
            imageio.write_png(folder / entry["clipped"], _remap(clipped, maps, nearest=True, border=255))
            bar.advance(task)
    meta = dict(decoded.meta)
    meta["images"] = [im for im in meta["images"] if im["name"] in set(posed.names)]
    meta["undistorted"] = {
        "by": "poses stage", "max_shift_px": und.max_shift_px,
        "note": "decoded images resampled (bilinear) to the pinhole cameras of cameras.json; pixels outside the "
        "original photo are 0 and marked clipped",
        "lenses": und.lenses, "lens_of": {n: und.lens_of[n] for n in posed.names},
    }
    write_json(folder / "decode.json", meta)


def _write_feature_masks(files: dict[str, Path], size: tuple[int, int], folder: Path, config: PosesConfig) -> Path:
    """COLMAP's feature masks (``<image>.png.png``, 0 = no features there): the object, grown a little."""
    import cv2

    from .. import imageio
    from ..sfm import colmap_name

    folder.mkdir(parents=True)
    r = config.mask_dilate_px
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)) if r else None
    for n, path in files.items():
        obj = read_mask(path, size).astype(np.uint8)
        if kernel is not None:
            obj = cv2.dilate(obj, kernel)
        imageio.write_png(folder / f"{colmap_name(n)}.png", np.where(obj > 0, 0, 255).astype(np.uint8))
    return folder


# ------------------------------------------------------------------------------------------------- report


class _Warnings(logging.Handler):
    """Collects the stage's warnings while installed, for the report (a person reads the JSON, not the log)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def _collect_warnings() -> Iterator[list[str]]:
    handler = _Warnings()
    log.addHandler(handler)
    try:
        yield handler.messages
    finally:
        log.removeHandler(handler)


def _entry(decoded: DecodeArtifacts, name: str) -> dict[str, Any]:
    """decode.json's record of one photo (its linear/srgb/clipped paths, EXIF)."""
    for im in decoded.meta["images"]:
        if im["name"] == name:
            return im
    raise KeyError(name)


def _report(posed: Posed, names: list[str], source: str, sphere: ObjectSphere, to_source: Similarity,
            undistort: UndistortMaps | None, config: PosesConfig, cameras: CameraSet) -> dict[str, Any]:
    centers = cameras.c2w()[:, :3, 3]
    dist = np.linalg.norm(centers, axis=1)
    lenses = Counter((c.model_name, tuple(np.round(c.params, 6))) for c in posed.lens)
    return {
        "schema": SCHEMA_VERSION,
        "source": source,
        "registered": len(posed.names),
        "total": len(names),
        "not_registered": [n for n in names if n not in set(posed.names)],
        **{k: v for k, v in posed.stats.items()},
        "intrinsics": [{"model": m, "params": list(p), "photos": k} for (m, p), k in lenses.items()],
        "undistorted": undistort is not None,
        "object": {
            "center_source_frame": sphere.center,
            "radius_source_frame": sphere.radius,
            "radius_from": sphere.method,
            "axes_convergence_source_frame": sphere.convergence,
            "axes_rms_distance_normalized": sphere.axes_rms / sphere.radius,
            "up_source_frame": sphere.up,
            "notes": sphere.notes,
        },
        "cameras_normalized": {"distance_min": float(dist.min()), "distance_median": float(np.median(dist)),
                               "distance_max": float(dist.max())},
        "to_colmap": to_source.matrix,
        "thresholds": {"min_registered": config.min_registered,
                       "min_registered_fraction": config.min_registered_fraction},
    }


def _figure(path: Path, cameras: CameraSet, points: np.ndarray | None, colors: np.ndarray | None,
            report: dict[str, Any]) -> None:
    """Top and side views of the cameras around the unit sphere (normalized frame), sparse points behind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c2w = cameras.c2w()
    centers, dirs = c2w[:, :3, 3], c2w[:, :3, 2]
    reach = 1.15 * max(float(np.abs(centers).max()), 1.0)
    arrow = 0.25 * float(np.median(np.linalg.norm(centers, axis=1)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6), constrained_layout=True)
    for ax, (i, j), title in zip(axes, [(0, 1), (0, 2)], ["top view (x, y)", "side view (x, z; z up)"]):
        if points is not None and len(points):
            sel = np.all(np.abs(points) < reach, axis=1)
            p, c = points[sel], (colors[sel] / 255.0 if colors is not None else "0.6")
            if len(p) > 4000:
                k = np.random.default_rng(0).choice(len(p), 4000, replace=False)
                p, c = p[k], (c[k] if not isinstance(c, str) else c)
            ax.scatter(p[:, i], p[:, j], s=1.5, c=c, alpha=0.5, linewidths=0)
        ax.add_patch(plt.Circle((0, 0), 1.0, fill=False, color="tab:red", lw=1.5, label="object (unit sphere)"))
        ax.quiver(centers[:, i], centers[:, j], dirs[:, i] * arrow, dirs[:, j] * arrow, angles="xy",
                  scale_units="xy", scale=1, color="tab:blue", width=0.004)
        ax.scatter(centers[:, i], centers[:, j], s=18, color="tab:blue", zorder=3, label="cameras")
        step = max(1, len(centers) // 12)
        for k in range(0, len(centers), step):
            ax.annotate(cameras.cameras[k].name, centers[k, [i, j]], fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    line = f"{report['registered']}/{report['total']} photos with cameras"
    if report["source"] == "sfm":
        line += (f"  |  reprojection {report['mean_reprojection_error_px']:.2f} px  |  track length "
                 f"{report['mean_track_length']:.1f}  |  {report['points3D']} points")
        if len(report.get("models", [])) > 1:
            line += f"  |  SfM split into {len(report['models'])} models"
    else:
        line += f"  |  known cameras: {Path(report['source']).name}"
    missing = report["not_registered"]
    if missing:
        line += "\nno camera: " + ", ".join(missing[:12]) + (" ..." if len(missing) > 12 else "")
    fig.suptitle(line, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca poses captures/mug                          # reads results/mug/decode -> results/mug/poses/
  orca poses captures/mug --masks my_masks/        # ignore features on the object (white = object)
  orca poses captures/mug --set matcher=sequential --set num_threads=4
  orca poses captures/mug --set min_registered_fraction=0.5 --preset fast

Known cameras: put cameras.json (orca schema) or transforms.json (nerfstudio) in the capture folder; SfM is
then skipped (--set known_poses=ignore runs it anyway). A calibration from `orca calibrate` in
CAPTURE/calibration/calibration.json fixes the intrinsics. Output: cameras.json (normalized frame: the object
in the unit sphere), transforms.json, sparse/ (COLMAP model), poses_report.json, poses.png, and undistorted/
(a decode-style folder for `orca train --decode`) when the lens distorts.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "poses",
        help="decoded photos -> cameras.json (SfM with pycolmap, or known cameras), object-centred frame",
        description="Find every photo's camera (intrinsics and pose) and put the object in the unit sphere.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("capture", type=Path, help="capture folder (for calibration/, masks/, cameras.json, capture.yaml)")
    p.add_argument("--decode", type=Path, default=None, help="decode stage folder (default: results/<capture>/decode)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/<capture>/poses)")
    p.add_argument("--masks", type=Path, default=None, help="object masks <name>.png (default: CAPTURE/masks if any)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> PosesResult:
    capture = Path(args.capture)
    config = config_from_arguments(args, "poses", capture / "capture.yaml")
    decode, out = stage_dir(capture, "decode", args.decode), stage_dir(capture, "poses", args.out)
    return run_poses(capture, decode, out, config.poses, masks_dir=args.masks, force=args.force)
