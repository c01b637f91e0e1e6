"""The front end (decode -> poses -> masks) on real photos of a glossy object: the blowtorch walk-around in
../shared/testdata/real/blowtorch, against the photographers' COLMAP poses (poses_bounds.npy) and object masks.

    python bench/blowtorch.py                               # all 67 photos, decode.downscale 2
    python bench/blowtorch.py --limit 16 --downscale 4      # the first 16 photos (~290 degrees of the orbit)
    python bench/blowtorch.py --every 3 --work /tmp/bt_bench --set poses.matcher=sequential
    python bench/blowtorch.py --known-poses                 # masks alone: the reference cameras, no SfM

Builds a capture folder in the work folder (symlinks to the photos and a capture.yaml with
``decode: {downscale: N}``; no masks and no known cameras, since both are what is measured, unless
``--known-poses`` links the reference poses_bounds.npy in to measure the masks on their own), runs
``orca decode``, ``orca poses`` and ``orca masks`` (the installed CLI beside this Python) one after the other,
each timed with its peak resident memory, then scores:

- poses: photos registered (and which not); after a similarity alignment to the reference cameras
  (:func:`pipeline.alignment.compare_poses`), rotation errors (the similarity's rotation from the cameras'
  orientations) and centre errors (the similarity from the centres) as a fraction of the reference cameras'
  mean distance from their centroid. The reference is another SfM run: agreement, not truth.
- masks: IoU of every view's mask with the reference mask resized to it (area average, then half way) and, when
  the poses stage undistorted the photos (the masks are then in the undistorted images' grid), resampled the
  way the photos were.

Prints a table and appends a JSON line (machine, commit, settings, figures) to bench/results/blowtorch.jsonl.
The scoring functions are shared with tests/stages/test_blowtorch.py.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from PIL import Image

from pipeline.alignment import compare_poses
from pipeline.cameras import CameraSet
from pipeline.layout import (
    CAPTURE_YAML,
    DECODE,
    LLFF_IMAGE_NAMES,
    MASKS,
    PHOTO_SUBDIR,
    POSES,
    POSES_BOUNDS,
    UNDISTORTED,
    USER_MASKS,
)
from pipeline.llff import load_poses_bounds
from pipeline.mask_file import read_mask
from pipeline.metrics import iou
from pipeline.results import load_decode, load_masks, load_poses
from pipeline.undistort import UndistortMaps, recorded_undistortion, remap

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT.parent / "shared" / "testdata" / "real" / "blowtorch"
RESULTS = Path(__file__).parent / "results" / "blowtorch.jsonl"
ORCA = Path(sys.executable).parent / "orca"  # the CLI installed beside this Python (.venv/bin/orca)
PHOTO_GLOB = "*.jpg"
FRONT_END = (DECODE, POSES, MASKS)
LOG_TAIL_LINES = 30
HALF = 0.5  # a resized reference mask's pixel is object where at least half of it was
# The poses stage accepts any number of registered photos (3 at least), so a partial registration is scored
# rather than stopping the run; --set poses.min_registered_fraction=... puts the stage's own threshold back.
BENCH_OVERRIDES = ("poses.min_registered_fraction=0.01",)


# ------------------------------------------------------------------------------------------- the capture


def select_photos(dataset: Path = DATASET, start: int = 0, every: int = 1, limit: int | None = None) -> list[Path]:
    """The dataset's photos in name order: from ``start``, every ``every``-th, at most ``limit``."""
    photos = sorted((dataset / PHOTO_SUBDIR).glob(PHOTO_GLOB))[start::every]
    return photos[:limit] if limit is not None else photos


def build_capture(folder: Path, photos: Sequence[Path], downscale: int, known_poses: Path | None = None) -> Path:
    """A capture folder of symlinks to ``photos`` (in ``images/``) and a capture.yaml setting the decode
    downscale; with ``known_poses`` (a dataset folder) also links to its LLFF poses, which the poses stage
    then uses instead of SfM. ``folder`` must not exist."""
    (folder / PHOTO_SUBDIR).mkdir(parents=True)
    for p in photos:
        (folder / PHOTO_SUBDIR / p.name).symlink_to(p.resolve())
    for name in (POSES_BOUNDS, LLFF_IMAGE_NAMES) if known_poses is not None else ():
        (folder / name).symlink_to((known_poses / name).resolve())
    (folder / CAPTURE_YAML).write_text(f"decode:\n  downscale: {downscale}\n", encoding="utf-8")
    return folder


# ------------------------------------------------------------------------------------------- the stages


@dataclass(frozen=True)
class StageRun:
    stage: str
    seconds: float
    peak_rss_mb: float
    returncode: int
    log: str  # the stage's stdout and stderr


def run_stage(stage: str, capture: Path, results: Path, overrides: Sequence[str] = ()) -> StageRun:
    """``orca <stage>`` on ``capture`` with its inputs and output in ``results/<stage>`` (a subprocess of the
    installed CLI); its wall time and peak memory (:func:`timed`)."""
    inputs = {DECODE: [], POSES: ["--decode", results / DECODE], MASKS: ["--decode", results / DECODE,
                                                                      "--poses", results / POSES]}[stage]
    cmd = [str(ORCA), stage, str(capture), "--out", str(results / stage), *map(str, inputs)]
    for o in overrides:
        cmd += ["--set", o]
    log = results / f"{stage}.log"
    seconds, peak_mb, returncode = timed(cmd, log)
    return StageRun(stage, seconds, peak_mb, returncode, log.read_text(encoding="utf-8"))


def timed(cmd: Sequence[str], log: Path, every_s: float = 0.2) -> tuple[float, float, int]:
    """Run ``cmd`` with its stdout and stderr in ``log``: its wall time (s), peak memory (MB) and exit code. The
    peak is the larger of ``wait4``'s (the process and the children it waited for) and the largest sum of the
    resident memory of the process and all its descendants seen every ``every_s``: the masks stage's worker
    processes run beside it, started by a fork server, and ``wait4`` would see neither."""
    import threading

    import psutil  # snakemake's dependency

    started = time.perf_counter()
    peak_tree = 0
    with open(log, "w", encoding="utf-8") as out:
        proc = subprocess.Popen(list(cmd), stdout=out, stderr=subprocess.STDOUT)
        done = threading.Event()

        def sample() -> None:
            nonlocal peak_tree
            while not done.wait(every_s):
                try:
                    root = psutil.Process(proc.pid)
                    tree = [root, *root.children(recursive=True)]
                    peak_tree = max(peak_tree, sum(p.memory_info().rss for p in tree if p.is_running()))
                except psutil.Error:  # a process ended between the listing and the reading
                    continue

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        _, status, usage = os.wait4(proc.pid, 0)
        done.set()
        sampler.join()
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
    return time.perf_counter() - started, max(usage.ru_maxrss / 1024, peak_tree / 2**20), proc.returncode


def run_front_end(capture: Path, results: Path, overrides: Sequence[str] = (),
                  stages: Sequence[str] = FRONT_END) -> dict[str, StageRun]:
    """``stages`` (decode, poses, masks) one after the other into ``results/``; stops at the first that fails."""
    results.mkdir(parents=True, exist_ok=True)
    runs: dict[str, StageRun] = {}
    for stage in stages:
        runs[stage] = run_stage(stage, capture, results, overrides)
        if runs[stage].returncode:
            break
    return runs


# ------------------------------------------------------------------------------------------- scoring


def reference_cameras(dataset: Path = DATASET) -> CameraSet:
    """The photographers' cameras of every row of poses_bounds.npy (OpenCV axes, original photo size)."""
    photos = [p.stem for p in sorted((dataset / PHOTO_SUBDIR).glob(PHOTO_GLOB))]
    return load_poses_bounds(dataset / POSES_BOUNDS, photos).cameras


def pose_agreement(cameras: CameraSet, reference: CameraSet) -> dict[str, Any]:
    """``cameras`` against the ``reference`` cameras of the same names after a similarity alignment.

    Returns:
        ``rotation_deg_median/max`` (rotation of the similarity from the cameras' orientations: each camera's
        own error), ``center_median/max_fraction`` (similarity from the centres; fraction of the reference
        cameras' mean distance from their centroid), ``cameras`` compared and ``per_camera`` errors.
    """
    ours, theirs = cameras.by_name(), reference.by_name()
    names = [n for n in ours if n in theirs]
    est = np.stack([ours[n].c2w for n in names])
    ref = np.stack([theirs[n].c2w for n in names])
    by_orientations = compare_poses(est, ref, rotation_from="orientations")
    by_centres = compare_poses(est, ref)
    spread = float(np.linalg.norm(ref[:, :3, 3] - ref[:, :3, 3].mean(0), axis=1).mean())
    centre = by_centres.summary(scale=spread)
    return {
        "cameras": len(names),
        "rotation_deg_median": float(np.median(by_orientations.rotation_deg)),
        "rotation_deg_max": float(by_orientations.rotation_deg.max()),
        "center_median_fraction": centre["center_median_fraction"],
        "center_max_fraction": centre["center_max_fraction"],
        "per_camera": {n: {"rotation_deg": float(r), "center_fraction": float(c / spread)}
                       for n, r, c in zip(names, by_orientations.rotation_deg, by_centres.center)},
    }


def reference_mask(path: Path, size: tuple[int, int], undistortion: UndistortMaps | None = None) -> np.ndarray:
    """``(H, W)`` bool reference mask at ``size`` (width, height): thresholded at the file's own size, then
    area-averaged, resampled (bilinear) like its photo when ``undistortion`` (the poses stage's) is given, and
    taken where at least half object (the rule of every figure in bench/results; the pipeline's reader,
    :func:`pipeline.mask_file.read_mask`, counts a pixel exactly half covered as background, which moves the
    blowtorch's IoU by about 0.002)."""
    full = read_mask(path, Image.open(path).size)
    small = cv2.resize(full.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    if undistortion is not None:
        small = remap(small, undistortion.maps[undistortion.lens_of[path.stem]])
    return small >= HALF


def masks_agreement(masks_dir: Path, reference: Path = DATASET / USER_MASKS,
                    undistortion: UndistortMaps | None = None) -> dict[str, Any]:
    """IoU of each mask of a masks stage folder with the ``reference`` mask of its photo (``<name>.png``,
    :func:`reference_mask` at our size, through ``undistortion``: the poses stage's, when it made one).

    Returns:
        ``iou_median``, ``iou_mean``, ``iou_worst``, ``worst_view``, ``views`` and ``per_view``.
    """
    masks = load_masks(masks_dir)
    scores = {}
    for name in masks.names:
        ours = masks.mask(name)
        scores[name] = iou(ours, reference_mask(reference / f"{name}.png", ours.shape[::-1], undistortion))
    values = np.array(list(scores.values()))
    worst = min(scores, key=scores.get)
    return {"views": len(scores), "iou_median": float(np.median(values)), "iou_mean": float(values.mean()),
            "iou_worst": float(values.min()), "worst_view": worst, "per_view": scores}


# ------------------------------------------------------------------------------------------- the record


def machine() -> dict[str, Any]:
    model = ""
    with open("/proc/cpuinfo", encoding="utf-8") as f:
        for line in f:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return {"cores": os.cpu_count(), "cpu": model or platform.processor(), "platform": platform.platform()}


def commit() -> str:
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], capture_output=True, text=True, cwd=ROOT, check=False).stdout.strip()

    return git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain", "--untracked-files=no")
                                                  else "")


def append_record(path: Path, record: dict[str, Any]) -> None:
    """``record`` appended to the JSON-lines file ``path`` (its folder made if missing): every bench's record."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps(record) + "\n")


def poses_undistortion(results: Path) -> UndistortMaps | None:
    """How the poses stage in ``results/`` resampled the photos (its ``undistorted/`` folder), or None."""
    undistorted = results / POSES / UNDISTORTED
    return recorded_undistortion(load_decode(undistorted)) if undistorted.is_dir() else None


def score(results: Path, photos: Sequence[Path], dataset: Path = DATASET) -> dict[str, Any]:
    """Registered photos, pose agreement and masks IoU of a front-end run in ``results/``."""
    cameras = load_poses(results / POSES).cameras()
    names = [p.stem for p in photos]
    registered = set(cameras.by_name())
    figures: dict[str, Any] = {"registered": len(registered), "total": len(names),
                               "unregistered": [n for n in names if n not in registered],
                               "poses": pose_agreement(cameras, reference_cameras(dataset))}
    if (results / MASKS).is_dir():
        figures["masks"] = masks_agreement(results / MASKS, dataset / USER_MASKS, poses_undistortion(results))
    return figures


def table(runs: dict[str, StageRun], figures: dict[str, Any]) -> str:
    lines = [f"{'stage':8} {'seconds':>8} {'peak RSS MB':>12}"]
    lines += [f"{r.stage:8} {r.seconds:8.1f} {r.peak_rss_mb:12.0f}" for r in runs.values()]
    if "poses" in figures:
        p = figures["poses"]
        lines += [
            f"registered {figures['registered']}/{figures['total']}"
            + (f" (not: {', '.join(figures['unregistered'])})" if figures["unregistered"] else ""),
            f"rotation error deg: median {p['rotation_deg_median']:.3f}, max {p['rotation_deg_max']:.3f}",
            f"centre error / mean camera distance: median {p['center_median_fraction']:.4f}, "
            f"max {p['center_max_fraction']:.4f}",
        ]
    if "masks" in figures:
        m = figures["masks"]
        lines.append(f"masks IoU ({m['views']} views): median {m['iou_median']:.3f}, mean {m['iou_mean']:.3f}, "
                     f"worst {m['iou_worst']:.3f} ({m['worst_view']})")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", type=Path, default=DATASET)
    parser.add_argument("--downscale", type=int, default=2, help="decode.downscale (default 2: 1060x707)")
    parser.add_argument("--start", type=int, default=0, help="first photo (index in name order)")
    parser.add_argument("--every", type=int, default=1, help="every K-th photo")
    parser.add_argument("--limit", type=int, default=None, help="at most this many photos")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="a config override for every stage (repeatable)")
    parser.add_argument("--work", type=Path, default=None,
                        help="keep the capture and the stages' folders in a new folder here (default: a temporary "
                        "folder, removed)")
    parser.add_argument("--known-poses", action="store_true",
                        help="give the capture the reference poses (no SfM): measures the masks on their own")
    parser.add_argument("--results", type=Path, default=RESULTS, help="the JSON lines file appended to")
    parser.add_argument("--no-record", action="store_true", help="append nothing")
    args = parser.parse_args()

    photos = select_photos(args.dataset, args.start, args.every, args.limit)
    if len(photos) < 2:
        sys.exit(f"blowtorch: {len(photos)} photo(s) selected from {args.dataset}; need 2 or more")
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=time.strftime("run_%Y%m%d_%H%M%S_"), dir=args.work))
    else:
        work = Path(tempfile.mkdtemp(prefix="orca_blowtorch_"))
    try:
        capture = build_capture(work / "blowtorch", photos, args.downscale,
                                args.dataset if args.known_poses else None)
        overrides = [*BENCH_OVERRIDES, *args.overrides]
        runs = run_front_end(capture, work / "results", overrides)
        failed = [r for r in runs.values() if r.returncode]
        figures = {} if failed and failed[0].stage != MASKS else score(work / "results", photos, args.dataset)
        record = {
            "date": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": machine(), "commit": commit(),
            "settings": {"photos": len(photos), "first": photos[0].name, "start": args.start, "every": args.every,
                         "limit": args.limit, "downscale": args.downscale, "known_poses": args.known_poses,
                         "overrides": overrides},
            "stages": {s: {"seconds": round(r.seconds, 1), "peak_rss_mb": round(r.peak_rss_mb),
                           "returncode": r.returncode} for s, r in runs.items()},
            **{k: v for k, v in figures.items() if k not in ("poses", "masks")},
            **{k: {f: v for f, v in figures[k].items() if not f.startswith("per_")} for k in ("poses", "masks")
               if k in figures},
        }
        if failed:
            record["failed"] = {"stage": failed[0].stage,
                                "log_tail": failed[0].log.splitlines()[-LOG_TAIL_LINES:]}
        print(table(runs, figures))
        if failed:
            print(f"\n{failed[0].stage} failed:\n" + "\n".join(record["failed"]["log_tail"]))
        if not args.no_record:
            append_record(args.results, record)
        if args.work is not None:
            print(f"work folder: {work}")
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
