"""``orca report``: one HTML page a person opens to see what every stage of a capture made.

Reads a capture's results folder (``results/<capture>/``: ``decode/``, ``poses/``, ``masks/``, ``train/``,
``mesh/``, ``export/`` and, for a synthetic capture, ``evaluate/``) and writes ``OUT/report.html`` (default
``results/<capture>/report/``) with ``manifest.json`` beside it, atomically.

The page is one self-contained file: every picture is embedded as a base64 PNG (pictures wider than
:data:`pipeline.report.reader.MAX_IMAGE_WIDTH` are shrunk), the style is inline, there is no script and
nothing is fetched from the network. Videos and the point cloud are not embedded: the page links to them
(paths relative to the page, so the links work where the results folder lies) and prints their paths.

One section per stage, from the files the stage writes:

- capture (``decode/decode.json``, the decode settings in ``decode/manifest.json``): photos, size, camera,
  white balance, exposure normalization, clipped-highlight fraction, a few thumbnails;
- poses (``poses_report.json``, ``poses.png``): registered photos, reprojection error, features, warnings;
- masks (``masks_report.json``, ``contact_sheet.jpg``): per-view area and agreement with the visual hull,
  views that disagree, the object's sphere, warnings;
- training (``train_report.json``, ``metrics.jsonl``, ``config.json``, ``previews/``): loss and PSNR curves
  (matplotlib), the final figures, training time, the last preview;
- mesh (``mesh_report.json``, ``mesh.png``): counts, watertightness, size;
- export (``export.json``, ``panorama/``, ``environment/``, ``object/``): the environment panorama and its
  depth, the cube views, the other virtual views, object renders, links to the videos and the point cloud;
- evaluation (``evaluate.json``, ``object_grid.png``, ``environment_grid.png``): the mean figures, pose and
  mesh errors, per-view tables and the comparison grids.

A stage whose folder is missing gets a section that says so; a file a stage should have written but did not
(or that does not parse) is named in its section. Text from the files is HTML-escaped.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

from ..artifacts import atomic_dir, write_manifest
from ..layout import REPORT, REPORT_HTML, STAGES
from ..report import page
from ..report.reader import Reader
from ..report.sections import section
from ..results import check_results_folder

log = logging.getLogger("orca.report")


def run_report(results_dir: Path, out_dir: Path | None = None) -> dict[str, Any]:
    """Write ``report.html`` (and ``manifest.json``) for the capture results in ``results_dir`` into
    ``out_dir`` (default ``results_dir/report``), atomically; returns what the page holds."""
    started = time.time()
    results = Path(results_dir)
    check_results_folder(results)
    out_dir = Path(out_dir) if out_dir is not None else results / REPORT
    reader = Reader(results=results, out_dir=out_dir)
    sections = [section(reader, stage) for stage in STAGES]
    document = page.render(capture=results.resolve().name, results=str(results.resolve()),
                           created=time.strftime("%Y-%m-%d %H:%M:%S %z"), sections=sections, problems=reader.problems)
    status = {s["id"]: s["status"] for s in sections}
    with atomic_dir(out_dir, REPORT, [results / s for s in STAGES]) as tmp:
        (tmp / REPORT_HTML).write_text(document, encoding="utf-8")
        write_manifest(tmp, stage=REPORT, inputs=reader.inputs, config={}, started=started,
                       extra={"results": str(results), "sections": status, "images": reader.images,
                              "problems": reader.problems})
    log.info("report: %s (%d pictures, %.1f MB; %s) in %.1f s", out_dir / REPORT_HTML, reader.images,
             len(document.encode()) / 1e6, ", ".join(f"{s} {v}" for s, v in status.items()), time.time() - started)
    return {"html": str(out_dir / REPORT_HTML), "sections": status,
            "summaries": {s["id"]: s["summary"] for s in sections}, "images": reader.images,
            "problems": reader.problems}


# -------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca report results/demo                  -> results/demo/report/report.html (one file: open it in a browser)
  orca report results/demo --out /tmp/demo_report

Works on partial results too: a stage that has not run gets a section saying so.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "report", help="a capture's results -> one self-contained HTML page of every stage's pictures and figures",
        description=__doc__, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("results", type=Path, help="a capture's results folder (results/<capture>, holding decode/, ...)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RESULTS/report)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> dict[str, Any]:
    return run_report(args.results, args.out)
