"""A capture's photos as a set: which files are photos, and what the whole set shares -- one size, one
reference photo, one white balance, exposures scaled to the reference's.

Where the photos are: in ``CAPTURE/images/`` if that folder exists (then nothing else is read as a photo),
otherwise at the top level of ``CAPTURE/``. Sub-folders (``masks/``, ``calibration/``, ``ground_truth/``, ...)
are never searched, and ``capture.yaml``, known cameras (``cameras.json``, ``transforms.json``) and hidden files
are not photos. Any other file in the photo folder that is not a photo (RAW: DNG, CR2, CR3, NEF, ARW, RAF, ORF,
RW2, PEF, KDC, ...; JPEG, PNG, TIFF) is skipped with a warning naming it. When a RAW and a JPEG/PNG/TIFF share
a name (RAW+JPEG shooting) the RAW is used and the other skipped with a warning.
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path
from typing import Any

from .config import MAX_DOWNSCALE
from .errors import InputError
from .layout import CAMERAS_JSON, CAPTURE_CONFIGS, LLFF_IMAGE_NAMES, PHOTO_SUBDIR, POSES_BOUNDS, TRANSFORMS_JSON
from .raw import PHOTO_SUFFIXES, RAW_SUFFIXES, PhotoInfo
from .video import VIDEO_SUFFIXES

log = logging.getLogger("orca.decode")

NOT_PHOTOS = {*CAPTURE_CONFIGS, CAMERAS_JSON, TRANSFORMS_JSON, POSES_BOUNDS, LLFF_IMAGE_NAMES}  # known cameras
EXPOSURE_FIELDS = ("shutter_s", "iso", "f_number")

# ------------------------------------------------------------------------------------------- finding photos


def find_photos(capture_dir: Path) -> tuple[Path, list[Path], list[str]]:
    """(photo folder, photo files in name order, names of skipped files). Warns for each skipped file."""
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
        elif p.suffix.lower() in VIDEO_SUFFIXES:
            log.warning("skipping %s: a video; `orca frames %s %s` makes photos of it", p, p, capture_dir)
            skipped.append(p.name)
        elif p.name.lower() not in NOT_PHOTOS or photo_dir is sub:
            log.warning("skipping %s: not a photo (RAW, JPEG, PNG, TIFF or HEIC)", p)
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


# ------------------------------------------------------------------------------------- what the set shares


def check_sizes(infos: list[PhotoInfo], photo_dir: Path) -> None:
    if len({(i.width, i.height) for i in infos}) > 1:
        raise_mixed_sizes([(i.path, i.width, i.height) for i in infos], photo_dir)


def raise_mixed_sizes(items: list[tuple[Path, int, int]], photo_dir: Path) -> None:
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


def reference_photo(infos: list[PhotoInfo], name: str | None, photo_dir: Path) -> PhotoInfo:
    """The photo named ``name`` (file name or stem; None: the first)."""
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


def white_balance(
    infos: list[PhotoInfo], ref: PhotoInfo, setting: str | tuple[float, float, float]
) -> tuple[tuple[float, float, float], str]:
    """One white balance for every RAW photo (G = 1) and where it comes from: ``setting`` (multipliers), or
    with ``"reference"`` the reference's as-shot multipliers (else a RAW's, else LibRaw's daylight ones)."""
    if setting != "reference":
        r, g, b = setting
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


def exposure_scales(infos: list[PhotoInfo], ref: PhotoInfo, normalize: bool) -> tuple[list[float], dict[str, Any]]:
    """Per photo, the factor that brings its exposure to the reference's: ``value(ref) / value(photo)`` with
    ``value = shutter_s * (iso / 100) / f_number**2`` over the EXIF fields every photo records; and the record
    of it for decode.json. A field only some photos record is an error: their exposure cannot be matched."""
    if not normalize:
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


def working_downscale(infos: list[PhotoInfo], downscale: int | None, max_size: int) -> int:
    """The decode's integer downscale factor: ``downscale`` when given, else the smallest that brings the photos'
    longest side to ``max_size`` or below (1 when ``max_size`` is 0), at most :data:`MAX_DOWNSCALE`."""
    if downscale is not None:
        return downscale
    longest = max(max(i.width, i.height) for i in infos)
    if max_size == 0 or longest <= max_size:
        return 1
    return min(MAX_DOWNSCALE, -(-longest // max_size))
