"""The automatic masks against a synthetic capture's ground truth: IoU per view (median, worst), time.

Runs the masks stage on an existing poses folder (the capture's photos decoded, cameras from ``orca poses``)
with the user masks ignored, and compares every mask with ``ground_truth/masks``:

    python bench/masks.py captures/demo --decode results/demo/decode --poses results/demo/poses

Appends a line to bench/results/masks.jsonl and prints it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.config import load_config
from pipeline.imageio import read_image
from pipeline.metrics import iou
from pipeline.stages.masks import run_masks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("capture", type=Path, help="a synthetic capture (with ground_truth/masks)")
    parser.add_argument("--decode", type=Path, required=True)
    parser.add_argument("--poses", type=Path, required=True)
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="masks.KEY=VALUE")
    parser.add_argument("--out", type=Path, default=None, help="keep the masks folder here")
    parser.add_argument("--threads", type=int, default=0, help="OpenCV threads (0: OpenCV's default)")
    args = parser.parse_args()
    if args.threads:
        import cv2

        cv2.setNumThreads(args.threads)
    config = load_config(overrides=["masks.user_masks=ignore", *args.overrides]).masks
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "masks"
        started = time.time()
        result = run_masks(args.capture, args.poses, out, config, decode_dir=args.decode)
        seconds = time.time() - started
        truth = args.capture / "ground_truth" / "masks"
        scores = {n: iou(read_image(out / "masks" / f"{n}.png") > 127, read_image(truth / f"{n}.png") > 127)
                  for n in result.names}
    values = np.array(list(scores.values()))
    worst = min(scores, key=scores.get)
    line = {
        "capture": str(args.capture), "views": len(scores), "iou_median": round(float(np.median(values)), 4),
        "iou_worst": round(float(values.min()), 4), "worst_view": worst, "iou_mean": round(float(values.mean()), 4),
        "seconds": round(seconds, 1), "overrides": args.overrides,
        "hull_agreement_median": round(result.agreement["median"], 4),
        "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=Path(__file__).parent, check=False).stdout.strip(),
    }
    results = Path(__file__).parent / "results"
    results.mkdir(exist_ok=True)
    with open(results / "masks.jsonl", "a", encoding="utf-8") as f:
        f.write(json.dumps(line) + "\n")
    print(json.dumps(line))


if __name__ == "__main__":
    main()
