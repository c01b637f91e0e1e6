"""What a depth-sweep setting changes in the evidence it gives, and what it costs: the outside sweep
(:func:`pipeline.masking.sweeps.occluder_evidence`) of every K-th view of front-end results folders, under
today's defaults and under a variant, pixel by pixel, in minutes instead of a masks run per setting.

    python bench/sweep_evidence.py /tmp/fe/random-1 /tmp/bt/results --radius 1 --radius 2.25 \\
        --variant '{"sweep_near": 0.5}' --every 5

Each folder is a front end's results (decode/ and poses/, from ``bench/front_end.py --work`` or
``bench/blowtorch.py --work``); ``--radius`` per folder: the sphere the masks stage ran in (its
``masks_report.json``, ``sphere_prior.radius``; 1 when it did not grow). Prints per folder the swept pixels
under the defaults, those the variant loses and gains, and the seconds of each; appends a JSON line to
bench/results/sweep_evidence.jsonl. The masks follow from the evidence: a variant that changes none of it
changes no mask.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch's helpers

from bench.blowtorch import append_record, commit, machine  # noqa: E402
from bench.masks_variants import working_views  # noqa: E402
from pipeline.config import MasksConfig  # noqa: E402
from pipeline.masking.prior import in_sphere_frame  # noqa: E402
from pipeline.masking.segment import segment_options  # noqa: E402
from pipeline.masking.sweeps import occluder_evidence  # noqa: E402
from pipeline.masking.views import neighbours  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "sweep_evidence.jsonl"


def compare(results: Path, radius: float, variant: dict[str, Any], every: int) -> dict[str, Any]:
    """Every ``every``-th view's swept pixels under the defaults and under ``variant`` (SegmentOptions fields)."""
    config = MasksConfig()
    views = [in_sphere_frame(v, np.zeros(3), radius) for v in working_views(results, config)[1]]
    base = segment_options(config)
    other = dataclasses.replace(base, **variant)
    near = neighbours(views, base.sweep_neighbours, base.neighbour_max_deg)
    out = {"results": str(results), "radius": radius, "views": 0, "swept": 0, "lost": 0, "gained": 0,
           "seconds_default": 0.0, "seconds_variant": 0.0}
    for i in range(0, len(views), every):
        others = [views[j] for j in near[i]]
        started = time.time()
        a = occluder_evidence(views[i], others, base)[0]
        out["seconds_default"] += time.time() - started
        started = time.time()
        b = occluder_evidence(views[i], others, other)[0]
        out["seconds_variant"] += time.time() - started
        view = {"swept": int(a.sum()), "lost": int((a & ~b).sum()), "gained": int((b & ~a).sum())}
        out["views"] += 1
        for key, count in view.items():
            out[key] += count
        print(f"  {views[i].name}: swept {view['swept']}, lost {view['lost']}, gained {view['gained']}", flush=True)
    out["seconds_default"] = round(out["seconds_default"], 1)
    out["seconds_variant"] = round(out["seconds_variant"], 1)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, nargs="+", help="front-end results folders (decode/, poses/)")
    parser.add_argument("--radius", type=float, action="append", help="the masks' sphere per folder (default 1)")
    parser.add_argument("--variant", required=True, help="SegmentOptions fields as JSON")
    parser.add_argument("--every", type=int, default=5, help="every K-th view")
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args()
    radii = args.radius or [1.0] * len(args.results)
    if len(radii) != len(args.results):
        parser.error("give --radius once per folder, or not at all")
    variant = json.loads(args.variant)
    rows = []
    for results, radius in zip(args.results, radii):
        print(f"{results} (sphere {radius}):", flush=True)
        rows.append(compare(results, radius, variant, args.every))
        r = rows[-1]
        print(f"  swept {r['swept']}, lost {r['lost']}, gained {r['gained']}; {r['seconds_default']} s -> "
              f"{r['seconds_variant']} s", flush=True)
    if not args.no_record:
        record = {"date": datetime.now().isoformat(timespec="seconds"), "machine": machine(), "commit": commit(),
                  "variant": variant, "every": args.every, "captures": rows}
        append_record(RESULTS, record)


if __name__ == "__main__":
    main()
