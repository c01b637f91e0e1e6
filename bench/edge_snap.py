"""The masks' outline snapped to the photo's edges at full size (masks.snap_*), under several settings, in seconds
per capture instead of a masks stage per setting.

    python bench/edge_snap.py --blowtorch /tmp/bt/run_x/results --family /tmp/fe/random-*

``--blowtorch``: a ``bench/blowtorch.py --work`` results folder (decode/, poses/, masks/; photos larger than the
working size): its written masks are snapped again and scored against the photographers' masks. ``--family``:
``bench/front_end.py --work`` scene folders (320x240, segmented at their own size): their masks are halved and
brought up again (:func:`pipeline.masking.scale.full_size_mask`), so the step runs at 2x as it would on larger
photos, and scored against the scene's ground truth (``--truth``: the rendered captures). Prints IoU median and
worst view per setting and capture set, and how many views kept the snap; writes
bench/results/masks_edge_snap.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from datetime import datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch's helpers

from bench.blowtorch import DATASET, commit, machine, poses_undistortion, reference_mask  # noqa: E402
from bench.front_end import CACHE  # noqa: E402
from pipeline.cameras import load_cameras  # noqa: E402
from pipeline.config import MasksConfig  # noqa: E402
from pipeline.layout import CAMERAS_JSON, DECODE, GROUND_TRUTH, MASKS, POSES, USER_MASKS  # noqa: E402
from pipeline.mask_file import read_mask  # noqa: E402
from pipeline.masking.scale import edge_snap, full_size_mask, reduce, snap_to_edges  # noqa: E402
from pipeline.metrics import iou  # noqa: E402
from pipeline.results import image_folder, load_decode, load_masks  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "masks_edge_snap.json"
WORK_SIZE = MasksConfig().work_size
DEFAULT = edge_snap(MasksConfig())
UNGUARDED = dataclasses.replace(DEFAULT, min_edge_gain=0.0, min_core=0.0)
SETTINGS = {
    "guided filter only": None,
    "band 1, unguarded": dataclasses.replace(UNGUARDED, band_px=1.0),
    "band 2, unguarded": UNGUARDED,
    "band 2, edge gain 1.1": dataclasses.replace(UNGUARDED, min_edge_gain=1.1),
    "band 2, edge gain 1.25": dataclasses.replace(UNGUARDED, min_edge_gain=1.25),
    "band 2, edge gain 1.5": dataclasses.replace(UNGUARDED, min_edge_gain=1.5),
    "band 1, edge gain 1.5, core 0.8": dataclasses.replace(DEFAULT, band_px=1.0),
    "band 2, edge gain 1.25, core 0.8": dataclasses.replace(DEFAULT, min_edge_gain=1.25),
    "band 2, edge gain 1.5, core 0.9": dataclasses.replace(DEFAULT, min_core=0.9),
    "band 2, edge gain 1.5, core 0.8 (default)": DEFAULT,
}


def blowtorch_views(results: Path):
    """(written mask, photo, reference, scale) per view of a blowtorch front end: the written masks are the
    guided filter's output already, so they are snapped as they are."""
    masks, undistortion = load_masks(results / MASKS), poses_undistortion(results)
    decoded = load_decode(image_folder(load_cameras(results / POSES / CAMERAS_JSON), results / POSES, None))
    for name in masks.names:
        ours = masks.mask(name)
        photo = decoded.srgb(name)
        reference = reference_mask(DATASET / USER_MASKS / f"{name}.png", ours.shape[::-1], undistortion)
        yield ours, photo, reference, max(ours.shape) / WORK_SIZE


def family_views(scene: Path, truth: Path):
    """(mask halved and brought up, photo, truth, 2) per view of a front-end scene folder."""
    masks, decoded = load_masks(scene / MASKS), load_decode(scene / DECODE)
    for name in masks.names:
        full = masks.mask(name)
        photo = decoded.srgb(name)
        small = reduce(full, (full.shape[0] // 2, full.shape[1] // 2))
        yield full_size_mask(small, photo)[0], photo, read_mask(truth / f"{name}.png", full.shape[::-1]), 2.0


def score(views) -> dict[str, dict[str, float]]:
    scores: dict[str, list[float]] = {s: [] for s in SETTINGS}
    kept: dict[str, int] = {s: 0 for s in SETTINGS}
    for mask, photo, truth, scale in views:
        for name, snap in SETTINGS.items():
            out, k = (mask, False) if snap is None else snap_to_edges(mask, photo, round(snap.band_px * scale), snap)
            scores[name].append(iou(out, truth))
            kept[name] += k
    return {s: {"iou_median": float(np.median(v)), "iou_worst": float(np.min(v)), "views": len(v),
                "snapped": kept[s]} for s, v in scores.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blowtorch", type=Path, help="a bench/blowtorch.py results folder")
    parser.add_argument("--family", type=Path, nargs="*", default=[], help="bench/front_end.py scene folders")
    parser.add_argument("--truth", type=Path, default=CACHE,
                        help="the rendered captures (<scene>/ground_truth/masks)")
    parser.add_argument("--results", type=Path, default=RESULTS)
    args = parser.parse_args()
    sets = {}
    if args.blowtorch:
        sets["blowtorch"] = score(blowtorch_views(args.blowtorch))
    if args.family:
        sets["family"] = score(v for scene in sorted(args.family)
                               for v in family_views(scene, args.truth / scene.name / GROUND_TRUTH / MASKS))
    for capture, figures in sets.items():
        print(capture)
        for name, f in figures.items():
            print(f"  {name:45} median {f['iou_median']:.3f} worst {f['iou_worst']:.3f} "
                  f"snapped {f['snapped']}/{f['views']}")
    record = {"date": datetime.now().isoformat(timespec="seconds"), "machine": machine(), "commit": commit(),
              "what": __doc__.split("\n\n")[0], "inputs": {"blowtorch": str(args.blowtorch),
                                                            "family": [str(p) for p in args.family]},
              "settings": {k: None if v is None else dataclasses.asdict(v) for k, v in SETTINGS.items()},
              "captures": sets}
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
