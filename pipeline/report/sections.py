"""What the report shows of each stage, read from the stage's folder: one function a stage, from its folder to
the data its part of the template (``templates/report.html.j2``, a macro named after the stage) lays out, and
a one-line summary for the overview. Labels and figures are chosen here; markup is the template's.

A file a stage should have written but did not (or that does not parse) is noted by the :class:`Reader` and
named in the section; a section that cannot be built at all says why, and the others are still shown."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..config import dotted
from ..evaluation import metric_rows
from ..layout import (
    CONTACT_SHEET,
    DECODE,
    DECODE_JSON,
    ENVIRONMENT,
    ENVIRONMENT_GRID,
    EVALUATE,
    EVALUATE_JSON,
    EXPORT,
    EXPORT_JSON,
    FLYTHROUGH_VIDEO,
    HELD_OUT_GRID,
    MANIFEST,
    MASKS,
    MASKS_REPORT,
    MESH,
    MESH_COLMAP_PLY,
    MESH_FIGURE,
    MESH_PLY,
    MESH_REPORT,
    METRICS,
    OBJECT_GRID,
    OBJECT_VIEWS,
    ORBIT_VIDEO,
    PANORAMA,
    POINT_CLOUD,
    POINT_CLOUD_COLMAP,
    POSES,
    POSES_FIGURE,
    POSES_REPORT,
    PREVIEWS,
    TENSORBOARD,
    TRAIN,
    TRAIN_CONFIG,
    TRAIN_REPORT,
    VIDEOS,
)
from .curves import appearance_figure, read_metrics, training_curves
from .page import duration, text
from .reader import Reader

log = logging.getLogger("orca.report")

THUMBNAILS = 8  # photos shown in the capture section (evenly spaced)
THUMBNAIL_WIDTH = 200
VIEW_WIDTH = 240

Data = dict[str, Any]


def _stats(values: Sequence[Any]) -> dict[str, float] | None:
    v = np.asarray([x for x in values if isinstance(x, int | float) and math.isfinite(x)], np.float64)
    if v.size == 0:
        return None
    return {"min": float(v.min()), "median": float(np.median(v)), "mean": float(v.mean()), "max": float(v.max())}


def _size_text(size: Any, sep: str = " x ") -> Any:
    """A report's ``[width, height]`` as text; anything else as it is."""
    return f"{size[0]}{sep}{size[1]}" if isinstance(size, list) and len(size) == 2 else size


def _evenly(items: Sequence[Any], n: int) -> list[Any]:
    if len(items) <= n:
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, n).round().astype(int)]


def section_decode(reader: Reader, folder: Path) -> tuple[str, Data]:
    meta = reader.json(folder / DECODE_JSON)
    if not isinstance(meta, dict):
        return f"{DECODE_JSON} missing", {"unreadable": folder / DECODE_JSON}
    manifest = reader.json(folder / MANIFEST, required=False) or {}
    images = meta.get("images") or []
    size = meta.get("size")
    formats = sorted({im.get("format", "?") for im in images})
    clip = _stats([im.get("clipped_fraction") for im in images])
    wb = meta.get("white_balance") or {}
    exposure = meta.get("exposure") or {}
    ref = next((im for im in images if im.get("source") == meta.get("reference_image")), images[0] if images else {})
    exif = ref.get("exif") or {}
    exif_values = [im.get("exif") or {} for im in images]

    def span(key: str) -> Any:
        s = _stats([e.get(key) for e in exif_values])
        if s is None:
            return None
        return text(s["min"]) if s["min"] == s["max"] else f"{text(s['min'])} – {text(s['max'])}"

    worst = max(images, key=lambda im: im.get("clipped_fraction") or 0.0) if images else None
    rows = [
        ("capture", meta.get("capture")),
        ("photos decoded", len(images)),
        ("skipped files", ", ".join(meta.get("skipped") or []) or "none"),
        ("size (width x height)", _size_text(size)),
        ("downscale", meta.get("downscale")),
        ("formats", ", ".join(formats)),
        ("reference image", meta.get("reference_image")),
        ("camera", " ".join(str(exif[k]) for k in ("make", "model") if exif.get(k)) or None),
        ("focal length (mm; 35 mm equivalent)",
         f"{text(exif.get('focal_length_mm'))}; {text(exif.get('focal_length_35mm'))}" if exif else None),
        ("shutter (s)", span("shutter_s")), ("ISO", span("iso")), ("f-number", span("f_number")),
        ("white balance", f"{text(wb.get('multipliers'))} ({text(wb.get('source'))})" if wb else None),
        ("exposure normalized", exposure.get("normalized")),
        ("exposure fields used", ", ".join(exposure.get("fields_used") or []) or "none"),
        ("clipped fraction (mean / max)",
         f"{100 * clip['mean']:.2f} % / {100 * clip['max']:.2f} % ({worst.get('name')})" if clip and worst else None),
    ]
    config = manifest.get("config") if isinstance(manifest, dict) else None
    warnings = []
    missing = exposure.get("fields_missing_in_all") or []
    if missing:
        warnings.append(f"EXIF fields missing in every photo: {', '.join(map(str, missing))}")
    if meta.get("skipped"):
        warnings.append(f"skipped files: {', '.join(map(str, meta['skipped']))}")
    thumbnails = [reader.picture(folder / im["srgb"], im.get("name"), width=THUMBNAIL_WIDTH, css="thumb")
                  for im in _evenly(images, THUMBNAILS) if im.get("srgb")]
    per_photo = [(im.get("name"), im.get("source"), im.get("format"), (im.get("exif") or {}).get("shutter_s"),
                  (im.get("exif") or {}).get("iso"), (im.get("exif") or {}).get("f_number"),
                  im.get("exposure_scale"),
                  100 * im["clipped_fraction"] if isinstance(im.get("clipped_fraction"), int | float) else None)
                 for im in images]
    summary = f"{len(images)} photos" + (
        f", {_size_text(size, 'x')}" if isinstance(size, list) and len(size) == 2 else "")
    if clip:
        summary += f", clipped {100 * clip['mean']:.2f} % mean"
    return summary, {"rows": rows, "settings": sorted(config.items()) if isinstance(config, dict) else [],
                     "warnings": warnings, "thumbnails": thumbnails, "shown": min(len(images), THUMBNAILS),
                     "per_photo": per_photo}


def section_poses(reader: Reader, folder: Path) -> tuple[str, Data]:
    report = reader.json(folder / POSES_REPORT)
    figure = reader.picture(folder / POSES_FIGURE, "cameras around the object (normalized frame): top and side views")
    if not isinstance(report, dict):
        return f"{POSES_REPORT} missing", {"unreadable": folder / POSES_REPORT, "figure": figure}
    features = report.get("features") or {}
    cams = report.get("cameras_normalized") or {}
    obj = report.get("object") or {}
    rows = [
        ("cameras from", "SfM (pycolmap)" if report.get("source") == "sfm" else
         f"known cameras: {report.get('source')}"),
        ("registered / total", f"{report.get('registered')} / {report.get('total')}"),
        ("not registered", ", ".join(report.get("not_registered") or []) or "none"),
        ("why not registered", "; ".join(f"{n}: {why}" for n, why in (report.get("not_registered_why") or {}).items())
         or ...),
        ("mean reprojection error (px)", report.get("mean_reprojection_error_px", ...)),
        ("mean track length", report.get("mean_track_length", ...)),
        ("3-D points", report.get("points3D", ...)),
        ("mean observations per image", report.get("mean_observations_per_image", ...)),
        ("features per photo (min / median / max)",
         f"{features.get('min')} / {features.get('median')} / {features.get('max')}" if features else ...),
        ("matcher", report.get("matcher", ...)),
        ("image pairs matched / verified", f"{report.get('pairs_matched')} / {report.get('pairs_verified')}"
         if "pairs_matched" in report else ...),
        ("models (photos in each)", report.get("models", ...)),
        ("intrinsics", "; ".join(f"{i.get('model')} {text(i.get('params'))} ({i.get('photos')} photos)"
                                 for i in report.get("intrinsics") or []) or None),
        ("undistorted to pinhole", report.get("undistorted")),
        ("object radius from", obj.get("radius_from")),
        ("camera distance from the object centre (min / median / max, object radii)",
         f"{text(cams.get('distance_min'))} / {text(cams.get('distance_median'))} / {text(cams.get('distance_max'))}"
         if cams else None),
    ]
    warnings = list(report.get("warnings") or [])
    if report.get("not_registered"):
        warnings.insert(0, f"{len(report['not_registered'])} photo(s) without a camera: "
                           f"{', '.join(report['not_registered'])}")
    if isinstance(report.get("models"), list) and len(report["models"]) > 1:
        warnings.insert(0, f"SfM split the photos into {len(report['models'])} models {report['models']}; the "
                           "largest is used")
    errors = report.get("reprojection_error_px_per_image") or {}
    feats = features.get("per_image") or {}
    summary = f"{report.get('registered')}/{report.get('total')} registered"
    if isinstance(report.get("mean_reprojection_error_px"), int | float):
        summary += f", reprojection {report['mean_reprojection_error_px']:.2f} px"
    return summary, {"rows": rows, "warnings": warnings, "figure": figure,
                     "per_photo": [(n, e, feats.get(n)) for n, e in errors.items()]}


def section_masks(reader: Reader, folder: Path) -> tuple[str, Data]:
    report = reader.json(folder / MASKS_REPORT)
    sheet = reader.picture(folder / CONTACT_SHEET,
                           "contact sheet: mask outline green (orange: your masks), visual hull magenta; views that "
                           "disagree with the hull framed in red")
    if not isinstance(report, dict):
        return f"{MASKS_REPORT} missing", {"unreadable": folder / MASKS_REPORT, "sheet": sheet}
    views = report.get("views") or []
    agreement = report.get("agreement") or {}
    sphere = report.get("object_sphere") or {}
    plane = report.get("support_plane")
    user = (report.get("user_masks") or {}).get("views") or []
    areas = _stats([v.get("area_fraction") for v in views])
    rows = [
        ("views", len(views)),
        ("your masks / automatic", f"{len(user)} / {len(views) - len(user)}"),
        ("mask area (share of the photo, min / median / max)",
         f"{100 * areas['min']:.1f} % / {100 * areas['median']:.1f} % / {100 * areas['max']:.1f} %" if areas else None),
        ("agreement with the visual hull (IoU median / mean / min)",
         f"{text(agreement.get('median'), 3)} / {text(agreement.get('mean'), 3)} / {text(agreement.get('min'), 3)}"
         if agreement else None),
        ("worst view", agreement.get("worst_view")),
        ("warning threshold (IoU)", agreement.get("threshold")),
        ("views that disagree with the hull", ", ".join(agreement.get("disagreeing_views") or []) or "none"),
        ("object sphere (poses frame): centre, radius",
         f"{text(sphere.get('centre'), 3)}, {text(sphere.get('radius'), 3)}" if sphere else None),
        ("support plane", "none found" if plane is None else
         f"normal {text(plane.get('normal'), 3)}, offset {text(plane.get('offset'), 3)}, explains "
         f"{text(plane.get('explained_fraction'), 3)} of the pixels"),
        ("rounds", len(report.get("rounds") or [])),
        ("time", duration(report.get("seconds"))),
    ]
    per_view = [(v.get("name"), v.get("source"), v.get("area_px"),
                 100 * v["area_fraction"] if isinstance(v.get("area_fraction"), int | float) else None,
                 v.get("hull_iou"), "DISAGREES" if v.get("disagrees_with_hull") else "") for v in views]
    summary = f"{len(views)} views"
    if isinstance(agreement.get("median"), int | float):
        summary += f", hull IoU median {agreement['median']:.3f}"
    if agreement.get("disagreeing_views"):
        summary += f", {len(agreement['disagreeing_views'])} flagged"
    return summary, {"rows": rows, "warnings": report.get("warnings") or [], "sheet": sheet,
                     "threshold": text(agreement.get("threshold")), "per_view": per_view}


def section_train(reader: Reader, folder: Path) -> tuple[str, Data]:
    report = reader.json(folder / TRAIN_REPORT)
    config = reader.json(folder / TRAIN_CONFIG, required=False)
    config = dotted(config) if isinstance(config, dict) else None  # the train config's groups as sdf.hidden, ...
    data: Data = {"losses": [], "curves": None, "last": None, "bad": 0, "metrics": folder / METRICS,
                  "metrics_state": "ok", "preview": None, "appearance": None,
                  "config": sorted(config.items()) if isinstance(config, dict) else [],
                  "tensorboard": folder / TENSORBOARD}
    if isinstance(report, dict):
        rows = [
            ("iterations", report.get("iterations")),
            ("training time", duration(report.get("training_seconds"))),
            ("time in the last run (resumed runs add up)", duration(report.get("seconds_this_run"))),
            ("device", report.get("device")),
            ("images", len(report.get("images") or [])),
            ("image size", _size_text(report.get("size"))),
            ("final beta (VolSDF)", report.get("beta")),
        ]
        if isinstance(config, dict):
            rows += [(k, config.get(k, ...)) for k in ("batch_rays", "mask_warmup", "lr", "sdf.encoding")]
        data["rows"] = rows
        data["losses"] = sorted((report.get("final_losses") or {}).items())
        gains = report.get("appearance")
        if isinstance(gains, dict) and gains:
            data["appearance"] = reader.figure(appearance_figure(gains), "each training photo's learned exposure "
                                               "and white balance, relative to the photos' average (train.appearance)")
        summary = f"{report.get('iterations')} iterations, {duration(report.get('training_seconds'))}"
    else:
        data["unreadable"] = folder / TRAIN_REPORT
        summary = "train_report.json missing"
    metrics = data["metrics"]
    if metrics.is_file():
        reader.record(metrics)
        rows, data["bad"] = read_metrics(metrics)
        if rows:
            last = rows[-1]
            data["curves"] = reader.figure(training_curves(rows), f"from metrics.jsonl ({len(rows)} rows, every "
                                           "logged step); dotted line: end of the mask-only warm-up")
            best = _stats([r.get("psnr_object") for r in rows])
            data["last"] = [("step", last.get("step")), ("phase", last.get("phase")), ("loss", last.get("loss")),
                            ("PSNR on object pixels (dB)", last.get("psnr_object")),
                            ("best PSNR logged (dB)", best["max"] if best else None),
                            ("wall-clock at this step", duration(last.get("seconds")))]
            if isinstance(last.get("psnr_object"), int | float) and math.isfinite(last["psnr_object"]):
                summary += f", PSNR {last['psnr_object']:.1f} dB"
        else:
            data["metrics_state"] = "empty"
        if data["bad"]:
            reader.problems.append(f"{reader.rel(metrics)}: {data['bad']} line(s) did not parse")
    else:
        reader.problems.append(f"{reader.rel(metrics)} is missing")
        data["metrics_state"] = "missing"
    previews = sorted((folder / PREVIEWS).glob("step_*.png")) if (folder / PREVIEWS).is_dir() else []
    if previews:
        data["preview"] = reader.picture(previews[-1], f"{previews[-1].stem} (first training image)")
    return summary, data


def section_mesh(reader: Reader, folder: Path) -> tuple[str, Data]:
    report = reader.json(folder / MESH_REPORT)
    data: Data = {
        "picture": reader.picture(folder / MESH_FIGURE, "three views of the mesh (shaded, diffuse vertex colours)"),
        "mesh": reader.link(folder / MESH_PLY),
        "colmap": reader.link(folder / MESH_COLMAP_PLY) if (folder / MESH_COLMAP_PLY).is_file() else None}
    if not isinstance(report, dict):
        return "mesh_report.json missing", {**data, "unreadable": folder / MESH_REPORT}
    tri = report.get("triangles")
    data["rows"] = [
        ("vertices", report.get("vertices")), ("triangles", tri),
        ("watertight", report.get("watertight")), ("winding consistent", report.get("winding_consistent", ...)),
        ("vertex manifold", report.get("vertex_manifold", ...)), ("Euler number", report.get("euler_number", ...)),
        ("pieces kept / found", f"{report.get('components_kept')} / {report.get('components')}"),
        ("grid (voxels per side), voxel size", f"{report.get('resolution')}, {text(report.get('voxel_size'))}"),
        ("bounds min / max", f"{text(report.get('bbox_min'), 3)} / {text(report.get('bbox_max'), 3)}"
         if "bbox_min" in report else ...),
        ("largest distance from the centre", report.get("max_radius", ...)),
        ("area", report.get("area", ...)), ("volume", report.get("volume", ...)),
        ("frame", report.get("frame")), ("vertex colours", report.get("colors")),
        ("time", duration(report.get("seconds_total"))),
    ]
    data["warnings"] = []
    if tri == 0:
        data["warnings"].append("the mesh is empty: the SDF never crosses zero (is the model trained?)")
    elif report.get("watertight") is False:
        data["warnings"].append("the mesh is not watertight (holes or non-manifold edges)")
    summary = f"{report.get('vertices')} vertices, {tri} triangles, " + (
        "watertight" if report.get("watertight") else "NOT watertight")
    return summary, data


EXPORT_FILES = (  # (file, what it is, named even when missing): the COLMAP-frame cloud only when the cameras
    # had that frame
    (Path(VIDEOS) / ORBIT_VIDEO, "orbit of the object (video)", True),
    (Path(VIDEOS) / FLYTHROUGH_VIDEO, "flythrough of the environment from inside the object (video)", True),
    (Path(POINT_CLOUD), "the environment as a coloured point cloud", True),
    (Path(POINT_CLOUD_COLMAP), "the same in COLMAP's frame", False),
)
OBJECT_PARTS = ("rgb", "diffuse", "specular", "normal")


def _views(reader: Reader, folder: Path, names: Sequence[str]) -> Data | None:
    """A table of environment views: each one's RGB and depth pictures."""
    if not names:
        return None
    return {"names": list(names),
            "rgb": [reader.picture(folder / f"{n}_rgb.png", alt=f"{n} RGB", width=VIEW_WIDTH) for n in names],
            "depth": [reader.picture(folder / f"{n}_depth.png", alt=f"{n} depth", width=VIEW_WIDTH) for n in names]}


def section_export(reader: Reader, folder: Path) -> tuple[str, Data]:
    report = reader.json(folder / EXPORT_JSON)
    data: Data = {}
    if not isinstance(report, dict):
        report = {}
        data["unreadable"] = folder / EXPORT_JSON
    else:
        pano = report.get("panorama") or {}
        scale = report.get("depth_png_scale") or {}
        cloud = report.get("point_cloud") or {}
        videos = report.get("videos") or {}
        frame = report.get("frame") or {}
        data["rows"] = [
            ("trained with cameras", report.get("cameras")),
            ("units", frame.get("units")),
            ("up (world)", frame.get("up")),
            ("environment views", f"{len(report.get('environment_views') or [])} at {report.get('view_size')} px"),
            ("panorama", f"{pano.get('width')} x {pano.get('height')}" if pano else None),
            ("depth colour scale", f"{text(scale.get('min'))} – {text(scale.get('max'))} "
                                   f"({text(scale.get('colormap'))}; {text(scale.get('meaning'))})"
                                   if scale else None),
            ("point cloud", f"{cloud.get('points')} points (depth below {text(cloud.get('max_depth'))})"
                            if cloud else None),
            ("videos", f"{text((videos.get('orbit') or {}).get('frames'))} + "
                       f"{text((videos.get('flythrough') or {}).get('frames'))} frames at "
                       f"{text(videos.get('size'))}, {text(videos.get('fps'))} fps" if videos else None),
            ("object views", ", ".join(report.get("object_views") or []) or "none"),
            ("tone mapping", report.get("tone_mapping")),
            ("time", ", ".join(f"{k} {duration(v)}" for k, v in (report.get("seconds") or {}).items()) or None),
        ]
    data["files"] = [(what, reader.link(folder / path)) for path, what, always in EXPORT_FILES
                     if always or (folder / path).exists()]
    data["panorama"] = [
        reader.picture(folder / PANORAMA / f"{PANORAMA}_rgb.png", "panorama (environment field, sRGB)"),
        reader.picture(folder / PANORAMA / f"{PANORAMA}_depth.png", "panorama depth (distance along each ray, turbo)")]
    env = folder / ENVIRONMENT
    names = list(report.get("environment_views") or [])
    if not names and env.is_dir():
        names = sorted(p.name[: -len("_rgb.png")] for p in env.glob("*_rgb.png"))
    data["cube"] = _views(reader, env, [n for n in names if n.startswith("cube_")])
    data["other"] = _views(reader, env, [n for n in names if not n.startswith("cube_")])
    data["objects"] = [(name, [reader.picture(folder / OBJECT_VIEWS / f"{name}_{part}.png", required=False)
                               for part in OBJECT_PARTS]) for name in report.get("object_views") or []]
    summary = f"{len(names)} environment views, panorama" + (
        f", {report['point_cloud'].get('points')} points" if isinstance(report.get("point_cloud"), dict) else "")
    return summary, data


def _evaluated_views(reader: Reader, folder: Path, part: Any, title: str, grid: str) -> tuple[Data | None, Data]:
    """One part of ``evaluate.json`` (object or environment views): the means (label, value, unit, which way
    is better), the compared region when the part names one, every view's figures and the comparison grid;
    and the means as they are. None when the part is absent."""
    if not isinstance(part, dict):
        return None, {}
    means = part.get("mean") or {}
    per_view = part.get("per_view") or {}
    keys = list(means)
    return {"title": title, "views": len(part.get("views") or []), "downscale": part.get("downscale"),
            "means": [(label, value, unit, f"{better} is better" if better else "")
                      for label, value, unit, better in metric_rows(means)],
            "region": part.get("region"), "each": title.lower()[:-1], "columns": ["view", *keys],
            "per_view": [(n, *[(v or {}).get(k) for k in keys]) for n, v in per_view.items()],
            "grid": reader.picture(folder / grid, f"{title.lower()}: ground truth beside prediction")}, means


def section_evaluate(reader: Reader, folder: Path) -> tuple[str, Data]:
    results = reader.json(folder / EVALUATE_JSON)
    if not isinstance(results, dict):
        return f"{EVALUATE_JSON} missing", {"unreadable": folder / EVALUATE_JSON}
    data: Data = {"rows": [
        ("ground truth", results.get("ground_truth")),
        ("alignment to the ground truth", results.get("alignment")),
        ("trained with the ground-truth cameras", results.get("trained_with_ground_truth_cameras")),
        ("downscale", results.get("downscale")),
        ("time", duration(results.get("seconds"))),
    ], "poses": None, "mesh": None}
    summary = []
    data["object"], means = _evaluated_views(reader, folder, results.get("object"), "Object views",
                                             OBJECT_GRID)
    for key, template in (("normal_mae_deg", "normals {:.2f}°"), ("psnr_srgb_specular", "specular {:.1f} dB (sRGB)")):
        if isinstance(means.get(key), int | float):
            summary.append(template.format(means[key]))
    data["environment"], means = _evaluated_views(reader, folder, results.get("environment"), "Environment views",
                                                  ENVIRONMENT_GRID)
    if isinstance(means.get("depth_absrel"), int | float):
        summary.append(f"environment depth AbsRel {means['depth_absrel']:.3g}")
    data["held_out"], means = _evaluated_views(reader, folder, results.get("held_out"), "Held-out photos",
                                               HELD_OUT_GRID)
    if isinstance(means.get("psnr_srgb_object"), int | float):
        summary.append(f"held-out photos: object {means['psnr_srgb_object']:.1f} dB, frame "
                       f"{text(means.get('psnr_srgb_frame'))} dB (sRGB; with each photo's gains matched: "
                       f"{text(means.get('psnr_srgb_object_matched'))} / {text(means.get('psnr_srgb_frame_matched'))}"
                       " dB)")
    poses = results.get("poses")
    if isinstance(poses, dict):
        s = poses.get("summary") or {}
        data["poses"] = [
            ("cameras aligned", s.get("cameras")), ("missing", s.get("missing")),
            ("rotation error median / max (deg)",
             f"{text(s.get('rotation_deg_median'))} / {text(s.get('rotation_deg_max'))}"),
            ("centre error median / max (% of orbit radius)",
             f"{text(s.get('center_median_percent'))} / {text(s.get('center_max_percent'))}"),
            ("method", poses.get("method")),
        ]
    mesh = results.get("mesh")
    if isinstance(mesh, dict):
        rows = [("Chamfer (object radii)", mesh.get("chamfer_fraction")),
                ("Hausdorff (object radii)", mesh.get("hausdorff_fraction"))]
        rows += [(f"F-score at {k[len('fscore_'):-len('pct')]} % of the radius", v) for k, v in mesh.items()
                 if k.startswith("fscore_")]
        data["mesh"] = [*rows, ("samples per surface", mesh.get("samples"))]
        if isinstance(mesh.get("chamfer_fraction"), int | float):
            summary.append(f"Chamfer {mesh['chamfer_fraction']:.3g} radii")
    return ", ".join(summary) or "evaluated", data


SECTIONS: dict[str, tuple[str, Callable[[Reader, Path], tuple[str, Data]]]] = {
    DECODE: ("Capture (decode)", section_decode),
    POSES: ("Poses", section_poses),
    MASKS: ("Masks", section_masks),
    TRAIN: ("Training", section_train),
    MESH: ("Mesh", section_mesh),
    EXPORT: ("Export: the environment and the object", section_export),
    EVALUATE: ("Evaluation against the ground truth", section_evaluate),
}


def _manifest_line(reader: Reader, folder: Path) -> Data:
    manifest = reader.json(folder / MANIFEST, required=False)
    if not isinstance(manifest, dict):
        return {"missing": reader.rel(folder / MANIFEST)}
    seconds = manifest.get("seconds")
    return {"created": manifest.get("created", "?"),
            "duration": duration(seconds) if isinstance(seconds, int | float) else None,
            "version": (manifest.get("versions") or {}).get("orca-capture")}


def section(reader: Reader, stage: str) -> Data:
    """The section of ``stage`` (a key of :data:`SECTIONS`): its ``id``, ``title``, ``status`` (missing,
    present, or incomplete when a file was missing or unreadable), ``summary``, ``folder``, and, for a stage
    that ran, its ``manifest`` line and either its ``data`` or the ``error`` that stopped it being built."""
    title, build = SECTIONS[stage]
    folder = reader.results / stage
    found: Data = {"id": stage, "title": title, "folder": folder}
    if not folder.is_dir():
        return {**found, "status": "missing", "summary": "not run" if stage != EVALUATE else "no evaluation"}
    problems_before = len(reader.problems)
    try:
        found["summary"], found["data"] = build(reader, folder)
    except Exception as e:  # noqa: BLE001 - a report shows what it can: one odd file must not hide the rest
        log.warning("report: the %s section failed: %s", stage, e)
        reader.problems.append(f"{stage}: {type(e).__name__}: {e}")
        found.update(summary="could not be read", error=f"{type(e).__name__}: {e}")
    found["status"] = "present" if len(reader.problems) == problems_before else "incomplete"
    return {**found, "manifest": _manifest_line(reader, folder)}
