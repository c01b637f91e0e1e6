"""Structure from motion with pycolmap: SIFT features, matching, incremental mapping, and the checks that
turn COLMAP's silent failures into messages a photographer can act on.

Glossy objects are where SfM fails in practice: reflections move with the viewpoint and make false matches,
so few photos register or the model splits in two. The remedies are the same every time (more overlap,
textured surroundings, locked exposure, masks on the object) and every error here says which applies.

Images are named ``<name>.png`` inside COLMAP (the decode stage's sRGB PNGs); callers map them back.

Intrinsics: each lens/zoom (EXIF make, model, focal length) shares one camera (:func:`camera_groups`), SIMPLE_RADIAL
unless configured, its focal length starting from the EXIF 35 mm-equivalent focal length when the photos record
it; a calibration (``orca calibrate``) gives OPENCV intrinsics held fixed. Exhaustive matching up to
``exhaustive_max_images`` photos, else each photo with its neighbours in name order (wrapping around: no
vocabulary tree needed); incremental mapping, and the global mapper (GLOMAP) when that leaves photos out
(:func:`global_models`); the model with the most photos is used and a split is reported.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import imageio
from .config import PosesConfig
from .errors import InputError
from .layout import SFM_DATABASE, SRGB
from .log import progress
from .mask_file import read_mask
from .object_frame import Posed, find_object
from .pose_checks import PoseChecks, ambiguous, capture_order, check_poses, rotation_disagreement
from .signals import import_pycolmap

if TYPE_CHECKING:
    import pycolmap  # noqa: TID251 - annotations only

    from .results import DecodeArtifacts

log = logging.getLogger("orca.poses")

# What helps when photos do not register, in the order a photographer can most easily do it.
FIX_OVERLAP = (
    "take the photos closer together (about 10-15 degrees apart as you walk around the object, each photo "
    "overlapping its neighbours by two thirds), put textured things around the object (a newspaper, a patterned "
    "cloth, posters) so the background has features, lock exposure and focus (AE/AF lock) so neighbouring photos "
    "look alike, and give object masks (CAPTURE/masks/<name>.png) so reflections on the object are not matched"
)


@dataclass(frozen=True)
class CameraGroup:
    """Photos that share one COLMAP camera (same lens and zoom), and what we know of its intrinsics."""

    names: tuple[str, ...]  # image stems
    model: str  # COLMAP model name
    params: tuple[float, ...] | None  # None: COLMAP's guess (focal 1.2 x the longest side)
    source: str  # where the intrinsics come from, for the report
    fixed: bool = False  # calibrated: bundle adjustment keeps them
    prior: bool = True  # COLMAP takes the focal length in params as known (else it starts there: poses.exif_focal)


@dataclass
class SfmResult:
    """The largest model and what the run learned on the way (for the report and the error messages)."""

    reconstruction: pycolmap.Reconstruction
    model_sizes: list[int]  # registered images per model, largest first
    other_models: list[list[str]]  # image stems of the models not chosen
    features: dict[str, int]  # SIFT features per image stem
    matcher: str
    num_pairs: int  # image pairs matched
    num_verified_pairs: int  # pairs with a verified two-view geometry
    seconds: dict[str, float] = field(default_factory=dict)
    mapper: str = "incremental"  # which mapper made the model: "incremental" or "global"
    unregistered: dict[str, str] = field(default_factory=dict)  # image stem -> why it has no camera
    relaxed: list[str] | None = None  # image stems the relaxed second pass registered (None: it did not run)
    # the model's photos' turn against the other mapper runs (repeat_mapping), and every run's figures
    disagreement: dict[str, list[float | None]] = field(default_factory=dict)
    mapping_runs: list[dict[str, Any]] = field(default_factory=list)


def colmap_name(name: str) -> str:
    return f"{name}.png"


def stem_of(colmap_image_name: str) -> str:
    return colmap_image_name[:-4] if colmap_image_name.endswith(".png") else Path(colmap_image_name).stem


def num_threads(config: PosesConfig) -> int:
    return config.num_threads or (os.cpu_count() or 1)


def quiet_colmap(verbose: bool) -> None:
    """COLMAP logs every step through glog; keep its errors and our own summary unless debugging."""
    pycolmap = import_pycolmap()

    pycolmap.logging.minloglevel = 0 if verbose else 3  # our own errors say what its ERROR lines would


# ------------------------------------------------------------------------------------- checks before SfM


def thumbnail(image: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` uint8 sRGB -> ``(24, 32)`` float32 grey thumbnail (what the identical-photo check compares;
    the stage keeps only these in memory, not 200 full photos)."""
    import cv2

    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.resize(grey, (32, 24), interpolation=cv2.INTER_AREA).astype(np.float32)


def check_not_identical(thumbs: dict[str, np.ndarray], folder: Path, tolerance: float = 1.0) -> list[list[str]]:
    """Stop when every photo shows the same picture; return groups of near-duplicates otherwise.

    Args:
        thumbs: image stem -> :func:`thumbnail` of the photo.
        tolerance: mean absolute difference of the thumbnails (8-bit levels) below which two photos count as
            the same picture (sensor noise and JPEG artefacts stay well under it; a step of a few degrees
            around an object moves far more).
    """
    # Blank photos are all alike too, but the feature check explains them better: leave them to it.
    names = [n for n in thumbs if float(np.std(thumbs[n])) >= 2.0]
    if not names:
        return []
    stack = np.stack([thumbs[n] for n in names])
    same = np.stack([np.abs(stack - t).mean(axis=(1, 2)) < tolerance for t in stack])  # (N, N), row by row
    if len(names) > 1 and same.all():
        worst = max(float(np.abs(stack - t).mean(axis=(1, 2)).max()) for t in stack)
        raise InputError(
            f"all {len(names)} photos show the same picture (mean difference of thumbnails "
            f"{worst:.2f} levels): the camera did not move, so there is no parallax to find poses from",
            folder,
            fix="walk around the object between photos (burst mode or a tripod without moving it gives identical "
            "photos); " + FIX_OVERLAP,
        )
    groups, seen = [], set()
    for i, n in enumerate(names):
        if n in seen:
            continue
        group = [names[j] for j in np.flatnonzero(same[i]) if names[j] not in seen]
        seen.update(group)
        if len(group) > 1:
            groups.append(group)
    return groups


def check_features(features: dict[str, int], pixel_std: dict[str, float], config: PosesConfig, folder: Path) -> None:
    """Stop when so many photos have no features that too few could ever register; warn about the others."""
    poor = sorted(n for n, k in features.items() if k < config.min_features)
    if not poor:
        return
    usable = len(features) - len(poor)
    needed = required_registered(len(features), config)
    blank = [n for n in poor if pixel_std.get(n, 1.0) < 2.0]
    detail = ", ".join(f"{n} ({features[n]})" for n in poor[:12]) + (" ..." if len(poor) > 12 else "")
    if len(blank) == len(poor):
        what = "they are blank (one flat colour)"
    elif blank:
        what = f"{len(blank)} of them are blank (one flat colour), the others too dark, blurred or plain"
    else:
        what = "they are too dark, too blurred or show only plain surfaces"

    if usable < needed:
        raise InputError(
            f"{len(poor)} of {len(features)} photos have (almost) no SIFT features (fewer than "
            f"poses.min_features={config.min_features}): {detail}; {what}. At least {needed} photos with features "
            "are needed",
            folder,
            fix="check that the photos are exposed and in focus (not black, white or blurred), lock exposure, and "
            "photograph the object where the surroundings have texture (SfM finds the cameras from the "
            "background, not from a glossy or plain object)",
        )
    log.warning("%d photo(s) have (almost) no SIFT features and will probably not register: %s", len(poor), detail)


def required_registered(total: int, config: PosesConfig) -> int:
    """How many photos must register for the stage to succeed."""
    return min(total, max(config.min_registered, int(np.ceil(config.min_registered_fraction * total - 1e-9))))


# ------------------------------------------------------------------------------------------------ pairing


def sequential_pairs(names: Sequence[str], overlap: int, wrap: bool = True) -> list[tuple[str, str]]:
    """Each photo with its ``overlap`` successors in file order, and with the photos 2^k ahead (COLMAP's
    quadratic overlap, which closes loops cheaply). ``wrap``: the last photos also pair with the first ones,
    as a capture that circles the object ends where it began."""
    n = len(names)
    steps = set(range(1, overlap + 1))
    k = 1
    while k < n:
        steps.add(k)
        k *= 2
    pairs = set()
    for i in range(n):
        for s in steps:
            j = i + s
            if j >= n:
                if not wrap:
                    continue
                j %= n
            if i != j:
                pairs.add((min(i, j), max(i, j)))
    return [(names[i], names[j]) for i, j in sorted(pairs)]


def viewing_pairs(names: Sequence[str], c2w: np.ndarray, k: int) -> list[tuple[str, str]]:
    """Each photo with the ``k`` photos whose views are nearest its own, for matching with known cameras.

    A view is its optical axis (unit) and its centre over the cameras' spread (median distance from their mean),
    compared as one 6-vector: around an object the axes separate the photos, in a forward-facing capture (axes
    alike) the centres do. ``c2w``: (N, 4, 4) camera-to-world, OpenCV axes (+z forward)."""
    from scipy.spatial.distance import cdist

    c2w = np.asarray(c2w, dtype=float)
    centres = c2w[:, :3, 3]
    spread = float(np.median(np.linalg.norm(centres - centres.mean(axis=0), axis=1))) or 1.0
    views = np.concatenate([c2w[:, :3, 2], centres / spread], axis=1)
    distance = cdist(views, views)
    np.fill_diagonal(distance, np.inf)
    nearest = np.argsort(distance, axis=1, kind="stable")[:, :min(k, len(names) - 1)]
    pairs = {(min(i, int(j)), max(i, int(j))) for i, row in enumerate(nearest) for j in row}
    return [(names[i], names[j]) for i, j in sorted(pairs)]


# -------------------------------------------------------------------------------------------------- SfM


def run_sfm(
    image_dir: Path,
    groups: Sequence[CameraGroup],
    work: Path,
    config: PosesConfig,
    *,
    feature_masks: Path | None = None,
    progress: Any = None,
    folder: Path | None = None,
    retry: RetryMatching | None = None,
) -> SfmResult:
    """Features, matches and incremental mapping of the photos in ``groups`` (``image_dir/<name>.png``).

    Args:
        work: an empty folder for ``database.db`` and the models (``sparse/<k>``).
        feature_masks: folder with ``<name>.png.png`` masks (0 = ignore features there), COLMAP's layout.
        progress: a :func:`pipeline.log.progress` bar to advance while the mapper registers photos.
        folder: the folder error messages name (default ``image_dir``), e.g. the capture's photo folder.
        retry: match as :class:`RetryMatching` says (a second run on photos the pose checks doubted).

    Raises:
        InputError: no features, no initial pair, or too few photos registered (see the module doc).
    """
    pycolmap = import_pycolmap()

    seconds: dict[str, float] = {}
    folder = folder or image_dir
    names = [n for g in groups for n in g.names]
    db_path = work / SFM_DATABASE
    threads = num_threads(config)
    pycolmap.set_random_seed(config.seed)

    t = time.time()
    extraction = extraction_options(config, threads, affine_shape=config.sift_affine_shape)
    pycolmap.Database.open(db_path).close()
    # A retry starts from the first run's database: its features exist, and the extractor skips them.
    extracted = set(_feature_counts(db_path)) >= set(names)
    sift_dir = image_dir if not config.sift_brightness or extracted else \
        write_sift_images(image_dir, names, work / "sift_images", config.sift_brightness)
    extract_features(db_path, sift_dir, groups, extraction, feature_masks)
    features = _feature_counts(db_path)
    seconds["features"] = time.time() - t
    log.info("SIFT: %d photos, %d-%d features each (median %d) [%.1f s]", len(names), min(features.values()),
             max(features.values()), int(np.median(list(features.values()))), seconds["features"])
    pixel_std = {n: float(np.std(_read_gray(image_dir / colmap_name(n)))) for n, k in features.items()
                 if k < config.min_features}
    check_features(features, pixel_std, config, folder)

    t = time.time()
    matcher, num_pairs, num_verified = match_features(db_path, names, work, config, threads, retry)
    seconds["matching"] = time.time() - t
    log.info("matching (%s): %d pairs, %d with a verified geometry [%.1f s]", matcher, num_pairs, num_verified,
             seconds["matching"])

    t = time.time()
    task = progress.add_task("register photos", total=len(names)) if progress is not None else None

    def next_image() -> None:
        if progress is not None:
            progress.advance(task)

    mapped = map_photos(db_path, image_dir, work, groups, config, threads, len(names), retry, next_image)
    seconds["mapping"] = time.time() - t
    if not mapped.ranked:
        raise _no_model_error(db_path, names, features, num_verified, folder)
    t = time.time()
    mapped, disagreement, mapping_runs = repeat_mapping(mapped, db_path, image_dir, work, groups, config, threads,
                                                        retry)
    seconds["repeat_mapping"] = time.time() - t
    ranked = mapped.ranked
    best = ranked[0]
    others = [sorted(registered_stems(r)) for r in ranked[1:]]
    registered = registered_stems(best)
    why = unregistered_reasons(db_path, names, registered, others, verification_options(config, retry).min_num_inliers)
    result = SfmResult(best, [r.num_reg_images() for r in ranked], others, features, matcher, num_pairs,
                       num_verified, seconds, mapped.mapper, why, mapped.relaxed, disagreement, mapping_runs)
    _check_registered(result, names, config, folder)
    return result


@dataclass(frozen=True)
class Mapping:
    """What :func:`map_photos` made."""

    ranked: list[pycolmap.Reconstruction]  # the models, largest first
    mapper: str  # "incremental" or "global": which mapper made the largest
    relaxed: list[str] | None  # image stems the relaxed pass added to it (None: it did not run)


def map_photos(db_path: Path, image_dir: Path, work: Path, groups: Sequence[CameraGroup], config: PosesConfig,
               threads: int, n: int, retry: RetryMatching | None, next_image: Any = None,
               quiet: bool = False) -> Mapping:
    """Models of the ``n`` photos of a matched database (``work/sparse*``): the incremental mapper; the global
    mapper on the same matches when that leaves photos out (``poses.mapper`` 'auto'); then the relaxed pass on the
    largest model. ``next_image``: called as the incremental mapper registers each photo; ``quiet``: log at debug
    level (a repeated run, :func:`repeat_mapping`)."""
    pycolmap = import_pycolmap()

    info, warning = (log.debug, log.debug) if quiet else (log.info, log.warning)
    options = _mapper_options(config, groups, threads, n)
    sparse = work / "sparse"
    sparse.mkdir()
    mapper = "incremental" if config.mapper == "auto" else config.mapper
    if mapper == "incremental":
        models = pycolmap.incremental_mapping(db_path, image_dir, sparse, options, next_image_callback=next_image)
        ranked = largest_first(models)
    else:
        ranked = global_then_incremental(db_path, image_dir, sparse, config, options, threads, n, info)
    if config.mapper == "auto" and (not ranked or ranked[0].num_reg_images() < n):
        info("incremental mapping registered %d of %d photos (models: %s); trying the global mapper on the same "
             "matches", ranked[0].num_reg_images() if ranked else 0, n,
             " + ".join(str(r.num_reg_images()) for r in ranked) or "none")
        found = global_then_incremental(db_path, image_dir, work / "sparse_global", config, options, threads, n,
                                        info)
        if found and (not ranked or found[0].num_reg_images() > ranked[0].num_reg_images()):
            # A warning: where the incremental mapper fails, the view graph is weak, and the global model is
            # less accurate (1-2 degrees on a tiled room where the incremental one stays under 0.1 on posters).
            warning("the global mapper's model is used (%d photos; the incremental mapper's largest had %d): the "
                    "photos overlap weakly, so check poses.png and poses_report.json's checks",
                    found[0].num_reg_images(), ranked[0].num_reg_images() if ranked else 0)
            ranked, mapper = found, "global"
    # not in a retry: that one is for photos placed where others look the same, and wants stricter bars, not laxer
    relaxed = None
    extend = ranked and ranked[0].num_reg_images() < n and config.relaxed_min_inliers and retry is None
    needed = relaxed_min_size(n, config)
    if extend and ranked[0].num_reg_images() < needed:
        info("the relaxed pass is skipped: the model holds %d photos, fewer than the %d it needs to extend one "
             "(poses.relaxed_min_model)", ranked[0].num_reg_images(), needed)
    elif extend:
        more = continued(db_path, image_dir, work / "sparse_relaxed", ranked[0],
                         relaxed_options(_mapper_options(config, groups, threads, n), config))[0]
        relaxed = sorted(registered_stems(more) - registered_stems(ranked[0]))
        if relaxed:
            info("%d more photo(s) registered with relaxed thresholds (%d inlier 2D-3D matches, %.0f %% of them): %s",
                 len(relaxed), config.relaxed_min_inliers, 100 * config.relaxed_min_inlier_ratio, ", ".join(relaxed))
            ranked = [more, *ranked[1:]]
    return Mapping(ranked, mapper, relaxed)


def repeat_mapping(first: Mapping, db_path: Path, image_dir: Path, work: Path, groups: Sequence[CameraGroup],
                   config: PosesConfig, threads: int,
                   retry: RetryMatching | None) -> tuple[Mapping, dict[str, list[float | None]], list[dict[str, Any]]]:
    """The same matches mapped again (:func:`map_photos` in ``work/mapping<k>``, seeds ``poses.seed`` + 1, + 2,
    ...), and the run the others agree with: a second run always, each further one, up to ``poses.mapping_runs``
    in all, only while every run so far has cameras turned by more than ``poses.mapping_max_deg`` against all the
    others (:func:`disputed`). Kept is the run with the most photos not so turned (:func:`kept_run`): when a
    second and a third run agree and the first placed a part of the capture elsewhere, the second is kept and no
    photo is lost. No repeat when ``first`` holds too few photos for the stage to go on.

    Returns:
        the kept run; ``{image stem: [degrees against each other run, None where it has no camera there]}`` for
        the kept model's photos (:func:`pipeline.pose_checks.rotation_disagreement`; the checks doubt those
        turned against all: :func:`pipeline.pose_checks.ambiguous`); per run its seed, photos registered,
        whether it was kept and the median and largest turn of the kept run's cameras against it.
    """
    n = sum(len(g.names) for g in groups)
    if config.mapping_runs < 2 or first.ranked[0].num_reg_images() < required_registered(n, config):
        return first, {}, []
    runs = [first]
    while len(runs) < config.mapping_runs and (len(runs) == 1 or not any(
            run.ranked and not doubts for run, doubts in zip(runs, disputed(runs, config)))):
        seed = config.seed + len(runs)
        log.info("mapping the same matches again (seed %d) to see that the poses hold (poses.mapping_runs)", seed)
        folder = work / f"mapping{len(runs) + 1}"
        folder.mkdir()
        runs.append(map_photos(db_path, image_dir, folder, groups, config.model_copy(update={"seed": seed}), threads,
                               n, retry, quiet=True))
    kept, doubts = kept_run(runs, config)
    if kept:
        log.warning("mapper run %d (seed %d) is kept: the other runs agree with it, while the first placed %d "
                    "photo(s) elsewhere (%s)", kept + 1, config.seed + kept, len(doubts[0]), ", ".join(doubts[0][:12]))
    stems = sorted(registered_stems(runs[kept].ranked[0]))
    table = turns(runs[kept], [r for i, r in enumerate(runs) if i != kept], stems, config)
    figures = []
    for i, run in enumerate(runs):
        column = table[:, i - (i > kept)] if i != kept else np.zeros(0)
        found = column[~np.isnan(column)]
        figures.append({"seed": config.seed + i, "registered": run.ranked[0].num_reg_images() if run.ranked else 0,
                        "kept": i == kept, "median_deg": float(np.median(found)) if len(found) else None,
                        "max_deg": float(found.max()) if len(found) else None})
        if i != kept:
            log.info("mapper run %d (seed %d): %d photos registered; the kept run's cameras turned against it by %s",
                     i + 1, config.seed + i, figures[-1]["registered"], "-" if not len(found) else
                     f"{figures[-1]['median_deg']:.2f} degrees median, {figures[-1]['max_deg']:.1f} at most")
    return runs[kept], {s: [None if np.isnan(v) else float(v) for v in row] for s, row in zip(stems, table)}, figures


def kept_run(runs: Sequence[Mapping], config: PosesConfig) -> tuple[int, list[list[str]]]:
    """Which of several mapper runs on the same matches to keep: the one with the most photos not turned against
    all the others (:func:`disputed`), then the fewest turned, then the earliest; and each run's turned photos."""
    doubts = disputed(runs, config)
    undoubted = [(r.ranked[0].num_reg_images() - len(d), -len(d)) if r.ranked else (-1, 0)
                 for r, d in zip(runs, doubts)]
    return undoubted.index(max(undoubted)), doubts


def turns(run: Mapping, others: Sequence[Mapping], stems: Sequence[str], config: PosesConfig) -> np.ndarray:
    """``(N, R)`` degrees each of the photos ``stems`` of ``run``'s model is turned against each of the R
    ``others``' models (NaN: no camera there; :func:`pipeline.pose_checks.rotation_disagreement`)."""
    c2w = _cameras_of(run.ranked[0], stems)
    columns = [rotation_disagreement(c2w, _cameras_of(o.ranked[0], stems) if o.ranked else np.full_like(c2w, np.nan),
                                     config.mapping_max_deg) for o in others]
    return np.stack(columns, 1) if columns else np.zeros((len(stems), 0))


def disputed(runs: Sequence[Mapping], config: PosesConfig) -> list[list[str]]:
    """Per run, the photos (stems) whose cameras are turned by more than ``poses.mapping_max_deg`` against every
    other run that placed them (:func:`pipeline.pose_checks.ambiguous`)."""
    out = []
    for i, run in enumerate(runs):
        stems = sorted(registered_stems(run.ranked[0])) if run.ranked else []
        table = turns(run, [r for j, r in enumerate(runs) if j != i], stems, config)
        out.append([s.name for s in ambiguous(stems, table, config.mapping_max_deg)])
    return out


def _cameras_of(rec: pycolmap.Reconstruction, stems: Sequence[str]) -> np.ndarray:
    """``(N, 4, 4)`` camera-to-world of the photos ``stems`` in ``rec``; NaN where it has no camera."""
    by_name = {stem_of(im.name): im for im in rec.images.values() if im.has_pose}
    return np.stack([camera_to_world(by_name[n]) if n in by_name else np.full((4, 4), np.nan) for n in stems])


def extract_features(db_path: Path, image_dir: Path, groups: Sequence[CameraGroup],
                     extraction: pycolmap.FeatureExtractionOptions, feature_masks: Path | None = None) -> None:
    """SIFT features of the photos of ``groups`` (``image_dir/<name>.png``) into the existing database ``db_path``,
    one COLMAP camera per group with its intrinsics (as a prior, or with ``prior`` False as the focal length's
    start). Each group's images are imported in the order of its names first, so that their ids (which order the
    matching and mapping) are the same on every run: the extractor's threads number the images they import in the
    order they finish."""
    pycolmap = import_pycolmap()
    for g in groups:
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = g.model
        if g.params is not None:
            reader.camera_params = ",".join(f"{p:.10g}" for p in g.params)  # also marks the focal as a prior
        if feature_masks is not None:
            reader.mask_path = str(feature_masks)
        colmap_names = [colmap_name(n) for n in g.names]
        pycolmap.import_images(db_path, image_dir, pycolmap.CameraMode.SINGLE, colmap_names, reader)
        pycolmap.extract_features(
            db_path, image_dir, image_names=colmap_names, camera_mode=pycolmap.CameraMode.SINGLE,
            reader_options=reader, extraction_options=extraction, device=pycolmap.Device.auto,
        )
        if g.params is not None and not g.prior:
            _focal_as_start(db_path, colmap_names[0])


def _focal_as_start(db_path: Path, image: str) -> None:
    """The camera of ``image`` (its COLMAP name) in ``db_path`` keeps its focal length as the start of the
    estimate, not as a known value (``camera_params`` marked it as one)."""
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        camera = db.read_camera(db.read_image_with_name(image).camera_id)
        camera.has_prior_focal_length = False
        db.update_camera(camera)
    finally:
        db.close()


def extraction_options(config: PosesConfig, threads: int, *,
                       affine_shape: bool) -> pycolmap.FeatureExtractionOptions:
    """SIFT as the poses section configures it; each feature's affine shape estimated when ``affine_shape``."""
    extraction = import_pycolmap().FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.max_image_size = config.max_image_size or -1
    extraction.sift.max_num_features = config.max_num_features
    extraction.sift.peak_threshold = config.sift_peak_threshold
    extraction.sift.estimate_affine_shape = affine_shape
    extraction.sift.domain_size_pooling = config.sift_domain_size_pooling
    return extraction


def match_features(db_path: Path, names: Sequence[str], work: Path, config: PosesConfig, threads: int,
                   retry: RetryMatching | None = None,
                   pairs: list[tuple[str, str]] | None = None) -> tuple[str, int, int]:
    """Match the features in ``db_path`` (exhaustively up to ``exhaustive_max_images`` photos, else neighbours in
    name order; with ``retry`` or ``pairs``, as they say) and verify the pairs' geometry. Returns the matcher
    used, the pairs matched and the pairs verified."""
    pycolmap = import_pycolmap()
    matcher = "neighbours" if retry is not None else "viewing" if pairs is not None else config.matcher
    if matcher == "auto":
        matcher = "exhaustive" if len(names) <= config.exhaustive_max_images else "sequential"
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    verification = verification_options(config, retry)
    if matcher == "exhaustive":
        num_pairs = len(names) * (len(names) - 1) // 2
        pycolmap.match_exhaustive(db_path, matching_options=matching, verification_options=verification,
                                  device=pycolmap.Device.auto)
    else:
        if retry is not None:
            pairs = neighbour_pairs(retry.order, retry.overlap)
        elif pairs is None:
            pairs = sequential_pairs(sorted(names), config.sequential_overlap)
        num_pairs = len(pairs)
        pair_file = work / "pairs.txt"
        pair_file.write_text("".join(f"{colmap_name(a)} {colmap_name(b)}\n" for a, b in pairs))
        pairing = pycolmap.ImportedPairingOptions()
        pairing.match_list_path = str(pair_file)
        pycolmap.match_image_pairs(db_path, matching_options=matching, pairing_options=pairing,
                                   verification_options=verification, device=pycolmap.Device.auto)
    return matcher, num_pairs, _verified_pairs(db_path, verification.min_num_inliers)


def triangulate_known(posed: Posed, image_dir: Path, work: Path, config: PosesConfig) -> pycolmap.Reconstruction:
    """Sparse points for known cameras: SIFT features and matches as SfM makes them (``image_dir/<name>.png``),
    triangulated with the cameras and lenses held as given. Known cameras (transforms.json, LLFF) come without
    points, and the masks stage seeds the object and the floor with them, training's sparse depth holds the room
    with them. ``work``: an empty folder to be. Returns the model (no points when nothing matched)."""
    pycolmap = import_pycolmap()
    threads = num_threads(config)
    work.mkdir()
    db_path = work / SFM_DATABASE
    rec = pycolmap.Reconstruction()
    db = pycolmap.Database.open(db_path)
    try:
        for i, (n, lens, c2w) in enumerate(zip(posed.names, posed.lens, posed.c2w), 1):
            camera = pycolmap.Camera(model=lens.model, width=lens.width, height=lens.height, params=lens.params,
                                     camera_id=i)
            image = pycolmap.Image(name=colmap_name(n), camera_id=i, image_id=i)
            db.write_camera(camera, use_camera_id=True)
            db.write_image(image, use_image_id=True)
            w2c = np.linalg.inv(c2w)
            rec.add_camera_with_trivial_rig(camera)
            rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3]))
    finally:
        db.close()
    t = time.time()
    # the images are in the database already: the extractor keeps their cameras and only adds features; plain
    # SIFT (no affine shapes, poses.sift_affine_shape says why)
    extraction = extraction_options(config, threads, affine_shape=False)
    pycolmap.extract_features(db_path, image_dir, image_names=[colmap_name(n) for n in posed.names],
                              extraction_options=extraction, device=pycolmap.Device.auto)
    pairs = viewing_pairs(posed.names, posed.c2w, config.known_pairs) if config.known_pairs else None
    matcher, num_pairs, num_verified = match_features(db_path, posed.names, work, config, threads, pairs=pairs)
    (work / "sparse").mkdir()
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    triangulated = pycolmap.triangulate_points(rec, db_path, image_dir, work / "sparse", options=options)
    log.info("known cameras: %d sparse points triangulated from %d verified pairs of %d (%s) [%.1f s]",
             triangulated.num_points3D(), num_verified, num_pairs, matcher, time.time() - t)
    return triangulated


def _mapper_options(config: PosesConfig, groups: Sequence[CameraGroup], threads: int, n: int):
    pycolmap = import_pycolmap()

    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    options.random_seed = config.seed
    options.mapper.random_seed = config.seed
    options.triangulation.random_seed = config.seed
    options.multiple_models = True  # to tell the user when and where the capture splits
    options.min_model_size = min(n, max(3, config.min_registered))  # COLMAP drops models under 10 by default
    options.extract_colors = True
    if any(g.fixed for g in groups):
        # Calibrated intrinsics are better than what bundle adjustment can get from an object capture.
        options.ba_refine_focal_length = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
        options.mapper.abs_pose_refine_focal_length = False
        options.mapper.abs_pose_refine_extra_params = False
    return options


def registered_stems(rec: pycolmap.Reconstruction) -> set[str]:
    """The image stems of a model's photos that have a camera."""
    return {stem_of(im.name) for im in rec.images.values() if im.has_pose}


def relaxed_min_size(total: int, config: PosesConfig) -> int:
    """The fewest photos a model of a ``total``-photo capture must hold for the relaxed pass to extend it:
    ``poses.relaxed_min_model``, or half the photos when fewer."""
    return min(config.relaxed_min_model, int(np.ceil(total / 2)))


def relaxed_options(options: Any, config: PosesConfig) -> Any:
    """The mapper's ``options`` with the absolute pose's bars lowered to ``poses.relaxed_min_inliers`` and
    ``relaxed_min_inlier_ratio``: the second pass for photos the first left without a camera."""
    options.mapper.abs_pose_min_num_inliers = config.relaxed_min_inliers
    options.mapper.abs_pose_min_inlier_ratio = config.relaxed_min_inlier_ratio
    return options


def largest_first(models: dict[int, pycolmap.Reconstruction]) -> list[pycolmap.Reconstruction]:
    """A mapper's models, the one with the most registered photos first."""
    return sorted(models.values(), key=lambda r: r.num_reg_images(), reverse=True)


def global_models(db_path: Path, image_dir: Path, out: Path, config: PosesConfig, threads: int, n: int,
                  info: Any = log.info) -> dict[int, pycolmap.Reconstruction]:
    """Models of GLOMAP's global mapper (pycolmap.global_mapping) on a matched database, each without the photos
    fewer than ``poses.global_min_observations`` of its 3D points support.

    The global mapper places every photo of the view graph at once (rotation averaging, then positions), so a
    capture whose neighbouring photos overlap weakly stays one model where the incremental mapper splits it. But
    it registers a photo however little supports it: one with a few observations can be far off (on a real
    walk-around with 10-30 degree gaps, photos under 30 observations were off by up to 24 degrees, the others
    agreed with the photographers' poses as well as the incremental mapper's). The incremental mapper needs
    ``abs_pose_min_num_inliers`` (30) 2D-3D inliers to register a photo; the same bar is applied here. ``info``
    logs what is left out.
    """
    pycolmap = import_pycolmap()

    options = pycolmap.GlobalPipelineOptions()
    options.num_threads = threads
    options.random_seed = config.seed
    options.min_model_size = min(n, max(3, config.min_registered))
    models = pycolmap.global_mapping(db_path, image_dir, out, options)
    for rec in models.values():
        weak = [im for im in rec.images.values() if im.has_pose and im.num_points3D < config.global_min_observations]
        if weak:
            info("global mapper: %d photo(s) with fewer than %d observations left out: %s", len(weak),
                 config.global_min_observations, ", ".join(stem_of(im.name) for im in weak))
        for frame_id in {im.frame_id for im in weak}:  # one photo per frame (no rigs here)
            rec.deregister_frame(frame_id)
    return {k: rec for k, rec in models.items() if rec.num_reg_images() >= options.min_model_size}


def global_then_incremental(db_path: Path, image_dir: Path, work: Path, config: PosesConfig, options: Any,
                            threads: int, n: int, info: Any = log.info) -> list[pycolmap.Reconstruction]:
    """The global mapper's models (:func:`global_models`, logging with ``info``), the largest :func:`continued`
    by the incremental mapper (``options``); largest first."""
    (work / "global").mkdir(parents=True)
    found = largest_first(global_models(db_path, image_dir, work / "global", config, threads, n, info))
    return continued(db_path, image_dir, work / "continued", found[0], options) + found[1:] if found else []


def continued(db_path: Path, image_dir: Path, work: Path, rec: pycolmap.Reconstruction,
              options: Any) -> list[pycolmap.Reconstruction]:
    """The incremental mapper continued from the global mapper's model ``rec`` (its models, largest first; ``[rec]``
    when it keeps fewer photos): its triangulation and outlier filtering redo what the global mapper accepted
    too easily, and its registration adds photos. Measured: the blowtorch walk-around from 52 to 54 photos,
    rotation agreement with the photographers' poses 0.84 -> 0.48 degrees median (15.7 -> 6.2 max); a tiled
    room 2.8 -> 1.9 degrees from the truth."""
    pycolmap = import_pycolmap()

    start, out = work / "start", work / "models"
    start.mkdir(parents=True)
    out.mkdir()
    rec.write(start)
    models = largest_first(pycolmap.incremental_mapping(db_path, image_dir, out, options, input_path=start))
    return models if models and models[0].num_reg_images() >= rec.num_reg_images() else [rec]


def _feature_counts(db_path: Path) -> dict[str, int]:
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        return {stem_of(im.name): db.num_keypoints_for_image(im.image_id) for im in db.read_all_images()}
    finally:
        db.close()


def unregistered_reasons(db_path: Path, names: Sequence[str], registered: set[str], other_models: list[list[str]],
                         min_inliers: int) -> dict[str, str]:
    """Why each photo of ``names`` not in ``registered`` has no camera, in one sentence a user can act on, from
    the matches in ``db_path``: a separate model; no photo verified with it (its best raw match count); verified
    only with photos that did not register either; or verified with registered photos yet not placed (too few of
    its features see the model's 3D points)."""
    pycolmap = import_pycolmap()

    missing = [n for n in names if n not in registered]
    if not missing:
        return {}
    db = pycolmap.Database.open(db_path)
    try:
        id_to_name = {im.image_id: stem_of(im.name) for im in db.read_all_images()}
        raw_ids, raw_counts = db.read_num_matches()
        verified_ids, verified_counts = db.read_two_view_geometry_num_inliers()
    finally:
        db.close()

    def by_photo(pair_ids: Any, counts: Any) -> dict[str, dict[str, int]]:
        out: dict[str, dict[str, int]] = {}
        for pid, k in zip(pair_ids, counts):
            a, b = (id_to_name[int(i)] for i in pycolmap.pair_id_to_image_pair(int(pid)))
            out.setdefault(a, {})[b] = int(k)
            out.setdefault(b, {})[a] = int(k)
        return out

    raw, verified = by_photo(raw_ids, raw_counts), by_photo(verified_ids, verified_counts)
    model_of = {n: m for m in other_models for n in m}
    reasons = {}
    for n in missing:
        partners = {m: k for m, k in verified.get(n, {}).items() if k >= min_inliers}
        placed = {m: k for m, k in partners.items() if m in registered}
        if n in model_of:
            reasons[n] = (f"in a separate model of {len(model_of[n])} photos that shares too few matches with the "
                          f"main one")
        elif not partners:
            best = max(raw.get(n, {}).items(), key=lambda t: t[1], default=None)
            seen = (f"best: {best[1]} matches with {best[0]} before verification" if best
                    else "no feature matched any photo it was compared with")
            reasons[n] = f"no photo shares a verified geometry with it ({seen}; {min_inliers} inliers needed)"
        elif not placed:
            reasons[n] = (f"verified only with photos that did not register either "
                          f"({', '.join(sorted(partners)[:4])})")
        else:
            best = max(placed.items(), key=lambda t: t[1])
            reasons[n] = (f"verified with {len(placed)} registered photo(s) (best: {best[1]} inliers with {best[0]}), "
                          f"but too few of its features see the model's 3D points to place it")
    return reasons


def _verified_pairs(db_path: Path, min_inliers: int) -> int:
    """Image pairs whose two-view geometry holds at least ``min_inliers`` matches (the database also keeps
    rows for pairs that failed verification)."""
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        _, geometries = db.read_two_view_geometries()
        return sum(len(g.inlier_matches) >= min_inliers for g in geometries)
    finally:
        db.close()


def equalized_gray(image: np.ndarray, target: float, max_gain: float = 8.0) -> np.ndarray:
    """``(H, W)`` uint8 grey of ``image`` (``(H, W)`` or ``(H, W, 3)`` uint8), brightened so that its median is
    at least ``target`` (0..1), by at most ``max_gain``. SIFT keeps a feature only above a fixed contrast: in a
    photo exposure normalization darkened by stops (or a camera under-exposed) most of the background's
    features fall under it, and that photo stops matching its brighter neighbours. Never darkened: a bright
    photo keeps its features."""
    import cv2

    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    gain = np.clip(255.0 * target / max(float(np.median(gray)), 1.0), 1.0, max_gain)
    return cv2.convertScaleAbs(gray, alpha=gain)


def write_sift_images(image_dir: Path, names: Sequence[str], out: Path, target: float) -> Path:
    """``out/<name>.png``: each photo of ``image_dir`` as :func:`equalized_gray` gives it (SIFT's input)."""
    out.mkdir(parents=True, exist_ok=True)
    for n in names:
        image = imageio.read_image(image_dir / colmap_name(n))
        imageio.write_png(out / colmap_name(n), equalized_gray(image, target))
    return out


def _read_gray(path: Path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    return img if img is not None else np.zeros((1, 1), np.uint8)


def _no_model_error(db_path: Path, names: list[str], features: dict[str, int], num_verified: int,
                    folder: Path) -> InputError:
    """Why the mapper could not start: the best-matched pair and how far its matches moved."""
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        id_to_name = {im.image_id: stem_of(im.name) for im in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
        best, best_n, motion = None, 0, None
        for pid, g in zip(pair_ids, geometries):
            k = len(g.inlier_matches)
            if k > best_n:
                i, j = pycolmap.pair_id_to_image_pair(pid)
                best, best_n = (id_to_name[i], id_to_name[j]), k
                ki, kj = db.read_keypoints(i), db.read_keypoints(j)
                m = np.asarray(g.inlier_matches)
                motion = float(np.median(np.linalg.norm(ki[m[:, 0], :2] - kj[m[:, 1], :2], axis=1)))
    finally:
        db.close()
    if best is None:
        detail = (f"no two of the {len(names)} photos share enough matching features "
                  f"({num_verified} verified pairs; "
                  f"features per photo: median {int(np.median(list(features.values())))})")
    else:
        detail = (f"no pair of photos has enough matches seen from different enough viewpoints to start a model "
                  f"(best pair {best[0]} & {best[1]}: {best_n} matches moving {motion:.1f} px)")
        if motion is not None and motion < 2.0:
            detail += "; the matched features barely move between photos, so the camera hardly moved"
    return InputError(f"SfM found no model: {detail}", folder, fix=FIX_OVERLAP)


def _check_registered(result: SfmResult, names: list[str], config: PosesConfig, folder: Path) -> None:
    registered = {stem_of(im.name) for im in result.reconstruction.images.values() if im.has_pose}
    needed = required_registered(len(names), config)
    missing = sorted(set(names) - registered)
    if len(result.model_sizes) > 1:
        log.warning("SfM split the capture into %d models (%s photos); using the largest. Photos in the others: %s",
                    len(result.model_sizes), " + ".join(map(str, result.model_sizes)),
                    "; ".join(", ".join(m) for m in result.other_models))
    if len(registered) >= needed:
        if missing:
            log.warning("%d of %d photos did not register and get no camera (why: below, and in "
                        "poses_report.json not_registered_why): %s", len(missing), len(names), ", ".join(missing))
            for n in missing:  # one line each in the log; the report holds them as data, not as more warnings
                log.info("  %s: %s", n, result.unregistered.get(n, "not placed by the mapper"))
        return
    split = ""
    if len(result.model_sizes) > 1:
        split = (f" SfM split the capture into {len(result.model_sizes)} models of "
                 f"{' + '.join(map(str, result.model_sizes))} photos (the overlap between them is too weak; "
                 f"photos of the second: {', '.join(result.other_models[0][:10])}).")
    shown = ", ".join(missing[:20]) + (" ..." if len(missing) > 20 else "")
    why = "".join(f" {n}: {result.unregistered[n]}." for n in missing[:5] if n in result.unregistered)
    raise InputError(
        f"only {len(registered)} of {len(names)} photos registered, at least {needed} needed "
        f"(poses.min_registered={config.min_registered}, poses.min_registered_fraction="
        f"{config.min_registered_fraction}). Not registered: {shown}.{split}{why}",
        folder,
        fix=FIX_OVERLAP + "; or, to accept fewer photos, lower poses.min_registered_fraction",
    )


# ------------------------------------------------------------------------------------- from a capture to cameras


def camera_groups(decoded: DecodeArtifacts, names: list[str], width: int, height: int, config: PosesConfig,
                  calibration: tuple[str, list[float], Path] | None) -> list[CameraGroup]:
    """One COLMAP camera per lens and zoom (EXIF make, model, focal length), with its intrinsics: the EXIF focal
    length as a start or a prior (``poses.exif_focal``), a calibration as a prior.

    Args:
        calibration: (COLMAP model, params at the decoded size, its file), from ``orca calibrate``.
    """
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
            params = _model_params(model, f, width, height)
            source = f"EXIF 35 mm focal length {f35:g} mm ({config.exif_focal})"
        else:
            params, source = None, "no EXIF focal length: COLMAP's default guess (1.2 x the longest side)"
        groups.append(CameraGroup(members, model, params, source, prior=config.exif_focal == "prior"))
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


def write_feature_masks(files: dict[str, Path], size: tuple[int, int], folder: Path, dilate_px: int) -> Path:
    """COLMAP's feature masks (``<image>.png.png``, 0 = no features there) from object masks (white = object),
    the object grown by ``dilate_px``."""
    import cv2

    folder.mkdir(parents=True)
    r = dilate_px
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)) if r else None
    for n, path in files.items():
        obj = read_mask(path, size).astype(np.uint8)
        if kernel is not None:
            obj = cv2.dilate(obj, kernel)
        imageio.write_png(folder / f"{colmap_name(n)}.png", np.where(obj > 0, 0, 255).astype(np.uint8))
    return folder


def posed_from_sfm(decoded: DecodeArtifacts, names: list[str], calibration: tuple[str, list[float], Path] | None,
                   mask_files: dict[str, Path] | None, work: Path, config: PosesConfig,
                   photo_dir: Path, retry: RetryMatching | None = None) -> tuple[Posed, pycolmap.Reconstruction]:
    """The registered photos' cameras from SfM on the decoded sRGB images, features on the object ignored where
    ``mask_files`` are given; and the reconstruction. ``work``: an empty folder to be (``database.db`` there;
    with ``retry``, a folder holding the first run's features in ``database.db``: they are reused)."""
    width, height = (int(v) for v in decoded.meta["size"])
    groups = camera_groups(decoded, names, width, height, config, calibration)
    work.mkdir(exist_ok=retry is not None)
    feature_masks = (write_feature_masks(mask_files, (width, height), work / "feature_masks", config.mask_dilate_px)
                     if mask_files else None)
    with progress() as bar:
        sfm = run_sfm(decoded.folder / SRGB, groups, work, config, feature_masks=feature_masks, progress=bar,
                      folder=photo_dir, retry=retry)
    rec = sfm.reconstruction
    stats = {
        "matcher": sfm.matcher,
        "mapper": sfm.mapper,
        "pairs_matched": sfm.num_pairs,
        "pairs_verified": sfm.num_verified_pairs,
        "models": sfm.model_sizes,
        "other_models": sfm.other_models,
        "features": {"min": min(sfm.features.values()), "median": int(np.median(list(sfm.features.values()))),
                     "max": max(sfm.features.values()), "per_image": dict(sorted(sfm.features.items()))},
        "camera_groups": [{"photos": len(g.names), "model": g.model, "intrinsics_from": g.source, "fixed": g.fixed}
                          for g in groups],
        "focal_prior_px": {n: None if g.params is None else g.params[0] for g in groups for n in g.names},
        "seconds": {k: round(v, 2) for k, v in sfm.seconds.items()},
        "not_registered_why": sfm.unregistered,
        "mapping_runs": sfm.mapping_runs,
        "mapping_disagreement_deg": sfm.disagreement,
        "relaxed_pass": None if sfm.relaxed is None else {
            "what": "photos without a camera after mapping, registered with the absolute pose needing "
            "poses.relaxed_min_inliers inlier 2D-3D matches and relaxed_min_inlier_ratio of them (COLMAP's bars: 30, "
            "0.25); the pose checks judged them like any other",
            "min_inliers": config.relaxed_min_inliers, "min_inlier_ratio": config.relaxed_min_inlier_ratio,
            "photos": sfm.relaxed},
    }
    return posed_from_reconstruction(rec, names, stats), rec


def posed_from_reconstruction(rec: pycolmap.Reconstruction, names: Sequence[str], stats: dict[str, Any]) -> Posed:
    """The registered photos of ``names`` (in that order) with their cameras, the reliable sparse points
    (tracks of 3+ photos) and the model's figures added to ``stats``."""
    by_name = {stem_of(im.name): im for im in rec.images.values() if im.has_pose}
    posed_names = [n for n in names if n in by_name]
    c2w = np.stack([camera_to_world(by_name[n]) for n in posed_names])
    lens = [rec.cameras[by_name[n].camera_id] for n in posed_names]
    reliable = [p for p in rec.points3D.values() if p.track.length() >= 3]
    points = np.array([p.xyz for p in reliable]).reshape(-1, 3)
    colors = np.array([p.color for p in reliable], np.uint8).reshape(-1, 3)
    per_image_error = _per_image_reprojection_error(rec)
    stats = {
        **stats,
        "points3D": rec.num_points3D(),
        "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        "mean_track_length": float(rec.compute_mean_track_length()),
        "mean_observations_per_image": float(rec.compute_mean_observations_per_reg_image()),
        "reprojection_error_px_per_image": dict(sorted((stem_of(rec.images[i].name), e)
                                                       for i, e in per_image_error.items())),
        "observations_per_image": dict(sorted(observations(rec).items())),
    }
    return Posed(posed_names, c2w, lens, points, colors, stats)


def refine_without_object(rec: pycolmap.Reconstruction, posed: Posed, config: PosesConfig) -> Posed:
    """Bundle-adjust again without the 3D points inside the object's bounding sphere: the cameras then rest on the
    surroundings alone. The points are put back afterwards, unchanged: the masks stage seeds the object with
    them (:mod:`pipeline.masking.tracks`: in each photo that observed one, that pixel shows the object or a
    reflection in it), and training's sparse depth leaves out every point seen on the object anyway. Returns the
    refreshed cameras and the points without them (``stats['object_points_removed']``: how many were left out).

    A glossy object's features are mostly reflections that move with the viewpoint: their matches triangulate
    to virtual points inside a convex object (or near a concave one) and pull the cameras a little (on three
    scenes of the synthetic family rotation errors fell 5-20 % without them; over the whole suite the change is
    within the mapper's run-to-run noise). The sphere is
    :func:`pipeline.object_frame.find_object`'s from these cameras and points; when it holds more than
    ``poses.object_points_max_share`` of the points it is not trusted (the object is not where the cameras
    converge, or the framing guess is far too large) and nothing is changed. Changes ``rec`` in place.
    """
    pycolmap = import_pycolmap()
    from .undistort import pinholes

    K, sizes = pinholes(posed.lens)
    sphere = find_object(posed.c2w, K, sizes, points=posed.points, window=config.object_window,
                         margin=config.radius_margin, seed=config.seed)
    inside = [i for i, p in rec.points3D.items() if np.linalg.norm(p.xyz - sphere.center) < sphere.radius]
    if not inside or len(inside) > config.object_points_max_share * rec.num_points3D():
        return posed
    kept = []
    for i in inside:
        point = rec.points3D[i]
        kept.append((point.xyz.copy(), pycolmap.Track(point.track.elements), point.color.copy()))
        rec.delete_point3D(i)
    options = pycolmap.BundleAdjustmentOptions()
    options.print_summary = False
    options.ceres.solver_options.num_threads = num_threads(config)
    # Poses and points only: the mapper's intrinsics rest on every point, and refitting the lens to fewer
    # (on a 20-photo synthetic orbit) turned a distortion-free pinhole fit into a 0.5 px radial term.
    options.refine_focal_length = options.refine_principal_point = options.refine_extra_params = False
    pycolmap.bundle_adjustment(rec, options)
    log.info("%d sparse points inside the object's sphere (reflections, mostly) left out; cameras adjusted again",
             len(inside))
    stats = {**posed.stats, "object_points_removed": len(inside)}
    refined = posed_from_reconstruction(rec, posed.names, stats)  # the object's sphere is found without them too
    for xyz, track, color in kept:
        rec.add_point3D(xyz, track, color)
    return refined


def observations(rec: pycolmap.Reconstruction) -> dict[str, int]:
    """Each registered photo's (stem) observations of the model's 3D points."""
    return {stem_of(im.name): im.num_points3D for im in rec.images.values() if im.has_pose}


def camera_to_world(image: Any) -> np.ndarray:
    """``(4, 4)`` OpenCV camera-to-world of a posed pycolmap image (COLMAP stores world-to-camera)."""
    m = np.eye(4)
    m[:3] = image.cam_from_world().matrix()
    return np.linalg.inv(m)


def _per_image_reprojection_error(rec: Any) -> dict[int, float]:
    """Mean reprojection error (px) of each registered image's triangulated observations."""
    sums: dict[int, list[float]] = {}
    for p in rec.points3D.values():
        for el in p.track.elements:
            sums.setdefault(el.image_id, []).append(p.error)
    return {i: float(np.mean(v)) for i, v in sums.items()}


# --------------------------------------------------------------------- checked SfM (pipeline.pose_checks)


@dataclass(frozen=True)
class RetryMatching:
    """How a second SfM run matches when the pose checks doubt photos: only neighbours in capture order (a
    repetitive texture then cannot pair photos taken far apart), and a pair's two-view geometry needs more
    inliers within a smaller error."""

    order: tuple[str, ...]  # photo stems in capture order
    overlap: int  # neighbours on each side
    min_num_inliers: int
    max_error_px: float


@dataclass
class CheckedSfm:
    """The SfM run kept after the checks, and what each run gave."""

    posed: Posed
    reconstruction: pycolmap.Reconstruction
    checks: PoseChecks
    work: Path  # the kept run's folder (its database.db)
    runs: list[dict[str, Any]]  # per run: matching, registered, flagged
    folders: list[Path]  # every run's folder (to remove)


def neighbour_pairs(names: Sequence[str], overlap: int, wrap: bool = True) -> list[tuple[str, str]]:
    """Each photo with its ``overlap`` successors in the given order, and (``wrap``) the last ones with the first
    ones (an orbit ends where it began); nothing farther apart, unlike :func:`sequential_pairs`."""
    n = len(names)
    pairs = set()
    for i in range(n):
        for s in range(1, overlap + 1):
            j = i + s
            if j >= n and not wrap:
                break
            j %= n
            if i != j:
                pairs.add((min(i, j), max(i, j)))
    return [(names[i], names[j]) for i, j in sorted(pairs)]


def verification_options(config: PosesConfig, retry: RetryMatching | None) -> pycolmap.TwoViewGeometryOptions:
    """COLMAP's two-view verification, seeded; stricter for a retry."""
    pycolmap = import_pycolmap()

    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = config.seed
    if retry is not None:
        verification.min_num_inliers = retry.min_num_inliers
        verification.ransac.max_error = retry.max_error_px
    return verification


def consecutive_matches(db_path: Path, order: Sequence[str]) -> np.ndarray:
    """``(N - 1,)`` verified matches between consecutive photos of ``order`` (image stems); 0 for a pair not
    matched or not verified."""
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        ids = {stem_of(im.name): im.image_id for im in db.read_all_images()}
        pair_ids, counts = db.read_two_view_geometry_num_inliers()
        inliers = {int(p): int(k) for p, k in zip(pair_ids, counts)}
        return np.array([inliers.get(int(pycolmap.image_pair_to_pair_id(ids[a], ids[b])), 0)
                         for a, b in zip(order[:-1], order[1:])], float)
    finally:
        db.close()


def checks_of(posed: Posed, db_path: Path, order: Sequence[str], order_by: str, config: PosesConfig) -> PoseChecks:
    """:func:`pipeline.pose_checks.check_poses` on the registered photos of one run (``order``: all photos'
    stems in capture order; each photo's support: its model's ``observations_per_image``; its focal length's
    prior: ``focal_prior_px``; its turn in other mapper runs: ``mapping_disagreement_deg``)."""
    from .undistort import pinholes

    index = {n: i for i, n in enumerate(posed.names)}
    registered = [n for n in order if n in index]
    K, sizes = pinholes(posed.lens)
    observed, prior = posed.stats["observations_per_image"], posed.stats["focal_prior_px"]
    turned = posed.stats.get("mapping_disagreement_deg") or {}
    runs = max((len(v) for v in turned.values()), default=0)
    disagreement = np.array([[np.nan if v is None else v for v in turned.get(n, [None] * runs)] for n in posed.names],
                            float).reshape(len(posed.names), runs)
    return check_poses(posed.names, posed.c2w, K, sizes, consecutive_matches(db_path, registered),
                       np.array([index[n] for n in registered], int), order_by, posed.points, config,
                       np.array([observed[n] for n in posed.names]),
                       np.array([np.nan if prior[n] is None else prior[n] for n in posed.names]), disagreement)


def posed_from_sfm_checked(decoded: DecodeArtifacts, names: list[str],
                           calibration: tuple[str, list[float], Path] | None, mask_files: dict[str, Path] | None,
                           work: Path, config: PosesConfig, photo_dir: Path) -> CheckedSfm:
    """:func:`posed_from_sfm`, then the pose checks; when they doubt photos (and ``poses.retry_matching``), a
    second run with :class:`RetryMatching` in ``work`` + ``_retry`` on the first run's features. The run with more
    undoubted photos is kept (registered less doubted; a tie: the fewer doubted). A retry that fails (too few
    photos register under the stricter matching) keeps the first run."""
    times = [(decoded.entry(n).get("exif") or {}).get("datetime") for n in names]
    index, order_by = capture_order(names, times)
    order = [names[i] for i in index]
    posed, rec = posed_from_sfm(decoded, names, calibration, mask_files, work, config, photo_dir)
    checks = checks_of(posed, work / SFM_DATABASE, order, order_by, config)
    runs = [_run_summary(config.matcher, posed, checks)]
    folders = [work]
    kept = CheckedSfm(posed, rec, checks, work, runs, folders)
    if not checks.flagged or not config.retry_matching:
        return kept
    log.warning("pose checks doubt %d of %d photos (%s); SfM again, matching only neighbours in %s order with "
                "a stricter verification", len(checks.flagged), len(posed.names), ", ".join(checks.flagged[:12]),
                order_by)
    retry_work = work.parent / f"{work.name}_retry"
    retry_work.mkdir()
    folders.append(retry_work)
    shutil.copy2(work / SFM_DATABASE, retry_work / SFM_DATABASE)
    _clear_matches(retry_work / SFM_DATABASE)
    retry = RetryMatching(tuple(order), config.retry_overlap, config.retry_min_inliers, config.retry_max_error_px)
    try:
        posed2, rec2 = posed_from_sfm(decoded, names, calibration, mask_files, retry_work, config, photo_dir, retry)
    except InputError as e:
        log.warning("the stricter SfM run failed (%s); keeping the first", e.message)
        runs.append({"matching": "neighbours, strict", "failed": e.message})
        return kept
    checks2 = checks_of(posed2, retry_work / SFM_DATABASE, order, order_by, config)
    runs.append(_run_summary("neighbours, strict", posed2, checks2))
    if _undoubted(posed2, checks2) > _undoubted(posed, checks):
        log.info("the stricter SfM run is kept: %d photos registered, %d doubted (first run: %d, %d)",
                 len(posed2.names), len(checks2.flagged), len(posed.names), len(checks.flagged))
        return CheckedSfm(posed2, rec2, checks2, retry_work, runs, folders)
    log.info("the first SfM run is kept: the stricter one registered %d photos, %d doubted", len(posed2.names),
             len(checks2.flagged))
    return kept


def act_on_suspects(posed: Posed, checks: PoseChecks, total: int, config: PosesConfig, folder: Path) -> Posed:
    """``poses.on_suspect`` on the photos ``checks`` doubt: the cameras to keep (``warn``: all; ``drop``: the
    others), each doubt logged.

    Raises:
        InputError: ``error`` and photos are doubted; or ``drop`` leaves fewer photos than required.
    """
    if not checks.flagged:
        return posed
    for line in checks.photo_warnings():
        log.warning("doubtful pose: %s", line)
    shown = ", ".join(checks.flagged[:20]) + (" ..." if len(checks.flagged) > 20 else "")
    fix = ("look at poses.png and poses_report.json (checks); " + FIX_OVERLAP + "; or set poses.on_suspect=drop "
           "(no camera for them) or warn (keep them)")
    if config.on_suspect == "error":
        raise InputError(f"{len(checks.flagged)} photos have doubtful poses (poses.on_suspect=error): {shown}",
                         folder, fix=fix)
    if config.on_suspect == "warn":
        log.warning("%d photos have doubtful poses and are kept (poses.on_suspect=warn): %s", len(checks.flagged),
                    shown)
        return posed
    kept = [i for i, n in enumerate(posed.names) if n not in set(checks.flagged)]
    needed = required_registered(total, config)
    if len(kept) < needed:
        raise InputError(f"{len(checks.flagged)} of {len(posed.names)} registered photos have doubtful poses "
                         f"({shown}); without them {len(kept)} of {total} remain, at least {needed} needed", folder,
                         fix=fix)
    log.warning("%d photos have doubtful poses and get no camera (poses.on_suspect=drop): %s", len(checks.flagged),
                shown)
    return Posed([posed.names[i] for i in kept], posed.c2w[kept], [posed.lens[i] for i in kept], posed.points,
                 posed.point_colors, posed.stats)


def without_dropped(rec: pycolmap.Reconstruction, kept: Sequence[str]) -> pycolmap.Reconstruction:
    """``rec`` with only the photos ``kept`` (stems) registered: a photo dropped as doubtful must not reach
    the COLMAP model other tools start from. Changes ``rec`` in place and returns it."""
    keep = set(kept)
    for frame_id in {im.frame_id for im in rec.images.values() if im.has_pose and stem_of(im.name) not in keep}:
        rec.deregister_frame(frame_id)
    return rec


def _run_summary(matching: str, posed: Posed, checks: PoseChecks) -> dict[str, Any]:
    return {"matching": matching, "registered": len(posed.names), "flagged": checks.flagged,
            "mean_reprojection_error_px": posed.stats["mean_reprojection_error_px"]}


def _undoubted(posed: Posed, checks: PoseChecks) -> tuple[int, int]:
    """(registered photos the checks do not doubt, minus the doubted ones): compared in that order."""
    return len(posed.names) - len(checks.flagged), -len(checks.flagged)


def _clear_matches(db_path: Path) -> None:
    """Keep a database's features, forget its matches (a new matching run starts from there)."""
    pycolmap = import_pycolmap()

    db = pycolmap.Database.open(db_path)
    try:
        db.clear_matches()
        db.clear_two_view_geometries()
    finally:
        db.close()
