"""Which capture an artifact came from: each stage's ``manifest.json`` carries a ``capture`` record, so a stage
given the inputs of two different captures (another capture's decode, its ground truth, its masks) says so
instead of computing figures that mean nothing.

The record: ``{"id": <hash of the photos' names and contents>, "folder": <capture folder>, "photos": [<paths
relative to it>]}``. The decode stage (and ``orca synth``, for the ground truth it renders) makes it from the
photos; every later stage copies it from its inputs.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .artifacts import file_sha256, read_json
from .errors import InputError
from .layout import MANIFEST
from .raw import PHOTO_SUFFIXES

log = logging.getLogger("orca")

FORCE_HELP = ("go on when the inputs record different captures (e.g. the same photos decoded twice under "
              "other names); the figures are then yours to trust")


def capture_record(folder: Path, photos: Sequence[Path]) -> dict[str, Any]:
    """The ``capture`` record of the capture ``folder`` whose photos (the files the decode stage reads) are
    ``photos``: the id hashes their file names and contents, so a copied or moved capture keeps it."""
    folder = Path(folder).resolve()
    digest = hashlib.sha256()
    for photo in sorted(photos, key=lambda p: p.name):
        digest.update(f"{photo.name}\0{file_sha256(photo)}\n".encode())
    relative = []
    for photo in photos:
        try:
            relative.append(str(Path(photo).resolve().relative_to(folder)))
        except ValueError:
            relative.append(str(Path(photo).resolve()))
    return {"id": digest.hexdigest()[:16], "folder": str(folder), "photos": sorted(relative)}


def recorded_capture(source: Path) -> dict[str, Any] | None:
    """The capture record of the stage folder ``source`` is, or holds (a file or sub-folder of a stage folder:
    ``masks/cameras.json``, ``masks/masks/``, ``poses/sparse/``); None for a user's own file or an artifact
    written before captures were recorded."""
    source = Path(source)
    for folder in (source, source.parent) if source.is_dir() else (source.parent,):
        if (folder / MANIFEST).is_file():
            try:
                record = read_json(folder / MANIFEST).get("capture")
            except (OSError, ValueError, AttributeError):
                return None
            return record if isinstance(record, dict) and isinstance(record.get("id"), str) else None
    return None


def common_capture(sources: Iterable[Path | None], *, force: bool = False) -> dict[str, Any] | None:
    """The capture record the stage inputs ``sources`` share (None when none records one).

    Raises:
        InputError: two inputs record different captures, unless ``force`` (then a warning).
    """
    found = [(Path(s), r) for s in sources if s is not None and (r := recorded_capture(Path(s))) is not None]
    if len({r["id"] for _, r in found}) > 1:
        _mismatch("the inputs come from different captures:\n" + "\n".join(
            f"  - {s} from {r.get('folder', '?')} (photos {r['id']})" for s, r in found), force)
    return found[0][1] if found else None


def check_capture_folder(capture_dir: Path, record: dict[str, Any] | None, *, force: bool = False) -> None:
    """Check that the capture folder a stage reads (its capture.yaml, masks, calibration, known cameras) is the
    one its other inputs came from: the same folder, or one holding the same photos (a moved or copied capture).
    A folder holding no photos at all is a folder of settings for those photos, not another capture.

    Raises:
        InputError: another capture's folder, unless ``force`` (then a warning).
    """
    if record is None or not _holds_photos(Path(capture_dir)):
        return
    capture_dir = Path(capture_dir).resolve()
    if Path(record.get("folder", "")) == capture_dir:
        return
    photos = [capture_dir / p for p in record.get("photos", [])]
    if photos and all(p.is_file() for p in photos) and capture_record(capture_dir, photos)["id"] == record["id"]:
        return
    _mismatch(f"the capture folder {capture_dir} is not the one the other inputs came from "
              f"({record.get('folder', '?')}: its photos are not there, or differ)", force)


def _holds_photos(folder: Path) -> bool:
    return any(p.suffix.lower() in PHOTO_SUFFIXES and p.is_file()
               for sub in (folder, folder / "images") if sub.is_dir() for p in sub.iterdir())


def _mismatch(message: str, force: bool) -> None:
    if force:
        log.warning("%s; going on (--force)", message)
        return
    raise InputError(message, fix="pass the results of one capture (rerun the earlier stages on it), or --force if "
                     "they do belong together")
