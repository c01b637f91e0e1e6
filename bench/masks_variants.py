"""The masks' rounds (hull carving <-> GrabCut) under other settings, in minutes instead of a front end per setting:
the evidence gathered before any hull (sphere prior, support plane, sweeps, first GrabCut) is computed once per
capture and cached; each variant then runs only :func:`pipeline.masking.segment.refine_checked` and is scored
against the reference masks at the working size.

    # once per capture: a front-end results folder (decode/, poses/) and its reference masks
    python bench/masks_variants.py build /tmp/bt/run_x/results --blowtorch --cache /tmp/mv/blowtorch.pkl
    python bench/masks_variants.py build /tmp/fe/random-0 --reference /tmp/orca_front_end/random-0/ground_truth/masks \\
        --cache /tmp/mv/s0.pkl
    # then any number of variants (SegmentOptions fields) over any set of caches
    python bench/masks_variants.py eval /tmp/mv/*.pkl --variant '{}' --variant '{"core_fraction": 0.2}'

The front-end folders come from ``bench/blowtorch.py --work DIR`` and ``bench/front_end.py --work DIR``. The
sphere prior is found again as the masks stage finds it (its probes). Only what the rounds read may vary:
options of the evidence (floor, sweeps, sphere prior) need a new build. The caches are pickles this script wrote
(load only your own). Prints per capture and in total: IoU median and worst, the median share of the reference's
area added and missed; appends a JSON line per variant to bench/results/masks_variants.jsonl.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pickle
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch's helpers

from bench.blowtorch import DATASET, append_record, commit, machine, poses_undistortion, reference_mask  # noqa: E402
from pipeline.cameras import CameraSet, load_cameras  # noqa: E402
from pipeline.config import MasksConfig  # noqa: E402
from pipeline.layout import CAMERAS_JSON, POSES, SPARSE, USER_MASKS  # noqa: E402
from pipeline.masking.parallel import MapViews, view_workers  # noqa: E402
from pipeline.masking.prior import find_prior_sphere, framed_options, in_sphere_frame  # noqa: E402
from pipeline.masking.scale import load_view  # noqa: E402
from pipeline.masking.segment import gather_evidence, probe_masks, refine_checked, segment_options  # noqa: E402
from pipeline.masking.tracks import tracks_for_views  # noqa: E402
from pipeline.masking.views import SegmentOptions, View  # noqa: E402
from pipeline.metrics import iou  # noqa: E402
from pipeline.results import image_folder, load_decode  # noqa: E402
from pipeline.sparse_depth import load_sparse_points  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "masks_variants.jsonl"


def working_views(results: Path, config: MasksConfig) -> tuple[CameraSet, list[View]]:
    """The front end in ``results``: its cameras, and its photos as the masks stage sees them (``config``'s working
    size), in the poses stage's frame."""
    cameras = load_cameras(results / POSES / CAMERAS_JSON)
    decoded = load_decode(image_folder(cameras, results / POSES, None))
    scale = min(1.0, config.work_size / max(max(c.width, c.height) for c in cameras.cameras))
    return cameras, [load_view(decoded, c, scale) for c in cameras.cameras]


def build(results: Path, cache: Path, reference: Path | None, overrides: dict[str, Any], run_views: MapViews
          ) -> None:
    """The views, options, evidence and reference masks (at the working size) of the front end in ``results``
    (``reference``: a folder of ``<name>.png``; None: the blowtorch's, resampled like the photos)."""
    config = MasksConfig(**overrides)
    cameras, views = working_views(results, config)
    names = [c.name for c in cameras.cameras]
    tracks = None
    if (results / POSES / SPARSE).is_dir():
        points = load_sparse_points(results / POSES / SPARSE, cameras)
        tracks = tracks_for_views(points.xyz, points.observers, names) if len(points.xyz) else None
    opts = segment_options(config)
    started = time.time()
    prior = find_prior_sphere(views, opts, probe_masks(tracks, run_views=run_views))
    views = [in_sphere_frame(v, prior.centre, prior.radius) for v in views]
    opts = framed_options(opts, prior.radius)
    framed = tracks.framed(prior.centre, prior.radius) if tracks is not None else None
    evidence = gather_evidence(views, opts, {}, tracks=framed, run_views=run_views)
    undistortion = poses_undistortion(results) if reference is None else None
    refs = []
    for cam, view in zip(cameras.cameras, views):
        if reference is None:
            path = next((DATASET / USER_MASKS).glob(cam.name + ".*"))
        else:
            path = reference / f"{cam.name}.png"
        full = reference_mask(path, (cam.width, cam.height), undistortion)
        refs.append(cv2.resize(full.astype(np.float32), view.shape[::-1], interpolation=cv2.INTER_AREA) >= 0.5)
    cache.parent.mkdir(parents=True, exist_ok=True)
    with open(cache, "wb") as f:
        pickle.dump({"results": str(results), "views": views, "opts": opts, "evidence": evidence, "references": refs,
                     "prior_radius": prior.radius, "overrides": overrides}, f)
    print(f"{cache}: {len(views)} views, sphere prior {prior.radius:.2f}, evidence in {time.time() - started:.0f} s")


def rounds_options(c: dict[str, Any], cache: Path) -> SegmentOptions:
    """The options the rounds run under: today's defaults with the build's overrides, framed by its sphere -- not
    the options pickled at build time, whose defaults may have changed since (a variant then compares against an
    old default). Caches written before the overrides were kept give their pickled options, with a warning."""
    if "overrides" not in c:
        print(f"  {cache.name}: an older cache, its build-time options are used; rebuild it for today's defaults")
        return c["opts"]
    return framed_options(segment_options(MasksConfig(**c["overrides"])), c["prior_radius"])


def evaluate(caches: list[Path], variant: dict[str, Any], pictures: Path | None, run_views: MapViews
             ) -> dict[str, Any]:
    """Every cache's rounds under ``variant``; per capture and over all views."""
    scenes, every = [], []
    for cache in caches:
        with open(cache, "rb") as f:
            c = pickle.load(f)  # noqa: S301 -- this script's own cache
        started = time.time()
        seg = refine_checked(c["views"], dataclasses.replace(rounds_options(c, cache), **variant), c["evidence"],
                             run_views=run_views)
        refs = c["references"]
        scores = np.array([iou(m, r) for m, r in zip(seg.masks, refs)])
        added = np.median([(m & ~r).sum() / max(r.sum(), 1) for m, r in zip(seg.masks, refs)])
        missed = np.median([(~m & r).sum() / max(r.sum(), 1) for m, r in zip(seg.masks, refs)])
        worst = int(scores.argmin())
        scenes.append({"capture": cache.stem, "views": len(scores), "iou_median": float(np.median(scores)),
                       "iou_worst": float(scores[worst]), "worst_view": c["views"][worst].name,
                       "added_median": float(added), "missed_median": float(missed),
                       "seconds": round(time.time() - started, 1), "unexplained_beside": seg.unexplained_beside})
        every += scores.tolist()
        s = scenes[-1]
        again = "  (segmented again: unexplained pixels beside the masks)" if (s["unexplained_beside"] or {}).get(
            "retried") else ""
        print(f"  {s['capture']:<14} median {s['iou_median']:.3f} worst {s['iou_worst']:.3f} ({s['worst_view']}) "
              f"added {s['added_median']:.3f} missed {s['missed_median']:.3f}  {s['seconds']:.0f} s{again}",
              flush=True)
        if pictures is not None:  # added in red, missed in blue
            label = json.dumps(variant, sort_keys=True).strip("{}").replace('"', "").replace(" ", "") or "defaults"
            folder = pictures / label / cache.stem
            folder.mkdir(parents=True, exist_ok=True)
            for v, m, r, score in zip(c["views"], seg.masks, refs, scores):
                bgr = np.ascontiguousarray(v.image[..., ::-1])
                marked = bgr.copy()
                marked[m & ~r] = (0, 0, 255)
                marked[~m & r] = (255, 0, 0)
                cv2.imwrite(str(folder / f"{score:.3f}_{v.name}.png"), cv2.addWeighted(bgr, 0.4, marked, 0.6, 0))
    total = {"iou_median": float(np.median(every)), "iou_worst": float(min(every)),
             "capture_median_worst": min(s["iou_median"] for s in scenes)}
    print(f"variant {json.dumps(variant)}: all {len(every)} views median {total['iou_median']:.3f} worst "
          f"{total['iou_worst']:.3f}; worst capture median {total['capture_median_worst']:.3f}")
    return {"variant": variant, "total": total, "captures": scenes}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="mode", required=True)
    b = sub.add_parser("build", help="cache one capture's evidence")
    b.add_argument("results", type=Path, help="a front end's results folder (decode/, poses/)")
    b.add_argument("--cache", type=Path, required=True)
    which = b.add_mutually_exclusive_group(required=True)
    which.add_argument("--reference", type=Path, help="folder of reference masks <name>.png")
    which.add_argument("--blowtorch", action="store_true", help="the blowtorch dataset's masks")
    b.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=JSON",
                   help="a masks option for the evidence (JSON value)")
    e = sub.add_parser("eval", help="run variants over cached captures")
    e.add_argument("caches", type=Path, nargs="+")
    e.add_argument("--variant", action="append", default=[], help="JSON object of SegmentOptions fields")
    e.add_argument("--pictures", type=Path, default=None, help="write each view's errors here")
    e.add_argument("--results", type=Path, default=RESULTS)
    e.add_argument("--no-record", action="store_true")
    parser.add_argument("--workers", type=int, default=0, help="processes per view's work (0: one per core)")
    args = parser.parse_args()
    with view_workers(args.workers) as run_views:
        if args.mode == "build":
            overrides = {k: json.loads(v) for k, v in (o.split("=", 1) for o in args.overrides)}
            build(args.results, args.cache, None if args.blowtorch else args.reference, overrides, run_views)
            return
        variants(args, run_views)


def variants(args: argparse.Namespace, run_views: MapViews) -> None:
    """Each ``--variant`` over the caches, recorded unless ``--no-record``."""
    code = commit()  # the code this process imported, whatever the tree holds when a variant ends
    for text in args.variant or ["{}"]:
        record = evaluate(args.caches, json.loads(text), args.pictures, run_views)
        if not args.no_record:
            record = {"date": datetime.now().isoformat(timespec="seconds"), "machine": machine(), "commit": code,
                      **record}
            append_record(args.results, record)


if __name__ == "__main__":
    main()
