"""Stage ``decode``: a capture folder's photos -> linear, exposure-normalized float RGB.

Which files are photos, and the set's one size, reference, white balance and exposure: :mod:`pipeline.photos`.

The colour pipeline, for every image ``i`` and the reference image ``r`` (``decode.reference_image``,
default the first file in name order):

- RAW via LibRaw (rawpy): black/white levels from the file (or ``decode.black_level/white_level``), **one**
  white balance for the whole set (the reference's as-shot multipliers, or ``decode.white_balance``),
  demosaic (``decode.demosaic``), camera -> linear sRGB matrix, no gamma, no auto-brightness, no
  ``adjust_maximum``. A neutral at the white level is 1.0 (G multiplier = 1). See :mod:`pipeline.raw`.
- JPEG/PNG/TIFF/HEIC: inverse sRGB transfer (8 or 16 bit), EXIF orientation applied (HEIC: pillow-heif applies
  the file's rotation on decoding).
- Exposure: ``linear_i *= value_r / value_i`` with ``value = shutter_s * ISO / f_number**2`` from EXIF
  (``decode.normalize_exposure``). A field no photo records is left out; a field only some photos record
  is an error (we cannot tell how those photos were exposed).
- Highlight-clipped pixels: raw values at or above ``black + clip_fraction * (white - black)`` in any
  channel (before white balance) and the pixels between such photosites, grown by ``decode.clip_dilate_raw``
  pixels, plus anything LibRaw's output clipped.
- ``decode.downscale``: k x k area averaging; a block is clipped if any of its pixels is. Without one, photos
  larger than ``decode.max_size`` (1600 px longest side) are downscaled by the smallest factor that fits.

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
from typing import Any

import numpy as np

from .. import imageio, raw
from ..artifacts import atomic_dir, write_json, write_manifest
from ..config import DecodeConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..layout import CAPTURE_YAML, DECODE, DECODE_JSON, IMAGE_KINDS, PHOTO_SUBDIR, decoded_files, stage_dir
from ..log import progress
from ..photos import (
    check_sizes,
    exposure_scales,
    find_photos,
    raise_mixed_sizes,
    reference_photo,
    white_balance,
    working_downscale,
)
from ..provenance import capture_record
from ..raw import PhotoInfo
from ..video import VIDEO_SUFFIXES

log = logging.getLogger("orca.decode")

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class DecodedImage:
    name: str  # output stem: linear/<name>.exr, srgb/<name>.png, clipped/<name>.png
    source: Path
    format: str  # raw | jpeg | png | tiff | heif
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


# ------------------------------------------------------------------------------------------------ the stage


def run_decode(capture_dir: Path, out_dir: Path, config: DecodeConfig) -> DecodeResult:
    """Decode every photo of ``capture_dir`` into ``out_dir`` (see the module doc)."""
    started = time.time()
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    photo_dir, files, skipped = find_photos(capture_dir)
    videos = [str(photo_dir / n) for n in skipped if Path(n).suffix.lower() in VIDEO_SUFFIXES]
    frames_fix = f"make photos of the video(s) with `orca frames {' '.join(videos)} {capture_dir}`"
    if not files:
        raise InputError(
            "no photos found (RAW, JPEG, PNG, TIFF or HEIC)",
            photo_dir,
            fix=frames_fix if videos else
            f"put the photos in {capture_dir / PHOTO_SUBDIR} or at the top level of {capture_dir}",
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
            fix=frames_fix if videos else "add photos to the capture, or lower decode.min_images",
        )
    check_sizes(infos, photo_dir)
    kinds = Counter(i.kind for i in infos)
    if "raw" in kinds and len(kinds) > 1:
        log.warning(
            "the capture mixes RAW and %s photos; in-camera JPEG/PNG/TIFF processing (tone curve, white balance) "
            "will not match the RAW images exactly", "/".join(k.upper() for k in kinds if k != "raw"),
        )
    ref = reference_photo(infos, config.reference_image, photo_dir)
    wb, wb_source = white_balance(infos, ref, config.white_balance)
    scales, exposure_doc = exposure_scales(infos, ref, config.normalize_exposure)

    k = working_downscale(infos, config.downscale, config.max_size)
    if config.downscale is None and k > 1:
        log.info("photos of %dx%d downscaled %dx to %dx%d (decode.max_size %d; set decode.downscale to choose)",
                 infos[0].width, infos[0].height, k, infos[0].width // k, infos[0].height // k, config.max_size)
    records: list[dict[str, Any]] = []
    images: list[DecodedImage] = []
    with atomic_dir(out_dir, DECODE, [capture_dir]) as tmp:
        for sub in IMAGE_KINDS:
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
                        clip_dilate=config.clip_dilate_raw,
                    )
                else:
                    d = raw.decode_raster(info, clip_fraction=config.clip_fraction)
                linear = raw.downscale_area(d.linear * np.float32(scale), k)
                clipped = raw.downscale_any(d.clipped, k)
                name = info.path.stem
                files = decoded_files(name)
                imageio.write_exr(tmp / files["linear"], linear)
                imageio.write_png(tmp / files["srgb"], imageio.to_srgb8(linear))
                imageio.write_png(tmp / files["clipped"], clipped.astype(np.uint8) * 255)
                frac = float(clipped.mean())
                h, w = linear.shape[:2]
                images.append(DecodedImage(name, info.path, info.kind, w, h, float(scale), frac))
                records.append(_record(info, d.meta, name, w, h, scale, frac, capture_dir))
                bar.advance(task)
        sizes = Counter((im.width, im.height) for im in images)
        if len(sizes) > 1:  # the header pass predicted sizes; this catches files whose decoded size differs
            raise_mixed_sizes([(im.source, im.width, im.height) for im in images], photo_dir)
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
        if (capture_dir / CAPTURE_YAML).is_file():
            inputs[CAPTURE_YAML] = capture_dir / CAPTURE_YAML
        write_manifest(tmp, stage=DECODE, inputs=inputs, config=config.model_dump(mode="json"), started=started,
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
        "clipped": f"raw >= black + {config.clip_fraction} (white - black) in any channel and the pixels between "
        f"such photosites (3 x 3 closing), grown by {config.clip_dilate_raw} raw pixels, "
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
        **decoded_files(name),
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
        help="photos (RAW/JPEG/PNG/TIFF/HEIC) -> linear exposure-normalized EXR, sRGB PNG, clipped masks",
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
    config = config_from_arguments(args, DECODE, capture / CAPTURE_YAML)
    return run_decode(capture, stage_dir(capture, DECODE, args.out), config.decode)
