"""Load a stage's artifacts as Python objects, for notebooks and later stages.

    >>> from pipeline.results import load_decode
    >>> dec = load_decode("results/demo/decode")
    >>> dec.names[:3], dec.linear(dec.names[0]).shape
    >>> from pipeline.results import load_poses
    >>> poses = load_poses("results/demo/poses")
    >>> poses.cameras().c2w().shape, poses.report["registered"]
    >>> from pipeline.results import load_masks
    >>> masks = load_masks("results/demo/masks")
    >>> masks.mask("IMG_0001").mean(), masks.report["agreement"]["median"], masks.report["object_sphere"]

A whole results folder, each stage loaded when first asked for (a stage that has not run is an InputError
naming its folder and the command that makes it):

    >>> from pipeline.results import load_results
    >>> res = load_results("results/demo")
    >>> res.ran()                                            # {"decode": True, ..., "evaluate": False}
    >>> res.train.curves()["loss"].shape, res.train.report["iterations"]
    >>> res.mesh.mesh(max_triangles=20000).triangles.shape
    >>> res.export.panorama()["rgb"].shape, res.evaluate.results["object"]["mean"]

``notebooks/inspect.ipynb`` shows every stage with these loaders.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from .artifacts import read_stage_json, rerun_fix
from .cameras import CameraSet, load_cameras
from .checkpoints import checkpoints as checkpoint_files
from .checkpoints import load_checkpoint
from .colmap_model import model_folder
from .config import TrainConfig
from .errors import InputError
from .imageio import read_exr, read_image
from .layout import (
    CAMERAS_JSON,
    CHECKPOINTS_SUFFIX,
    DECODE,
    DECODE_JSON,
    ENVIRONMENT,
    ENVIRONMENT_GRID,
    EVALUATE,
    EVALUATE_JSON,
    EXPORT,
    EXPORT_JSON,
    HELD_OUT_GRID,
    IMAGE_KINDS,
    MANIFEST,
    MASKS,
    MASKS_REPORT,
    MESH,
    MESH_COLMAP_PLY,
    MESH_FIGURE,
    MESH_PLY,
    MESH_REPORT,
    METRICS,
    MODEL,
    OBJECT_GRID,
    OBJECT_VIEWS,
    OVERVIEW,
    PANORAMA,
    POINT_CLOUD,
    POINT_CLOUD_COLMAP,
    POSES,
    POSES_REPORT,
    PREVIEWS,
    REPORT,
    REPORT_HTML,
    RESULTS,
    SPARSE,
    STAGES,
    TRAIN,
    TRAIN_CONFIG,
    TRAIN_REPORT,
    VIDEOS,
    mask_file,
)
from .model_io import training_cameras
from .rendering import load_renderer
from .report.curves import read_metrics
from .signals import import_pycolmap
from .sparse_depth import SparsePoints, load_sparse_points


def _read_image_file(path: Path, reader: Any, written_by: Path, stage: str) -> np.ndarray:
    """``reader(path)``; a missing or damaged image is an InputError saying which stage to rerun."""
    try:
        return reader(path)
    except (OSError, ValueError) as e:
        what = "file not found" if isinstance(e, FileNotFoundError) else "not a readable image"
        raise InputError(what, path, rerun_fix(written_by, stage)) from e


@dataclass(frozen=True)
class DecodeArtifacts:
    """The decode stage's folder: ``decode.json`` plus per-image linear EXR, sRGB PNG and clipped mask."""

    folder: Path

    @cached_property
    def meta(self) -> dict[str, Any]:
        return read_stage_json(self.folder / DECODE_JSON, DECODE)

    @cached_property
    def manifest(self) -> dict[str, Any]:
        return read_stage_json(self.folder / MANIFEST, DECODE)

    @property
    def names(self) -> list[str]:
        return [im["name"] for im in self.meta["images"]]

    def entry(self, name: str) -> dict[str, Any]:
        """decode.json's record of one photo (its linear/srgb/clipped files, EXIF)."""
        for im in self.meta["images"]:
            if im["name"] == name:
                return im
        raise KeyError(f"{name!r} is not in {self.folder / DECODE_JSON}; known: {', '.join(self.names)}")

    def _image(self, name: str, kind: str, reader: Any) -> np.ndarray:
        return _read_image_file(self.folder / self.entry(name)[kind], reader, self.folder / DECODE_JSON, DECODE)

    def linear(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` float32 linear, exposure-normalized radiance."""
        return self._image(name, "linear", read_exr)

    def srgb(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` uint8 sRGB."""
        return self._image(name, "srgb", read_image)

    def clipped(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True where a highlight clipped."""
        return self._image(name, "clipped", read_image) > 127


def load_decode(folder: str | Path) -> DecodeArtifacts:
    """The decode folder, checked whole: a stage given a damaged one stops here, naming what is wrong, rather
    than at the first missing image it reaches (after minutes of work, with a traceback)."""
    folder = Path(folder)
    if not (folder / DECODE_JSON).is_file():
        raise InputError("not a decode artifact (no decode.json)", folder, "run `orca decode` on the capture first")
    decoded = DecodeArtifacts(folder)
    path = folder / DECODE_JSON
    meta, fix = decoded.meta, rerun_fix(path, DECODE)
    images = meta.get("images") if isinstance(meta, dict) else None
    entries_ok = isinstance(images, list) and all(
        isinstance(im, dict) and all(isinstance(im.get(k), str) for k in ("name", *IMAGE_KINDS)) for im in images)
    if not entries_ok or "size" not in meta:
        raise InputError("decode.json lacks the image list or size (every image needs its name, linear, srgb and "
                         "clipped files)", path, fix)
    missing = [im[k] for im in images for k in IMAGE_KINDS if not (folder / im[k]).is_file()]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise InputError(f"{len(missing)} of the image files decode.json lists are missing: {shown}", folder, fix)
    return decoded


@dataclass(frozen=True)
class PosesArtifacts:
    """The poses stage's folder: ``cameras.json`` (normalized frame), ``poses_report.json``, ``sparse/0/`` beside
    ``images/``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / POSES_REPORT, POSES)

    def cameras(self) -> CameraSet:
        """The cameras in the object-centred unit-sphere frame."""
        return load_cameras(self.folder / CAMERAS_JSON)

    def reconstruction(self) -> Any:
        """The COLMAP model (``pycolmap.Reconstruction``, COLMAP's frame; ``sparse/0``, or ``sparse`` as older
        poses stages wrote it); None for known cameras other than a COLMAP model."""
        if not (self.folder / SPARSE).is_dir():
            return None
        return import_pycolmap().Reconstruction(model_folder(self.folder / SPARSE))

    def points(self, min_track: int = 2) -> SparsePoints | None:
        """The COLMAP model's 3D points seen in at least ``min_track`` photos, in the cameras' normalized frame:
        ``xyz`` ``(M, 3)`` and each point's photos; None without a model (known cameras other than a COLMAP
        model)."""
        if not (self.folder / SPARSE).is_dir():
            return None
        return load_sparse_points(self.folder / SPARSE, self.cameras(), min_track)


def load_poses(folder: str | Path) -> PosesArtifacts:
    folder = Path(folder)
    if not (folder / CAMERAS_JSON).is_file():
        raise InputError("not a poses artifact (no cameras.json)", folder, "run `orca poses` on the capture first")
    return PosesArtifacts(folder)


@dataclass(frozen=True)
class MasksArtifacts:
    """The masks stage's folder: ``masks/<name>.png``, ``cameras.json`` (the object's tight sphere is the unit
    sphere), ``masks_report.json``, ``overlays/``, ``contact_sheet.jpg``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        return read_stage_json(self.folder / MASKS_REPORT, MASKS)

    @property
    def names(self) -> list[str]:
        return [v["name"] for v in self.report["views"]]

    def mask(self, name: str) -> np.ndarray:
        """``(H, W)`` bool, True on the object."""
        path = self.folder / mask_file(name)
        if not path.is_file():
            raise KeyError(f"no mask {name!r} in {self.folder}; known: {', '.join(self.names[:10])}")
        return _read_image_file(path, read_image, self.folder / MASKS_REPORT, MASKS) > 127

    def cameras(self) -> CameraSet:
        """The cameras re-normalized to the object's tight sphere (see the report): the DAG trains with them."""
        return load_cameras(self.folder / CAMERAS_JSON)

    def photo(self, name: str) -> np.ndarray:
        """``(H, W, 3)`` float32 linear: the image camera ``name`` points at, in the masks' pixel grid (the decoded
        photo, or the poses stage's undistorted one)."""
        cam = self.cameras().by_name().get(name)
        if cam is None or not cam.image:
            raise KeyError(f"no camera {name!r} with an image in {self.folder / CAMERAS_JSON}")
        return _read_image_file(self.folder / cam.image, read_exr, self.folder / CAMERAS_JSON, MASKS)


def load_masks(folder: str | Path) -> MasksArtifacts:
    folder = Path(folder)
    if not (folder / MASKS_REPORT).is_file():
        raise InputError("not a masks artifact (no masks_report.json)", folder, "run `orca masks` on the capture first")
    return MasksArtifacts(folder)


# --------------------------------------------------------------------------------- train, mesh, export, ...


def _required(folder: Path, file: str, stage: str) -> Path:
    """``folder``, which must hold the file that marks a finished ``stage`` folder."""
    folder = Path(folder)
    if not (folder / file).is_file():
        raise InputError(f"not a {stage} artifact (no {file})", folder, f"run `orca {stage}` first")
    return folder


RENDERED_KINDS = ("rgb", "diffuse", "specular", "normal", "depth")  # rendering.write_views's EXRs


def read_views(folder: Path, name: str, written_by: Path, stage: str) -> dict[str, np.ndarray]:
    """The images :func:`pipeline.rendering.write_views` wrote for camera ``name``: each of ``rgb``, ``diffuse``,
    ``specular``, ``normal`` ``(H, W, 3)`` and ``depth`` ``(H, W)`` whose EXR is there (environment views have
    only ``rgb`` and ``depth``), float32 linear, and ``mask`` ``(H, W)`` bool when ``_mask.png`` is."""
    views = {kind: _read_image_file(path, read_exr, written_by, stage)
             for kind in RENDERED_KINDS if (path := folder / f"{name}_{kind}.exr").is_file()}
    if "rgb" not in views:
        raise KeyError(f"no view {name!r} in {folder} (no {name}_rgb.exr)")
    if (folder / f"{name}_mask.png").is_file():
        views["mask"] = _read_image_file(folder / f"{name}_mask.png", read_image, written_by, stage) > 127
    return views


@dataclass(frozen=True)
class TrainArtifacts:
    """The train stage's folder: ``model.pt`` (weights and the config that rebuilds the network), ``config.json``,
    ``metrics.jsonl``, ``previews/step_<k>.png``, ``tensorboard/``, ``train_report.json``; the resumable
    checkpoints are beside it in ``<folder>.checkpoints/``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        """``iterations``, ``images``, ``size``, ``final_losses``, ``beta``, timing."""
        return read_stage_json(self.folder / TRAIN_REPORT, TRAIN)

    @cached_property
    def config(self) -> TrainConfig:
        """The training settings the model was trained with."""
        path = self.folder / TRAIN_CONFIG
        try:
            return TrainConfig.model_validate(read_stage_json(path, TRAIN))
        except ValidationError as e:
            raise InputError(f"not a train config of this version ({e.error_count()} problems)", path,
                             rerun_fix(path, TRAIN)) from e

    def metrics(self) -> list[dict[str, Any]]:
        """The rows of ``metrics.jsonl``, one a logged step: ``step``, ``phase``, ``loss``, ``psnr_object``, each
        loss term, ``beta``, ``lr``, ``seconds``; lines that do not parse are left out."""
        path = self.folder / METRICS
        if not path.is_file():
            raise InputError("file not found", path, rerun_fix(path, TRAIN))
        return read_metrics(path)[0]

    def curves(self) -> dict[str, np.ndarray]:
        """Each number of the metrics as ``(N,)`` float64 over the ``N`` logged steps (``step`` among them), NaN
        where a step did not log it."""
        rows = self.metrics()
        number = lambda v: isinstance(v, int | float) and not isinstance(v, bool)  # noqa: E731
        keys = dict.fromkeys(k for r in rows for k, v in r.items() if number(v))
        return {k: np.array([r[k] if number(r.get(k)) else np.nan for r in rows], np.float64) for k in keys}

    def checkpoint(self) -> dict[str, Any]:
        """``model.pt`` loaded safely (``weights_only``): ``step``, ``model`` (the state dict), ``config`` (JSON)."""
        return load_checkpoint(self.folder / MODEL)

    def checkpoints(self) -> list[Path]:
        """The resumable checkpoints in ``<folder>.checkpoints/``, oldest first; none once cleaned up."""
        return checkpoint_files(self.folder.with_name(self.folder.name + CHECKPOINTS_SUFFIX))

    def previews(self) -> list[Path]:
        """The preview images, in step order."""
        return sorted((self.folder / PREVIEWS).glob("step_*.png"))

    def model(self, device: str = "auto") -> Any:
        """The trained ``orca.model.OrcaModel`` ready to render (:func:`pipeline.rendering.load_renderer`):
        :func:`pipeline.rendering.render_object_view` and its siblings take it with a camera."""
        return load_renderer(self.folder, device)

    def cameras(self) -> CameraSet:
        """The cameras the model was trained with, as the train manifest records them."""
        cameras, where = training_cameras(self.folder, None)
        if cameras is None:
            raise InputError(f"the training cameras are unknown: {where}", self.folder / MANIFEST,
                             "use the masks stage's cameras (load_results(...).masks.cameras()), which the DAG "
                             "trains with")
        return cameras


def load_train(folder: str | Path) -> TrainArtifacts:
    return TrainArtifacts(_required(folder, MODEL, TRAIN))


@dataclass(frozen=True)
class TriangleMesh:
    """A triangle mesh as arrays: ``vertices`` ``(V, 3)`` float64, ``triangles`` ``(F, 3)`` int64 vertex indices,
    ``colors`` ``(V, 3)`` float64 sRGB in [0, 1] (None when the file has none)."""

    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray | None


@dataclass(frozen=True)
class MeshArtifacts:
    """The mesh stage's folder: ``mesh.ply`` (the model's normalized frame), ``mesh_colmap.ply`` (COLMAP's frame,
    when the cameras record it), ``mesh.png``, ``mesh_report.json``."""

    folder: Path

    @cached_property
    def report(self) -> dict[str, Any]:
        """Counts, topology (``watertight``, ...), size, timing."""
        return read_stage_json(self.folder / MESH_REPORT, MESH)

    def mesh(self, colmap: bool = False, max_triangles: int | None = None) -> TriangleMesh:
        """``mesh.ply`` (``colmap``: ``mesh_colmap.ply``), decimated to at most ``max_triangles`` by quadric error
        (open3d) when it has more: a plot needs a few thousand, not the full mesh."""
        import open3d as o3d

        path = self.folder / (MESH_COLMAP_PLY if colmap else MESH_PLY)
        if not path.is_file():
            raise InputError("file not found", path, rerun_fix(path, MESH))
        mesh = o3d.io.read_triangle_mesh(str(path))
        if max_triangles is not None and len(mesh.triangles) > max_triangles:
            mesh = mesh.simplify_quadric_decimation(max_triangles)
        colors = np.asarray(mesh.vertex_colors, np.float64) if mesh.has_vertex_colors() else None
        return TriangleMesh(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.triangles, np.int64), colors)

    def picture(self) -> np.ndarray:
        """``mesh.png``: ``(H, W, 3)`` uint8, three shaded views."""
        return _read_image_file(self.folder / MESH_FIGURE, read_image, self.folder / MESH_REPORT, MESH)


def load_mesh(folder: str | Path) -> MeshArtifacts:
    return MeshArtifacts(_required(folder, MESH_PLY, MESH))


@dataclass(frozen=True)
class ExportArtifacts:
    """The export stage's folder: ``environment/`` (virtual views from inside the object, with their
    ``cameras.json``), ``panorama/``, ``environment_points.ply``, ``videos/``, ``object/`` (renders of training
    cameras), ``overview.png``, ``export.json``."""

    folder: Path

    @cached_property
    def meta(self) -> dict[str, Any]:
        """``export.json``: what was written, sizes, the panorama's frame, timing."""
        return read_stage_json(self.folder / EXPORT_JSON, EXPORT)

    @property
    def environment_names(self) -> list[str]:
        return list(self.meta["environment_views"])

    @property
    def object_names(self) -> list[str]:
        return list(self.meta["object_views"])

    def environment(self, name: str) -> dict[str, np.ndarray]:
        """The environment field alone from virtual camera ``name``: ``rgb`` ``(H, W, 3)`` linear, ``depth``
        ``(H, W)`` z-depth in object radii."""
        return read_views(self.folder / ENVIRONMENT, name, self.folder / EXPORT_JSON, EXPORT)

    def environment_cameras(self) -> CameraSet:
        """The virtual cameras of the environment views (the model's frame)."""
        return load_cameras(self.folder / ENVIRONMENT / CAMERAS_JSON)

    def panorama(self) -> dict[str, np.ndarray]:
        """The equirectangular panorama from the object centre: ``rgb`` ``(H, 2H, 3)`` linear, ``depth``
        ``(H, 2H)`` distance along each ray (not z-depth)."""
        folder = self.folder / PANORAMA
        return {kind: _read_image_file(folder / f"{PANORAMA}_{kind}.exr", read_exr, self.folder / EXPORT_JSON,
                                       EXPORT) for kind in ("rgb", "depth")}

    def point_cloud(self, colmap: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The panorama as points: ``(M, 3)`` positions (``colmap``: in COLMAP's frame) and ``(M, 3)`` sRGB
        colours in [0, 1]."""
        import open3d as o3d

        path = self.folder / (POINT_CLOUD_COLMAP if colmap else POINT_CLOUD)
        if not path.is_file():
            raise InputError("file not found", path, rerun_fix(path, EXPORT))
        cloud = o3d.io.read_point_cloud(str(path))
        return np.asarray(cloud.points, np.float64), np.asarray(cloud.colors, np.float64)

    def object_view(self, name: str) -> dict[str, np.ndarray]:
        """The model's render of training camera ``name`` (:func:`read_views`: ``rgb``, ``diffuse``,
        ``specular``, ``normal``, ``depth``, ``mask``), at 1/``meta["object_downscale"]`` size."""
        return read_views(self.folder / OBJECT_VIEWS, name, self.folder / EXPORT_JSON, EXPORT)

    def videos(self) -> dict[str, Path]:
        """``orbit`` and ``flythrough`` MP4s, those that were written."""
        return {p.stem: p for p in sorted((self.folder / VIDEOS).glob("*.mp4"))}

    def overview(self) -> np.ndarray:
        """``overview.png``: ``(H, W, 3|4)`` uint8 (RGB or RGBA)."""
        return _read_image_file(self.folder / OVERVIEW, read_image, self.folder / EXPORT_JSON, EXPORT)


def load_export(folder: str | Path) -> ExportArtifacts:
    return ExportArtifacts(_required(folder, EXPORT_JSON, EXPORT))


@dataclass(frozen=True)
class EvaluateArtifacts:
    """The evaluate stage's folder: ``evaluate.json``, ``object_grid.png``, ``environment_grid.png`` and the
    predicted views it compared (ground-truth frame, rendered size) of a synthetic capture; ``held_out_grid.png``
    and the renders of the held-out photos of a real one (``orca evaluate --held-out``)."""

    folder: Path

    @cached_property
    def results(self) -> dict[str, Any]:
        """``evaluate.json``: ``object``, ``environment`` (``views``, ``per_view``, ``mean``), ``poses``, ``mesh``;
        or ``held_out`` (the same keys); ``definitions`` of every figure."""
        return read_stage_json(self.folder / EVALUATE_JSON, EVALUATE)

    def means(self, part: str) -> dict[str, float | None]:
        """The mean figures of ``part`` (``object``, ``environment`` or ``held_out``); None where a figure is
        undefined."""
        return dict(self.results[part]["mean"])

    def object_view(self, name: str) -> dict[str, np.ndarray]:
        """The predicted object view ``name`` (:func:`read_views`)."""
        return read_views(self.folder, name, self.folder / EVALUATE_JSON, EVALUATE)

    def environment_view(self, name: str) -> dict[str, np.ndarray]:
        """The predicted environment view ``name``: ``rgb`` ``(H, W, 3)``, ``depth`` ``(H, W)``."""
        return read_views(self.folder, f"env_{name}", self.folder / EVALUATE_JSON, EVALUATE)

    def grid(self, part: str) -> np.ndarray:
        """``(H, W, 3|4)`` uint8: ground truth beside prediction for ``part`` (``object`` or ``environment``), or
        photo, render and error of the held-out photos (``held_out``)."""
        file = {"object": OBJECT_GRID, "environment": ENVIRONMENT_GRID, "held_out": HELD_OUT_GRID}[part]
        return _read_image_file(self.folder / file, read_image, self.folder / EVALUATE_JSON, EVALUATE)


def load_evaluate(folder: str | Path) -> EvaluateArtifacts:
    return EvaluateArtifacts(_required(folder, EVALUATE_JSON, EVALUATE))


@dataclass(frozen=True)
class ReportArtifacts:
    """The report stage's folder: ``report.html`` (one self-contained page) and its manifest."""

    folder: Path

    @property
    def html(self) -> Path:
        return self.folder / REPORT_HTML

    @cached_property
    def manifest(self) -> dict[str, Any]:
        """Its inputs, each section's status (``present``, ``incomplete``, ``missing``), the problems met."""
        return read_stage_json(self.folder / MANIFEST, REPORT)


def load_report(folder: str | Path) -> ReportArtifacts:
    return ReportArtifacts(_required(folder, REPORT_HTML, REPORT))


# ------------------------------------------------------------------------------------ a whole results folder


def check_results_folder(results: Path) -> None:
    """Raise a clear :class:`InputError` unless ``results`` is a capture's results folder (it holds at least
    one stage folder)."""
    if not results.exists():
        raise InputError("results folder not found", results,
                         "pass a capture's results folder, e.g. results/demo (run the pipeline first)")
    if not results.is_dir():
        raise InputError("not a results folder (a file, not a folder)", results,
                         "pass a capture's results folder, e.g. results/demo")
    if not any((results / s).is_dir() for s in STAGES):
        hint = "pass a capture's results folder, e.g. results/demo, the one holding decode/, poses/, ..."
        if (results / MANIFEST).is_file() and results.parent != results:
            hint = f"this looks like one stage's folder: pass its parent, {results.parent}"
        elif (RESULTS / results.resolve().name).is_dir() and results.resolve() != (
                RESULTS / results.resolve().name).resolve():
            hint = f"this looks like a capture folder: its results are in {RESULTS / results.resolve().name}"
        raise InputError(f"not a results folder: none of {', '.join(s + '/' for s in STAGES)} is in it", results,
                         hint)


_LOADERS = {DECODE: load_decode, POSES: load_poses, MASKS: load_masks, TRAIN: load_train, MESH: load_mesh,
            EXPORT: load_export, EVALUATE: load_evaluate, REPORT: load_report}


@dataclass(frozen=True)
class Results:
    """A capture's results folder (``results/<capture>/``): each stage's artifacts, loaded when first asked for.
    A stage that has not run is an :class:`InputError` naming its folder and the command that makes it."""

    folder: Path

    def ran(self) -> dict[str, bool]:
        """Which stages have a folder here, in DAG order (the report last)."""
        return {stage: (self.folder / stage).is_dir() for stage in _LOADERS}

    def stage(self, stage: str) -> Any:
        """The artifacts of ``stage`` (one of :data:`pipeline.layout.STAGES` or ``report``)."""
        folder = self.folder / stage
        if not folder.is_dir():
            what = ("evaluate runs on a synthetic capture (with ground_truth/) or one trained with "
                    "train.holdout_every; " if stage == EVALUATE else "")
            raise InputError(f"the {stage} stage has not run: no {stage}/ folder", folder,
                             f"{what}run `orca {stage}` for this capture, or `snakemake --cores N` for every stage")
        return _LOADERS[stage](folder)

    @cached_property
    def decode(self) -> DecodeArtifacts:
        return self.stage(DECODE)

    @cached_property
    def poses(self) -> PosesArtifacts:
        return self.stage(POSES)

    @cached_property
    def masks(self) -> MasksArtifacts:
        return self.stage(MASKS)

    @cached_property
    def train(self) -> TrainArtifacts:
        return self.stage(TRAIN)

    @cached_property
    def mesh(self) -> MeshArtifacts:
        return self.stage(MESH)

    @cached_property
    def export(self) -> ExportArtifacts:
        return self.stage(EXPORT)

    @cached_property
    def evaluate(self) -> EvaluateArtifacts:
        return self.stage(EVALUATE)

    @cached_property
    def report(self) -> ReportArtifacts:
        return self.stage(REPORT)


def load_results(folder: str | Path) -> Results:
    """A capture's results folder (``results/<capture>``), checked to be one; its stages load lazily."""
    folder = Path(folder)
    check_results_folder(folder)
    return Results(folder)


# --------------------------------------------------------------------------------- the images of cameras.json


def image_folder(cameras: CameraSet, folder: Path, fallback: Path | None = None) -> Path:
    """The decode-style folder holding the images the cameras (of a cameras.json in ``folder``) point at
    (``<folder>/linear/<name>.exr``): the decode stage's, or the poses stage's ``undistorted/``. ``fallback``
    (a decode folder) serves cameras without image paths. Every later stage reads its images from here."""
    for cam in cameras.cameras:
        if cam.image:
            found = (folder / cam.image).resolve().parent.parent
            if (found / DECODE_JSON).is_file():
                return found
    if fallback is not None and (fallback / DECODE_JSON).is_file():
        return fallback
    raise InputError("cannot tell which decoded images the cameras belong to", folder / CAMERAS_JSON,
                     fix="pass --decode results/<capture>/decode")


def relocated(cameras: CameraSet, folder: Path, to: Path) -> CameraSet:
    """The cameras of a cameras.json in ``folder`` with image paths relative to ``to`` (where a new one goes)."""
    cams = []
    for c in cameras.cameras:
        image = c.image
        if image:
            image = os.path.relpath((folder / image).resolve(), to.resolve())
        cams.append(c.model_copy(update={"image": image}))
    return cameras.model_copy(update={"cameras": cams})
