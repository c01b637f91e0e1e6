"""Stage ``poses``: decoded photos -> cameras (intrinsics and poses) in the object-centred normalized frame.

Inputs: the decode stage's folder (``srgb/*.png`` for SIFT, ``decode.json`` for names, size and EXIF) and
the capture folder, where these are optional:

- ``calibration/calibration.json`` (``orca calibrate``): OPENCV intrinsics, scaled to the decoded size and
  held fixed. Without it each lens/zoom shares one camera (:mod:`pipeline.sfm`).
- ``cameras.json``, ``transforms.json``, ``poses_bounds.npy`` (LLFF) or a COLMAP model (``sparse/0/``, or
  nerfstudio's ``colmap/sparse/0/``): known cameras (:mod:`pipeline.known_cameras`). Then SfM is skipped
  (``poses.known_poses=ignore`` runs it anyway; refining known cameras with SfM is not built). A COLMAP model's
  3D points are kept, as SfM's are.
- ``masks/<name>.png`` (or ``--masks``; white = object): features on the glossy object are ignored (its
  reflections move with the viewpoint and make false matches), and the object's sphere is the masks'
  visual hull.

SfM (:mod:`pipeline.sfm`): bad input stops the stage with an :class:`~pipeline.errors.InputError` that names
the folder and the fix: identical photos, no features, no initial pair, too few photos registered
(``poses.min_registered``, ``poses.min_registered_fraction``).

Checks (:mod:`pipeline.pose_checks`, SfM only): registered is not right (repetitive textures put photos where
others look the same). Photos whose camera jumps away from its capture neighbours or whose axis misses the
object are doubted; SfM runs again with neighbour-only, stricter matching and the better run is kept
(:func:`pipeline.sfm.posed_from_sfm_checked`); photos still doubted are dropped, kept or stop the stage
(``poses.on_suspect``). The up direction is compared with the plane under the object. ``poses_report.json``'s
``checks`` lists each doubted photo and why; ``poses.png`` marks them.

Normalization (:mod:`pipeline.object_frame`): the object's centre is where the optical axes converge, its
radius from the framing, the support plane or the masks; the normalized frame has the object's bounding
sphere as the unit sphere, z up. ``cameras.json``'s ``frame.to_colmap`` is the 4x4 similarity from the
normalized frame to COLMAP's (for known cameras: to the frame of the given file).

Undistortion (:mod:`pipeline.undistort`): cameras.json is pinhole. When the lens model moves some pixel by
more than ``poses.undistort_threshold_px``, the decoded images are resampled to the pinhole camera into
``undistorted/``, a folder in the decode stage's layout: train on it with
``orca train --decode results/<capture>/poses/undistorted``. Below the threshold (a synthetic capture; a good
lens at low resolution) the decoded images are used as they are and cameras.json points at them.

Outputs (``out_dir``, written atomically): ``cameras.json``, ``transforms.json`` (nerfstudio, same frame: the
decoded 8-bit sRGB PNGs, ``sparse_pc.ply`` the sparse points in that frame; :mod:`pipeline.transforms`; the masks
stage writes the one to train on, with masks, in its frame),
``sparse/0/`` (COLMAP binary model, COLMAP's frame; SfM's or the capture's COLMAP model with cameras.json's
PINHOLE cameras) beside ``images/`` (8-bit PNGs named as in the model, undistorted where the photos were: the
layout 3DGS, gsplat and nerfstudio read, :mod:`pipeline.colmap_model`), ``poses_report.json``, ``poses.png``
(cameras around the object, top and side views), ``undistorted/`` (only if needed), ``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration import load_calibration

from ..alignment import Similarity
from ..artifacts import atomic_dir, write_json, write_manifest
from ..cameras import CameraSet, save_cameras
from ..colmap_model import model_files, write_dataset
from ..config import PosesConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..known_cameras import find_known_cameras, known_cameras
from ..layout import (
    CALIBRATION,
    CAMERAS_JSON,
    CAPTURE_YAML,
    DECODE,
    DECODE_JSON,
    LINEAR,
    POSES,
    POSES_FIGURE,
    POSES_REPORT,
    SFM_DATABASE,
    SPARSE_PLY,
    SRGB,
    TRANSFORMS_JSON,
    UNDISTORTED,
    USER_MASKS,
    decoded_files,
    stage_dir,
)
from ..log import collect_warnings
from ..mask_file import read_mask
from ..media import write_point_cloud
from ..object_frame import ObjectSphere, Posed, find_object, normalized_cameras, normalizing_similarity
from ..pose_checks import PoseChecks, frame_up_check
from ..provenance import FORCE_HELP, check_capture_folder, common_capture
from ..qa import cameras_figure
from ..results import load_decode
from ..sfm import (
    act_on_suspects,
    check_not_identical,
    posed_from_sfm_checked,
    quiet_colmap,
    refine_without_object,
    thumbnail,
    triangulate_known,
    without_dropped,
)
from ..transforms import nerfstudio_transforms
from ..undistort import UndistortMaps, pinholes, undistort_mask, undistortion, write_undistorted

log = logging.getLogger("orca.poses")

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
    known_file = find_known_cameras(capture_dir, config.known_poses)
    mask_files = _mask_files(masks_dir, capture_dir, names, (width, height), config)
    calibration = _calibration(capture_dir, width, height)
    inputs: dict[str, Path] = {DECODE_JSON: decode_dir / DECODE_JSON}
    for key, path in (("known_cameras", known_file), ("calibration", calibration[2] if calibration else None)):
        if path is not None and path.is_dir():  # a COLMAP model
            inputs.update({f"{key}/{f.name}": f for f in model_files(path)})
        elif path is not None:
            inputs[key] = path
    if (capture_dir / CAPTURE_YAML).is_file():
        inputs[CAPTURE_YAML] = capture_dir / CAPTURE_YAML

    sources = [p for p in (capture_dir, decode_dir, masks_dir) if p is not None]
    with collect_warnings(log) as warnings, atomic_dir(out_dir, POSES, sources) as tmp:
        checks, checks_runs, suspects = None, [], {}  # pose checks: SfM only
        if known_file is not None:
            log.info("known cameras: %s (SfM skipped)", known_file)
            posed, reconstruction = known_cameras(known_file, names, width, height)
            source = str(known_file)
            if reconstruction is None and config.triangulate_known:
                triangulated = triangulate_known(posed, decoded.folder / SRGB, tmp / "work", config)
                shutil.rmtree(tmp / "work")
                posed.stats["points3D"] = triangulated.num_points3D()
                if triangulated.num_points3D():  # none: no model, as before (training then has no sparse depth)
                    reconstruction = triangulated
        else:
            duplicates = check_not_identical({n: thumbnail(decoded.srgb(n)) for n in names}, photo_dir)
            if duplicates:
                log.warning("near-identical photos (the camera did not move between them): %s",
                            "; ".join(", ".join(g) for g in duplicates))
            sfm = posed_from_sfm_checked(decoded, names, calibration, mask_files, tmp / "work", config, photo_dir)
            posed, checks = sfm.posed, sfm.checks
            suspects = {n: posed.c2w[posed.names.index(n), :3, 3] for n in checks.flagged}
            posed = act_on_suspects(posed, checks, len(names), config, photo_dir)
            reconstruction = without_dropped(sfm.reconstruction, posed.names)
            if config.object_points == "drop" and not mask_files:
                posed = refine_without_object(reconstruction, posed, config)
            if config.keep_database:
                shutil.move(str(sfm.work / SFM_DATABASE), str(tmp / SFM_DATABASE))
            for work in sfm.folders:
                shutil.rmtree(work)
            checks_runs = sfm.runs
            source = "sfm"
            if duplicates:
                posed.stats["duplicates"] = duplicates

        undistort, posed.stats["distortion_max_shift_px"] = undistortion(posed.names, posed.lens,
                                                                         config.undistort_threshold_px)
        if undistort:
            write_undistorted(decoded, posed.names, undistort, tmp / UNDISTORTED)
            image_of = {n: f"{UNDISTORTED}/{decoded_files(n)[LINEAR]}" for n in posed.names}
            srgb_of = {n: f"{UNDISTORTED}/{decoded_files(n)[SRGB]}" for n in posed.names}
        else:
            rel = os.path.relpath(decode_dir.resolve(), out_dir.resolve())
            image_of = {n: f"{rel}/{decoded.entry(n)[LINEAR]}" for n in posed.names}
            srgb_of = {n: f"{rel}/{decoded.entry(n)[SRGB]}" for n in posed.names}
        if reconstruction is not None:
            images = tmp / UNDISTORTED if undistort else decode_dir
            write_dataset(reconstruction, tmp, {n: images / decoded.entry(n)[SRGB] for n in posed.names})

        K, sizes = pinholes(posed.lens)
        hull, mask_scale = _hull_masks(mask_files, posed, undistort, (width, height)) if mask_files else (None, 1.0)
        sphere = find_object(
            posed.c2w, K, sizes, points=posed.points, masks=hull, mask_scale=mask_scale,
            window=config.object_window, margin=config.radius_margin, seed=config.seed,
        )
        to_source = normalizing_similarity(sphere, posed.c2w)
        cameras = normalized_cameras(posed, K, to_source, image_of)
        save_cameras(tmp / CAMERAS_JSON, cameras)
        points_n = to_source.inverse().apply(posed.points) if posed.points is not None else None
        has_points = points_n is not None and len(points_n) > 0 and posed.point_colors is not None
        if has_points:
            write_point_cloud(tmp / SPARSE_PLY, points_n, posed.point_colors / 255.0)
        write_json(tmp / TRANSFORMS_JSON, nerfstudio_transforms(cameras, srgb_of,
                                                                points_file=SPARSE_PLY if has_points else None))
        report = _report(posed, names, source, sphere, to_source, undistort, config, cameras)
        if checks is not None:
            report["checks"] = _checks_report(checks, checks_runs, posed, K, sizes, sphere, config)
        report["warnings"] = list(warnings)
        write_json(tmp / POSES_REPORT, report)
        suspects_n = {n: to_source.inverse().apply(c[None])[0] for n, c in suspects.items()}
        cameras_figure(tmp / POSES_FIGURE, cameras, points_n, posed.point_colors, report, suspects_n)
        write_manifest(tmp, stage=POSES, inputs=inputs, config=config.model_dump(mode="json"), started=started,
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


def _mask_files(masks_dir: Path | None, capture_dir: Path, names: list[str], size: tuple[int, int],
                config: PosesConfig) -> dict[str, Path] | None:
    """Object mask files per photo, or None when there are none or they are not wanted. Masks are read one
    at a time where needed (200 full-size masks would not fit in memory together).

    Raises:
        InputError: empty masks (one carves the object out of the visual hull the sphere comes from), named.
    """
    if masks_dir is None:
        if not config.use_masks or not (capture_dir / USER_MASKS).is_dir():
            return None
        masks_dir = capture_dir / USER_MASKS
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
    path = capture_dir / CALIBRATION
    if not path.is_file():
        return None
    calib = load_calibration(path).scaled_to(width, height)
    model, params = calib.colmap_params()
    log.info("intrinsics from %s (%s, fx %.1f fy %.1f at %dx%d), held fixed", path, model, params[0], params[1],
             width, height)
    return model, [float(p) for p in params], path


# ------------------------------------------------------------------------------------------------- report


def _report(posed: Posed, names: list[str], source: str, sphere: ObjectSphere, to_source: Similarity,
            undistort: UndistortMaps | None, config: PosesConfig, cameras: CameraSet) -> dict[str, Any]:
    centers = cameras.c2w()[:, :3, 3]
    dist = np.linalg.norm(centers, axis=1)
    lenses = Counter((c.model_name, tuple(np.round(c.params, 6))) for c in posed.lens)
    posed_names = set(posed.names)
    missing = [n for n in names if n not in posed_names]
    return {
        "schema": SCHEMA_VERSION,
        "source": source,
        "registered": len(posed.names),
        "total": len(names),
        "not_registered": missing,
        **{k: v for k, v in posed.stats.items()},
        "not_registered_why": {n: posed.stats.get("not_registered_why", {}).get(n, _unplaced(source)) for n in missing},
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


def _unplaced(source: str) -> str:
    """Why a photo SfM gave no reason for has no camera: SfM registered it and the pose checks dropped it, or the
    known cameras (``source``: their file) have none for it."""
    if source == "sfm":
        return "registered, but its pose contradicts the capture (checks) and poses.on_suspect=drop"
    return f"no camera for it in {source}"


def _checks_report(checks: PoseChecks, runs: list[dict[str, Any]], posed: Posed, K: np.ndarray, sizes: np.ndarray,
                   sphere: ObjectSphere, config: PosesConfig) -> dict[str, Any]:
    """The pose checks for the report, the up check redone on the cameras kept and the frame's own up; the
    warnings about the model as a whole (up, focal length) logged."""
    if posed.points is not None:
        checks.up = frame_up_check(posed.points, posed.c2w, K, sizes, sphere.up, sphere.center, config)
    for line in checks.frame_warnings():
        log.warning("%s", line)
    kept = set(posed.names)
    return {**checks.to_json(), "on_suspect": config.on_suspect, "runs": runs,
            "dropped": [n for n in checks.flagged if n not in kept]}


# ---------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca poses captures/mug                          # reads results/mug/decode -> results/mug/poses/
  orca poses captures/mug --masks my_masks/        # ignore features on the object (white = object)
  orca poses captures/mug --set matcher=sequential --set num_threads=4
  orca poses captures/mug --set min_registered_fraction=0.3 --preset fast

Known cameras: put cameras.json (orca schema), transforms.json (nerfstudio), poses_bounds.npy (LLFF, with
all_image_names.txt naming its rows when it has more than the photos) or a COLMAP model (sparse/0/ or
colmap/sparse/0/, .bin or .txt) in the capture folder; SfM is then skipped (--set known_poses=ignore runs it
anyway). A calibration from `orca calibrate` in CAPTURE/calibration/calibration.json fixes the intrinsics.
Output: cameras.json (normalized frame: the object in the unit sphere), transforms.json, sparse/0/ (COLMAP
model) beside images/ (train 3DGS/gsplat on the poses folder), poses_report.json, poses.png, and undistorted/
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
    config = config_from_arguments(args, POSES, capture / CAPTURE_YAML)
    decode, out = stage_dir(capture, DECODE, args.decode), stage_dir(capture, POSES, args.out)
    return run_poses(capture, decode, out, config.poses, masks_dir=args.masks, force=args.force)
