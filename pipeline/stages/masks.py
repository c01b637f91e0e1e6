"""Stage ``masks``: decoded photos + cameras -> an object mask per photo, the object's tight bounding sphere, QA.

Inputs: the poses stage's folder (``cameras.json``, normalized frame: the object inside the unit sphere) and
the images its cameras point at (the decode stage's folder, or ``poses/undistorted/`` when the poses stage
resampled the photos: the masks are in the pixel grid of the images training reads). Optional: user masks.

**Automatic masks** (no downloaded weights): :mod:`pipeline.masking` -- the unit sphere's image as a prior,
the poses stage's sparse points where each photo saw them (on the floor or far: background; clearly above the
floor in the sphere: object), the support plane found by photo-consistency (the floor and its shadows are
background), a depth sweep outside the sphere (props in front, the room behind) and, against each round's hull,
one between the cameras and the hull (props standing in front inside the sphere: their tops and the sides under
them), the floor seen through the hull (holes, overhangs), GrabCut per view, made to agree by visual-hull
carving, a few rounds.
Segmentation runs at ``masks.work_size``; the masks are written at full size, their outline snapped to the
photo's edges by a guided filter. The method's failure cases are in that module's doc and the README.

**User masks** (``CAPTURE/masks/`` or ``--user-masks``; ``masks.user_masks=ignore`` to skip them;
:mod:`pipeline.user_masks`): one image per photo, named like the photo (``IMG_0001.png`` for ``IMG_0001.dng``),
white (non-zero) = object. Any common encoding is read: 8/16-bit grey 0/255 (or 0/65535), 0/1, RGB, or an alpha
channel (a cut-out PNG: the alpha is the mask when it is not constant). They may cover every photo (the automatic
method is then not run) or only a few (corrections: they replace those views' masks and take part in every carve,
so they also improve the others). Files whose name matches no photo, a mask of another aspect ratio, an empty or
nearly empty mask (under ``masks.user_mask_min_fraction`` of the image; only empty ones: always), an unreadable
file or a multi-page TIFF stop the stage with an :class:`~pipeline.errors.InputError` naming the files and the fix;
a mask at another size with the photo's aspect ratio (drawn on the original while decode downscaled) is resized,
with a log line (:mod:`pipeline.mask_file`, training's rule too). Masks of photos that got no camera (SfM dropped
them) are skipped, with a log line. Drawn on the photos, they are resampled like the photos when the poses stage
undistorted them (its ``undistorted/decode.json`` records the lenses).

**Bounding sphere**: the visual hull of the final masks (:func:`pipeline.object_frame.sphere_from_masks`,
the poses stage's function) is the object's bounding sphere, recorded in ``masks_report.json`` as
``object_sphere`` (poses frame) and used to write ``cameras.json`` re-normalized so that the sphere
(times ``masks.sphere_margin``) is the unit sphere: training's bounds are then tight. ``frame.to_colmap``
composes, so exports in COLMAP units stay right. When the hull is empty the poses stage's sphere is kept and
``object_sphere`` says so (``fallback``, ``from``).

Outputs (``out_dir``, written atomically): ``masks/<name>.png`` (0/255 at the image's full size),
``cameras.json`` (re-normalized; ``masks.renormalize=false``: the poses frame), ``transforms.json`` (nerfstudio's, in
cameras.json's frame: the 8-bit sRGB photos, the masks, ``sparse_pc.ply`` the poses stage's sparse points in that
frame when it has some, ``applied_transform`` from COLMAP's; :mod:`pipeline.transforms`) and
``transforms_colmap.json`` with ``sparse_pc_colmap.ply`` (the same in COLMAP's frame), ``overlays/<name>.jpg``
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, check_output_dir, read_stage_json, write_json, write_manifest
from ..cameras import load_cameras, save_cameras
from ..colmap_model import model_files, model_folder, model_points
from ..config import MasksConfig, add_config_arguments, config_from_arguments
from ..errors import InputError, OrcaError
from ..imageio import write_png
from ..layout import (
    CAMERAS_JSON,
    CAPTURE_YAML,
    CONTACT_SHEET,
    DECODE,
    DECODE_JSON,
    MASK_FILES,
    MASKS,
    MASKS_REPORT,
    OVERLAYS,
    POSES,
    POSES_REPORT,
    SPARSE,
    SPARSE_PLY,
    SPARSE_PLY_COLMAP,
    SRGB,
    TRANSFORMS_COLMAP_JSON,
    TRANSFORMS_JSON,
    USER_MASKS,
    mask_file,
    stage_dir,
)
from ..log import progress
from ..masking.hull import carve, carve_votes, hull_grid, reproject, stand_on_plane, voxel_pixels
from ..masking.parallel import view_workers
from ..masking.prior import (
    PriorSphere,
    find_prior_sphere,
    framed_options,
    in_sphere_frame,
    outgrown,
    touching_views,
)
from ..masking.scale import edge_snap, full_size_mask, load_view, reduce
from ..masking.segment import probe_masks, segment, segment_options
from ..masking.tracks import tracks_for_views
from ..masking.views import Plane, View
from ..media import write_point_cloud
from ..metrics import iou
from ..object_frame import renormalized, sphere_from_masks
from ..provenance import FORCE_HELP, check_capture_folder, common_capture
from ..qa import contact_sheet, mask_overlay, tile, write_jpeg
from ..results import DecodeArtifacts, image_folder, load_decode, relocated
from ..sparse_depth import load_sparse_points
from ..transforms import from_colmap_frame, in_colmap_frame, nerfstudio_transforms
from ..undistort import recorded_undistortion
from ..user_masks import find_user_masks, refuse_empty, user_mask

log = logging.getLogger("orca.masks")

SCHEMA_VERSION = 1


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
    started = time.time()
    poses_dir, out_dir = Path(poses_dir), Path(out_dir)
    sources = [p for p in (capture_dir, poses_dir, decode_dir, user_masks_dir) if p is not None]
    check_output_dir(out_dir, MASKS, sources)  # before minutes of segmentation, not after
    capture = common_capture([poses_dir, decode_dir, user_masks_dir], force=force)
    if capture_dir is not None:
        check_capture_folder(capture_dir, capture, force=force)
    cameras = load_cameras(poses_dir / CAMERAS_JSON)
    names = [c.name for c in cameras.cameras]
    if len(names) < 2:
        raise InputError(f"only {len(names)} camera(s); masks need at least 2 views", poses_dir / CAMERAS_JSON)
    decoded = load_decode(image_folder(cameras, poses_dir, Path(decode_dir) if decode_dir else None))
    # the poses stage's sparse points (COLMAP's frame), for nerfstudio's files; known cameras may have none
    sparse_files = model_files(model_folder(poses_dir / SPARSE)) if cameras.frame.to_colmap is not None else []
    sparse = model_points(poses_dir / SPARSE) if sparse_files else None
    if sparse is not None and not len(sparse[0]):  # a model without points: no PLY, as the poses stage does
        sparse = None
    tracks = None
    if sparse is not None and config.tracks:
        points = load_sparse_points(poses_dir / SPARSE, cameras)
        tracks = tracks_for_views(points.xyz, points.observers, names)
    user_dir = user_masks_dir
    if user_dir is None and config.user_masks == "auto" and capture_dir is not None:
        user_dir = Path(capture_dir) / USER_MASKS if (Path(capture_dir) / USER_MASKS).is_dir() else None
    elif user_dir is not None and config.user_masks == "ignore":
        log.warning("--user-masks given but masks.user_masks=ignore: the user masks are not used")
        user_dir = None
    user_files = {} if user_dir is None else \
        find_user_masks(Path(user_dir), names, _photos_without_camera(poses_dir, decoded, names))
    # a user draws on the photos; training reads the poses stage's undistorted images when it made them
    undistortion = recorded_undistortion(decoded) if user_files else None
    if user_dir is not None:
        log.info("user masks for %d of %d views from %s%s", len(user_files), len(names), user_dir,
                 "" if len(user_files) == len(names) else " (the others automatic)")

    longest = max(max(c.width, c.height) for c in cameras.cameras)
    scale = min(1.0, config.work_size / longest)
    opts = segment_options(config)
    warnings: list[str] = []
    with progress() as bar, view_workers(config.workers) as run_views:
        load = bar.add_task("load views", total=len(names))
        views, fixed, areas = [], {}, {}
        for i, cam in enumerate(cameras.cameras):  # one full-size photo in memory at a time
            view = load_view(decoded, cam, scale)
            views.append(view)
            if cam.name in user_files:
                m = user_mask(user_files[cam.name], cam, undistortion)
                areas[cam.name] = np.count_nonzero(m) / m.size
                fixed[i] = reduce(m, view.shape)
            bar.advance(load)
        refuse_empty(areas, user_files, config.user_mask_min_fraction)
        if len(fixed) == len(views):
            log.info("every view has a user mask: the automatic method is skipped")
            final, plane, rounds, labelled = [fixed[i] for i in range(len(views))], None, [], None
            beside = None
            # the hull is carved in a sphere: grown while the masks reach past it, or the object is cut
            prior = find_prior_sphere(views, opts, lambda vs, o, c, r: final)
            views = [in_sphere_frame(v, prior.centre, prior.radius) for v in views]
        else:
            probe = bar.add_task("sphere prior", total=None)
            grown: PriorSphere | None = find_prior_sphere(views, opts, probe_masks(tracks, fixed, run_views))
            bar.update(probe, total=1, completed=1)
            # the support plane, floor and first GrabCut per view; per round the carve, GrabCut per view and, from
            # the second, the evidence against the hull per view
            n = len(views)
            evidence_steps = 1 + 2 * n
            task = bar.add_task("segment", total=evidence_steps + opts.rounds * (1 + n) + (opts.rounds - 1) * n)
            unframed = views
            while grown is not None:
                prior = grown
                bar.reset(task)
                views = [in_sphere_frame(v, prior.centre, prior.radius) for v in unframed]
                framed_tracks = tracks.framed(prior.centre, prior.radius) if tracks is not None else None
                seg = segment(views, framed_options(opts, prior.radius), fixed=fixed,
                              on_step=lambda label: bar.advance(task), tracks=framed_tracks,
                              on_retry=lambda: bar.update(task, completed=evidence_steps),  # the rounds again
                              run_views=run_views)
                # The probe's cheap masks can stop short of a part the full evidence keeps (a mirror-like neck that
                # colour alone loses): when the final masks reach past the sphere it grows, and they are made again.
                prior, grown = outgrown(prior, seg.masks, views, opts, "segmentation")
            final, plane, rounds, labelled = seg.masks, seg.plane, seg.rounds, seg.track_labels
            beside = seg.unexplained_beside
            if not any(m.any() for i, m in enumerate(final) if i not in fixed):
                raise OrcaError(
                    f"the automatic masks found the object in none of the {len(views) - len(fixed)} photos they "
                    "segmented: their visual hull emptied in the rounds (the cues and the cameras disagree); nothing "
                    "was written", poses_dir / CAMERAS_JSON,
                    fix="check the cameras (poses/poses_report.json and its overlays), and give your masks for some "
                    "or all photos in CAPTURE/masks/<name>.png (white = object) or with --user-masks DIR")
        if beside is not None and beside["retried"]:
            lost = (f"the first masks left out, beside them, pixels no background explains "
                    f"({100 * beside['median']:.0f} % of a mask's area, median view)")
            after = "?" if beside["median_after"] is None else f"{100 * beside['median_after']:.0f} %"
            if beside["kept"] == "second":
                warnings.append(
                    f"{lost}: a part lost alike in every view (mirror-like, or coloured like the room). The masks were "
                    f"made again counting those pixels as the object's ({after} left beside them); check "
                    "contact_sheet.jpg: a table or a prop next to the object may now be in them "
                    "(masks.unexplained_retry_share=0 turns this off), or give masks for a few views in CAPTURE/masks/")
            else:
                warnings.append(
                    f"{lost}. Made again counting them as the object's, the masks still left {after} beside them: "
                    "not a part of the object lost alike in every view but something wider that no background "
                    "explains (a table under the object, when the support plane found is the floor), so the first "
                    "masks are kept; check contact_sheet.jpg for a mirror-like part missing, and give masks for a "
                    "few views in CAPTURE/masks/ if one is")

        # The hull of the final masks: the views' agreement and the object's bounding sphere.
        points, index = hull_grid(opts.hull_resolution, plane)
        votes = stand_on_plane(carve(final, voxel_pixels(points, views, run_views), index, opts.hull_resolution,
                                     run_views=run_views), plane, opts.stand_height)
        hull_task = bar.add_task("hull", total=len(views))
        hulls = []
        for v in views:
            hulls.append(reproject(votes, v, carve_votes(opts, len(views)) - 0.5, plane))
            bar.advance(hull_task)
    agreement = [iou(m, h) for m, h in zip(final, hulls)]
    c2w = np.stack([v.c2w for v in views])
    K = np.stack([v.K for v in views])
    floor = (plane.normal, plane.offset) if plane is not None else None
    sphere = sphere_from_masks(final, c2w, K, np.zeros(3), 1.0, floor=floor)
    if sphere is None:
        warnings.append("the masks' visual hull is empty (the masks disagree with each other or with the "
                        "cameras); the sphere the masks were searched in is kept")
        centre, radius = np.zeros(3), 1.0
    else:
        centre, radius = sphere[0], sphere[1] * config.sphere_margin
    warnings += _check(names, final, agreement, views, radius, prior, config)
    if plane is None and config.floor and len(fixed) < len(views):
        warnings.append("no support plane was found (the floor or table under the object, by photo-consistency): "
                        "the automatic masks cannot tell the floor beside the object from the object and may keep a "
                        "skirt of it; check contact_sheet.jpg, and give masks for a few views in CAPTURE/masks/")
    # back to the poses frame: segmentation ran where the prior sphere is the unit sphere
    centre, radius = prior.centre + prior.radius * centre, prior.radius * radius
    if plane is not None:
        plane = plane.unframed(prior.centre, prior.radius)
    for w in warnings:
        log.warning("%s", w)

    snap = edge_snap(config)
    with atomic_dir(out_dir, MASKS, sources) as tmp:
        (tmp / MASK_FILES).mkdir()
        (tmp / OVERLAYS).mkdir()
        records, tiles = [], []
        with progress() as bar:
            task = bar.add_task("write masks", total=len(names))
            for i, cam in enumerate(cameras.cameras):
                photo = decoded.srgb(cam.name)
                snapped = False
                if cam.name in user_files:  # read again, not kept from loading: one full-size mask in memory
                    full = user_mask(user_files[cam.name], cam, undistortion)
                else:
                    full, snapped = full_size_mask(final[i], photo, snap)
                write_png(tmp / mask_file(cam.name), np.where(full, 255, 0).astype(np.uint8))
                flagged = agreement[i] < config.agreement_warning
                overlay = mask_overlay(photo, full, hulls[i], cam.name in user_files, config.overlay_size)
                write_jpeg(tmp / OVERLAYS / f"{cam.name}.jpg", overlay)
                tiles.append(tile(overlay, cam.name, agreement[i], flagged))
                records.append({
                    "name": cam.name,
                    "source": "user" if cam.name in user_files else "auto",
                    "user_file": str(user_files[cam.name]) if cam.name in user_files else None,
                    "area_px": int(np.count_nonzero(full)),
                    "area_fraction": float(np.count_nonzero(full) / full.size),
                    "hull_iou": agreement[i],
                    "disagrees_with_hull": bool(flagged),
                    "outline_snapped": snapped,
                })
                bar.advance(task)
        write_jpeg(tmp / CONTACT_SHEET, contact_sheet(tiles))
        moved = relocated(cameras, poses_dir, out_dir)
        trained = renormalized(moved, centre, radius) if config.renormalize else moved
        save_cameras(tmp / CAMERAS_JSON, trained)
        # nerfstudio's files: ours (the frame training uses) and COLMAP's, each with the sparse points in its frame
        photos = {n: os.path.relpath(decoded.folder.resolve() / decoded.entry(n)[SRGB], out_dir.resolve())
                  for n in names}
        for cams, doc, ply in ((trained, TRANSFORMS_JSON, SPARSE_PLY),
                               (in_colmap_frame(trained), TRANSFORMS_COLMAP_JSON, SPARSE_PLY_COLMAP)):
            if sparse is not None:
                write_point_cloud(tmp / ply, from_colmap_frame(cams, sparse[0]), sparse[1] / 255.0)
            write_json(tmp / doc, nerfstudio_transforms(cams, photos, {n: mask_file(n) for n in names},
                                                        ply if sparse is not None else None))
        report = _report(records, agreement, (centre, radius, sphere is not None), config, plane, rounds, warnings,
                         scale, user_dir, time.time() - started)
        report["sparse_points"] = {
            "what": "the poses stage's sparse points by where they lie (pipeline.masking.tracks), in the final "
            "sphere prior: each photo that observed one takes it as object or background (no_evidence: neither)",
            "points": None if tracks is None else len(tracks.xyz), "labels": labelled}
        report["sphere_prior"] = {
            "what": "the sphere segmentation and the hull ran in (poses frame): the poses stage's unit sphere, "
            "grown while the probe's masks (the user's, when every view has one), then the final masks, reached "
            "its outline (pipeline.masking.prior; each probe's 'by' says which)",
            "centre": prior.centre.tolist(), "radius": prior.radius, "probes": prior.probes}
        report["unexplained_beside"] = None if beside is None else {
            "what": "pixels outside the masks, touching them, that no background explains (the support plane "
            "clearly does not, no surface outside the sphere does), as a share of the mask's area, median view: "
            "above the threshold the masks were made again with those pixels' background votes not counted, "
            "and the second masks kept (kept: second) only where they leave at most the threshold beside them "
            "(pipeline.masking.segment.refine_checked)", **beside}
        write_json(tmp / MASKS_REPORT, report)
        inputs: dict[str, Path] = {CAMERAS_JSON: poses_dir / CAMERAS_JSON, DECODE_JSON: decoded.folder / DECODE_JSON}
        inputs.update({f"user_mask:{n}": p for n, p in user_files.items()})
        inputs.update({f"{SPARSE}/{f.name}": f for f in sparse_files})
        write_manifest(tmp, stage=MASKS, inputs=inputs, config=config.model_dump(mode="json"), started=started,
                       capture=capture)
    seconds = time.time() - started
    summary = report["agreement"]
    log.info("masks: %d views (%d user, %d automatic), hull agreement IoU median %.3f (worst %.3f, %s), object "
             "sphere centre %s radius %.3f of the poses sphere -> %s (%.1f s)", len(names), len(user_files),
             len(names) - len(user_files), summary["median"], summary["min"], summary["worst_view"],
             np.array2string(centre, precision=3), radius, out_dir, seconds)
    return MasksResult(out_dir, names, sorted(user_files), centre, float(radius),
                       {"median": summary["median"], "min": summary["min"]}, warnings, seconds)


def _photos_without_camera(poses_dir: Path, decoded: DecodeArtifacts, names: list[str]) -> set[str]:
    """Decoded photos that got no camera (the poses stage lets SfM drop a few): those in the decoded folder and
    those the poses stage's report lists (its ``undistorted/`` folder holds only the posed photos)."""
    photos = set(decoded.names)
    if (poses_dir / POSES_REPORT).is_file():
        photos |= set(read_stage_json(poses_dir / POSES_REPORT, POSES).get("not_registered", []))
    return photos - set(names)


def _check(names: list[str], masks: list[np.ndarray], agreement: list[float], views: list[View], radius: float,
           prior: PriorSphere, config: MasksConfig) -> list[str]:
    """Warnings a person should act on: empty masks, views that disagree with the hull, an object that seems
    larger than the sphere the masks were searched in (its masks were clipped by that sphere's image). ``views``
    and ``radius``: in the frame where ``prior`` is the unit sphere."""
    out = []
    empty = [n for n, m in zip(names, masks) if not m.any()]
    if empty:
        out.append(f"empty mask (no object found) in {len(empty)} view(s): {', '.join(empty[:10])}")
    bad = [(n, a) for n, a in zip(names, agreement) if a < config.agreement_warning]
    if bad:
        out.append(f"{len(bad)} view(s) disagree with the visual hull (IoU < {config.agreement_warning}): "
                   + ", ".join(f"{n} ({a:.2f})" for n, a in bad[:10])
                   + "; check their overlays, or give corrected masks for them in CAPTURE/masks/")
    touching = touching_views(masks, views)
    if touching > config.prior_touch_share * len(views) or radius > 1.0:
        out.append(f"the object reaches the edge of the sphere the masks were searched in ({prior.radius:.2f} times "
                   f"the poses stage's) in {touching} view(s): it may be larger and cut; raise "
                   "masks.prior_max_growth, rerun poses with a larger poses.object_window, or give masks")
    return out


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
            # training reads this one (its hull start is cut below it)
            "cameras_json": {"normal": plane.normal.tolist(),
                             "offset": plane.framed(centre, radius).offset if config.renormalize else plane.offset},
        },
        "rounds": rounds,
        "work_scale": scale,
        "outline_snapped": {
            "what": "views whose outline, brought up from the working size, was moved onto the photo's edges "
            "(masks.snap_*: kept only where it found clearly stronger edges)",
            "views": [r["name"] for r in records if r["outline_snapped"]]},
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
sphere is the unit sphere: train on it), transforms.json and transforms_colmap.json (nerfstudio: ns-train
splatfacto --data results/mug/masks/transforms.json), overlays/, contact_sheet.jpg, masks_report.json.
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
    config = config_from_arguments(args, MASKS, capture / CAPTURE_YAML)
    poses, out = stage_dir(capture, POSES, args.poses), stage_dir(capture, MASKS, args.out)
    return run_masks(capture, poses, out, config.masks, decode_dir=stage_dir(capture, DECODE, args.decode),
                     user_masks_dir=args.user_masks, force=args.force)
