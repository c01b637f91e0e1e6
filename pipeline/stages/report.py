"""``orca report``: one HTML page a person opens to see what every stage of a capture made.

Reads a capture's results folder (``results/<capture>/``: ``decode/``, ``poses/``, ``masks/``, ``train/``,
``mesh/``, ``export/`` and, for a synthetic capture, ``evaluate/``) and writes ``OUT/report.html`` (default
``results/<capture>/report/``) with ``manifest.json`` beside it, atomically.

The page is one self-contained file: every picture is embedded as a base64 PNG (pictures wider than
:data:`MAX_IMAGE_WIDTH` are shrunk), the style is inline, there is no script and nothing is fetched from the
network. Videos and the point cloud are not embedded: the page links to them (paths relative to the page, so
the links work where the results folder lies) and prints their paths.

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
import base64
import datetime
import html
import io
import json
import logging
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import MANIFEST, atomic_dir, read_json, write_manifest
from ..errors import InputError
from ..evaluation import metric_rows

log = logging.getLogger("orca.report")

REPORT_HTML = "report.html"
STAGES = ("decode", "poses", "masks", "train", "mesh", "export", "evaluate")
MAX_IMAGE_WIDTH = 1200  # pixels; wider pictures are shrunk before embedding
THUMBNAILS = 8  # photos shown in the capture section (evenly spaced)
THUMBNAIL_WIDTH = 200

STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1250px;
       padding: 0 1em; color: #222; line-height: 1.4; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 2px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }
h3 { margin-bottom: 0.3em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.92em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f4f4f4; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; image-rendering: auto; border: 1px solid #eee; }
figure { display: inline-block; margin: 0.3em 0.6em 0.6em 0; vertical-align: top; }
figcaption { font-size: 0.85em; color: #555; }
.missing { color: #8a5a00; background: #fff6e0; border-left: 4px solid #e0a000; padding: 0.5em 0.8em; }
.error { color: #8b0000; background: #fde8e8; border-left: 4px solid #c00; padding: 0.5em 0.8em; }
ul.warnings { color: #8b0000; } .ok { color: #176b1a; } .bad { color: #8b0000; font-weight: bold; }
details { margin: 0.5em 0 1em; } summary { cursor: pointer; color: #345; }
code { background: #f4f4f4; padding: 0 0.2em; }
nav a { margin-right: 1em; }
table.views img { width: 180px; image-rendering: pixelated; } figure.thumb img { width: 200px; }
"""


# ------------------------------------------------------------------------------------------------ HTML bits


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def text(value: Any, digits: int = 4) -> str:
    """A value as plain text (not escaped): numbers to ``digits`` significant figures, None/NaN as a dash,
    booleans as yes/no, lists and dicts inline."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.{digits}g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(text(v, digits) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {text(v, digits)}" for k, v in value.items())
    return str(value)


def fmt(value: Any, digits: int = 4) -> str:
    """:func:`text`, HTML-escaped."""
    return esc(text(value, digits))


def _cell(value: Any, digits: int = 4) -> str:
    numeric = isinstance(value, int | float) and not isinstance(value, bool)
    return f'<td class="num">{fmt(value, digits)}</td>' if numeric else f"<td>{fmt(value, digits)}</td>"


def kv_table(rows: Sequence[tuple[str, Any]], digits: int = 4) -> str:
    """A two-column table of (label, value); rows whose value is ``...`` (Ellipsis) are left out."""
    body = "".join(f"<tr><th>{esc(k)}</th>{_cell(v, digits)}</tr>" for k, v in rows if v is not ...)
    return f"<table>{body}</table>"


def grid_table(header: Sequence[str], rows: Sequence[Sequence[Any]], digits: int = 4) -> str:
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(_cell(v, digits) for v in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def warnings_html(warnings: Sequence[Any], title: str = "Warnings") -> str:
    if not warnings:
        return ""
    items = "".join(f"<li>{esc(w)}</li>" for w in warnings)
    return f"<h3>{esc(title)}</h3><ul class=\"warnings\">{items}</ul>"


def details(summary: str, body: str) -> str:
    return f"<details><summary>{esc(summary)}</summary>{body}</details>"


def png_data_uri(image: np.ndarray, max_width: int = MAX_IMAGE_WIDTH) -> str:
    """``(H, W)`` / ``(H, W, 3|4)`` uint8 or uint16 array in RGB(A) order -> ``data:image/png;base64,...``,
    shrunk to ``max_width`` wide."""
    import cv2

    image = np.asarray(image)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        image = np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)
    if image.shape[1] > max_width:
        h = max(1, round(image.shape[0] * max_width / image.shape[1]))
        image = cv2.resize(image, (max_width, h), interpolation=cv2.INTER_AREA)
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def figure_data_uri(fig) -> str:
    """A matplotlib figure as a PNG data URI."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


# ---------------------------------------------------------------------------------------------- the page


@dataclass
class Page:
    """What a report is built from: the results folder, where the page goes (for relative links), the files
    read (for the manifest) and the problems met (files missing or unreadable)."""

    results: Path
    out_dir: Path
    inputs: dict[str, Path] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    images: int = 0

    def json(self, path: Path, required: bool = True) -> Any:
        """A JSON file's content, recorded as an input; None (and a problem noted) when absent or unreadable."""
        if not path.is_file():
            if required:
                self.problems.append(f"{self._rel(path)} is missing")
            return None
        try:
            data = read_json(path)
        except (OSError, ValueError) as e:
            self.problems.append(f"{self._rel(path)} could not be read: {e}")
            return None
        self.inputs[self._rel(path)] = path
        return data

    def image(self, path: Path, caption: str | None = None, *, alt: str | None = None,
              width: int | None = None, required: bool = True, css: str | None = None) -> str:
        """A ``<figure>`` with the picture at ``path`` embedded (or a line saying it is missing)."""
        from ..imageio import read_image

        if not path.is_file():
            if required:
                self.problems.append(f"{self._rel(path)} is missing")
                return f'<p class="missing">{esc(self._rel(path))} is missing.</p>'
            return ""
        try:
            uri = png_data_uri(read_image(path), min(width or MAX_IMAGE_WIDTH, MAX_IMAGE_WIDTH))
        except (OSError, ValueError) as e:
            self.problems.append(f"{self._rel(path)} could not be read: {e}")
            return f'<p class="error">{esc(self._rel(path))} could not be read: {esc(e)}</p>'
        self.images += 1
        cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
        klass = f' class="{esc(css)}"' if css else ""
        return f'<figure{klass}><img src="{uri}" alt="{esc(alt or caption or path.name)}">{cap}</figure>'

    def figure(self, fig, caption: str) -> str:
        self.images += 1
        return f'<figure><img src="{figure_data_uri(fig)}" alt="{esc(caption)}"><figcaption>{esc(caption)}' \
               "</figcaption></figure>"

    def link(self, path: Path, text: str | None = None) -> str:
        """A link relative to the page (and the path as text), or a note that the file is missing."""
        if not path.exists():
            return f'<span class="missing">{esc(self._rel(path))} (missing)</span>'
        href = os.path.relpath(path.resolve(), self.out_dir.resolve())
        size = path.stat().st_size if path.is_file() else None
        extra = f" ({size / 1e6:.2f} MB)" if size is not None and size >= 1e5 else (
            f" ({size} bytes)" if size is not None else "")
        return (f'<a href="{esc(Path(href).as_posix())}">{esc(text or path.name)}</a> '
                f'<code>{esc(path)}</code>{esc(extra)}')

    def _rel(self, path: Path) -> str:
        try:
            return Path(path).relative_to(self.results).as_posix()
        except ValueError:
            return str(path)


def _missing_stage(page: Page, stage: str) -> str:
    folder = page.results / stage
    if stage == "evaluate":
        return (f'<p class="missing">No evaluation: {esc(folder)} does not exist. A synthetic capture (one with '
                "<code>ground_truth/</code>) is evaluated by <code>orca evaluate</code>; a real capture has no ground "
                "truth to compare with.</p>")
    return (f'<p class="missing">This stage has not run: {esc(folder)} does not exist. Run '
            f"<code>orca {esc(stage)}</code> (or <code>snakemake</code>) to make it.</p>")


def _unreadable(path: Path) -> str:
    return f'<p class="error">{esc(path)} is missing or unreadable.</p>'


def _manifest_line(page: Page, folder: Path) -> str:
    manifest = page.json(folder / MANIFEST, required=False)
    if not isinstance(manifest, dict):
        return f'<p class="missing">{esc(page._rel(folder / MANIFEST))} is missing: the folder may be incomplete.</p>'
    parts = [f"written {esc(manifest.get('created', '?'))}"]
    if isinstance(manifest.get("seconds"), int | float):
        parts.append(f"in {_duration(manifest['seconds'])}")
    version = (manifest.get("versions") or {}).get("orca-capture")
    if version:
        parts.append(f"orca {esc(version)}")
    return f"<p>Folder <code>{esc(folder)}</code>, " + ", ".join(parts) + ".</p>"


def _duration(seconds: float | None) -> str:
    if seconds is None or not isinstance(seconds, int | float) or not math.isfinite(seconds):
        return "—"
    if seconds < 60:
        return f"{seconds:.1f} s"
    return str(datetime.timedelta(seconds=round(seconds)))


def _stats(values: Sequence[float]) -> dict[str, float] | None:
    v = np.asarray([x for x in values if isinstance(x, int | float) and math.isfinite(x)], np.float64)
    if v.size == 0:
        return None
    return {"min": float(v.min()), "median": float(np.median(v)), "mean": float(v.mean()), "max": float(v.max())}


def _size_text(size: Any, sep: str = " x ") -> Any:
    """A report's ``[width, height]`` as text; anything else as it is."""
    return f"{size[0]}{sep}{size[1]}" if isinstance(size, list) and len(size) == 2 else size


def _evenly(items: Sequence[Any], n: int) -> list[Any]:
    if len(items) <= n:
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, n).round().astype(int)]


# --------------------------------------------------------------------------------------------- sections


def section_decode(page: Page, folder: Path) -> tuple[str, str]:
    meta = page.json(folder / "decode.json")
    if not isinstance(meta, dict):
        return "decode.json missing", _unreadable(folder / "decode.json")
    manifest = page.json(folder / MANIFEST, required=False) or {}
    images = meta.get("images") or []
    size = meta.get("size")
    formats = sorted({im.get("format", "?") for im in images})
    clipped = [im.get("clipped_fraction") for im in images]
    clip = _stats(clipped)
    wb = meta.get("white_balance") or {}
    exposure = meta.get("exposure") or {}
    ref = next((im for im in images if im.get("source") == meta.get("reference_image")), images[0] if images else {})
    exif = ref.get("exif") or {}
    exif_values = [im.get("exif") or {} for im in images]

    def span(key: str) -> Any:
        s = _stats([e.get(key) for e in exif_values])
        if s is None:
            return None
        return text(s["min"]) if s["min"] == s["max"] else f"{text(s['min'])} – {text(s['max'])}"

    worst = max(images, key=lambda im: im.get("clipped_fraction") or 0.0) if images else None
    rows = [
        ("capture", meta.get("capture")),
        ("photos decoded", len(images)),
        ("skipped files", ", ".join(meta.get("skipped") or []) or "none"),
        ("size (width x height)", _size_text(size)),
        ("downscale", meta.get("downscale")),
        ("formats", ", ".join(formats)),
        ("reference image", meta.get("reference_image")),
        ("camera", " ".join(str(exif[k]) for k in ("make", "model") if exif.get(k)) or None),
        ("focal length (mm; 35 mm equivalent)",
         f"{text(exif.get('focal_length_mm'))}; {text(exif.get('focal_length_35mm'))}" if exif else None),
        ("shutter (s)", span("shutter_s")), ("ISO", span("iso")), ("f-number", span("f_number")),
        ("white balance", f"{text(wb.get('multipliers'))} ({text(wb.get('source'))})" if wb else None),
        ("exposure normalized", exposure.get("normalized")),
        ("exposure fields used", ", ".join(exposure.get("fields_used") or []) or "none"),
        ("clipped fraction (mean / max)",
         f"{100 * clip['mean']:.2f} % / {100 * clip['max']:.2f} % ({worst.get('name')})" if clip and worst else None),
    ]
    body = kv_table(rows)
    config = manifest.get("config") if isinstance(manifest, dict) else None
    if isinstance(config, dict) and config:
        body += "<h3>Decode settings</h3>" + kv_table(sorted(config.items()))
    warnings = []
    missing = exposure.get("fields_missing_in_all") or []
    if missing:
        warnings.append(f"EXIF fields missing in every photo: {', '.join(map(str, missing))}")
    if meta.get("skipped"):
        warnings.append(f"skipped files: {', '.join(map(str, meta['skipped']))}")
    body += warnings_html(warnings)
    thumbs = "".join(page.image(folder / im["srgb"], im.get("name"), width=THUMBNAIL_WIDTH, css="thumb")
                     for im in _evenly(images, THUMBNAILS) if im.get("srgb"))
    if thumbs:
        body += f"<h3>Photos ({min(len(images), THUMBNAILS)} of {len(images)}, decoded sRGB)</h3>" + thumbs
    per_image = [(im.get("name"), im.get("source"), im.get("format"), (im.get("exif") or {}).get("shutter_s"),
                  (im.get("exif") or {}).get("iso"), (im.get("exif") or {}).get("f_number"),
                  im.get("exposure_scale"),
                  100 * im["clipped_fraction"] if isinstance(im.get("clipped_fraction"), int | float) else None)
                 for im in images]
    body += details(f"every photo ({len(images)})", grid_table(
        ["name", "file", "format", "shutter (s)", "ISO", "f-number", "exposure scale", "clipped %"], per_image))
    summary = f"{len(images)} photos" + (
        f", {_size_text(size, 'x')}" if isinstance(size, list) and len(size) == 2 else "")
    if clip:
        summary += f", clipped {100 * clip['mean']:.2f} % mean"
    return summary, body


def section_poses(page: Page, folder: Path) -> tuple[str, str]:
    report = page.json(folder / "poses_report.json")
    figure = page.image(folder / "poses.png", "cameras around the object (normalized frame): top and side views")
    if not isinstance(report, dict):
        return "poses_report.json missing", _unreadable(folder / "poses_report.json") + figure
    sfm = report.get("source") == "sfm"
    features = report.get("features") or {}
    cams = report.get("cameras_normalized") or {}
    obj = report.get("object") or {}
    rows = [
        ("cameras from", "SfM (pycolmap)" if sfm else f"known cameras: {report.get('source')}"),
        ("registered / total", f"{report.get('registered')} / {report.get('total')}"),
        ("not registered", ", ".join(report.get("not_registered") or []) or "none"),
        ("mean reprojection error (px)", report.get("mean_reprojection_error_px", ...)),
        ("mean track length", report.get("mean_track_length", ...)),
        ("3-D points", report.get("points3D", ...)),
        ("mean observations per image", report.get("mean_observations_per_image", ...)),
        ("features per photo (min / median / max)",
         f"{features.get('min')} / {features.get('median')} / {features.get('max')}" if features else ...),
        ("matcher", report.get("matcher", ...)),
        ("image pairs matched / verified", f"{report.get('pairs_matched')} / {report.get('pairs_verified')}"
         if "pairs_matched" in report else ...),
        ("models (photos in each)", report.get("models", ...)),
        ("intrinsics", "; ".join(f"{i.get('model')} {text(i.get('params'))} ({i.get('photos')} photos)"
                                 for i in report.get("intrinsics") or []) or None),
        ("undistorted to pinhole", report.get("undistorted")),
        ("object radius from", obj.get("radius_from")),
        ("camera distance from the object centre (min / median / max, object radii)",
         f"{text(cams.get('distance_min'))} / {text(cams.get('distance_median'))} / {text(cams.get('distance_max'))}"
         if cams else None),
    ]
    body = kv_table(rows)
    warnings = list(report.get("warnings") or [])
    if report.get("not_registered"):
        warnings.insert(0, f"{len(report['not_registered'])} photo(s) without a camera: "
                           f"{', '.join(report['not_registered'])}")
    if isinstance(report.get("models"), list) and len(report["models"]) > 1:
        warnings.insert(0, f"SfM split the photos into {len(report['models'])} models {report['models']}; the "
                           "largest is used")
    body += warnings_html(warnings)
    body += figure
    per_image = report.get("reprojection_error_px_per_image") or {}
    if per_image:
        feats = features.get("per_image") or {}
        body += details(f"reprojection error per photo ({len(per_image)})", grid_table(
            ["photo", "reprojection error (px)", "features"], [(n, e, feats.get(n)) for n, e in per_image.items()]))
    summary = f"{report.get('registered')}/{report.get('total')} registered"
    if isinstance(report.get("mean_reprojection_error_px"), int | float):
        summary += f", reprojection {report['mean_reprojection_error_px']:.2f} px"
    return summary, body


def section_masks(page: Page, folder: Path) -> tuple[str, str]:
    report = page.json(folder / "masks_report.json")
    sheet = page.image(folder / "contact_sheet.jpg",
                       "contact sheet: mask outline green (orange: your masks), visual hull magenta; views that "
                       "disagree with the hull framed in red")
    if not isinstance(report, dict):
        return "masks_report.json missing", _unreadable(folder / "masks_report.json") + sheet
    views = report.get("views") or []
    agreement = report.get("agreement") or {}
    sphere = report.get("object_sphere") or {}
    plane = report.get("support_plane")
    user = (report.get("user_masks") or {}).get("views") or []
    areas = _stats([v.get("area_fraction") for v in views])
    rows = [
        ("views", len(views)),
        ("your masks / automatic", f"{len(user)} / {len(views) - len(user)}"),
        ("mask area (share of the photo, min / median / max)",
         f"{100 * areas['min']:.1f} % / {100 * areas['median']:.1f} % / {100 * areas['max']:.1f} %" if areas else None),
        ("agreement with the visual hull (IoU median / mean / min)",
         f"{text(agreement.get('median'), 3)} / {text(agreement.get('mean'), 3)} / {text(agreement.get('min'), 3)}"
         if agreement else None),
        ("worst view", agreement.get("worst_view")),
        ("warning threshold (IoU)", agreement.get("threshold")),
        ("views that disagree with the hull", ", ".join(agreement.get("disagreeing_views") or []) or "none"),
        ("object sphere (poses frame): centre, radius",
         f"{text(sphere.get('centre'), 3)}, {text(sphere.get('radius'), 3)}" if sphere else None),
        ("support plane", "none found" if plane is None else
         f"normal {text(plane.get('normal'), 3)}, offset {text(plane.get('offset'), 3)}, explains "
         f"{text(plane.get('explained_fraction'), 3)} of the pixels"),
        ("rounds", len(report.get("rounds") or [])),
        ("time", _duration(report.get("seconds"))),
    ]
    body = kv_table(rows) + warnings_html(report.get("warnings") or []) + sheet
    threshold = agreement.get("threshold")
    table_rows = []
    for v in views:
        flag = "DISAGREES" if v.get("disagrees_with_hull") else ""
        table_rows.append((v.get("name"), v.get("source"), v.get("area_px"),
                           100 * v["area_fraction"] if isinstance(v.get("area_fraction"), int | float) else None,
                           v.get("hull_iou"), flag))
    body += details(f"every view ({len(views)}; hull IoU below {text(threshold)} is flagged)", grid_table(
        ["view", "source", "area (px)", "area %", "hull IoU", ""], table_rows, digits=3))
    summary = f"{len(views)} views"
    if isinstance(agreement.get("median"), int | float):
        summary += f", hull IoU median {agreement['median']:.3f}"
    if agreement.get("disagreeing_views"):
        summary += f", {len(agreement['disagreeing_views'])} flagged"
    return summary, body


def read_metrics(path: Path) -> tuple[list[dict[str, Any]], int]:
    """The rows of a ``metrics.jsonl`` and the number of lines that did not parse."""
    rows, bad = [], 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError:
            bad += 1
            continue
        if isinstance(row, dict) and isinstance(row.get("step"), int | float):
            rows.append(row)
        else:
            bad += 1
    return rows, bad


_NOT_TERMS = {"step", "seconds", "phase", "loss", "psnr_object", "beta", "lr"}


def training_curves(rows: list[dict[str, Any]]):
    """A matplotlib figure: total loss, object PSNR, each loss term, beta and learning rate against the step;
    the end of the mask-only warm-up marked."""
    from matplotlib.figure import Figure

    steps = np.array([r["step"] for r in rows], np.float64)

    def series(key: str) -> np.ndarray:
        return np.array([r.get(key) if isinstance(r.get(key), int | float) else np.nan for r in rows], np.float64)

    fig = Figure(figsize=(11, 6.5))
    axes = fig.subplots(2, 2)
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.08, top=0.95, wspace=0.25, hspace=0.35)  # constrained
    # layout takes seconds with log axes
    joint = next((r["step"] for r in rows if r.get("phase") == "joint"), None)

    def positive(v: np.ndarray) -> np.ndarray:  # log axes
        return np.where(v > 0, v, np.nan)

    window = len(rows) // 50  # a running mean over 2 % of the rows on top of the noisy per-batch values

    def smooth(v: np.ndarray) -> np.ndarray:
        ok = np.isfinite(v)
        num = np.convolve(np.where(ok, v, 0), np.ones(window), "same")
        den = np.convolve(ok.astype(float), np.ones(window), "same")
        return np.where(den > 0, num / np.maximum(den, 1), np.nan)

    for ax, key, colour, title in ((axes[0, 0], "loss", "tab:blue", "total loss"),
                                   (axes[0, 1], "psnr_object", "tab:green",
                                    "PSNR on object pixels (dB, training batch)")):
        v = series(key)
        ax.plot(steps, positive(v) if key == "loss" else v, color=colour, lw=0.8, alpha=0.5 if window > 1 else 1)
        if window > 1:
            ax.plot(steps, smooth(v), color="k", lw=1, label=f"running mean of {window}")
            ax.legend(fontsize=7)
        if key == "loss":
            ax.set_yscale("log")
        ax.set_title(title)
    ax = axes[1, 0]
    terms = sorted({k for r in rows for k, v in r.items() if k not in _NOT_TERMS and isinstance(v, int | float)})
    for k in terms:
        ax.plot(steps, positive(series(k)), lw=1, label=k)
    ax.set_yscale("log")
    ax.set_title("loss terms")
    if terms:
        ax.legend(fontsize=7, ncol=2)
    ax = axes[1, 1]
    ax.plot(steps, series("beta"), color="tab:purple", lw=1, label="beta (VolSDF)")
    ax.set_yscale("log")
    ax2 = ax.twinx()
    ax2.plot(steps, series("lr"), color="tab:gray", lw=1, ls="--", label="learning rate")
    ax2.set_yscale("log")
    ax.set_title("beta (solid) and learning rate (dashed)")
    for a in axes.ravel():
        a.set_xlabel("step")
        a.grid(alpha=0.3)
        if joint is not None and len(steps) and joint > steps.min():
            a.axvline(joint, color="k", lw=0.8, ls=":")
    return fig


def section_train(page: Page, folder: Path) -> tuple[str, str]:
    report = page.json(folder / "train_report.json")
    config = page.json(folder / "config.json", required=False)
    body = ""
    if isinstance(report, dict):
        images = report.get("images") or []
        size = report.get("size")
        rows = [
            ("iterations", report.get("iterations")),
            ("training time", _duration(report.get("training_seconds"))),
            ("time in the last run (resumed runs add up)", _duration(report.get("seconds_this_run"))),
            ("device", report.get("device")),
            ("images", len(images)),
            ("image size", _size_text(size)),
            ("final beta (VolSDF)", report.get("beta")),
        ]
        if isinstance(config, dict):
            rows += [(k, config.get(k, ...)) for k in ("batch_rays", "mask_warmup", "lr", "sdf_encoding")]
        body += kv_table(rows)
        losses = report.get("final_losses") or {}
        if losses:
            body += "<h3>Final loss terms (last batch)</h3>" + grid_table(["term", "value"], sorted(losses.items()))
    else:
        body += _unreadable(folder / "train_report.json")
    metrics_path = folder / "metrics.jsonl"
    summary = f"{report.get('iterations')} iterations, {_duration(report.get('training_seconds'))}" \
        if isinstance(report, dict) else "train_report.json missing"
    if metrics_path.is_file():
        page.inputs[page._rel(metrics_path)] = metrics_path
        rows, bad = read_metrics(metrics_path)
        if rows:
            last = rows[-1]
            body += "<h3>Training curves</h3>" + page.figure(
                training_curves(rows), f"from metrics.jsonl ({len(rows)} rows, every logged step); dotted line: "
                "end of the mask-only warm-up")
            psnr = [r.get("psnr_object") for r in rows]
            best = _stats(psnr)
            body += "<h3>Last logged step</h3>" + kv_table(
                [("step", last.get("step")), ("phase", last.get("phase")), ("loss", last.get("loss")),
                 ("PSNR on object pixels (dB)", last.get("psnr_object")),
                 ("best PSNR logged (dB)", best["max"] if best else None),
                 ("wall-clock at this step", _duration(last.get("seconds")))])
            if isinstance(last.get("psnr_object"), int | float) and math.isfinite(last["psnr_object"]):
                summary += f", PSNR {last['psnr_object']:.1f} dB"
        else:
            body += f'<p class="missing">{esc(metrics_path)} has no rows.</p>'
        if bad:
            page.problems.append(f"{page._rel(metrics_path)}: {bad} line(s) did not parse")
            body += f'<p class="error">{bad} line(s) of metrics.jsonl did not parse.</p>'
    else:
        page.problems.append(f"{page._rel(metrics_path)} is missing")
        body += f'<p class="missing">{esc(metrics_path)} is missing: no curves.</p>'
    previews = sorted((folder / "previews").glob("step_*.png")) if (folder / "previews").is_dir() else []
    if previews:
        body += "<h3>Preview</h3>" + page.image(previews[-1], f"{previews[-1].stem} (first training image)")
    if isinstance(config, dict):
        body += details("training configuration (config.json)", kv_table(sorted(config.items())))
    body += f"<p>TensorBoard: <code>tensorboard --logdir {esc(folder / 'tensorboard')}</code></p>"
    return summary, body


def section_mesh(page: Page, folder: Path) -> tuple[str, str]:
    report = page.json(folder / "mesh_report.json")
    picture = page.image(folder / "mesh.png", "three views of the mesh (shaded, diffuse vertex colours)")
    links = f"<p>Mesh: {page.link(folder / 'mesh.ply')}"
    if (folder / "mesh_colmap.ply").is_file():
        links += f"<br>In COLMAP's frame: {page.link(folder / 'mesh_colmap.ply')}"
    links += "</p>"
    if not isinstance(report, dict):
        return "mesh_report.json missing", _unreadable(folder / "mesh_report.json") + picture + links
    tri = report.get("triangles")
    rows = [
        ("vertices", report.get("vertices")), ("triangles", tri),
        ("watertight", report.get("watertight")), ("winding consistent", report.get("winding_consistent", ...)),
        ("vertex manifold", report.get("vertex_manifold", ...)), ("Euler number", report.get("euler_number", ...)),
        ("pieces kept / found", f"{report.get('components_kept')} / {report.get('components')}"),
        ("grid (voxels per side), voxel size", f"{report.get('resolution')}, {text(report.get('voxel_size'))}"),
        ("bounds min / max", f"{text(report.get('bbox_min'), 3)} / {text(report.get('bbox_max'), 3)}"
         if "bbox_min" in report else ...),
        ("largest distance from the centre", report.get("max_radius", ...)),
        ("area", report.get("area", ...)), ("volume", report.get("volume", ...)),
        ("frame", report.get("frame")), ("vertex colours", report.get("colors")),
        ("time", _duration(report.get("seconds_total"))),
    ]
    warnings = []
    if tri == 0:
        warnings.append("the mesh is empty: the SDF never crosses zero (is the model trained?)")
    elif report.get("watertight") is False:
        warnings.append("the mesh is not watertight (holes or non-manifold edges)")
    body = kv_table(rows) + warnings_html(warnings) + picture + links
    summary = f"{report.get('vertices')} vertices, {tri} triangles, " + (
        "watertight" if report.get("watertight") else "NOT watertight")
    return summary, body


def section_export(page: Page, folder: Path) -> tuple[str, str]:
    report = page.json(folder / "export.json")
    if not isinstance(report, dict):
        report = {}
        body = _unreadable(folder / "export.json")
    else:
        pano = report.get("panorama") or {}
        scale = report.get("depth_png_scale") or {}
        cloud = report.get("point_cloud") or {}
        videos = report.get("videos") or {}
        frame = report.get("frame") or {}
        rows = [
            ("trained with cameras", report.get("cameras")),
            ("units", frame.get("units")),
            ("up (world)", frame.get("up")),
            ("environment views", f"{len(report.get('environment_views') or [])} at {report.get('view_size')} px"),
            ("panorama", f"{pano.get('width')} x {pano.get('height')}" if pano else None),
            ("depth colour scale", f"{text(scale.get('min'))} – {text(scale.get('max'))} "
                                   f"({text(scale.get('colormap'))}; {text(scale.get('meaning'))})"
                                   if scale else None),
            ("point cloud", f"{cloud.get('points')} points (depth below {text(cloud.get('max_depth'))})"
                            if cloud else None),
            ("videos", f"{text((videos.get('orbit') or {}).get('frames'))} + "
                       f"{text((videos.get('flythrough') or {}).get('frames'))} frames at "
                       f"{text(videos.get('size'))}, {text(videos.get('fps'))} fps" if videos else None),
            ("object views", ", ".join(report.get("object_views") or []) or "none"),
            ("tone mapping", report.get("tone_mapping")),
            ("time", ", ".join(f"{k} {_duration(v)}" for k, v in (report.get("seconds") or {}).items()) or None),
        ]
        body = kv_table(rows)
    body += "<h3>Files</h3><ul>"
    for path, what in ((folder / "videos" / "orbit.mp4", "orbit of the object (video)"),
                       (folder / "videos" / "flythrough.mp4",
                        "flythrough of the environment from inside the object (video)"),
                       (folder / "environment_points.ply", "the environment as a coloured point cloud"),
                       (folder / "environment_points_colmap.ply", "the same in COLMAP's frame")):
        if path.exists() or path.name != "environment_points_colmap.ply":
            body += f"<li>{esc(what)}: {page.link(path)}</li>"
    body += "</ul>"
    body += "<h3>Environment panorama from the object centre</h3>"
    body += page.image(folder / "panorama" / "panorama_rgb.png", "panorama (environment field, sRGB)")
    body += page.image(folder / "panorama" / "panorama_depth.png", "panorama depth (distance along each ray, turbo)")
    env = folder / "environment"
    names = list(report.get("environment_views") or [])
    if not names and env.is_dir():
        names = sorted(p.name[: -len("_rgb.png")] for p in env.glob("*_rgb.png"))
    cube = [n for n in names if n.startswith("cube_")]
    other = [n for n in names if not n.startswith("cube_")]
    if cube:
        body += "<h3>Cube views from the object centre (RGB, depth)</h3>" + _view_table(page, env, cube)
    if other:
        body += "<h3>Translated and rotated views (parallax around occluders)</h3>" + _view_table(page, env, other)
    objects = list(report.get("object_views") or [])
    if objects:
        body += "<h3>Object renders</h3>"
        rows = []
        for name in objects:
            cells = "".join(f"<td>{page.image(folder / 'object' / f'{name}_{part}.png', required=False)}</td>"
                            for part in ("rgb", "diffuse", "specular", "normal"))
            rows.append(f"<tr><th>{esc(name)}</th>{cells}</tr>")
        body += ('<table class="views"><tr><th>view</th><th>combined</th><th>diffuse</th>'
                 '<th>specular</th><th>normals</th></tr>'
                 + "".join(rows) + "</table>")
    summary = f"{len(names)} environment views, panorama" + (
        f", {report['point_cloud'].get('points')} points" if isinstance(report.get("point_cloud"), dict) else "")
    return summary, body


def _view_table(page: Page, folder: Path, names: Sequence[str]) -> str:
    head = "".join(f"<th>{esc(n)}</th>" for n in names)
    rgb = "".join(f"<td>{page.image(folder / f'{n}_rgb.png', alt=f'{n} RGB', width=240)}</td>" for n in names)
    depth = "".join(f"<td>{page.image(folder / f'{n}_depth.png', alt=f'{n} depth', width=240)}</td>" for n in names)
    return (f'<table class="views"><tr><th></th>{head}</tr><tr><th>RGB</th>{rgb}</tr>'
            f'<tr><th>depth</th>{depth}</tr></table>')


def _metric_rows(means: dict[str, Any]) -> list[tuple[str, Any, str, str]]:
    return [(label, value, unit, f"{better} is better" if better else "")
            for label, value, unit, better in metric_rows(means)]


def _evaluated_views(page: Page, folder: Path, part: Any, title: str, grid: str) -> tuple[str, dict[str, Any]]:
    """One part of ``evaluate.json`` (object or environment views) as HTML: the means' table, the compared
    region when the part names one, every view's figures and the comparison grid; and the means. Nothing
    when the part is absent."""
    if not isinstance(part, dict):
        return "", {}
    means = part.get("mean") or {}
    per_view = part.get("per_view") or {}
    keys = list(means)
    region = f"<p>Region: {esc(part['region'])}</p>" if part.get("region") else ""
    body = (f"<h3>{esc(title)}: mean of {len(part.get('views') or [])}, 1/{esc(part.get('downscale'))} size</h3>"
            + grid_table(["metric", "mean", "unit", ""], _metric_rows(means)) + region
            + details(f"every {title.lower()[:-1]} ({len(per_view)})", grid_table(
                ["view", *keys], [(n, *[(v or {}).get(k) for k in keys]) for n, v in per_view.items()]))
            + page.image(folder / grid, f"{title.lower()}: ground truth beside prediction"))
    return body, means


def section_evaluate(page: Page, folder: Path) -> tuple[str, str]:
    results = page.json(folder / "evaluate.json")
    if not isinstance(results, dict):
        return "evaluate.json missing", _unreadable(folder / "evaluate.json")
    body = kv_table([
        ("ground truth", results.get("ground_truth")),
        ("alignment to the ground truth", results.get("alignment")),
        ("trained with the ground-truth cameras", results.get("trained_with_ground_truth_cameras")),
        ("downscale", results.get("downscale")),
        ("time", _duration(results.get("seconds"))),
    ])
    summary_parts = []
    html_object, means = _evaluated_views(page, folder, results.get("object"), "Object views", "object_grid.png")
    body += html_object
    for key, template in (("normal_mae_deg", "normals {:.2f}°"), ("psnr_srgb_specular", "specular {:.1f} dB (sRGB)")):
        if isinstance(means.get(key), int | float):
            summary_parts.append(template.format(means[key]))
    html_env, means = _evaluated_views(page, folder, results.get("environment"), "Environment views",
                                       "environment_grid.png")
    body += html_env
    if isinstance(means.get("depth_absrel"), int | float):
        summary_parts.append(f"environment depth AbsRel {means['depth_absrel']:.3g}")
    poses = results.get("poses")
    if isinstance(poses, dict):
        s = poses.get("summary") or {}
        body += "<h3>Poses against the ground truth</h3>" + kv_table([
            ("cameras aligned", s.get("cameras")), ("missing", s.get("missing")),
            ("rotation error median / max (deg)",
             f"{text(s.get('rotation_deg_median'))} / {text(s.get('rotation_deg_max'))}"),
            ("centre error median / max (% of orbit radius)",
             f"{text(s.get('center_median_percent'))} / {text(s.get('center_max_percent'))}"),
            ("method", poses.get("method")),
        ])
    mesh = results.get("mesh")
    if isinstance(mesh, dict):
        rows = [("Chamfer (object radii)", mesh.get("chamfer_fraction")),
                ("Hausdorff (object radii)", mesh.get("hausdorff_fraction"))]
        rows += [(f"F-score at {k[len('fscore_'):-len('pct')]} % of the radius", v) for k, v in mesh.items()
                 if k.startswith("fscore_")]
        rows += [("samples per surface", mesh.get("samples"))]
        body += "<h3>Mesh against the ground truth</h3>" + kv_table(rows)
        if isinstance(mesh.get("chamfer_fraction"), int | float):
            summary_parts.append(f"Chamfer {mesh['chamfer_fraction']:.3g} radii")
    return ", ".join(summary_parts) or "evaluated", body


SECTIONS: dict[str, tuple[str, Callable[[Page, Path], tuple[str, str]]]] = {
    "decode": ("Capture (decode)", section_decode),
    "poses": ("Poses", section_poses),
    "masks": ("Masks", section_masks),
    "train": ("Training", section_train),
    "mesh": ("Mesh", section_mesh),
    "export": ("Export: the environment and the object", section_export),
    "evaluate": ("Evaluation against the ground truth", section_evaluate),
}


# ------------------------------------------------------------------------------------------------- stage


def check_results_folder(results: Path) -> None:
    """Raise a clear :class:`InputError` unless ``results`` is a capture's results folder (it holds at least
    one stage folder)."""
    if not results.exists():
        raise InputError("results folder not found", results,
                         "pass a capture's results folder, e.g. results/demo (run the pipeline first)")
    if not results.is_dir():
        raise InputError("not a results folder (a file, not a folder)", results,
                         "pass a capture's results folder, e.g. results/demo")
    if not any((results / s).is_dir() for s in STAGES):
        hint = "pass a capture's results folder, e.g. results/demo, the one holding decode/, poses/, ..."
        if (results / MANIFEST).is_file() and results.parent != results:
            hint = f"this looks like one stage's folder: pass its parent, {results.parent}"
        elif (Path("results") / results.resolve().name).is_dir() and results.resolve() != (
                Path("results") / results.resolve().name).resolve():
            hint = f"this looks like a capture folder: its results are in {Path('results') / results.resolve().name}"
        raise InputError(f"not a results folder: none of {', '.join(s + '/' for s in STAGES)} is in it", results,
                         hint)


def run_report(results_dir: Path, out_dir: Path | None = None) -> dict[str, Any]:
    """Write ``report.html`` (and ``manifest.json``) for the capture results in ``results_dir`` into
    ``out_dir`` (default ``results_dir/report``), atomically; returns what the page holds."""
    started = time.time()
    results = Path(results_dir)
    check_results_folder(results)
    out_dir = Path(out_dir) if out_dir is not None else results / "report"
    page = Page(results=results, out_dir=out_dir)
    capture = results.resolve().name
    status: dict[str, str] = {}
    summaries: dict[str, str] = {}
    parts: list[str] = []
    for stage, (title, build) in SECTIONS.items():
        folder = results / stage
        if not folder.is_dir():
            status[stage] = "missing"
            summaries[stage] = "not run" if stage != "evaluate" else "no evaluation"
            body = _missing_stage(page, stage)
        else:
            problems_before = len(page.problems)
            try:
                summary, body = build(page, folder)
            except Exception as e:  # noqa: BLE001 - a report shows what it can: one odd file must not hide the rest
                log.warning("report: the %s section failed: %s", stage, e)
                page.problems.append(f"{stage}: {type(e).__name__}: {e}")
                summary = "could not be read"
                body = f'<p class="error">This section could not be built: {esc(type(e).__name__)}: {esc(e)}</p>'
            status[stage] = "present" if len(page.problems) == problems_before else "incomplete"
            summaries[stage] = summary
            body = _manifest_line(page, folder) + body
        parts.append(f'<section id="{stage}"><h2>{esc(title)}</h2>{body}</section>')

    overview = grid_table(["stage", "status", "summary"],
                          [(s, status[s], summaries[s]) for s in SECTIONS])
    nav = "".join(f'<a href="#{s}">{esc(s)}</a>' for s in SECTIONS)
    problems = warnings_html(page.problems, "Files missing or unreadable") if page.problems else ""
    created = time.strftime("%Y-%m-%d %H:%M:%S %z")
    document = (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>ORCa report: {esc(capture)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
        f"<h1>ORCa report: {esc(capture)}</h1>\n"
        f"<p>Results folder <code>{esc(results.resolve())}</code>, report written {esc(created)}.</p>\n"
        f"<nav>{nav}</nav>\n<h2>Stages</h2>{overview}{problems}\n" + "\n".join(parts) + "\n</body>\n</html>\n"
    )
    with atomic_dir(out_dir, "report", [results / s for s in STAGES]) as tmp:
        (tmp / REPORT_HTML).write_text(document, encoding="utf-8")
        write_manifest(tmp, stage="report", inputs=page.inputs, config={}, started=started,
                       extra={"results": str(results), "sections": status, "images": page.images,
                              "problems": page.problems})
    log.info("report: %s (%d pictures, %.1f MB; %s) in %.1f s", out_dir / REPORT_HTML, page.images,
             len(document.encode()) / 1e6, ", ".join(f"{s} {v}" for s, v in status.items()), time.time() - started)
    return {"html": str(out_dir / REPORT_HTML), "sections": status, "summaries": summaries, "images": page.images,
            "problems": page.problems}


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
