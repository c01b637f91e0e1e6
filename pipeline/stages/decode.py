"""Stage ``decode``: a capture folder's photos -> linear, exposure-normalized float RGB.

Where the photos are: in ``CAPTURE/images/`` if that folder exists (then nothing else is read as a photo),
otherwise at the top level of ``CAPTURE/``. Sub-folders (``masks/``, ``calibration/``, ``ground_truth/``,
...) are never searched, and ``capture.yaml``, known cameras (``cameras.json``, ``transforms.json``) and hidden files
are not photos. Any other file in the photo
folder that is not a photo (RAW: DNG, CR2, CR3, NEF, ARW, RAF, ORF, RW2, PEF, KDC, ...; JPEG, PNG, TIFF) is
skipped with a warning naming it. When a RAW and a JPEG/PNG/TIFF share a name (RAW+JPEG shooting) the RAW
is used and the other skipped with a warning.

The colour pipeline, for every image ``i`` and the reference image ``r`` (``decode.reference_image``,
default the first file in name order):

- RAW via LibRaw (rawpy): black/white levels from the file (or ``decode.black_level/white_level``), **one**
  white balance for the whole set (the reference's as-shot multipliers, or ``decode.white_balance``),
  demosaic (``decode.demosaic``), camera -> linear sRGB matrix, no gamma, no auto-brightness, no
  ``adjust_maximum``. A neutral at the white level is 1.0 (G multiplier = 1). See :mod:`pipeline.raw`.
- JPEG/PNG/TIFF: inverse sRGB transfer (8 or 16 bit), EXIF orientation applied.
- Exposure: ``linear_i *= value_r / value_i`` with ``value = shutter_s * ISO / f_number**2`` from EXIF
  (``decode.normalize_exposure``). A field no photo records is left out; a field only some photos record
  is an error (we cannot tell how those photos were exposed).
- Highlight-clipped pixels: raw values at or above ``black + clip_fraction * (white - black)`` in any
  channel, dilated 2 raw pixels (before white balance), plus anything LibRaw's output clipped.
- ``decode.downscale``: k x k area averaging; a block is clipped if any of its pixels is.

Bad input stops the stage with an :class:`~pipeline.errors.InputError` before anything is written:
the header pass collects **all** unreadable/corrupt files and names them together; a file whose pixel
data turns out to be truncated while decoding stops the run at that file, naming it. ``out_dir`` is
written through :func:`pipeline.artifacts.atomic_dir`, so a failed run leaves a previous result untouched.

Outputs (``out_dir``): ``linear/<stem>.exr`` (float32 RGB), ``srgb/<stem>.png`` (8-bit sRGB, for feature
matching), ``clipped/<stem>.png`` (0/255), ``decode.json``, ``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..artifacts import stage_dir
from ..config import DecodeConfig, add_config_arguments, config_from_arguments
from ..errors import InputError

if TYPE_CHECKING:
    from ..raw import PhotoInfo

log = logging.getLogger("orca.decode")

PHOTO_SUBDIR = "images"
NOT_PHOTOS = {"capture.yaml", "capture.yml", "cameras.json", "transforms.json"}  # the last two: known cameras
EXPOSURE_FIELDS = ("shutter_s", "iso", "f_number")
DECODE_JSON = "decode.json"
SCHEMA_VERSION = 1


@dataclass(frozen=True)
class DecodedImage:
    name: str  # output stem: linear/<name>.exr, srgb/<name>.png, clipped/<name>.png
    source: Path
    format: str  # raw | jpeg | png | tiff
    width: int
    height: int
    exposure_scale: float
    clipped_fraction: float


@dataclass(frozen=True)
class DecodeResult:
    out_dir: Path
    images: tuple[DecodedImage, ...]
    reference: str  # file name of the reference image
    white_balance: tuple[float, float, float]  # multipliers applied to RAW images (G = 1)
    skipped: tuple[str, ...]  # file names skipped with a warning
    seconds: float


# ------------------------------------------------------------------------------------------- finding photos


def find_photos(capture_dir: Path) -> tuple[Path, list[Path], list[str]]:
    """(photo folder, photo files in name order, names of skipped files). Warns for each skipped file."""
    from ..raw import PHOTO_SUFFIXES, RAW_SUFFIXES

    if not capture_dir.is_dir():
        raise InputError(
            "capture folder not found" if not capture_dir.exists() else "not a folder",
            capture_dir,
            fix="pass the folder that holds the photos (or their images/ folder's parent)",
        )
    sub = capture_dir / PHOTO_SUBDIR
    photo_dir = sub if sub.is_dir() else capture_dir
    skipped: list[str] = []
    if photo_dir is sub:
        stray = sorted(p.name for p in capture_dir.iterdir() if p.is_file() and p.suffix.lower() in PHOTO_SUFFIXES)
        if stray:
            log.warning(
                "%s: %d photo file(s) at the top level are ignored because %s/ exists: %s",
                capture_dir, len(stray), PHOTO_SUBDIR, ", ".join(stray),
            )
            skipped += stray
    photos: list[Path] = []
    for p in sorted(photo_dir.iterdir(), key=lambda q: q.name):
        if p.is_dir() or p.name.startswith("."):
            continue
        if p.suffix.lower() in PHOTO_SUFFIXES:
            photos.append(p)
        elif p.name.lower() not in NOT_PHOTOS or photo_dir is sub:
            log.warning("skipping %s: not a photo (RAW, JPEG, PNG or TIFF)", p)
            skipped.append(p.name)
    # RAW+JPEG pairs: keep the RAW. Other name clashes would overwrite each other's outputs.
    by_stem: dict[str, list[Path]] = {}
    for p in photos:
        by_stem.setdefault(p.stem, []).append(p)
    kept: list[Path] = []
    for stem, group in by_stem.items():
        if len(group) == 1:
            kept.append(group[0])
            continue
        raws = [p for p in group if p.suffix.lower() in RAW_SUFFIXES]
        if len(raws) == 1:
            kept.append(raws[0])
            others = [p.name for p in group if p is not raws[0]]
            log.warning("using %s; skipping %s (same shot, RAW preferred)", raws[0].name, ", ".join(others))
            skipped += others
        else:
            raise InputError(
                f"{len(group)} photos share the name {stem!r}: {', '.join(p.name for p in group)}",
                photo_dir,
                fix="rename or remove all but one (outputs are named after the file stem)",
            )
    kept.sort(key=lambda q: q.name)
    return photo_dir, kept, skipped


# ------------------------------------------------------------------------------------------------ the stage


def run_decode(capture_dir: Path, out_dir: Path, config: DecodeConfig) -> DecodeResult:
    """Decode every photo of ``capture_dir`` into ``out_dir`` (see the module doc)."""
    import numpy as np

    from .. import imageio, raw
    from ..artifacts import atomic_dir, write_json, write_manifest
    from ..log import progress
    from ..provenance import capture_record

    started = time.time()
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    photo_dir, files, skipped = find_photos(capture_dir)
    if not files:
        raise InputError(
            "no photos found (RAW, JPEG, PNG or TIFF)",
            photo_dir,
            fix=f"put the photos in {capture_dir / PHOTO_SUBDIR} or at the top level of {capture_dir}",
        )

    # Pass 1: headers only. Collect every unreadable file so the user can fix them all at once.
    infos: list[PhotoInfo] = []
    bad: list[InputError] = []
    for f in files:
        try:
            infos.append(raw.probe(f))
        except InputError as e:
            bad.append(e)
    if bad:
        names = "\n".join(f"  - {e.path.name}: {e.message}" for e in bad)  # their fixes: the one below
        raise InputError(
            f"{len(bad)} of {len(files)} photos cannot be read:\n{names}",
            photo_dir,
            fix="copy those files again from the camera/card, or remove them from the capture",
        )
    if len(infos) < config.min_images:
        raise InputError(
            f"only {len(infos)} usable photo(s), at least {config.min_images} needed (decode.min_images)",
            photo_dir,
            fix="add photos to the capture, or lower decode.min_images",
        )
    _check_sizes(infos, photo_dir)
    kinds = Counter(i.kind for i in infos)
    if "raw" in kinds and len(kinds) > 1:
        log.warning(
            "the capture mixes RAW and %s photos; in-camera JPEG/PNG/TIFF processing (tone curve, white balance) "
            "will not match the RAW images exactly", "/".join(k.upper() for k in kinds if k != "raw"),
        )
    ref = _reference(infos, config.reference_image, photo_dir)
    wb, wb_source = _white_balance(infos, ref, config)
    scales, exposure_doc = _exposure_scales(infos, ref, config)

    k = config.downscale
    records: list[dict[str, Any]] = []
    images: list[DecodedImage] = []
    with atomic_dir(out_dir, "decode", [capture_dir]) as tmp:
        for sub in ("linear", "srgb", "clipped"):
            (tmp / sub).mkdir()
        with progress() as bar:
            task = bar.add_task("decode", total=len(infos))
            for info, scale in zip(infos, scales):
                if info.kind == "raw":
                    d = raw.decode_raw(
                        info,
                        white_balance=wb,
                        demosaic=config.demosaic,
                        color_space=config.color_space,
                        black_level=config.black_level,
                        white_level=config.white_level,
                        clip_fraction=config.clip_fraction,
                    )
                else:
                    d = raw.decode_raster(info, clip_fraction=config.clip_fraction)
                linear = raw.downscale_area(d.linear * np.float32(scale), k)
                clipped = raw.downscale_any(d.clipped, k)
                name = info.path.stem
                imageio.write_exr(tmp / "linear" / f"{name}.exr", linear)
                imageio.write_png(tmp / "srgb" / f"{name}.png", imageio.to_srgb8(linear))
                imageio.write_png(tmp / "clipped" / f"{name}.png", clipped.astype(np.uint8) * 255)
                frac = float(clipped.mean())
                h, w = linear.shape[:2]
                images.append(DecodedImage(name, info.path, info.kind, w, h, float(scale), frac))
                records.append(_record(info, d.meta, name, w, h, scale, frac, capture_dir))
                bar.advance(task)
        sizes = Counter((im.width, im.height) for im in images)
        if len(sizes) > 1:  # the header pass predicted sizes; this catches files whose decoded size differs
            _raise_mixed([(im.source, im.width, im.height) for im in images], photo_dir)
        doc = {
            "schema": SCHEMA_VERSION,
            "capture": str(capture_dir),
            "photo_folder": str(photo_dir.relative_to(capture_dir)) if photo_dir != capture_dir else ".",
            "reference_image": ref.path.name,
            "white_balance": {"multipliers": list(wb), "source": wb_source, "applies_to": "RAW images"},
            "exposure": exposure_doc,
            "colour_pipeline": _pipeline_doc(config, infos),
            "downscale": k,
            "size": [images[0].width, images[0].height],
            "skipped": skipped,
            "images": records,
        }
        write_json(tmp / DECODE_JSON, doc)
        inputs = {f"photo:{i.path.name}": i.path for i in infos}
        if (capture_dir / "capture.yaml").is_file():
            inputs["capture.yaml"] = capture_dir / "capture.yaml"
        write_manifest(tmp, stage="decode", inputs=inputs, config=config.model_dump(mode="json"), started=started,
                       capture=capture_record(capture_dir, [i.path for i in infos]))
    seconds = time.time() - started
    lo, hi = min(scales), max(scales)
    log.info(
        "decode: %d photos (%s) -> %dx%d, reference %s, WB (%.3f, 1, %.3f), exposure scales %.3g-%.3g, "
        "clipped %.2f %% -> %s (%.1f s)",
        len(images), ", ".join(f"{n} {kind}" for kind, n in Counter(i.kind for i in infos).items()),
        images[0].width, images[0].height, ref.path.name, wb[0], wb[2], lo, hi,
        100 * float(np.mean([im.clipped_fraction for im in images])), out_dir, seconds,
    )
    return DecodeResult(out_dir, tuple(images), ref.path.name, wb, tuple(skipped), seconds)


def _check_sizes(infos: list[PhotoInfo], photo_dir: Path) -> None:
    if len({(i.width, i.height) for i in infos}) > 1:
        _raise_mixed([(i.path, i.width, i.height) for i in infos], photo_dir)


def _raise_mixed(items: list[tuple[Path, int, int]], photo_dir: Path) -> None:
    counts = Counter((w, h) for _, w, h in items)
    (mw, mh), n = counts.most_common(1)[0]
    odd = [f"{p.name} ({w}x{h})" for p, w, h in items if (w, h) != (mw, mh)]
    raise InputError(
        f"photos of different sizes: {n} are {mw}x{mh} (width x height, as displayed), but {len(odd)} are not: "
        + ", ".join(odd),
        photo_dir,
        fix="remove the odd photos (or resize them to the majority size); all photos of a capture must come "
        "from one camera at one resolution and orientation",
    )


def _reference(infos: list[PhotoInfo], name: str | None, photo_dir: Path) -> PhotoInfo:
    if name is None:
        return infos[0]
    for i in infos:
        if i.path.name == name:
            return i
    for i in infos:
        if i.path.stem == name:
            return i
    shown = ", ".join(i.path.name for i in infos[:5]) + (", ..." if len(infos) > 5 else "")
    raise InputError(
        f"decode.reference_image {name!r} is not one of the photos ({shown})",
        photo_dir,
        fix="set decode.reference_image to one of the photo file names, or leave it unset (the first photo)",
    )


def _white_balance(
    infos: list[PhotoInfo], ref: PhotoInfo, config: DecodeConfig
) -> tuple[tuple[float, float, float], str]:
    if config.white_balance != "reference":
        r, g, b = config.white_balance
        return (r / g, 1.0, b / g), "config (decode.white_balance)"
    raws = [i for i in infos if i.kind == "raw"]
    if not raws:
        return (1.0, 1.0, 1.0), "none (no RAW images; JPEG/PNG/TIFF are balanced in camera)"
    src = ref
    if ref.kind != "raw":
        src = raws[0]
        log.warning(
            "the reference image %s is not RAW; the RAW images use the as-shot white balance of %s",
            ref.path.name, src.path.name,
        )
    if src.as_shot_wb is not None:
        return src.as_shot_wb, f"as-shot of {src.path.name}"
    if src.daylight_wb is not None:
        log.warning("%s records no as-shot white balance; using LibRaw's daylight multipliers", src.path)
        return src.daylight_wb, f"daylight multipliers for the camera of {src.path.name} (no as-shot WB)"
    log.warning("%s records no white balance; using none (1, 1, 1)", src.path)
    return (1.0, 1.0, 1.0), f"none ({src.path.name} records no white balance)"


def _exposure_scales(
    infos: list[PhotoInfo], ref: PhotoInfo, config: DecodeConfig
) -> tuple[list[float], dict[str, Any]]:
    if not config.normalize_exposure:
        return [1.0] * len(infos), {"normalized": False}
    used, ignored = [], []
    for f in EXPOSURE_FIELDS:
        missing = [i for i in infos if getattr(i.exif, f) is None]
        if len(missing) == len(infos):
            ignored.append(f)
        elif missing:
            names = ", ".join(i.path.name for i in missing[:10]) + (" ..." if len(missing) > 10 else "")
            raise InputError(
                f"EXIF {f} is missing in {len(missing)} of {len(infos)} photos ({names}), so their exposure "
                "cannot be matched to the others",
                missing[0].path.parent,
                fix="restore the EXIF data, remove those photos, or set decode.normalize_exposure: false if all "
                "photos were taken with the same settings",
            )
        else:
            used.append(f)
    if ignored:
        log.info("exposure normalization: no photo records %s; left out", ", ".join(ignored))

    def value(i: PhotoInfo) -> float:
        v = 1.0
        if "shutter_s" in used:
            v *= i.exif.shutter_s  # type: ignore[operator]
        if "iso" in used:
            v *= i.exif.iso / 100.0  # type: ignore[operator]
        if "f_number" in used:
            v /= i.exif.f_number**2  # type: ignore[operator]
        return v

    ref_value = value(ref)
    scales = [ref_value / value(i) for i in infos]
    doc = {
        "normalized": True,
        "formula": "linear *= value(reference) / value(image), value = shutter_s * (iso / 100) / f_number**2 "
        "over the fields used",
        "fields_used": used,
        "fields_missing_in_all": ignored,
        "reference_value": ref_value,
    }
    return scales, doc


def _pipeline_doc(config: DecodeConfig, infos: list[PhotoInfo]) -> dict[str, Any]:
    import rawpy

    return {
        "raw": f"LibRaw {'.'.join(map(str, rawpy.libraw_version))} via rawpy: (raw - black) / (white - black), "
        f"white balance (G = 1), {config.demosaic} demosaic, "
        + ("camera -> linear sRGB matrix (file or LibRaw table)" if config.color_space == "srgb" else "camera RGB")
        + "; gamma 1, no auto-brightness, adjust_maximum_thr 0, highlights clipped",
        "jpeg_png_tiff": "inverse sRGB transfer of the stored values (1.0 = maximum code value); float TIFF as is",
        "units": "1.0 = a neutral at the reference image's white level; other images scaled to the reference's "
        "exposure",
        "clipped": f"raw >= black + {config.clip_fraction} (white - black) in any channel, dilated 2 raw pixels, "
        "plus LibRaw output overflow; 8/16-bit files: any channel >= "
        f"{config.clip_fraction} of the maximum, dilated 1 pixel",
        "formats": sorted({i.kind for i in infos}),
    }


def _record(
    info: PhotoInfo, meta: dict[str, Any], name: str, w: int, h: int, scale: float, frac: float, capture_dir: Path
) -> dict[str, Any]:
    try:
        source = str(info.path.relative_to(capture_dir))
    except ValueError:
        source = str(info.path)
    return {
        "name": name,
        "source": source,
        "format": info.kind,
        "extension": info.path.suffix.lower().lstrip("."),
        "exif": info.exif.to_json(),
        "orientation": info.orientation,
        "source_size": [info.width, info.height],
        "width": w,
        "height": h,
        "white_balance": meta.get("white_balance"),
        "levels": {k: meta[k] for k in ("black_level", "black_level_per_channel", "white_level") if k in meta}
        or None,
        "decoder": {k: v for k, v in meta.items() if k not in ("white_balance",)},
        "exposure_scale": scale,
        "clipped_fraction": frac,
        "linear": f"linear/{name}.exr",
        "srgb": f"srgb/{name}.png",
        "clipped": f"clipped/{name}.png",
    }


# ---------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca decode captures/mug                         # -> results/mug/decode/
  orca decode captures/mug --out /tmp/mug-decode --set decode.downscale=4
  orca decode captures/mug --set reference_image=IMG_0012.CR2 --set min_images=1
  orca decode captures/mug --set 'white_balance=[2.1, 1, 1.6]' --preset fast
  orca decode captures/mug --config my.yaml        # YAML with a `decode:` section

Photos are read from CAPTURE/images/ if it exists, else from CAPTURE/ itself. The config is built from the
preset, CAPTURE/capture.yaml (if present), --config and --set (later wins); `--set key=value` accepts
`decode.key` or just `key` for the decode section. Output: linear/*.exr, srgb/*.png, clipped/*.png,
decode.json, manifest.json.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "decode",
        help="photos (RAW/JPEG/PNG/TIFF) -> linear exposure-normalized EXR, sRGB PNG, clipped masks",
        description="Decode a capture's photos into linear, white-balanced, exposure-normalized float RGB.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("capture", type=Path, help="capture folder (photos at its top level or in images/)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/<capture name>/decode)")
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> DecodeResult:
    capture = Path(args.capture)
    config = config_from_arguments(args, "decode", capture / "capture.yaml")
    return run_decode(capture, stage_dir(capture, "decode", args.out), config.decode)
