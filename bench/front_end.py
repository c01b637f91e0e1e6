"""The front end (decode -> poses -> masks) on the randomized synthetic family: the figure of merit of every
poses and masks setting, measured on a distribution of scenes rather than one.

    python bench/front_end.py                          # FRONT_END_SUITE, captures cached in /tmp/orca_front_end
    python bench/front_end.py --seeds 0 4 --set poses.mapper=incremental
    python bench/front_end.py --no-plain               # skip the plain-pycolmap baseline
    python bench/front_end.py --known-poses            # masks alone: the true cameras as known cameras, no SfM

Each seed of :data:`pipeline.synth.family.FRONT_END_SUITE` is rendered once (``orca synth random-<seed>
--truth front_end``, 40 photos at 320x240; cached in ``--cache``, rendered again only when missing), then
``orca decode``, ``orca poses`` and ``orca masks`` run on it as a user would run them (subprocesses of the
installed CLI, timed, with their peak memory). Scored against the scene's ground truth:

- poses: photos registered (and which not); rotation error (similarity rotation from the cameras'
  orientations) and centre error (similarity from the centres, as a fraction of the true cameras' mean
  distance from their centroid) after a similarity alignment to the true cameras;
- the same for **plain pycolmap** on the same decoded sRGB photos (its defaults: SIFT, exhaustive matching,
  incremental mapping, the largest model), and the ratio of our median errors to its;
- masks: IoU of every view with the true mask; median and worst per scene and over all views of all scenes.

Prints a table per scene and the suite's median and worst, and appends a JSON line (machine, commit, settings,
figures) to bench/results/front_end.jsonl.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: bench.blowtorch's shared helpers

from bench.blowtorch import (  # noqa: E402
    FRONT_END,
    ORCA,
    append_record,
    commit,
    machine,
    masks_agreement,
    pose_agreement,
    poses_undistortion,
    run_front_end,
)
from pipeline.cameras import CameraSet, load_cameras  # noqa: E402
from pipeline.layout import CAMERAS_JSON, DECODE, GROUND_TRUTH, MASKS, POSES, SRGB  # noqa: E402
from pipeline.results import load_poses  # noqa: E402
from pipeline.sfm import camera_to_world, largest_first, quiet_colmap  # noqa: E402
from pipeline.signals import import_pycolmap  # noqa: E402
from pipeline.synth.family import FRONT_END_SUITE, traits  # noqa: E402
from pipeline.synth.scenes import get_scene  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "front_end.jsonl"
CACHE = Path(tempfile.gettempdir()) / "orca_front_end"
# The suite's captures: small enough that rendering and the front end of every scene fit well under an hour
# on 2 cores, large enough that SIFT and the masks' sweeps see what they would on a phone's photo downscaled.
RENDER = ("--views", "40", "--width", "320", "--height", "240", "--spp", "16", "--coverage-spp", "16",
          "--truth", "front_end")
# As bench/blowtorch.py: a partial registration is scored instead of stopping the run.
BENCH_OVERRIDES = ("poses.min_registered_fraction=0.01",)


def render(seed: int, cache: Path) -> Path:
    """The capture of ``random-<seed>``, rendered into ``cache`` unless it is there already."""
    capture = cache / f"random-{seed}"
    if not (capture / GROUND_TRUTH / CAMERAS_JSON).is_file():
        subprocess.run([str(ORCA), "synth", f"random-{seed}", str(capture), *RENDER, "--overwrite"], check=True,
                       stdout=subprocess.DEVNULL)
    return capture


def plain_pycolmap(srgb: Path, work: Path) -> dict[str, np.ndarray]:
    """Camera-to-world ``(4, 4)`` per photo stem from pycolmap with its defaults (the largest model)."""
    pycolmap = import_pycolmap()
    quiet_colmap(verbose=False)
    work.mkdir(parents=True)
    db = work / "database.db"
    pycolmap.extract_features(db, srgb, camera_mode=pycolmap.CameraMode.SINGLE)
    pycolmap.match_exhaustive(db)
    models = pycolmap.incremental_mapping(db, srgb, work)
    if not models:
        return {}
    return {Path(image.name).stem: camera_to_world(image) for image in largest_first(models)[0].images.values()
            if image.has_pose}


def score_poses(cameras: CameraSet, truth: CameraSet) -> dict[str, Any]:
    figures = pose_agreement(cameras, truth)
    return {k: v for k, v in figures.items() if k != "per_camera"}


def with_known_cameras(capture: Path, folder: Path) -> Path:
    """A capture folder of symlinks to ``capture``'s files, with its true cameras as the capture's known
    cameras (``cameras.json``), which the poses stage then uses instead of SfM. ``folder`` must not exist."""
    folder.mkdir(parents=True)
    for p in capture.iterdir():
        (folder / p.name).symlink_to(p.resolve())
    shutil.copy(capture / GROUND_TRUTH / CAMERAS_JSON, folder / CAMERAS_JSON)
    return folder


def run_scene(seed: int, cache: Path, work: Path, overrides: list[str], plain: bool,
              stages: tuple[str, ...] = FRONT_END, known_poses: bool = False) -> dict[str, Any]:
    capture = render(seed, cache)
    truth = load_cameras(capture / GROUND_TRUTH / CAMERAS_JSON)
    if known_poses:
        capture = with_known_cameras(capture, work / "captures" / f"random-{seed}")
    results = work / f"random-{seed}"
    runs = run_front_end(capture, results, [*BENCH_OVERRIDES, *overrides], stages)
    names = [c.name for c in truth.cameras]
    record: dict[str, Any] = {"seed": seed, "traits": traits(get_scene(f"random-{seed}")), "photos": len(names),
                              "known_poses": known_poses,
                              "stages": {s: {"seconds": round(r.seconds, 1), "peak_rss_mb": round(r.peak_rss_mb),
                                             "returncode": r.returncode} for s, r in runs.items()}}
    failed = [r for r in runs.values() if r.returncode]
    if failed:
        record["failed"] = {"stage": failed[0].stage, "log_tail": failed[0].log.splitlines()[-12:]}
    if runs.get(POSES) is not None and not runs[POSES].returncode:
        ours = load_poses(results / POSES).cameras()
        record["registered"] = len(ours.cameras)
        record["unregistered"] = sorted(set(names) - set(ours.by_name()))
        record["poses"] = score_poses(ours, truth)
    if runs.get(MASKS) is not None and not runs[MASKS].returncode:
        record["masks"] = masks_agreement(results / MASKS, capture / GROUND_TRUTH / MASKS,
                                          poses_undistortion(results))
    if plain and not known_poses and (results / DECODE / SRGB).is_dir():
        started = time.perf_counter()
        c2w = plain_pycolmap(results / DECODE / SRGB, results / "plain_pycolmap")
        record["plain"] = {"registered": len(c2w), "seconds": round(time.perf_counter() - started, 1)}
        if len(c2w) >= 3:
            plain_cameras = [c.model_copy(update={"camera_to_world": c2w[c.name].tolist()})
                             for c in truth.cameras if c.name in c2w]
            record["plain"].update(score_poses(CameraSet(cameras=plain_cameras), truth))
    return record


def summary(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The suite's figures: every scene registered?, pose errors' median and worst over scenes, masks IoU
    median and worst over every view of every scene, and our median errors over plain pycolmap's."""
    out: dict[str, Any] = {"scenes": len(records),
                           "fully_registered": sum(r.get("registered") == r["photos"] for r in records)}
    posed = [r for r in records if "poses" in r]
    for key in ("rotation_deg_median", "center_median_fraction"):
        values = [r["poses"][key] for r in posed]
        if values:
            out[f"{key}_median"], out[f"{key}_worst"] = float(np.median(values)), float(np.max(values))
        plain = [r["plain"][key] for r in records if key in r.get("plain", {})]
        if plain:
            out[f"plain_{key}_median"] = float(np.median(plain))
            ours_vs_plain = [r["poses"][key] / r["plain"][key] for r in posed if key in r.get("plain", {})]
            out[f"ratio_{key}_median"] = float(np.median(ours_vs_plain))
    views = [v for r in records if "masks" in r for v in r["masks"]["per_view"].values()]
    if views:
        out["masks_iou_median"], out["masks_iou_worst"] = float(np.median(views)), float(np.min(views))
        out["masks_scene_median_worst"] = float(min(r["masks"]["iou_median"] for r in records if "masks" in r))
    return out


def table(records: list[dict[str, Any]], total: dict[str, Any]) -> str:
    head = (f"{'seed':>4} {'scene':34} {'reg':>7} {'rot°':>6} {'ctr%':>6} {'plain reg':>9} {'rot°':>6} {'ctr%':>6} "
            f"{'IoU med':>7} {'worst':>6} {'poses s':>7} {'masks s':>7}")
    lines = [head]
    nan = float("nan")
    for r in records:
        t = r["traits"]
        scene = f"{t.get('shape')}/{t.get('placement')}/{t.get('room')}/{t.get('size_fraction', 0):.2f}"
        p, q, m = r.get("poses", {}), r.get("plain", {}), r.get("masks", {})
        lines.append(
            f"{r['seed']:>4} {scene:34} {str(r.get('registered', '-')) + '/' + str(r['photos']):>7} "
            f"{p.get('rotation_deg_median', nan):6.3f} {100 * p.get('center_median_fraction', nan):6.2f} "
            f"{str(q.get('registered', '-')):>9} {q.get('rotation_deg_median', nan):6.3f} "
            f"{100 * q.get('center_median_fraction', nan):6.2f} "
            f"{m.get('iou_median', nan):7.3f} {m.get('iou_worst', nan):6.3f} "
            f"{r['stages'].get(POSES, {}).get('seconds', nan):7.0f} "
            f"{r['stages'].get(MASKS, {}).get('seconds', nan):7.0f}"
            + (f"  FAILED at {r['failed']['stage']}" if "failed" in r else ""))
    lines.append("suite: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                       for k, v in total.items()))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=list(FRONT_END_SUITE))
    parser.add_argument("--cache", type=Path, default=CACHE, help="rendered captures (kept between runs)")
    parser.add_argument("--work", type=Path, default=None, help="keep the stages' folders here (default: removed)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--no-plain", action="store_true", help="skip the plain-pycolmap baseline")
    parser.add_argument("--until", choices=FRONT_END[1:], default=FRONT_END[-1],
                        help="the last stage run (poses: no masks)")
    parser.add_argument("--known-poses", action="store_true",
                        help="give each capture its true cameras (no SfM): measures the masks on their own")
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--no-record", action="store_true", help="append nothing")
    args = parser.parse_args()

    args.cache.mkdir(parents=True, exist_ok=True)
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="front_end_", dir=args.work))
    started = time.perf_counter()
    records = []
    try:
        for seed in args.seeds:
            stages = FRONT_END[:FRONT_END.index(args.until) + 1]
            records.append(run_scene(seed, args.cache, work, args.overrides, not args.no_plain, stages,
                                     args.known_poses))
            print(table(records[-1:], summary(records)), flush=True)
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    total = summary(records)
    print("\n" + table(records, total))
    record = {"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": machine(), "commit": commit(),
              "settings": {"seeds": args.seeds, "render": list(RENDER), "overrides": args.overrides,
                           "until": args.until, "known_poses": args.known_poses},
              "seconds": round(time.perf_counter() - started), "suite": total,
              "scenes": [{k: ({f: v for f, v in r[k].items() if f != "per_view"} if k == "masks" else r[k])
                          for k in r} for r in records]}
    if not args.no_record:
        append_record(args.results, record)


if __name__ == "__main__":
    main()
