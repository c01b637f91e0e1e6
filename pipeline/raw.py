"""Reading photos: RAW through rawpy/LibRaw, JPEG/PNG/TIFF through Pillow/OpenCV; EXIF; orientation.

Every reader returns **linear** float32 RGB and a highlight-clipping mask; what the numbers mean:

- RAW: ``(raw - black) / (white - black)`` per photosite, times the white-balance multipliers (G = 1),
  demosaiced by LibRaw, then (``color_space="srgb"``) LibRaw's camera -> linear sRGB matrix (from the file,
  e.g. a DNG's ColorMatrix, or LibRaw's table for the camera). So a neutral at the white level is 1.0.
  No gamma, no auto-brightness, no ``adjust_maximum`` rescale, highlights clipped (not reconstructed):
  a pixel whose every photosite nearby is saturated is set to the neutral level at which all channels saturate
  (``max(wb)``, G = 1), the least neutral radiance that saturates them all, and no clipped pixel's channel
  exceeds that level. White-balancing and colour-converting the saturated values instead gives a tint, not a
  level: ``wb * 1`` through the matrix, pink for a typical daylight balance, which a model trained on it would
  copy into every reflected light (the loss takes a clipped pixel's value as a lower bound).
- JPEG/PNG/TIFF (8 or 16 bit): the inverse sRGB transfer of the stored values (1.0 = the file's maximum).
  Float TIFFs are taken as already linear.

LibRaw's 16-bit integer output would clip white-balanced values above the white level (a red surface
that is not clipped in the raw data but has a red multiplier of 2) and it normalizes the multipliers so
the smallest is 1. We give it a white level raised by ``headroom`` (``user_sat``) so that nothing in range
overflows, and rescale exactly afterwards; what still reaches 65535 is flagged as clipped.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .errors import InputError

log = logging.getLogger("orca.decode")

RAW_SUFFIXES = frozenset(
    ".dng .cr2 .cr3 .crw .nef .nrw .arw .srf .sr2 .raf .orf .rw2 .rwl .pef .ptx .srw .kdc .dcr .k25 .mos .mrw "
    ".3fr .fff .erf .iiq .mef .x3f .raw .gpr".split()
)
RASTER_SUFFIXES = {".jpg": "jpeg", ".jpeg": "jpeg", ".png": "png", ".tif": "tiff", ".tiff": "tiff", ".heic": "heif",
                   ".heif": "heif"}
PHOTO_SUFFIXES = RAW_SUFFIXES | frozenset(RASTER_SUFFIXES)

Kind = Literal["raw", "jpeg", "png", "tiff", "heif"]

# LibRaw's ``sizes.flip`` -> EXIF orientation (dcraw maps EXIF to flip with "50132467"[orientation & 7]).
_FLIP_TO_EXIF = {0: 1, 1: 2, 3: 3, 2: 4, 4: 5, 6: 6, 7: 7, 5: 8}
# Extra factor of headroom for LibRaw's camera -> sRGB matrix, which can push saturated colours above 1.
MATRIX_HEADROOM = 2.0
# Half-size of the window whose photosites must all be saturated for a pixel to be set neutral: with 2 (AHD's
# whole 5 x 5 window) small highlights kept LibRaw's saturated value, a 3 x 3 window catches every such pixel.
SATURATED_REACH = 1
CLIP_DILATE_RASTER = 1
# exifread's words for a file that simply has no EXIF (logged at debug level, not as warnings)
NO_EXIF_MESSAGES = ("does not have exif data", "No EXIF header")
# Pillow's EXIF: the sub-IFD holding the exposure tags, and the tags read (TIFF/EXIF 2.3 numbers)
PIL_EXIF_IFD = 0x8769
PIL_TAGS = {"make": 0x010F, "model": 0x0110, "datetime": 0x0132, "shutter_s": 0x829A, "f_number": 0x829D,
            "iso": 0x8827, "datetime_original": 0x9003, "focal_length_mm": 0x920A, "focal_length_35mm": 0xA405}


def kind_of(path: Path) -> Kind | None:
    s = path.suffix.lower()
    if s in RAW_SUFFIXES:
        return "raw"
    return RASTER_SUFFIXES.get(s)  # type: ignore[return-value]


# ------------------------------------------------------------------------------------------------------ EXIF


@dataclass(frozen=True)
class ExifInfo:
    """What the pipeline uses from EXIF; ``None`` where the file does not say."""

    make: str | None = None
    model: str | None = None
    shutter_s: float | None = None
    iso: float | None = None
    f_number: float | None = None
    focal_length_mm: float | None = None
    focal_length_35mm: float | None = None
    orientation: int = 1
    datetime: str | None = None

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _num(tag: Any) -> float | None:
    """First numeric value of an exifread tag (Ratio, int, or list of them); None if absent/zero/garbage."""
    if tag is None:
        return None
    values = getattr(tag, "values", tag)
    if isinstance(values, (list, tuple)):
        if not values:
            return None
        values = values[0]
    try:
        if hasattr(values, "num") and hasattr(values, "den"):
            v = float(values.num) / float(values.den) if values.den else 0.0
        else:
            v = float(values)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return v if np.isfinite(v) and v > 0 else None


def _text(tag: Any) -> str | None:
    if tag is None:
        return None
    s = str(tag).strip().strip("\x00").strip()
    return s or None


def read_exif(path: Path) -> ExifInfo:
    """EXIF through exifread (JPEG, TIFF and TIFF-based RAW, PNG eXIf, ...); empty if there is none."""
    import exifread

    try:
        with open(path, "rb") as f, _naming_the_file(logging.getLogger("exifread"), path):
            tags = exifread.process_file(f, details=False)
    except Exception as e:  # exifread raises many things on odd files; EXIF is optional
        log.debug("%s: no EXIF (%s)", path, e)
        tags = {}

    def get(*names: str) -> Any:
        for n in names:
            if n in tags:
                return tags[n]
        return None

    orient = _num(get("Image Orientation"))
    orientation = int(orient) if orient is not None and 1 <= int(orient) <= 8 else 1
    return ExifInfo(
        make=_text(get("Image Make")),
        model=_text(get("Image Model")),
        shutter_s=_num(get("EXIF ExposureTime", "Image ExposureTime")),
        iso=_num(get("EXIF ISOSpeedRatings", "EXIF PhotographicSensitivity", "Image ISOSpeedRatings")),
        f_number=_num(get("EXIF FNumber", "Image FNumber")),
        focal_length_mm=_num(get("EXIF FocalLength", "Image FocalLength")),
        focal_length_35mm=_num(get("EXIF FocalLengthIn35mmFilm")),
        orientation=orientation,
        datetime=_text(get("EXIF DateTimeOriginal", "Image DateTimeOriginal", "Image DateTime")),
    )


@contextlib.contextmanager
def _naming_the_file(logger: logging.Logger, path: Path) -> Iterator[None]:
    """While reading ``path``, ``logger``'s messages name it: exifread's warnings ("File format not
    recognized.") do not say which of a capture's photos they are about."""

    def name_it(record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if any(m in message for m in NO_EXIF_MESSAGES):  # a photo without EXIF is common (PNG exports): no warning
            log.debug("%s: EXIF: %s", path, message)
            return False
        record.msg, record.args = f"{path}: EXIF: {message}", ()
        return True

    logger.addFilter(name_it)
    try:
        yield
    finally:
        logger.removeFilter(name_it)


# ----------------------------------------------------------------------------------------------- orientation


def apply_orientation(image: np.ndarray, orientation: int) -> np.ndarray:
    """Turn an image as stored into the image as seen, for an EXIF orientation 1..8 (works on (H, W, ...))."""
    a = image
    if orientation == 1:
        return a
    if orientation == 2:
        return a[:, ::-1]
    if orientation == 3:
        return a[::-1, ::-1]
    if orientation == 4:
        return a[::-1]
    if orientation == 5:  # transpose
        return a.swapaxes(0, 1)
    if orientation == 6:  # rotate 90 degrees clockwise
        return np.rot90(a, -1)
    if orientation == 7:  # transverse (anti-diagonal)
        return a[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:  # rotate 90 degrees counter-clockwise
        return np.rot90(a, 1)
    raise ValueError(f"EXIF orientation must be 1..8, got {orientation}")


def oriented_size(width: int, height: int, orientation: int) -> tuple[int, int]:
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


# ----------------------------------------------------------------------------------------------------- probe


@dataclass(frozen=True)
class PhotoInfo:
    """A photo's metadata, read without decoding its pixels."""

    path: Path
    kind: Kind
    width: int  # as seen (orientation applied), before any downscale
    height: int
    orientation: int
    exif: ExifInfo
    as_shot_wb: tuple[float, float, float] | None = None  # RAW: camera white balance, G = 1
    daylight_wb: tuple[float, float, float] | None = None  # RAW: LibRaw's daylight multipliers, G = 1
    extra: dict[str, Any] = field(default_factory=dict)


def _wb3(values: Any) -> tuple[float, float, float] | None:
    v = [float(x) for x in list(values)[:3]]
    if len(v) < 3 or not all(np.isfinite(v)) or v[1] <= 0 or min(v) <= 0:
        return None
    return (v[0] / v[1], 1.0, v[2] / v[1])


def probe(path: Path) -> PhotoInfo:
    """Open a photo's header: size, orientation, EXIF, as-shot white balance. InputError if unreadable."""
    path = Path(path)
    kind = kind_of(path)
    if kind is None:
        raise InputError("not a photo format the pipeline reads", path)
    if path.stat().st_size == 0:
        raise InputError("the file is empty", path, fix="copy the photo again from the camera or remove it")
    if kind == "heif":
        return _probe_heif(path)
    exif = read_exif(path)
    if kind == "raw":
        return _probe_raw(path, exif)
    return _probe_raster(path, kind, exif)


def _probe_raw(path: Path, exif: ExifInfo) -> PhotoInfo:
    import rawpy

    raw = rawpy.RawPy()
    try:
        raw.open_file(str(path))
        s = raw.sizes
        other = raw.other
        camera_wb = _wb3(raw.camera_whitebalance)
        daylight_wb = _wb3(raw.daylight_whitebalance)
        colors = raw.num_colors
    except rawpy.LibRawError as e:
        raise InputError(
            f"LibRaw cannot read this RAW file ({_libraw_message(e)}); it is corrupt, truncated or not a RAW file",
            path,
            fix="copy it again from the camera/card, or remove it from the capture folder",
        ) from e
    finally:
        raw.close()
    width, height = s.width, s.height
    if s.pixel_aspect and abs(s.pixel_aspect - 1) > 1e-3:  # LibRaw stretches non-square pixels
        if s.pixel_aspect < 1:
            height = int(round(height / s.pixel_aspect))
        else:
            width = int(round(width * s.pixel_aspect))
    orientation = _FLIP_TO_EXIF.get(int(s.flip), 1)
    w, h = oriented_size(width, height, orientation)
    # Standard EXIF tags first (exact rationals); LibRaw's maker-note values (float32) fill the gaps.
    def pick(exif_value: float | None, libraw_value: float) -> float | None:
        return exif_value if exif_value is not None else (float(libraw_value) if libraw_value > 0 else None)

    exif = ExifInfo(
        make=exif.make,
        model=exif.model,
        shutter_s=pick(exif.shutter_s, other.shutter_speed),
        iso=pick(exif.iso, other.iso_speed),
        f_number=pick(exif.f_number, other.aperture),
        focal_length_mm=pick(exif.focal_length_mm, other.focal_length),
        focal_length_35mm=exif.focal_length_35mm,
        orientation=orientation,
        datetime=exif.datetime,
    )
    return PhotoInfo(
        path, "raw", w, h, orientation, exif, as_shot_wb=camera_wb, daylight_wb=daylight_wb,
        extra={"colors": int(colors)},
    )


def _probe_raster(path: Path, kind: Kind, exif: ExifInfo) -> PhotoInfo:
    from PIL import Image

    try:
        if kind == "tiff":  # tifffile reads every TIFF header (float, planar, 16-bit) that OpenCV decodes
            import tifffile

            with tifffile.TiffFile(path) as tf:
                page = tf.pages.first
                width, height = int(page.imagewidth), int(page.imagelength)
        else:
            with Image.open(path) as im:
                width, height = im.size
    except Exception as e:  # Pillow/tifffile raise various errors on garbage
        raise InputError(
            f"not a readable {kind.upper()} image ({type(e).__name__}: {e})",
            path,
            fix="copy it again or remove it from the capture folder",
        ) from e
    w, h = oriented_size(width, height, exif.orientation)
    return PhotoInfo(path, kind, w, h, exif.orientation, exif)


def _open_heif(path: Path) -> Any:
    """A HEIC/HEIF photo (the iPhone's default) opened by Pillow through pillow-heif, which applies the file's
    rotation and mirroring on decoding (and so reports orientation 1)."""
    import pillow_heif
    from PIL import Image

    pillow_heif.register_heif_opener()
    try:
        return Image.open(path)
    except Exception as e:  # libheif raises various errors on garbage
        raise InputError(f"not a readable HEIC/HEIF image ({type(e).__name__}: {e})", path,
                         fix="copy it again from the phone or remove it from the capture folder") from e


def _probe_heif(path: Path) -> PhotoInfo:
    """HEIC/HEIF header: size (as seen) and EXIF from Pillow (exifread does not read these files)."""
    with _open_heif(path) as im:
        width, height = im.size
        exif = exif_from_pillow(im.getexif())
    return PhotoInfo(path, "heif", width, height, 1, exif)


def exif_from_pillow(tags: Any) -> ExifInfo:
    """:class:`ExifInfo` from a Pillow ``Image.Exif``, orientation left at 1 (the decoder applied it)."""
    sub = tags.get_ifd(PIL_EXIF_IFD)

    def get(tag: int) -> Any:
        return sub.get(tag, tags.get(tag))

    return ExifInfo(
        make=_text(get(PIL_TAGS["make"])), model=_text(get(PIL_TAGS["model"])),
        shutter_s=_num(get(PIL_TAGS["shutter_s"])), iso=_num(get(PIL_TAGS["iso"])),
        f_number=_num(get(PIL_TAGS["f_number"])), focal_length_mm=_num(get(PIL_TAGS["focal_length_mm"])),
        focal_length_35mm=_num(get(PIL_TAGS["focal_length_35mm"])),
        datetime=_text(get(PIL_TAGS["datetime_original"]) or get(PIL_TAGS["datetime"])),
    )


def _libraw_message(e: Exception) -> str:
    msg = e.args[0] if e.args else str(e)
    if isinstance(msg, bytes):
        msg = msg.decode(errors="replace")
    return f"{type(e).__name__}: {msg}"


# ---------------------------------------------------------------------------------------------------- decode


@dataclass
class Decoded:
    linear: np.ndarray  # (H, W, 3) float32, orientation applied
    clipped: np.ndarray  # (H, W) bool
    meta: dict[str, Any]


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    if radius <= 0 or not mask.any():
        return mask
    import cv2

    k = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    return cv2.dilate(mask.astype(np.uint8), k).astype(bool)


def _closed(mask: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: the mask with the photosites between its own filled (a 3 x 3 closing). A light that
    saturates one colour's photosites flags every pixel among them, whose other colours demosaicing reads from
    them (so are at least what they record); the mask grows no further than its outermost photosites."""
    if not mask.any():
        return mask
    import cv2

    k = np.ones((3, 3), np.uint8)
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, k, borderType=cv2.BORDER_REPLICATE).astype(bool)


def _saturated_everywhere(saturated: np.ndarray, colors: np.ndarray | None) -> np.ndarray:
    """``(H, W)`` bool: pixels whose photosites of every colour within :data:`SATURATED_REACH` are saturated.

    Args:
        saturated: ``(H, W)`` per photosite of a mosaic, or ``(H, W, C)`` per channel of a linear raw.
        colors: ``(H, W)`` LibRaw colour index (0..3, 3 = second green) of a mosaic's photosites; None for
            a linear raw.
    """
    import cv2

    size = 2 * SATURATED_REACH + 1
    if colors is None:
        return cv2.erode(saturated.all(axis=2).astype(np.uint8), np.ones((size, size), np.uint8)).astype(bool)
    colors = np.where(colors == 3, 1, colors)
    out = np.ones(saturated.shape, bool)
    for c in np.unique(colors):
        of_c = (colors == c).astype(np.float32)
        # A colour's photosites in the window, and how many of them are saturated: all of them, or not.
        count = cv2.boxFilter(of_c, -1, (size, size), normalize=False, borderType=cv2.BORDER_REPLICATE)
        hits = cv2.boxFilter(of_c * saturated, -1, (size, size), normalize=False, borderType=cv2.BORDER_REPLICATE)
        out &= hits >= count - 0.5
    return out


def _resized(mask: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A raw-sized bool mask at LibRaw's output size (they differ for some sensors' margins)."""
    if mask.shape == shape[:2]:
        return mask
    import cv2

    return cv2.resize(mask.astype(np.uint8), (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST).astype(bool)


def decode_raw(
    info: PhotoInfo,
    *,
    white_balance: tuple[float, float, float],
    demosaic: str = "AHD",
    color_space: Literal["srgb", "camera"] = "srgb",
    black_level: int | None = None,
    white_level: int | None = None,
    clip_fraction: float = 0.98,
    clip_dilate: int = 0,
) -> Decoded:
    """Demosaic a RAW file into linear float RGB (see the module doc for units), plus its clipped mask: the
    pixels whose photosite saturated and those between them (:func:`_closed`), grown by ``clip_dilate`` raw
    pixels."""
    import rawpy

    path = info.path
    wb = np.asarray(white_balance, dtype=np.float64)
    wb = wb / wb[1]
    try:
        with rawpy.imread(str(path)) as r:
            file_black = [int(b) for b in r.black_level_per_channel]
            black = int(black_level) if black_level is not None else min(file_black)
            white = int(white_level) if white_level is not None else int(r.white_level)
            if white <= black:
                raise InputError(
                    f"white level {white} is not above the black level {black}",
                    path,
                    fix="check decode.black_level / decode.white_level",
                )
            raw = r.raw_image_visible
            if black_level is not None:
                thr = black + clip_fraction * (white - black)
                raw_clip = raw >= thr
            else:
                blacks = np.asarray(file_black, dtype=np.float64)
                if raw.ndim == 2 and len(set(file_black)) > 1:
                    per_pixel = blacks[np.clip(r.raw_colors_visible, 0, 3)]
                else:
                    per_pixel = float(black)
                raw_clip = raw >= per_pixel + clip_fraction * (white - per_pixel)
            saturated = _saturated_everywhere(raw_clip, None if raw.ndim == 3 else r.raw_colors_visible)
            if raw_clip.ndim == 3:
                raw_clip = raw_clip.any(axis=2)
            raw_clip = _dilate(_closed(raw_clip), clip_dilate)

            lo, hi = float(wb.min()), float(wb.max())
            headroom = hi / lo * (MATRIX_HEADROOM if color_space == "srgb" else 1.0)
            # LibRaw sets its maximum to user_sat *after* subtracting black: it is the span above black.
            user_sat = int(np.ceil((white - black) * headroom))
            params: dict[str, Any] = dict(
                demosaic_algorithm=rawpy.DemosaicAlgorithm[demosaic],
                use_camera_wb=False,
                use_auto_wb=False,
                user_wb=[float(wb[0]), 1.0, float(wb[2]), 1.0],
                output_color=rawpy.ColorSpace.sRGB if color_space == "srgb" else rawpy.ColorSpace.raw,
                output_bps=16,
                gamma=(1.0, 1.0),
                no_auto_bright=True,
                adjust_maximum_thr=0.0,
                bright=1.0,
                highlight_mode=rawpy.HighlightMode.Clip,
                user_flip=0,  # orientation is applied below, to the image and the mask alike
                user_sat=user_sat,
            )
            if black_level is not None:
                params.update(user_black=int(black_level), user_cblack=[0, 0, 0, 0])
            out = r.postprocess(**params)
    except rawpy.LibRawError as e:
        raise InputError(
            f"LibRaw could not decode the image data ({_libraw_message(e)}); the file is truncated or corrupt",
            path,
            fix="copy it again from the camera/card, or remove it from the capture folder",
        ) from e
    # LibRaw: out = 65535 * (wb / min(wb)) * (raw - black) / user_sat, then the colour matrix.
    factor = user_sat / (white - black) * lo / 65535.0
    linear = out.astype(np.float32) * np.float32(factor)
    overflow = (out >= 65535).any(axis=2)
    clipped = _resized(raw_clip, overflow.shape) | overflow
    # A clipped pixel's value is a lower bound. Where the colour matrix mixed saturated photosites with
    # unsaturated ones it can exceed what any neutral light needs (R 4.3 on the demo), a bound the true light
    # does not meet; capped at the all-channels level it stays a bound every light at least that bright meets.
    np.minimum(linear, np.float32(hi), out=linear, where=clipped[..., None])
    linear[_resized(saturated, overflow.shape)] = np.float32(hi)
    linear = np.ascontiguousarray(apply_orientation(linear, info.orientation))
    clipped = np.ascontiguousarray(apply_orientation(clipped, info.orientation))
    meta = {
        "black_level": black,
        "black_level_per_channel": file_black if black_level is None else [black] * 4,
        "white_level": white,
        "white_balance": wb.tolist(),
        "demosaic": demosaic,
        "color_space": "linear sRGB (LibRaw camera matrix)" if color_space == "srgb" else "camera RGB",
        "libraw_user_sat": user_sat,
    }
    return Decoded(linear, clipped, meta)


def decode_raster(info: PhotoInfo, *, clip_fraction: float = 0.98) -> Decoded:
    """JPEG/PNG/TIFF/HEIC -> linear float RGB (inverse sRGB), EXIF orientation applied, clipped mask."""
    path = info.path
    if info.kind == "jpeg":
        encoded = _read_jpeg(path)
    elif info.kind == "heif":
        encoded = _read_heif(path)
    else:
        encoded = _read_cv2(path, info.kind)
    if encoded.ndim == 2:
        encoded = np.repeat(encoded[..., None], 3, axis=2)
    elif encoded.shape[2] == 4:
        encoded = encoded[..., :3]
    elif encoded.shape[2] != 3:
        raise InputError(f"{encoded.shape[2]}-channel images are not supported", path, fix="save it as RGB")
    if encoded.dtype == np.uint8 or encoded.dtype == np.uint16:
        top = float(np.iinfo(encoded.dtype).max)
        values = encoded.astype(np.float32) / top
        clipped = (encoded >= clip_fraction * top).any(axis=2)
        from .imageio import srgb_to_linear

        linear = srgb_to_linear(values)
        transfer = f"inverse sRGB, {8 * encoded.dtype.itemsize}-bit"
    elif np.issubdtype(encoded.dtype, np.floating):
        linear = encoded.astype(np.float32)
        clipped = np.zeros(linear.shape[:2], bool)
        transfer = "float, taken as linear"
    else:
        raise InputError(f"unsupported sample type {encoded.dtype}", path, fix="save it as 8/16-bit or float")
    clipped = _dilate(clipped, CLIP_DILATE_RASTER)
    linear = np.ascontiguousarray(apply_orientation(linear, info.orientation))
    clipped = np.ascontiguousarray(apply_orientation(clipped, info.orientation))
    return Decoded(linear, clipped, {"transfer": transfer, "white_balance": None})


def _read_jpeg(path: Path) -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(path) as im:
            im.load()  # raises on truncated data (Pillow's default)
            if im.mode not in ("RGB", "L"):
                im = im.convert("RGB")
            return np.asarray(im)
    except (OSError, ValueError, SyntaxError) as e:
        raise InputError(
            f"the JPEG data cannot be decoded ({e}); the file is truncated or corrupt",
            path,
            fix="copy it again from the camera or remove it from the capture folder",
        ) from e


def _read_heif(path: Path) -> np.ndarray:
    """8-bit RGB of a HEIC/HEIF photo (pillow-heif gives 10/12-bit ones as 8-bit), rotation applied."""
    with _open_heif(path) as im:
        try:
            im.load()
        except Exception as e:
            raise InputError(f"the HEIC/HEIF data cannot be decoded ({e}); the file is truncated or corrupt", path,
                             fix="copy it again from the phone or remove it from the capture folder") from e
        return np.asarray(im.convert("RGB") if im.mode != "RGB" else im)


def _read_cv2(path: Path, kind: str) -> np.ndarray:
    import cv2

    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None  # no automatic EXIF rotation
    if image is None:
        raise InputError(
            f"the {kind.upper()} data cannot be decoded; the file is truncated or corrupt",
            path,
            fix="copy it again or remove it from the capture folder",
        )
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
    return image


# -------------------------------------------------------------------------------------------------- resample


def downscale_area(image: np.ndarray, k: int) -> np.ndarray:
    """Average k x k blocks (the bottom/right remainder is cropped)."""
    if k == 1:
        return image
    import cv2

    h, w = image.shape[0] // k, image.shape[1] // k
    a = np.ascontiguousarray(image[: h * k, : w * k])
    return cv2.resize(a, (w, h), interpolation=cv2.INTER_AREA)  # integer factor: the exact block mean


def downscale_any(mask: np.ndarray, k: int) -> np.ndarray:
    """A k x k block is flagged if any of its pixels is."""
    if k == 1:
        return mask
    h, w = mask.shape[0] // k * k, mask.shape[1] // k * k
    return mask[:h, :w].reshape(h // k, k, w // k, k).any(axis=(1, 3))
