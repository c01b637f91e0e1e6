"""Stage ``masks``: decoded photos + cameras -> an object mask per photo, the object's tight bounding sphere, QA.

Inputs: the poses stage's folder (``cameras.json``, normalized frame: the object inside the unit sphere) and
the images its cameras point at (the decode stage's folder, or ``poses/undistorted/`` when the poses stage
resampled the photos: the masks are in the pixel grid of the images training reads). Optional: user masks.

**Automatic masks** (no downloaded weights): :mod:`pipeline.masking` -- the unit sphere's image as a prior,
the support plane found by photo-consistency (the floor and its shadows are background), a depth sweep
outside the sphere (props in front, the room behind) and, against each round's hull, one between the cameras and
the hull (props standing in front inside the sphere: their tops and the sides under them), the floor seen
through the hull (holes, overhangs), GrabCut per view, made to agree by visual-hull carving, a few rounds.
Segmentation runs at ``masks.work_size``; the masks are written at full size, their outline snapped to the
photo's edges by a guided filter. The method's failure cases are in that module's doc and the README.

**User masks** (``CAPTURE/masks/`` or ``--user-masks``; ``masks.user_masks=ignore`` to skip them): one
image per photo, named like the photo (``IMG_0001.png`` for ``IMG_0001.dng``), white (non-zero) = object.
Any common encoding is read: 8/16-bit grey 0/255 (or 0/65535), 0/1, RGB, or an alpha channel (a cut-out PNG:
the alpha is the mask when it is not constant). They may cover every photo (the automatic method is then not
run) or only a few (corrections: they replace those views' masks and take part in every carve, so they also
improve the others). Files whose name matches no photo, a mask of another aspect ratio, an empty or nearly
empty mask (under ``masks.user_mask_min_fraction`` of the image; only empty ones: always), an unreadable file
or a multi-page TIFF stop the stage with an :class:`~pipeline.errors.InputError` naming the files and the fix;
a mask at another size with the photo's aspect ratio (drawn on the original while decode downscaled) is
resized, with a log line (:mod:`pipeline.mask_file`, training's rule too). Masks of photos that got no camera
(SfM dropped them) are skipped, with a log line. Drawn on the photos, they are resampled like the photos when
the poses stage undistorted them (its ``undistorted/decode.json`` records the lenses).

**Bounding sphere**: the visual hull of the final masks (:func:`pipeline.object_frame.sphere_from_masks`,
the poses stage's function) is the object's bounding sphere, recorded in ``masks_report.json`` as
``object_sphere`` (poses frame) and used to write ``cameras.json`` re-normalized so that the sphere
(times ``masks.sphere_margin``) is the unit sphere: training's bounds are then tight. ``frame.to_colmap``
composes, so exports in COLMAP units stay right. When the hull is empty the poses stage's sphere is kept and
``object_sphere`` says so (``fallback``, ``from``).

Outputs (``out_dir``, written atomically): ``masks/<name>.png`` (0/255 at the image's full size),
``cameras.json`` (re-normalized; ``masks.renormalize=false``: the poses frame), ``overlays/<name>.jpg``
(mask outline in green -- orange for a user's mask -- and the visual hull's in magenta on the photo),
``contact_sheet.jpg`` (every overlay; views that disagree with the hull framed in red),
``masks_report.json`` (per view: source, area, agreement with the hull; the support plane, the rounds,
warnings), ``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..artifacts import stage_dir
from ..config import MasksConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..mask_file import read_mask
from ..provenance import FORCE_HELP

if TYPE_CHECKING:
    from ..cameras import CameraSet
    from ..masking.views import Plane, View
    from ..results import DecodeArtifacts
    from .poses import UndistortMaps

log = logging.getLogger("orca.masks")

MASKS = "masks"
OVERLAYS = "overlays"
CAMERAS_JSON = "cameras.json"
REPORT_JSON = "masks_report.json"
CONTACT_SHEET = "contact_sheet.jpg"
SCHEMA_VERSION = 1
MASK_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".webp")


@dataclass(frozen=True)
class MasksResult:
    out_dir: Path
    names: list[str]
    user: list[str]  # views whose mask the user gave
    sphere_centre: np.ndarray  # (3,) poses frame
    sphere_radius: float  # poses frame
    agreement: dict[str, float]  # IoU of each mask with the hull's reprojection: median, min
    warnings: list[str]
    seconds: float


# ---------------------------------------------------------------------------------------------- user masks


def find_user_masks(folder: Path, names: list[str], no_camera: Collection[str] = ()) -> dict[str, Path]:
    """``name -> file`` for the mask images in ``folder`` (see the module doc); every file must match a photo.

    Args:
        names: the photos with a camera.
        no_camera: photos that exist but got no camera (SfM did not register them): their masks are skipped
            with a log line, as the photos are.

    Raises:
        InputError: a file that matches no photo (listing them and a few photo names), two files for one photo.
    """
    if not folder.is_dir():
        raise InputError("user masks folder not found", folder, fix="pass a folder of <photo name>.png masks")
    known, dropped = set(names), set(no_camera)
    photos = known | dropped
    found: dict[str, Path] = {}
    unmatched: list[str] = []
    skipped: list[str] = []
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or not path.is_file():
            continue
        if path.suffix.lower() not in MASK_SUFFIXES:
            log.warning("%s: not a mask image (%s); skipped", path, ", ".join(MASK_SUFFIXES))
            continue
        stem = path.stem
        if stem not in photos and Path(stem).stem in photos:  # IMG_0001.jpg.png (COLMAP's naming)
            stem = Path(stem).stem
        if stem in dropped:
            skipped.append(path.name)
            continue
        if stem not in known:
            unmatched.append(path.name)
            continue
        if stem in found:
            raise InputError(f"two masks for photo {stem}: {found[stem].name} and {path.name}", folder,
                             fix="keep one of them")
        found[stem] = path
    if unmatched:
        sample = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
        raise InputError(
            f"{len(unmatched)} mask file(s) match no photo: {', '.join(unmatched[:10])}"
            + (" ..." if len(unmatched) > 10 else "") + f" (photos: {sample})",
            folder, fix="name each mask like its photo (IMG_0001.png for IMG_0001.dng), or remove the extra files",
        )
    if skipped:
        log.info("%d user mask(s) skipped: their photos have no camera (the poses stage did not register them): %s",
                 len(skipped), ", ".join(skipped[:10]) + (" ..." if len(skipped) > 10 else ""))
    return found


def user_mask(path: Path, cam: Any, undistortion: UndistortMaps | None) -> np.ndarray:
    """A user's mask for camera ``cam``, in the pixel grid of the images the cameras point at: resampled
    like the photo when the poses stage undistorted it."""
    from .poses import undistort_mask

    m = read_mask(path, (cam.width, cam.height))
    return undistort_mask(m, undistortion, cam.name) if undistortion is not None else m


# -------------------------------------------------------------------------------------------------- images


def image_folder(poses_dir: Path, cameras: CameraSet, decode_dir: Path | None) -> Path:
    """The decode-style folder holding the images the cameras point at (``<folder>/linear/<name>.exr``): the
    decode stage's, or the poses stage's ``undistorted/``. ``decode_dir`` is the fallback for cameras without
    image paths."""
    for cam in cameras.cameras:
        if cam.image:
            folder = (poses_dir / cam.image).resolve().parent.parent
            if (folder / "decode.json").is_file():
                return folder
    if decode_dir is not None and (decode_dir / "decode.json").is_file():
        return decode_dir
    raise InputError("cannot tell which decoded images the cameras belong to", poses_dir / CAMERAS_JSON,
                     fix="pass --decode results/<capture>/decode")


def photos_without_camera(poses_dir: Path, decoded: DecodeArtifacts, names: list[str]) -> set[str]:
    """Decoded photos that got no camera (the poses stage lets SfM drop a few): those in the decoded folder and
    those the poses stage's report lists (its ``undistorted/`` folder holds only the posed photos)."""
    from ..results import read_stage_json
    from .poses import REPORT_JSON as POSES_REPORT

    photos = set(decoded.names)
    if (poses_dir / POSES_REPORT).is_file():
        photos |= set(read_stage_json(poses_dir / POSES_REPORT, "poses").get("not_registered", []))
    return photos - set(names)


def load_view(decoded: DecodeArtifacts, cam: Any, scale: float) -> View:
    """One photo at the working size (``scale`` of the camera's size): sRGB, clipped highlights, intrinsics."""
    import cv2

    from ..masking.views import View

    srgb = decoded.srgb(cam.name)
    if srgb.shape[:2] != (cam.height, cam.width):
        raise InputError(f"image {cam.name} is {srgb.shape[1]}x{srgb.shape[0]} but its camera says "
                         f"{cam.width}x{cam.height}", decoded.folder, fix="rerun poses on this decode folder")
    size = (max(1, round(cam.width * scale)), max(1, round(cam.height * scale)))
    clipped = decoded.clipped(cam.name)
    K = cam.K.copy()
    if scale != 1.0:
        srgb = cv2.resize(srgb, size, interpolation=cv2.INTER_AREA)
        clipped = cv2.resize(clipped.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
        K[0] *= size[0] / cam.width  # pixel (0, 0) is the image corner: every entry scales
        K[1] *= size[1] / cam.height
    return View(cam.name, np.ascontiguousarray(srgb), K, cam.c2w, clipped)


def full_size_mask(mask: np.ndarray, photo: np.ndarray) -> np.ndarray:
    """A working-size mask ``(h, w)`` -> ``(H, W)`` bool at the photo's size, its outline snapped to the photo's
    edges (guided filter of the upsampled mask, guide the photo, radius ~ the scale factor)."""
    import cv2

    H, W = photo.shape[:2]
    if mask.shape == (H, W):
        return mask
    soft = cv2.resize(mask.astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR)
    radius = max(1, round(W / mask.shape[1]))
    snapped = cv2.ximgproc.guidedFilter(photo.astype(np.float32) / 255.0, soft, radius, 1e-3)
    return snapped > 0.5


# --------------------------------------------------------------------------------------------------- stage


def run_masks(
    capture_dir: Path | None,
    poses_dir: Path,
    out_dir: Path,
    config: MasksConfig,
    *,
    decode_dir: Path | None = None,
    user_masks_dir: Path | None = None,
    force: bool = False,
) -> MasksResult:
    """Object masks for every posed photo into ``out_dir`` (see the module doc)."""
    from ..artifacts import atomic_dir, check_output_dir, write_json, write_manifest
    from ..cameras import load_cameras
    from ..log import progress
    from ..masking.hull import carve, carve_votes, hull_grid, reproject
    from ..masking.segment import segment
    from ..metrics import iou
    from ..object_frame import sphere_from_masks
    from ..provenance import check_capture_folder, common_capture
    from ..results import load_decode
    from .poses import recorded_undistortion

    started = time.time()
    poses_dir, out_dir = Path(poses_dir), Path(out_dir)
    sources = [p for p in (capture_dir, poses_dir, decode_dir, user_masks_dir) if p is not None]
    check_output_dir(out_dir, "masks", sources)  # before minutes of segmentation, not after
    capture = common_capture([poses_dir, decode_dir, user_masks_dir], force=force)
    if capture_dir is not None:
        check_capture_folder(capture_dir, capture, force=force)
    cameras = load_cameras(poses_dir / CAMERAS_JSON)
    names = [c.name for c in cameras.cameras]
    if len(names) < 2:
        raise InputError(f"only {len(names)} camera(s); masks need at least 2 views", poses_dir / CAMERAS_JSON)
    decoded = load_decode(image_folder(poses_dir, cameras, Path(decode_dir) if decode_dir else None))
    user_dir = user_masks_dir
    if user_dir is None and config.user_masks == "auto" and capture_dir is not None:
        user_dir = Path(capture_dir) / "masks" if (Path(capture_dir) / "masks").is_dir() else None
    elif user_dir is not None and config.user_masks == "ignore":
        log.warning("--user-masks given but masks.user_masks=ignore: the user masks are not used")
        user_dir = None
    user_files = {} if user_dir is None else \
        find_user_masks(Path(user_dir), names, photos_without_camera(poses_dir, decoded, names))
    # a user draws on the photos; training reads the poses stage's undistorted images when it made them
    undistortion = recorded_undistortion(decoded) if user_files else None
    if user_dir is not None:
        log.info("user masks for %d of %d views from %s%s", len(user_files), len(names), user_dir,
                 "" if len(user_files) == len(names) else " (the others automatic)")

    longest = max(max(c.width, c.height) for c in cameras.cameras)
    scale = min(1.0, config.work_size / longest)
    opts = _segment_options(config)
    warnings: list[str] = []
    with progress() as bar:
        load = bar.add_task("load views", total=len(names))
        views, fixed, areas = [], {}, {}
        for i, cam in enumerate(cameras.cameras):  # one full-size photo in memory at a time
            view = load_view(decoded, cam, scale)
            views.append(view)
            if cam.name in user_files:
                m = user_mask(user_files[cam.name], cam, undistortion)
                areas[cam.name] = np.count_nonzero(m) / m.size
                fixed[i] = _reduce(m, view.shape)
            bar.advance(load)
        _refuse_empty(areas, user_files, config)
        if len(fixed) == len(views):
            log.info("every view has a user mask: the automatic method is skipped")
            final, plane, rounds = [fixed[i] for i in range(len(views))], None, []
        else:
            # the support plane, floor and first GrabCut per view; per round the carve, GrabCut per view and, from
            # the second, the evidence against the hull per view
            n = len(views)
            task = bar.add_task("segment", total=1 + 2 * n + opts.rounds * (1 + n) + (opts.rounds - 1) * n)
            seg = segment(views, opts, fixed=fixed, on_step=lambda label: bar.advance(task))
            final, plane, rounds = seg.masks, seg.plane, seg.rounds

        # The hull of the final masks: the views' agreement and the object's bounding sphere.
        points, index = hull_grid(opts.hull_resolution, plane)
        votes = carve(final, views, points, index, opts.hull_resolution)
        hull_task = bar.add_task("hull", total=len(views))
        hulls = []
        for v in views:
            hulls.append(reproject(votes, v, carve_votes(opts, len(views)) - 0.5))
            bar.advance(hull_task)
    agreement = [iou(m, h) for m, h in zip(final, hulls)]
    c2w = np.stack([v.c2w for v in views])
    K = np.stack([v.K for v in views])
    floor = (plane.normal, plane.offset) if plane is not None else None
    sphere = sphere_from_masks(final, c2w, K, np.zeros(3), 1.0, floor=floor)
    if sphere is None:
        warnings.append("the masks' visual hull is empty (the masks disagree with each other or with the "
                        "cameras); the poses stage's sphere is kept")
        centre, radius = np.zeros(3), 1.0
    else:
        centre, radius = sphere[0], sphere[1] * config.sphere_margin
    warnings += _check(names, final, agreement, views, radius, config)
    for w in warnings:
        log.warning("%s", w)

    with atomic_dir(out_dir, "masks", sources) as tmp:
        (tmp / MASKS).mkdir()
        (tmp / OVERLAYS).mkdir()
        records, tiles = [], []
        with progress() as bar:
            task = bar.add_task("write masks", total=len(names))
            for i, (cam, _view) in enumerate(zip(cameras.cameras, views)):
                photo = decoded.srgb(cam.name)
                if cam.name in user_files:  # read again, not kept from loading: one full-size mask in memory
                    full = user_mask(user_files[cam.name], cam, undistortion)
                else:
                    full = full_size_mask(final[i], photo)
                _write_mask(tmp / MASKS / f"{cam.name}.png", full)
                flagged = agreement[i] < config.agreement_warning
                overlay = _overlay(photo, full, hulls[i], cam.name in user_files, config.overlay_size)
                _write_jpeg(tmp / OVERLAYS / f"{cam.name}.jpg", overlay)
                tiles.append(_tile(overlay, cam.name, agreement[i], flagged))
                records.append({
                    "name": cam.name,
                    "source": "user" if cam.name in user_files else "auto",
                    "user_file": str(user_files[cam.name]) if cam.name in user_files else None,
                    "area_px": int(np.count_nonzero(full)),
                    "area_fraction": float(np.count_nonzero(full) / full.size),
                    "hull_iou": agreement[i],
                    "disagrees_with_hull": bool(flagged),
                })
                bar.advance(task)
        _write_jpeg(tmp / CONTACT_SHEET, _contact_sheet(tiles))
        tight = _renormalized(cameras, centre, radius, poses_dir, out_dir) if config.renormalize else \
            _relocated(cameras, poses_dir, out_dir)
        from ..cameras import save_cameras

        save_cameras(tmp / CAMERAS_JSON, tight)
        report = _report(records, agreement, (centre, radius, sphere is not None), config, plane, rounds, warnings,
                         scale, user_dir, time.time() - started)
        write_json(tmp / REPORT_JSON, report)
        inputs: dict[str, Path] = {"cameras.json": poses_dir / CAMERAS_JSON, "decode.json": decoded.folder /
                                   "decode.json"}
        inputs.update({f"user_mask:{n}": p for n, p in user_files.items()})
        write_manifest(tmp, stage="masks", inputs=inputs, config=config.model_dump(mode="json"), started=started,
                       capture=capture)
    seconds = time.time() - started
    summary = report["agreement"]
    log.info("masks: %d views (%d user, %d automatic), hull agreement IoU median %.3f (worst %.3f, %s), object "
             "sphere centre %s radius %.3f of the poses sphere -> %s (%.1f s)", len(names), len(user_files),
             len(names) - len(user_files), summary["median"], summary["min"], summary["worst_view"],
             np.array2string(centre, precision=3), radius, out_dir, seconds)
    return MasksResult(out_dir, names, sorted(user_files), centre, float(radius),
                       {"median": summary["median"], "min": summary["min"]}, warnings, seconds)


def _segment_options(config: MasksConfig) -> Any:
    from ..masking.views import SegmentOptions

    return SegmentOptions(
        rounds=config.rounds, grabcut_iterations=config.grabcut_iterations, hull_resolution=config.hull_resolution,
        carve_votes=config.carve_votes, carve_share=config.carve_share, seed_radius=config.seed_radius,
        neighbours=config.neighbours, neighbour_max_deg=config.neighbour_max_deg,
        consistency_rank=config.consistency_rank, floor=config.floor,
        floor_threshold=config.floor_threshold, sweep=config.sweep, sweep_neighbours=config.sweep_neighbours,
        sweep_rank=config.sweep_rank, sweep_threshold=config.sweep_threshold,
        texture_threshold=config.texture_threshold, doubtful_vote=config.doubtful_vote, dark_level=config.dark_level,
        final_reach_px=config.final_reach_px, front_sweep=config.front_sweep,
        through_floor=config.through_floor, through_reach_px=config.through_reach_px,
        through_views=config.through_views,
    )


def _reduce(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A full-size bool mask at the working ``shape`` (area average, then half)."""
    import cv2

    if mask.shape == shape:
        return mask
    return cv2.resize(mask.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA) > 0.5


def _refuse_empty(areas: dict[str, float], files: dict[str, Path], config: MasksConfig) -> None:
    """Stop on user masks with (almost) no object, naming the files: one empty view carves the object out of the
    visual hull (the object sphere then falls back to the poses stage's loose one), and a set of empty masks has
    no object at all. ``areas``: each user-masked view's object fraction of its image.

    Raises:
        InputError: every user mask is empty; some cover less than ``config.user_mask_min_fraction``.
    """
    def listing(views: list[str]) -> str:
        return ", ".join(files[n].name for n in views[:10]) + (" ..." if len(views) > 10 else "")

    folder = next(iter(files.values())).parent if files else None
    if areas and not any(areas.values()):
        raise InputError(f"every user mask is empty (no object pixel): {listing(list(areas))}", folder,
                         fix="draw the object white (non-zero) on black, or remove the folder for automatic masks")
    small = [n for n, a in areas.items() if a < config.user_mask_min_fraction]
    if small:
        raise InputError(
            f"{len(small)} user mask(s) empty or nearly (object under {config.user_mask_min_fraction:g} of the image): "
            f"{listing(small)}", folder,
            fix="draw the object white on them, or delete those files (their views then get automatic masks); if "
            "the object is really out of those photos, set masks.user_mask_min_fraction=0",
        )


def _check(names: list[str], masks: list[np.ndarray], agreement: list[float], views: list[View], radius: float,
           config: MasksConfig) -> list[str]:
    """Warnings a person should act on: empty masks, views that disagree with the hull, an object that seems
    larger than the poses stage's sphere (its masks were clipped by that sphere's image)."""
    from ..masking.views import sphere_distance

    out = []
    empty = [n for n, m in zip(names, masks) if not m.any()]
    if empty:
        out.append(f"empty mask (no object found) in {len(empty)} view(s): {', '.join(empty[:10])}")
    bad = [(n, a) for n, a in zip(names, agreement) if a < config.agreement_warning]
    if bad:
        out.append(f"{len(bad)} view(s) disagree with the visual hull (IoU < {config.agreement_warning}): "
                   + ", ".join(f"{n} ({a:.2f})" for n, a in bad[:10])
                   + "; check their overlays, or give corrected masks for them in CAPTURE/masks/")
    touching = 0
    for v, m in zip(views, masks):
        rim = (sphere_distance(v) > 0.97) & (sphere_distance(v) < 1.0)
        touching += bool(np.count_nonzero(m & rim) > 0.02 * max(1, np.count_nonzero(rim)))
    if touching > 0.25 * len(views) or radius > 1.0:
        out.append(f"the object reaches the edge of the poses stage's sphere in {touching} view(s): it may be "
                   "larger than that sphere and cut; rerun poses with a larger poses.radius_margin or "
                   "poses.object_window, or give masks")
    return out


# ---------------------------------------------------------------------------------------------- outputs


def _write_mask(path: Path, mask: np.ndarray) -> None:
    from ..imageio import write_png

    write_png(path, np.where(mask, 255, 0).astype(np.uint8))


def _write_jpeg(path: Path, rgb: np.ndarray, quality: int = 90) -> None:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise OSError(f"{path}: JPEG encoding failed")
    path.write_bytes(buf.tobytes())


def _overlay(photo: np.ndarray, mask: np.ndarray, hull: np.ndarray, user: bool, size: int) -> np.ndarray:
    """``(h, w, 3)`` uint8: the photo (longest side ``size``), the mask's outline (green; orange for a user's
    mask) and the visual hull's (magenta), the object slightly brightened."""
    import cv2

    H, W = photo.shape[:2]
    s = min(1.0, size / max(H, W))
    wh = (max(1, round(W * s)), max(1, round(H * s)))
    img = cv2.resize(photo, wh, interpolation=cv2.INTER_AREA) if s < 1 else photo.copy()
    m = cv2.resize(mask.astype(np.uint8), wh, interpolation=cv2.INTER_NEAREST) if s < 1 else mask.astype(np.uint8)
    h8 = cv2.resize(hull.astype(np.uint8), wh, interpolation=cv2.INTER_NEAREST)
    img = np.where(m[..., None] > 0, np.minimum(255, img.astype(np.int16) + 25), img).astype(np.uint8)
    thick = max(1, round(max(wh) / 400))
    contours, _ = cv2.findContours(h8, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (255, 0, 255), thick)
    contours, _ = cv2.findContours(m, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (255, 150, 0) if user else (0, 255, 0), thick)
    return img


def _tile(overlay: np.ndarray, name: str, agreement: float, flagged: bool, width: int = 200) -> np.ndarray:
    """A contact-sheet tile: the overlay at ``width`` px with its name and hull IoU; red frame if flagged."""
    import cv2

    h, w = overlay.shape[:2]
    tile = cv2.resize(overlay, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)
    label = f"{name}  {agreement:.2f}"
    cv2.rectangle(tile, (0, 0), (width, 14), (0, 0, 0), -1)
    cv2.putText(tile, label, (3, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
    if flagged:
        cv2.rectangle(tile, (0, 0), (tile.shape[1] - 1, tile.shape[0] - 1), (255, 0, 0), 3)
    return tile


def _contact_sheet(tiles: list[np.ndarray]) -> np.ndarray:
    """The tiles in a grid (about 4:3), on black."""
    cols = max(1, int(np.ceil(np.sqrt(len(tiles) * 4 / 3))))
    rows = int(np.ceil(len(tiles) / cols))
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    sheet = np.zeros((rows * (th + 2), cols * (tw + 2), 3), np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        sheet[r * (th + 2): r * (th + 2) + t.shape[0], c * (tw + 2): c * (tw + 2) + t.shape[1]] = t
    return sheet


def _relocated(cameras: CameraSet, poses_dir: Path, out_dir: Path) -> CameraSet:
    """The same cameras with image paths relative to ``out_dir`` (where the new cameras.json lives)."""
    cams = []
    for c in cameras.cameras:
        image = c.image
        if image:
            image = os.path.relpath((poses_dir / image).resolve(), out_dir.resolve())
        cams.append(c.model_copy(update={"image": image}))
    return cameras.model_copy(update={"cameras": cams})


def _renormalized(cameras: CameraSet, centre: np.ndarray, radius: float, poses_dir: Path,
                  out_dir: Path) -> CameraSet:
    """The cameras in the frame where the sphere ``(centre, radius)`` of the poses frame is the unit sphere:
    ``x_poses = radius * x_new + centre``; ``frame.to_colmap`` composed with it."""
    from ..alignment import Similarity
    from ..cameras import Frame

    to_poses = Similarity(float(radius), np.eye(3), np.asarray(centre, float))
    moved = _relocated(cameras, poses_dir, out_dir)
    c2w = to_poses.inverse().apply_c2w(moved.c2w())
    cams = [c.model_copy(update={"camera_to_world": m.tolist()}) for c, m in zip(moved.cameras, c2w)]
    to_colmap = cameras.frame.to_colmap
    frame = Frame(to_colmap=(np.asarray(to_colmap) @ to_poses.matrix).tolist() if to_colmap is not None else None)
    return cameras.model_copy(update={"cameras": cams, "frame": frame})


def _report(records: list[dict[str, Any]], agreement: list[float], sphere: tuple[np.ndarray, float, bool],
            config: MasksConfig, plane: Plane | None, rounds: list[dict[str, float]], warnings: list[str],
            scale: float, user_dir: Path | None, seconds: float) -> dict[str, Any]:
    """``sphere``: centre, radius, and whether they are the hull's (else the poses stage's unit sphere)."""
    centre, radius, from_hull = sphere
    worst = int(np.argmin(agreement))
    return {
        "schema": SCHEMA_VERSION,
        "views": records,
        "user_masks": {"folder": str(user_dir) if user_dir else None,
                       "views": [r["name"] for r in records if r["source"] == "user"]},
        "agreement": {
            "what": "IoU of each view's mask with the reprojection of the visual hull carved from all masks",
            "median": float(np.median(agreement)), "mean": float(np.mean(agreement)),
            "min": float(np.min(agreement)), "worst_view": records[worst]["name"],
            "threshold": config.agreement_warning,
            "disagreeing_views": [r["name"] for r in records if r["disagrees_with_hull"]],
        },
        "object_sphere": {
            "frame": "poses (results/<capture>/poses/cameras.json)",
            "centre": np.asarray(centre).tolist(), "radius": float(radius), "margin": config.sphere_margin,
            "from": "bounding sphere of the visual hull of the masks (pipeline.object_frame.sphere_from_masks)"
            if from_hull else "the poses stage's sphere, kept: the masks' visual hull is empty (see warnings)",
            "fallback": not from_hull,
            "cameras_json": "re-normalized: this sphere is the unit sphere" if config.renormalize else
            "the poses frame",
        },
        "support_plane": None if plane is None else {
            "normal": plane.normal.tolist(), "offset": plane.offset,
            "explained_fraction": plane.consistent_fraction, "frame": "poses",
        },
        "rounds": rounds,
        "work_scale": scale,
        "warnings": warnings,
        "seconds": round(seconds, 2),
    }


# ---------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca masks captures/mug                         # results/mug/poses -> results/mug/masks/
  orca masks captures/mug --user-masks my_masks/  # your masks for all or some views (white = object)
  orca masks captures/mug --set work_size=640 --set rounds=4
  orca masks captures/mug --set user_masks=ignore # automatic masks even if CAPTURE/masks/ exists

User masks: CAPTURE/masks/<photo name>.png (any of 0/255, 0/1, 16-bit, RGB, or a cut-out's alpha channel); a
few files correct those views and help the rest. Output: masks/<name>.png, cameras.json (the object's tight
sphere is the unit sphere: train on it), overlays/, contact_sheet.jpg, masks_report.json.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "masks",
        help="posed photos -> object masks (automatic, or the user's), tight bounding sphere, QA overlays",
        description="Find the object in every photo: where the cameras converge, the support plane, colour "
        "(GrabCut) and the visual hull, made to agree. User masks override.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("capture", type=Path, help="capture folder (for masks/ and capture.yaml)")
    p.add_argument("--poses", type=Path, default=None, help="poses stage folder (default: results/<capture>/poses)")
    p.add_argument("--decode", type=Path, default=None,
                   help="decode folder, if cameras.json has no image paths (default: results/<capture>/decode)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/<capture>/masks)")
    p.add_argument("--user-masks", type=Path, default=None, help="folder of <name>.png masks (default: CAPTURE/masks)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> MasksResult:
    capture = Path(args.capture)
    config = config_from_arguments(args, "masks", capture / "capture.yaml")
    poses, out = stage_dir(capture, "poses", args.poses), stage_dir(capture, "masks", args.out)
    return run_masks(capture, poses, out, config.masks, decode_dir=stage_dir(capture, "decode", args.decode),
                     user_masks_dir=args.user_masks, force=args.force)
