"""The blowtorch through the whole DAG (`scripts/blowtorch.sh`), summarized: seconds and peak memory per stage
(Snakemake's benchmark files), the held-out photos' PSNR and SSIM, the learned per-photo exposures against decode's
EXIF exposure normalization, and the pictures a person looks at (mesh, environment overview, held-out grid).

    ORCA_BLOWTORCH_REFERENCE=1 bash scripts/blowtorch.sh    # the photographers' cameras and masks
    python bench/blowtorch_dag.py                           # -> bench/results/blowtorch_dag.jsonl + pictures

Prints a table, appends a JSON line to bench/results/blowtorch_dag.jsonl and copies the pictures to
bench/results/blowtorch_dag/.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch

from bench.blowtorch import ROOT, append_record, commit, machine  # noqa: E402
from pipeline.layout import HELD_OUT_GRID, MESH_FIGURE, OVERVIEW  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "blowtorch_dag.jsonl"
PICTURES = Path(__file__).parent / "results" / "blowtorch_dag"
PICTURE_WIDTH, JPEG_QUALITY = 800, 85
STAGES = ("decode", "poses", "masks", "train", "mesh", "export", "evaluate", "report")


def stage_costs(results: Path) -> dict[str, dict[str, float]]:
    """Seconds and peak resident memory (MB) of each stage Snakemake benchmarked."""
    costs = {}
    for stage in STAGES:
        path = results / "benchmarks" / f"{stage}.tsv"
        if path.is_file():
            with open(path, encoding="utf-8") as f:
                row = next(csv.DictReader(f, delimiter="\t"))
            costs[stage] = {"seconds": float(row["s"]), "peak_rss_mb": float(row["max_rss"])}
    return costs


def exposure_against_exif(results: Path) -> dict[str, float] | None:
    """The learned per-photo exposures (stops) regressed on decode's EXIF exposure scale (stops): the slope is
    the share of the EXIF normalization training took back (0: EXIF was right), with its correlation."""
    train = json.loads((results / "train" / "train_report.json").read_text(encoding="utf-8"))
    gains = train.get("appearance")
    if not gains:
        return None
    decoded = {im["name"]: im for im in json.loads((results / "decode" / "decode.json").read_text())["images"]}
    exif = np.array([np.log2(decoded[n]["exposure_scale"]) for n in gains])
    learned = np.array([np.log2(g).mean() for g in gains.values()])
    if np.ptp(exif) == 0:
        return {"learned_stops_range": float(np.ptp(learned))}
    slope = np.polyfit(exif, learned, 1)[0]
    return {"learned_stops_range": float(np.ptp(learned)), "slope_on_exif_stops": float(slope),
            "correlation": float(np.corrcoef(exif, learned)[0, 1])}


def summary(results: Path) -> dict[str, Any]:
    train = json.loads((results / "train" / "train_report.json").read_text(encoding="utf-8"))
    evaluate = json.loads((results / "evaluate" / "evaluate.json").read_text(encoding="utf-8"))
    return {"stages": stage_costs(results), "held_out": evaluate["held_out"]["mean"],
            "held_out_views": evaluate["held_out"]["views"], "training_images": len(train["images"]),
            "size": train["size"], "iterations": train["iterations"], "exposure": exposure_against_exif(results)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, nargs="?", default=ROOT / "results" / "blowtorch")
    parser.add_argument("--label", default="", help="what this run was (cameras, masks, preset)")
    args = parser.parse_args()
    figures = summary(args.results)
    for stage, cost in figures["stages"].items():
        print(f"{stage:9s} {cost['seconds']:8.1f} s  {cost['peak_rss_mb']:8.0f} MB")
    print(json.dumps({k: v for k, v in figures.items() if k != "stages"}, indent=1))
    PICTURES.mkdir(parents=True, exist_ok=True)
    for picture in (args.results / "mesh" / MESH_FIGURE, args.results / "export" / OVERVIEW,
                    args.results / "evaluate" / HELD_OUT_GRID):
        if picture.is_file():  # at most PICTURE_WIDTH wide, as JPEG: data kept in git
            image = cv2.imread(str(picture))
            scale = min(PICTURE_WIDTH / image.shape[1], 1.0)
            image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
            cv2.imwrite(str(PICTURES / f"{picture.stem}.jpg"), image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    append_record(RESULTS, {"machine": machine(), "commit": commit(), "label": args.label, **figures})


if __name__ == "__main__":
    main()
