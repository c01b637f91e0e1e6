"""``orca calibrate``: a folder of board photos -> ``OUT/calibration.json`` (+ pictures), written atomically.

Photos: every JPEG/PNG/TIFF/BMP/WebP at the top level of the folder, in name order, all of one size (EXIF
orientation applied, as ``decode`` does). Photos where the board is not found are rejected and reported
(in the log, in ``calibration.json``, and as ``detections/<name>.jpg``); so are photos whose reprojection
error is an outlier after a first solve. Too few usable photos is an :class:`~pipeline.errors.InputError`
that names the folder, says what was seen in the photos, and lists the likely fixes.

Output folder (replaced whole, only on success): ``calibration.json`` (see :mod:`calibration.result`),
``calibration.png`` (per-image errors, corner coverage, distortion), ``detections/<stem>.jpg`` (corners found
in green, reprojected in red), ``manifest.json``.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from pipeline.errors import InputError

from .board import Board
from .detect import BoardNotFound, Detection, Detector
from .result import CALIBRATION_JSON, Calibration, calibration_doc
from .solve import Solution

log = logging.getLogger("orca.calibration")

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp"}
RAW_SUFFIXES = {".dng", ".cr2", ".cr3", ".nef", ".arw", ".raf", ".orf", ".rw2", ".pef", ".srw", ".kdc"}
SUMMARY_PNG = "calibration.png"

NOT_FOUND_FIX = (
    "check the board parameters against the printed board: --board charuco|chessboard; --squares-x/--squares-y "
    "count squares, not inner corners (a chessboard with 9x6 inner corners has 10x7 squares); --dictionary must "
    "be the markers' dictionary; a board with white markers on black needs --inverted yes (or auto). If the "
    "parameters are right, retake the photos: sharp (no motion blur), evenly lit without glare on the board, the "
    "whole board in view and filling a good part of the frame"
)


class CalibrateOptions(BaseModel):
    """How a calibration is run (board-independent)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    min_images: int = Field(5, ge=3, description="fewer photos with the board found is an error")
    min_corners: int = Field(6, ge=4, description="photos with fewer board corners found are rejected")
    fit_k3: bool = Field(False, description="also fit the radial k3 term (model FULL_OPENCV)")
    outlier_factor: float = Field(
        3.0, gt=1, description="photos with a reprojection error above this x the median (and the floor) are dropped"
    )
    outlier_floor_px: float = Field(1.0, ge=0, description="never drop photos whose error is below this (px)")
    max_detect_side: int = Field(2000, ge=320, description="chessboards are searched at most this large (px)")


def find_images(images_dir: Path) -> list[Path]:
    """Photos at the top level of ``images_dir`` in name order; RAW files are skipped with a warning."""
    if not images_dir.is_dir():
        raise InputError(
            "folder not found" if not images_dir.exists() else "not a folder",
            images_dir,
            fix="pass the folder holding the photos of the calibration board",
        )
    files, raws = [], []
    for p in sorted(images_dir.iterdir(), key=lambda q: q.name):
        if not p.is_file() or p.name.startswith("."):
            continue
        if p.suffix.lower() in IMAGE_SUFFIXES:
            files.append(p)
        elif p.suffix.lower() in RAW_SUFFIXES:
            raws.append(p.name)
    if raws:
        log.warning("%s: skipping %d RAW file(s) (%s): calibrate from the camera's JPEGs of the same shots, at "
                    "the capture's resolution", images_dir, len(raws), ", ".join(raws[:5]))
    if not files:
        raise InputError("no photos (JPEG, PNG, TIFF, BMP, WebP) found", images_dir,
                         fix="pass the folder holding the photos of the calibration board")
    return files


def run_calibration(
    images_dir: str | Path, out_dir: str | Path, board: Board, options: CalibrateOptions | None = None
) -> Calibration:
    """Calibrate one camera from photos of ``board`` in ``images_dir``; write ``out_dir`` (see the module doc)."""
    import cv2

    from pipeline.artifacts import atomic_dir, check_output_dir, write_json, write_manifest

    options = options or CalibrateOptions()
    started = time.time()
    images_dir, out_dir = Path(images_dir), Path(out_dir)
    files = find_images(images_dir)
    check_output_dir(out_dir, "calibrate", [images_dir])
    log.info("calibrate: %d photos in %s; board: %s", len(files), images_dir, board.describe())

    detector = Detector(board, min_corners=options.min_corners, max_detect_side=options.max_detect_side)
    sizes: dict[str, tuple[int, int]] = {}
    found: dict[str, Detection] = {}
    rejected: dict[str, str] = {}
    unreadable: list[str] = []
    for f in files:
        gray = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)  # applies EXIF orientation, like decode
        if gray is None:
            unreadable.append(f.name)
            continue
        sizes[f.name] = (gray.shape[1], gray.shape[0])
        try:
            found[f.name] = detector.detect(gray)
            log.debug("%s: %d corners", f.name, found[f.name].n)
        except BoardNotFound as e:
            rejected[f.name] = f"board not found ({e})"
            log.warning("%s: board not found (%s)", f.name, e)
    if unreadable:
        raise InputError(f"{len(unreadable)} photo(s) cannot be read: {', '.join(unreadable)}", images_dir,
                         fix="copy them again or remove them from the folder")
    size = _common_size(sizes, images_dir)
    if len(found) < options.min_images:
        raise _not_found_error(images_dir, files, found, rejected, board, options)

    fit = calibrate(found, size, options)
    rejected.update(fit.dropped)
    solution, names, calibration = fit.solution, fit.names, fit.calibration
    detections = [found[n] for n in names]
    per_image = []
    for n, d, e in zip(names, detections, solution.per_image_rms_px):
        per_image.append({"name": n, "corners": d.n, "rms_px": round(float(e), 4)})
        if board.kind == "charuco":
            per_image[-1]["inverted"] = d.inverted
    coverage = frame_coverage(np.concatenate([d.image_points for d in detections]), size)
    std = dict(zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"), map(float, solution.std)))
    doc = calibration_doc(
        calibration,
        intrinsics_std=std,
        frame_coverage=round(coverage, 3),
        per_image=per_image,
        board=board.to_json(),
        images_dir=str(images_dir),
        images_rejected=sorted(rejected),
        rejection_reasons=dict(sorted(rejected.items())),
        options=options.model_dump(mode="json"),
    )

    with atomic_dir(out_dir, "calibrate", [images_dir]) as tmp:
        write_json(tmp / CALIBRATION_JSON, doc)
        from .figures import summary_figure

        title = (f"{images_dir}: {board.describe()} -- {size[0]}x{size[1]}, fx {calibration.fx:.1f} fy "
                 f"{calibration.fy:.1f} cx {calibration.cx:.1f} cy {calibration.cy:.1f}, {solution.rms_px:.3f} px RMS")
        summary_figure(tmp / SUMMARY_PNG, names, detections, solution, size, rejected, title)
        reprojected = dict(zip(names, solution.reprojected))
        reprojected.update(_reproject_dropped(found, reprojected, calibration))
        _write_overlays(tmp / "detections", files, found, reprojected, rejected)
        write_manifest(
            tmp, stage="calibrate", inputs={f"photo:{f.name}": f for f in files},
            config={"board": board.to_json(), "options": options.model_dump(mode="json")}, started=started,
        )
    log.info(
        "calibrate: %d of %d photos used, %.3f px RMS; fx %.2f fy %.2f cx %.2f cy %.2f (pixel centres at +0.5), "
        "k1 %.4f k2 %.4f -> %s (%.1f s)",
        len(names), len(files), solution.rms_px, calibration.fx, calibration.fy, calibration.cx, calibration.cy,
        calibration.dist[0], calibration.dist[1], out_dir / CALIBRATION_JSON, time.time() - started,
    )
    if len(names) < 10:
        log.warning("only %d photos used: 15-30 photos, the board tilted 20-45 degrees and reaching every part of the "
                    "frame, give stable intrinsics", len(names))
    if coverage < 0.5:
        log.warning("the board's corners reached only %.0f %% of the frame (see %s): the principal point and the "
                    "distortion near the edges are guesses; add photos with the board near the edges and corners",
                    100 * coverage, out_dir / SUMMARY_PNG)
    if solution.rms_px > 1.0:
        log.warning("reprojection error %.2f px RMS is high: blurred photos, a board that is not flat, or wrong "
                    "board parameters? See %s", solution.rms_px, out_dir / SUMMARY_PNG)
    return calibration


def _common_size(sizes: dict[str, tuple[int, int]], images_dir: Path) -> tuple[int, int]:
    counts = Counter(sizes.values())
    (w, h), n = counts.most_common(1)[0]
    if len(counts) > 1:
        odd = [f"{name} ({a}x{b})" for name, (a, b) in sizes.items() if (a, b) != (w, h)]
        raise InputError(
            f"photos of different sizes: {n} are {w}x{h} but {len(odd)} are not: {', '.join(odd[:10])}"
            + (" ..." if len(odd) > 10 else ""),
            images_dir,
            fix="calibrate one camera at one resolution and orientation: remove the odd photos (portrait shots "
            "among landscape ones, or another zoom/resolution setting) or calibrate them separately",
        )
    return w, h


@dataclass(frozen=True)
class Fit:
    """The result of :func:`calibrate`."""

    calibration: Calibration  # project pixel convention
    solution: Solution  # OpenCV pixel convention; per-image arrays in the order of ``names``
    names: list[str]  # images used
    dropped: dict[str, str]  # images dropped as outliers -> why


def calibrate(detections: dict[str, Detection], size: tuple[int, int], options: CalibrateOptions) -> Fit:
    """Solve from the detections of several images (name -> detection, OpenCV convention); drop outlier
    images and solve again, at most three rounds. ``size``: (width, height)."""
    from .solve import outliers, solve

    names = list(detections)
    dropped: dict[str, str] = {}
    solution = solve([detections[n] for n in names], size, fit_k3=options.fit_k3)
    for _ in range(3):
        bad = outliers(solution.per_image_rms_px, options.outlier_factor, options.outlier_floor_px)
        if len(bad) == 0 or len(names) - len(bad) < options.min_images:
            break
        median = float(np.median(solution.per_image_rms_px))
        for i in bad:
            dropped[names[i]] = (
                f"reprojection error {solution.per_image_rms_px[i]:.2f} px, over {options.outlier_factor:g} x the "
                f"median {median:.2f} px (blur or a misdetected corner)"
            )
            log.warning("%s: dropped, %s", names[i], dropped[names[i]])
        names = [n for i, n in enumerate(names) if i not in set(bad.tolist())]
        solution = solve([detections[n] for n in names], size, fit_k3=options.fit_k3)
    K = solution.K
    calibration = Calibration(
        model="FULL_OPENCV" if options.fit_k3 else "OPENCV",
        width=size[0],
        height=size[1],
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]) + 0.5,  # OpenCV's pixel centres are integers; the project's are at +0.5
        cy=float(K[1, 2]) + 0.5,
        dist=tuple(float(v) for v in solution.dist),
        rms_reprojection_px=float(solution.rms_px),
        images_used=len(names),
    )
    return Fit(calibration, solution, names, dropped)


def _not_found_error(
    images_dir: Path, files: list[Path], found: dict[str, Detection], rejected: dict[str, str], board: Board,
    options: CalibrateOptions,
) -> InputError:
    shown = "; ".join(f"{n}: {r.removeprefix('board not found ')}" for n, r in list(rejected.items())[:6])
    more = f"; ... {len(rejected) - 6} more" if len(rejected) > 6 else ""
    hints = _diagnose(images_dir, [images_dir / n for n in rejected][:2], board)
    return InputError(
        f"the board was found in {len(found)} of {len(files)} photos, at least {options.min_images} needed "
        f"(--min-images). Looked for: {board.describe()}. Per photo: {shown}{more}."
        + (f"\nWhat the photos show: {hints}" if hints else ""),
        images_dir,
        fix=NOT_FOUND_FIX,
    )


def _diagnose(images_dir: Path, samples: list[Path], board: Board) -> str:
    """Which ArUco dictionaries' markers appear in a couple of the failed photos: the usual cause of a
    ChArUco board not being found is the wrong dictionary (or a ChArUco board calibrated as a chessboard)."""
    import cv2

    from .detect import dictionary_family, probe_dictionaries

    seen: dict[str, tuple[int, bool]] = {}
    for path in samples:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if gray is not None:
            seen = probe_dictionaries(gray)
        if seen:
            break  # one photo with markers tells enough; a probe costs up to ~1 s
    if not seen:
        return ""
    listed = ", ".join(f"{name} ({n} markers{', inverted' if inv else ''})" for name, (n, inv) in seen.items())
    if board.kind == "chessboard":
        return f"ArUco markers were found ({listed}): is this a ChArUco board (--board charuco)?"
    ours = [inv for name, (_, inv) in seen.items() if dictionary_family(name) == dictionary_family(board.dictionary)]
    if ours and ours[0] and board.inverted is False:
        return f"the markers ({listed}) are white on black: use --inverted yes (or auto)"
    if ours:
        return (f"markers of {board.dictionary} were found ({listed}) but not enough board corners: check "
                "--squares-x/--squares-y (and --legacy-pattern for boards drawn by OpenCV < 4.6)")
    return f"markers of other dictionaries were found: {listed}; try --dictionary {next(iter(seen))}"


def _reproject_dropped(
    found: dict[str, Detection], reprojected: dict[str, np.ndarray], calibration: Calibration
) -> dict[str, np.ndarray]:
    """Corners of the photos dropped as outliers, reprojected through their best pose under the final
    intrinsics (solvePnP), so their overlay shows what did not fit. name -> (N, 2), OpenCV convention."""
    import cv2

    K, dist = calibration.opencv_camera_matrix(), calibration.dist_coeffs()
    out = {}
    for name, det in found.items():
        if name in reprojected:
            continue
        ok, r, t = cv2.solvePnP(det.object_points, det.image_points, K, dist)
        if ok:
            out[name] = cv2.projectPoints(det.object_points, r, t, K, dist)[0].reshape(-1, 2)
    return out


def frame_coverage(points: np.ndarray, size: tuple[int, int], cells: tuple[int, int] = (8, 6)) -> float:
    """Fraction of an 8 x 6 grid over the frame holding at least one detected corner. (N, 2) -> [0, 1].

    Intrinsics (the principal point and distortion above all) are only measured where corners were seen.
    """
    w, h = size
    ix = np.clip((points[:, 0] + 0.5) / w * cells[0], 0, cells[0] - 1).astype(int)
    iy = np.clip((points[:, 1] + 0.5) / h * cells[1], 0, cells[1] - 1).astype(int)
    return len(set(zip(ix.tolist(), iy.tolist()))) / (cells[0] * cells[1])


def _write_overlays(
    folder: Path, files: list[Path], found: dict[str, Detection], reprojected: dict[str, np.ndarray],
    rejected: dict[str, str],
) -> None:
    import cv2

    from .detect import draw_detection

    folder.mkdir()
    for f in files:
        gray = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        det = found.get(f.name)
        if f.name in rejected:
            label = f"REJECTED: {rejected[f.name]}"[:120]
        else:
            label = f"{f.name}: {det.n} corners{' (inverted)' if det.inverted else ''}"
        overlay = draw_detection(gray, det, reprojected.get(f.name), label)
        cv2.imwrite(str(folder / f"{f.stem}.jpg"), overlay, [cv2.IMWRITE_JPEG_QUALITY, 85])
