"""``orca evaluate``: a trained model against a synthetic capture's ground truth.

Object views (the capture's cameras) are rendered from the model and compared with the ground truth: normals,
mask, combined, diffuse and specular radiance, depth. Environment views (virtual cameras at and near the object
centre, the object removed) are rendered from the environment field alone and compared in RGB and depth, over
all pixels and over the pixels of the scene's props. The model's frame is aligned to the ground truth's by a
similarity fitted on the cameras it was trained with (``--cameras``; default: those the train manifest
records), whose pose errors are reported; ``--mesh`` compares a mesh of the model with ``object.ply``. What
each figure is: :data:`pipeline.evaluation.DEFINITIONS`, also written into every ``evaluate.json``.

Writes ``OUT/`` atomically: ``evaluate.json`` (every figure per view and the means, what was compared, timing),
``object_grid.png`` and ``environment_grid.png`` (ground truth beside prediction), the predicted images at the
rendered size in decoded units and the ground-truth frame (``<view>_rgb|diffuse|specular|normal|depth.exr``,
the normal as rendered: opacity-weighted, not normalized; ``<view>_mask.png``; ``env_<view>_rgb|depth.exr``)
and ``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..alignment import Similarity, align_cameras
from ..artifacts import atomic_dir, file_sha256, read_json, write_json, write_manifest
from ..cameras import Camera, load_cameras, select_views
from ..downscale import block_all, block_mean
from ..errors import InputError
from ..evaluation import (
    DEFINITIONS,
    ENVIRONMENT_METRICS,
    HELD_OUT_METRICS,
    OBJECT_METRICS,
    environment_figures,
    held_out_figures,
    json_safe,
    means,
    object_figures,
    summary_tables,
)
from ..figures import environment_grid, held_out_grid, object_grid
from ..ground_truth import GroundTruth, resolve_ground_truth
from ..imageio import write_exr
from ..layout import (
    CAMERAS_JSON,
    ENVIRONMENT_GRID,
    EVALUATE_JSON,
    HELD_OUT_GRID,
    MANIFEST,
    MASK_FILES,
    MESH,
    MESH_PLY,
    MODEL,
    OBJECT_GRID,
    POSES,
    TRAIN,
    TRAIN_REPORT,
)
from ..log import console, progress
from ..mask_file import read_mask
from ..metrics import mesh_errors
from ..model_io import model_file
from ..props import PROP_MARGIN
from ..provenance import FORCE_HELP, common_capture
from ..rendering import load_renderer, render_composite_view, render_environment_view, render_object_view, write_views
from ..results import image_folder, load_decode

log = logging.getLogger("orca.evaluate")

GRID_OBJECT_VIEWS = 4


def render(model, cam: Camera, downscale: int, align: Similarity, environment: bool = False) -> dict[str, np.ndarray]:
    """A ground-truth camera rendered from the model (the environment field alone for an environment view):
    the camera moved into the model's frame, depth and normals moved back into the ground truth's."""
    in_model = cam.model_copy(update={"camera_to_world": align.apply_inverse_c2w(cam.c2w).tolist()})
    r = (render_environment_view if environment else render_object_view)(model, in_model, downscale)
    if not environment:
        r["normal"] = align.rotate(r["normal"]).astype(np.float32)
    r["depth"] = (r["depth"] * align.scale).astype(np.float32)
    return r


def evaluate_views(model, gt: GroundTruth, align: Similarity, views: int | Sequence[str] | None, downscale: int,
                   out: Path, environment: bool) -> dict[str, Any]:
    """Every selected object (or environment) view rendered, compared, written to ``out`` with its grid."""
    cams = (gt.environment_cameras if environment else gt.cameras).by_name()
    names = select_views(list(cams), views)
    in_grid = set(names if environment else select_views(names, GRID_OBJECT_VIEWS))
    part = "environment" if environment else "object"
    per_view: dict[str, dict[str, Any]] = {}
    rows = []
    started = time.time()
    with progress() as bar:
        task = bar.add_task(f"evaluate {part} views", total=len(names))
        for name in names:
            if environment:
                truth = gt.environment_view(cams[name], downscale)
                pred = render(model, cams[name], downscale, align, environment=True)
                figures = environment_figures(pred, truth)
            else:
                truth, region = gt.object_view(cams[name], downscale)
                pred = render(model, cams[name], downscale, align)
                figures = {**object_figures(pred, truth), "region": region}
                if figures["pixels"]["region"] == 0:
                    log.warning("view %s: no object region pixels at downscale %d; its radiance figures are NaN",
                                name, downscale)
            per_view[name] = figures
            write_views(out, f"env_{name}" if environment else name, pred)
            if name in in_grid:
                rows.append((name, pred, truth, figures))
            bar.advance(task)
    seconds = time.time() - started
    if rows:
        grid, name = (environment_grid, ENVIRONMENT_GRID) if environment else (object_grid, OBJECT_GRID)
        grid(out / name, rows)
    compared = {"prop_margin": PROP_MARGIN} if environment else {
        "region": next(iter(per_view.values()))["region"] if per_view else None}
    return {"views": names, "downscale": downscale, **compared, "per_view": per_view,
            "mean": means(per_view, ENVIRONMENT_METRICS if environment else OBJECT_METRICS),
            "seconds_per_view": seconds / max(len(names), 1)}


def _train_input(train_dir: Path, key: str = "cameras") -> dict[str, Any]:
    """The train manifest's record of one of its inputs (``path``, ``sha256``; ``cameras``: the cameras.json it
    was trained with, ``decode``: the decode.json of its images), or {}."""
    try:
        record = read_json(train_dir / MANIFEST)["inputs"][key]
    except (OSError, KeyError, TypeError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def run_evaluate(
    train_dir: Path,
    gt_dir: Path,
    out_dir: Path,
    *,
    views: int | Sequence[str] | None = None,
    downscale: int = 1,
    object: bool = True,  # the name of the CLI's --no-object (shadows the builtin here only)
    environment: bool = True,
    to_ground_truth: np.ndarray | None = None,
    cameras: Path | None = None,
    mesh: Path | None = None,
    device: str = "auto",
    force: bool = False,
) -> dict[str, Any]:
    """Evaluate a train folder against a ground-truth folder and write ``out_dir`` atomically.

    Args:
        views: object views: None (all), N evenly spaced, or names. Environment views: always all.
        downscale: render (and compare) k times smaller, for both object and environment views.
        to_ground_truth: 4x4 similarity model frame -> ground-truth frame; default: fitted on the centres of
            ``cameras`` (below), else identity.
        cameras: the cameras.json the model was trained with (its frame is the model's); default: the one the
            train manifest records. Gives the alignment and the pose errors.
        mesh: a mesh of the model (``orca mesh``'s mesh.ply, model frame) to compare with ``object.ply``.
    Returns:
        The content of ``evaluate.json`` (NaN written as null).
    """
    started = time.time()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    if not object and not environment:
        raise InputError("nothing to evaluate: both the object and the environment views are switched off",
                         fix="drop --no-object or --no-environment")
    if downscale < 1:
        raise InputError(f"--downscale must be at least 1, got {downscale}")
    weights = model_file(train_dir)
    gt = resolve_ground_truth(gt_dir)
    if environment and not gt.has_environment:
        raise InputError("the ground truth has no environment views", gt.folder / "environment" / CAMERAS_JSON,
                         "pass --no-environment, or regenerate the capture with `orca synth`")
    if mesh is not None and not Path(mesh).is_file():
        raise InputError("mesh not found", mesh, "run `orca mesh` first, or drop --mesh")
    recorded = _train_input(train_dir)
    trained_on_gt = recorded["sha256"] == file_sha256(gt.folder / CAMERAS_JSON) if "sha256" in recorded else None
    if cameras is None and isinstance(recorded.get("path"), str) and Path(recorded["path"]).is_file():
        cameras = Path(recorded["path"])
    cameras = Path(cameras) if cameras is not None else None
    capture = common_capture([train_dir, gt.folder, cameras, mesh], force=force)
    matrix = np.eye(4) if to_ground_truth is None else np.asarray(to_ground_truth, np.float64)
    poses: dict[str, Any] = {}
    if cameras is not None:
        fitted, poses = align_cameras(load_cameras(cameras), gt.cameras, gt.object_centre, cameras)
        poses["cameras"] = str(cameras)
        s = poses["summary"]
        log.info("poses: %d cameras of %s aligned to the ground truth: rotation error median %.3g deg, centre "
                 "error median %.3g %% of the orbit radius", s["cameras"], cameras, s["rotation_deg_median"],
                 s["center_median_percent"])
        if to_ground_truth is None:
            matrix = fitted.matrix
    elif trained_on_gt is False and to_ground_truth is None:
        log.warning("the model was trained with other cameras than %s; without them (--cameras) its frame may "
                    "differ from the ground truth's and the figures will be meaningless", gt.folder / CAMERAS_JSON)
    align = Similarity.from_matrix(matrix)
    model = load_renderer(train_dir, device)
    log.info("evaluate: %s against %s (downscale %d)", train_dir, gt.folder, downscale)
    results: dict[str, Any] = {
        "train": str(train_dir), "ground_truth": str(gt.folder), "downscale": downscale,
        "to_ground_truth": matrix.tolist(),
        "alignment": "given" if to_ground_truth is not None else (
            "fitted on camera centres" if cameras is not None else "identity (no cameras to fit on)"),
        "trained_with_ground_truth_cameras": trained_on_gt, "radiance_to_decoded": gt.factor,
        "definitions": DEFINITIONS, **({"poses": poses} if poses else {}),
    }
    with atomic_dir(out_dir, "evaluate", [train_dir, gt.folder, *(p for p in (cameras, mesh) if p)]) as tmp:
        if mesh is not None:
            results["mesh"] = {**mesh_errors(Path(mesh), gt.object_mesh(), gt.object_radius, matrix),
                               "definition": DEFINITIONS["mesh"]}
        if object:
            results["object"] = evaluate_views(model, gt, align, views, downscale, tmp, environment=False)
        if environment:
            results["environment"] = evaluate_views(model, gt, align, None, downscale, tmp, environment=True)
        results["seconds"] = round(time.time() - started, 2)
        results["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        results = json_safe(results)
        write_json(tmp / EVALUATE_JSON, results)
        inputs = {"model": weights, "cameras": gt.folder / CAMERAS_JSON, "scene": gt.scene_path,
                  **({"result_cameras": cameras} if cameras is not None else {}),
                  **({"mesh": Path(mesh)} if mesh is not None else {})}
        write_manifest(tmp, stage="evaluate", inputs=inputs, started=started,
                       config={"views": results.get("object", {}).get("views"), "downscale": downscale,
                               "object": object, "environment": environment}, capture=capture)
    for table in summary_tables(results):
        console.print(table)
    log.info("evaluate: wrote %s in %.1f s", out_dir, time.time() - started)
    return results


def run_held_out(
    train_dir: Path,
    out_dir: Path,
    *,
    cameras: Path | None = None,
    masks: Path | None = None,
    decode: Path | None = None,
    downscale: int = 1,
    device: str = "auto",
    force: bool = False,
) -> dict[str, Any]:
    """Evaluate a model on the photos its training held out (``train.holdout_every``): each held-out camera
    rendered (the object over the environment field) and compared with the photo; ``out_dir`` written atomically
    (``evaluate.json`` with a ``held_out`` part, ``held_out_grid.png``, ``<view>_render.exr``).

    Args:
        cameras: the cameras.json the model was trained with; default: the one the train manifest records.
        masks: the object masks (``masks/masks``); default: ``masks/`` beside ``cameras``.
        decode: the photos' decode folder, for cameras without image paths; default: the train manifest's.
    Returns:
        The content of ``evaluate.json`` (NaN written as null).
    """
    started = time.time()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    if downscale < 1:
        raise InputError(f"--downscale must be at least 1, got {downscale}")
    weights = model_file(train_dir)
    held = read_json(train_dir / TRAIN_REPORT).get("held_out") or []
    if not held:
        raise InputError("the model was trained on every photo: none was held out to compare with",
                         train_dir / TRAIN_REPORT, fix="train with --set holdout_every=8 (every 8th photo held out)")
    recorded = _train_input(train_dir)
    if cameras is None and isinstance(recorded.get("path"), str):
        cameras = Path(recorded["path"])
    if cameras is None or not Path(cameras).is_file():
        raise InputError("the cameras the model was trained with are not found", cameras or train_dir / MANIFEST,
                         fix="pass --cameras results/<capture>/masks/cameras.json")
    cameras = Path(cameras)
    masks = Path(masks) if masks is not None else cameras.parent / MASK_FILES
    if not masks.is_dir():
        raise InputError("no masks folder", masks, fix="pass --masks results/<capture>/masks/masks")
    camera_set = load_cameras(cameras)
    cams = camera_set.by_name()
    lacking = [n for n in held if n not in cams]
    if lacking:
        raise InputError(f"held-out photo(s) without a camera: {', '.join(lacking)}", cameras,
                         fix="pass the cameras.json the model was trained with (--cameras)")
    recorded_decode = _train_input(train_dir, "decode").get("path")
    fallback = Path(decode) if decode is not None else Path(recorded_decode).parent if recorded_decode else None
    decoded = load_decode(image_folder(camera_set, cameras.parent, fallback))
    capture = common_capture([train_dir, cameras, masks], force=force)
    model = load_renderer(train_dir, device)
    log.info("evaluate: %d held-out photo(s) of %s (downscale %d)", len(held), train_dir, downscale)
    per_view: dict[str, dict[str, Any]] = {}
    with atomic_dir(out_dir, "evaluate", [train_dir, cameras, masks]) as tmp, progress() as bar:
        task = bar.add_task("evaluate held-out photos", total=len(held))
        rows = []
        for name in held:
            render = render_composite_view(model, cams[name], downscale)
            h, w = render.shape[:2]
            photo = block_mean(decoded.linear(name)[: h * downscale, : w * downscale], downscale)
            valid = block_all(~decoded.clipped(name)[: h * downscale, : w * downscale], downscale)
            mask = read_mask(masks / f"{name}.png", (w, h))
            per_view[name] = held_out_figures(render, photo, mask, valid)
            write_exr(tmp / f"{name}_render.exr", render)
            rows.append((name, photo, render, mask, per_view[name]))
            bar.advance(task)
        held_out_grid(tmp / HELD_OUT_GRID, rows)
        results = json_safe({
            "train": str(train_dir), "cameras": str(cameras), "masks": str(masks), "definitions": DEFINITIONS,
            "held_out": {"views": held, "downscale": downscale, "per_view": per_view,
                         "mean": means(per_view, HELD_OUT_METRICS)},
            "seconds": round(time.time() - started, 2), "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        })
        write_json(tmp / EVALUATE_JSON, results)
        write_manifest(tmp, stage="evaluate", inputs={"model": weights, "cameras": cameras}, started=started,
                       config={"held_out": held, "downscale": downscale}, capture=capture)
    for table in summary_tables(results):
        console.print(table)
    log.info("evaluate: wrote %s in %.1f s", out_dir, time.time() - started)
    return results


# ------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth
        every object view and every environment view at full resolution (slow on a CPU)
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth --views 4 --downscale 2
        4 evenly spaced object views at half resolution: a quick look
  orca evaluate results/demo/train --ground-truth captures/demo/ground_truth --no-environment
  orca evaluate results/mug --held-out
        a real capture trained with --set holdout_every=8: the held-out photos against the model's renders

Writes <out>/evaluate.json (per view and means, and the definition of every figure), object_grid.png,
environment_grid.png and the predicted images (EXR).
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "evaluate", help="trained model vs a synthetic capture's ground truth -> figures + comparison pictures",
        description="Compare a trained model with ground truth: normals, mask, diffuse/specular/combined "
        "PSNR/SSIM on object views; RGB and depth of environment views (all pixels and prop pixels).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("train_dir", type=Path, metavar="RESULTS",
                   help="train stage folder (holds model.pt), or a capture's results folder holding train/")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--ground-truth", type=Path, help="a synthetic capture's ground_truth/ folder")
    which.add_argument("--held-out", action="store_true",
                       help="a real capture: the photos training held out (train.holdout_every) against the model's "
                            "renders of their cameras")
    p.add_argument("--masks", type=Path, default=None,
                   help="--held-out: the object masks (default: masks/ beside the cameras.json)")
    p.add_argument("--decode", type=Path, default=None,
                   help="--held-out: the photos' decode folder when the cameras name no images (default: the one "
                        "the model was trained on)")
    p.add_argument("--cameras", type=Path, default=None,
                   help="the cameras.json the model was trained with (e.g. results/<capture>/poses/cameras.json): "
                        "aligns its frame to the ground truth's and reports pose errors (default: RESULTS/poses/"
                        "cameras.json, else the cameras the train manifest records)")
    p.add_argument("--mesh", type=Path, default=None,
                   help="the model's mesh.ply (orca mesh) to compare with ground_truth/object.ply (default: "
                        "RESULTS/mesh/mesh.ply when RESULTS is a results folder)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: evaluate/ beside TRAIN_DIR)")
    p.add_argument("--views", type=int, default=None, metavar="N",
                   help="evaluate N evenly spaced object views (default: every view)")
    p.add_argument("--downscale", type=int, default=1, metavar="K", help="render and compare K times smaller")
    p.add_argument("--no-object", action="store_true", help="skip the object views")
    p.add_argument("--no-environment", action="store_true", help="skip the environment views")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto", help="where to render")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=main)


def resolve_results(path: Path) -> tuple[Path, Path | None, Path | None]:
    """``(train_dir, cameras, mesh)`` of a train folder (no cameras or mesh implied), or of a capture's results
    folder (``train/``, ``poses/cameras.json`` and ``mesh/mesh.ply`` where they exist)."""
    path = Path(path)
    if (path / MODEL).is_file() or not (path / TRAIN / MODEL).is_file():
        return path, None, None

    def found(p: Path) -> Path | None:
        return p if p.is_file() else None

    return path / TRAIN, found(path / POSES / CAMERAS_JSON), found(path / MESH / MESH_PLY)


def main(args: argparse.Namespace) -> dict[str, Any]:
    train_dir, cameras, mesh = resolve_results(args.train_dir)
    out = args.out if args.out is not None else train_dir.parent / "evaluate"
    if args.held_out:
        return run_held_out(train_dir, out, cameras=args.cameras, masks=args.masks, decode=args.decode,
                            downscale=args.downscale, device=args.device, force=args.force)
    return run_evaluate(train_dir, args.ground_truth, out, views=args.views, downscale=args.downscale,
                        object=not args.no_object, environment=not args.no_environment,
                        cameras=args.cameras or cameras, mesh=args.mesh or mesh, device=args.device,
                        force=args.force)
